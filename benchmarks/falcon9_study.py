"""The numbers of docs/real-telemetry.md: the Falcon 9 first stage fitted to CRS-11 and CRS-12.

For each flight: the base model (no throttle), the diagnosis's location and ranking, the model
with the throttle effect on the flagged span, and the RMS residuals against the reading noise;
then both flights jointly (aerodynamics, thrust and mass-flow scales shared; attitude, throttle,
lift-off mass and start states per flight). The events files are printed beside the findings as
the answer key; nothing reads them as input.

Run: ``nice python3 benchmarks/falcon9_study.py`` (about 5-10 minutes on 2 busy cores).
"""

from __future__ import annotations

import time

import numpy as np

import rocketid as ri
from rocketid.diagnostics import rank_candidates, throttle_effect, with_effects
from rocketid.diagnostics.locate import locate
from rocketid.estimability import uncertainty
from rocketid.examples.falcon9 import FLIGHTS, falcon9_events, falcon9_measurements, falcon9_model, reading_noise
from rocketid.joint import Flight, joint_estimate

CANDIDATES = ["thrust_level", "transonic_drag", "bias_v", "bias_h", "back_pressure"]


def rms_by_window(fit, data, channel, edges=(20, 50, 90, 110, 140)):
    r, t = fit.residuals[channel], data[channel].times
    return [float(np.sqrt(np.mean(r[(t >= a) & (t < b)] ** 2))) for a, b in zip(edges[:-1], edges[1:])]


def main():
    flights = []
    for label in FLIGHTS:
        data = falcon9_measurements(label)
        ev = falcon9_events(label)
        noise = reading_noise(data)
        base = falcon9_model(data)
        t0 = time.perf_counter()
        fit0 = ri.estimate(base, data, options={"max_iter": 500})
        print(f"\n== {label}: answer key throttle-down {ev['throttle_down_start']}-{ev['throttle_down_end']} s, "
              f"max-q {ev['maxq']} s; reading noise h {noise['h']:.1f} m, v {noise['v']:.3f} m/s")
        print(f"base: chi2/dof {fit0.chi2_per_dof:.4g}, RMS h {fit0.rms['h']:.1f} m, v {fit0.rms['v']:.3f} m/s "
              f"({time.perf_counter() - t0:.1f} s); at bounds: {', '.join(str(s) for s, _ in fit0.active_bounds())}")
        loc = locate(fit0)
        for f in loc.findings[:4]:
            print(f"  finding: {f.text}")
        v = sorted([f for f in loc.findings if f.channel == "v"][:2], key=lambda f: f.t_start)
        lo, hi = 5.0 * np.floor(v[0].t_start / 5.0), 5.0 * np.ceil(v[1].t_end / 5.0)
        knots = np.arange(lo, min(hi, base.tf - 10.0) + 1e-9, 5.0)
        print(f"  speed residual turns from {v[0].sign:+d} to {v[1].sign:+d} at "
              f"{0.5 * (v[0].t_end + v[1].t_start):.1f} s; throttle knots {knots[0]:g}-{knots[-1]:g} s every 5 s")
        rk = rank_candidates(fit0, CANDIDATES + [throttle_effect(knots)])
        print("  ranking: " + ", ".join(f"{c.name} (drop of J {c.predicted_drop:.3g})" for c in rk.candidates))
        # refined shape for the refit: knots every 2.5 s over the same span (the ranking's 5 s knots
        # name the effect; the steps of a real throttle need the finer ones)
        knots = np.arange(knots[0], knots[-1] + 1e-9, 2.5)
        spec = with_effects(base, [throttle_effect(knots)])
        t0 = time.perf_counter()
        fit = ri.estimate(spec, data, options={"max_iter": 500})
        try:
            se = uncertainty(fit).standard_errors
        except ri.SensitivityError as exc:
            se = np.full(len(spec.parameters), np.nan)
            print(f"  no standard errors: {exc}")
        print(f"throttle: chi2/dof {fit.chi2_per_dof:.4g}, RMS h {fit.rms['h']:.1f} m, v {fit.rms['v']:.3f} m/s "
              f"({time.perf_counter() - t0:.1f} s)")
        print("  RMS v by window 20-50/50-90/90-110/110-140 s: "
              + ", ".join(f"{x:.3f}" for x in rms_by_window(fit, data, "v")))
        print("  RMS h by window: " + ", ".join(f"{x:.1f}" for x in rms_by_window(fit, data, "h")))
        print("  throttle reduction d(t): " + ", ".join(
            f"{t:g}s {fit.value(f'd_throttle_{j}'):.3f}" for j, t in enumerate(knots) if 0 < j < len(knots) - 1))
        for name in ("k_P", "k_mdot", "dm0", *(f"CD_{j}" for j in range(6))):
            i = spec.parameter_names.index(name)
            print(f"  {name:7s} {fit.p[i]: .4g} +- {se[i]:.3g}")
        print(f"  at bounds: {', '.join(str(s) for s, _ in fit.active_bounds()) or 'none'}")
        flights.append(Flight(label, spec, data))
    per = sorted({n for fl in flights for n in fl.spec.parameter_names
                  if n.startswith(("alpha", "d_throttle")) or n == "dm0"})
    t0 = time.perf_counter()
    joint = joint_estimate(flights, per_flight=per, options={"max_iter": 500})
    print(f"\n== joint ({time.perf_counter() - t0:.1f} s)")
    print(joint.summary())
    for fl, r in zip(flights, joint.flights):
        print(f"  {fl.label}: RMS v by window " + ", ".join(f"{x:.3f}" for x in rms_by_window(r, fl.data, "v")))
    print(joint.estimability().summary())


if __name__ == "__main__":
    main()
