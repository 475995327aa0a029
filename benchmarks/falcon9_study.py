"""The numbers of docs/real-telemetry.md: the Falcon 9 first stage fitted to CRS-11 and CRS-12.

For each flight: the base model (no throttle), the diagnosis's location and ranking, the model
with the throttle effect on the flagged span, its residuals per time window against two
model-free references (the reading noise per window, and least-squares cubic splines with knots
every 5 and 2 s), and the same model fitted with the noise estimated (``sigma="estimate"``);
then both flights jointly (aerodynamics, thrust and mass-flow scales shared; attitude, throttle,
lift-off mass and start states per flight), with the quantization's sigma and with the noise
estimated. The events files are printed beside the findings as the answer key; nothing reads
them as input.

Run: ``nice python3 benchmarks/falcon9_study.py`` (about 5-10 minutes on 2 busy cores);
``nice python3 benchmarks/falcon9_study.py --variants [CRS-12]`` fits CRS-11 (or CRS-12) with the throttle and each
model change tried against the misfit after 90 s (docs/real-telemetry.md, "After 90 s");
``--load-limit`` runs the whole study with the attitude bounded by a load limit on both flights
(``rocketid.examples.falcon9.LOAD_LIMIT``).
"""

from __future__ import annotations

import math
import sys
import time

import numpy as np
import rocketid as ri
from rocketid.diagnostics import rank_candidates, throttle_effect, with_effects
from rocketid.diagnostics.locate import locate
from rocketid.estimability import uncertainty
from rocketid.examples.falcon9 import (FLIGHTS, LOAD_LIMIT, MACH_KNOTS, falcon9_events, falcon9_measurements,
                                       falcon9_model, reading_noise, smooth_residuals)
from rocketid.joint import Flight, joint_estimate

CANDIDATES = ["thrust_level", "transonic_drag", "bias_v", "bias_h", "back_pressure"]
EDGES = (20, 50, 90, 110, 140)
#: The model changes tried against the misfit after 90 s (keywords of ``falcon9_model``).
VARIANTS = {
    "as shipped (attitude +-3 deg, knots every 10 s)": {},
    "attitude +-10 deg": {"alpha_max": math.radians(10.0)},
    "attitude bound q-alpha 1571 Pa rad, at most 15 deg": LOAD_LIMIT,
    "attitude knots every 5 s": {"alpha_step": 5.0},
    "Earth rotation (28.5 N, heading 45 deg)": {"earth_rotation": True},
    "drag knots 3.5, 5, 7 added above Mach 2.5": {"mach_knots": MACH_KNOTS[:5] + (3.5, 5.0, 7.0)},
}


def rms_by_window(residuals, times, edges=EDGES):
    """RMS of ``residuals`` in each window between consecutive ``edges``."""
    r, t = np.asarray(residuals), np.asarray(times)
    return [float(np.sqrt(np.mean(r[(t >= a) & (t < b)] ** 2))) for a, b in zip(edges[:-1], edges[1:])]


def spline_floor(data, channel, step):
    """Residuals of a least-squares cubic spline with knots every ``step`` s (no model)."""
    return smooth_residuals(data, step)[channel]


def chi2_at_reading_noise(fit, data, noise, n_parameters):
    """chi2/dof of ``fit`` with the (whole-window) reading noise as each channel's sigma."""
    n = sum(data[c].values.size for c in noise)
    return sum(float(np.sum((fit.residuals[c] / noise[c]) ** 2)) for c in noise) / (n - n_parameters)


def fmt(xs, f="{:.3f}"):
    return ", ".join(f.format(x) for x in xs)


def report_windows(fit, data, noise, n_parameters):
    """Print chi2/dof at the reading noise and the RMS per window beside the model-free references."""
    print(f"  chi2/dof with the reading noise as sigma: {chi2_at_reading_noise(fit, data, noise, n_parameters):.3f}")
    for c in ("v", "h"):
        f = "{:.3f}" if c == "v" else "{:.1f}"
        t = data[c].times
        print(f"  RMS {c} by window {EDGES}: model {fmt(rms_by_window(fit.residuals[c], t), f)}")
        print("      reading noise per window: "
              + fmt([reading_noise(data.window(a, b))[c] for a, b in zip(EDGES[:-1], EDGES[1:])], f))
        for step in (5.0, 2.0):
            print(f"      spline, knots every {step:g} s: " + fmt(rms_by_window(spline_floor(data, c, step), t), f))
    t = data["v"].times
    late = t >= 90.0
    print(f"  RMS v 90-140 s: model {np.sqrt(np.mean(fit.residuals['v'][late] ** 2)):.3f}, spline with knots every "
          f"5 s {np.sqrt(np.mean(spline_floor(data, 'v', 5.0)[late] ** 2)):.3f}")
    # 1 s means of the residuals (model - measured) beside a 10 s spline's, and the speed's slope per 1 s
    spl = -spline_floor(data, "v", 10.0)
    print("  1 s mean residual v, model / 10 s spline: " + " ".join(
        f"{a:.0f}:{np.mean(fit.residuals['v'][(t >= a) & (t < a + 1)]):+.2f}/{np.mean(spl[(t >= a) & (t < a + 1)]):+.2f}"
        for a in np.arange(108.0, 126.0)))
    y = data["v"].values
    print("  slope of v over 1 s pieces, m/s^2: " + " ".join(
        f"{a:.0f}:{np.polyfit(t[(t >= a) & (t < a + 1)], y[(t >= a) & (t < a + 1)], 1)[0]:.1f}"
        for a in np.arange(100.0, 140.0)))


def acf(r, lags=(1, 15, 30)):
    """Autocorrelation of a residual series at the given lags (samples; 30 is about 1 s of broadcast)."""
    r = np.asarray(r, float) - np.mean(r)
    return [float(np.dot(r[:-k], r[k:]) / np.dot(r, r)) for k in lags]


def colour_report(fit_s, fit, data, spec):
    """How long the errors last, model-free and in the residuals of ``fit_s`` (the noise estimated), and what
    it does to the standard errors of ``fit`` (the quantization's sigma; the sandwich takes the residuals' own
    scale, so the stated sigma enters only through the priors' relative weight): the smooth curve's RMS over the window (the floor a continuous trajectory can reach), the
    autocorrelation at 1, 15 and 30 samples, and the coloured-residual standard errors against white ones
    scaled by sqrt(chi2/dof) (the sigma the residuals give)."""
    smooth = smooth_residuals(data, 5.0)
    for c in ("h", "v"):
        print(f"  {c}: smooth-curve floor RMS {np.sqrt(np.mean(smooth[c] ** 2)):.3g} (model {fit_s.rms[c]:.3g}); "
              f"autocorrelation at 1, 15, 30 samples: data about the curve {fmt(acf(smooth[c]), '{:.2f}')}, "
              f"model residual {fmt(acf(fit_s.residuals[c]), '{:.2f}')}")
    try:
        white = uncertainty(fit).standard_errors * np.sqrt(fit.chi2_per_dof)
        col = uncertainty(fit, coloured=True)
    except ri.SensitivityError as exc:
        print(f"  no standard errors: {exc}")
        return
    ratio = col.standard_errors / white
    print(f"  coloured-residual standard errors / white (x sqrt(chi2/dof) = {np.sqrt(fit.chi2_per_dof):.3g}): median "
          f"{np.median(ratio):.2f}, range {ratio.min():.2f}-{ratio.max():.2f}; {col.notes[-1]}")
    for name in ("k_P", "k_mdot", "dm0", *(f"CD_{j}" for j in range(6))):
        i = spec.parameter_names.index(name)
        print(f"    {name:7s} {fit.p[i]: .4g} +- {white[i]:.3g} (white) +- {col.standard_errors[i]:.3g} (coloured)")


def throttle_fit(label, data, base):
    """The base fit, its diagnosis, and the refit with the throttle; returns the throttled spec and fit."""
    ev = falcon9_events(label)
    noise = reading_noise(data)
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
    print(f"throttle: chi2/dof {fit.chi2_per_dof:.4g}, RMS h {fit.rms['h']:.1f} m, v {fit.rms['v']:.3f} m/s "
          f"({time.perf_counter() - t0:.1f} s)")
    return spec, fit, knots


def main(model_kw=None):
    flights = []
    for label in FLIGHTS:
        data = falcon9_measurements(label)
        noise = reading_noise(data)
        spec, fit, knots = throttle_fit(label, data, falcon9_model(data, **(model_kw or {})))
        try:
            se = uncertainty(fit).standard_errors
        except ri.SensitivityError as exc:
            se = np.full(len(spec.parameters), np.nan)
            print(f"  no standard errors: {exc}")
        report_windows(fit, data, noise, len(spec.parameters))
        print("  throttle reduction d(t): " + ", ".join(
            f"{t:g}s {fit.value(f'd_throttle_{j}'):.3f}" for j, t in enumerate(knots) if 0 < j < len(knots) - 1))
        for name in ("k_P", "k_mdot", "dm0", *(f"CD_{j}" for j in range(6))):
            i = spec.parameter_names.index(name)
            print(f"  {name:7s} {fit.p[i]: .4g} +- {se[i]:.3g}")
        print(f"  at bounds: {', '.join(str(s) for s, _ in fit.active_bounds()) or 'none'}")
        # the noise estimated with the parameters (maximum likelihood), from the fit above
        t0 = time.perf_counter()
        fit_s = ri.estimate(spec, data, sigma="estimate", warm_start=fit, options={"max_iter": 500})
        print(f"noise estimated ({time.perf_counter() - t0:.1f} s): sigma h {fit_s.sigma['h']:.1f} m, "
              f"v {fit_s.sigma['v']:.3f} m/s (quantization 28.9 m, 0.080 m/s; reading noise "
              f"{noise['h']:.1f} m, {noise['v']:.3f} m/s); RMS v by window "
              + fmt(rms_by_window(fit_s.residuals["v"], data["v"].times)))
        colour_report(fit_s, fit, data, spec)
        flights.append(Flight(label, spec, data))
    per = sorted({n for fl in flights for n in fl.spec.parameter_names
                  if n.startswith(("alpha", "d_throttle")) or n == "dm0"})
    for sigma in (None, "estimate"):
        t0 = time.perf_counter()
        joint = joint_estimate(flights, per_flight=per, options={"max_iter": 500},
                               **({"sigma": sigma} if sigma else {}))
        print(f"\n== joint, sigma {sigma or 'quantization'} ({time.perf_counter() - t0:.1f} s)")
        print(joint.summary())
        for fl, r in zip(flights, joint.flights):
            noise = reading_noise(fl.data)
            k = len(joint.layout.shared) + sum(1 for n in fl.spec.parameter_names if n in per)
            k += sum(1 for n in fl.spec.parameter_names if n.endswith("_0") and n in ("h_0", "v_0", "theta_0"))
            print(f"  {fl.label}: chi2/dof at the reading noise {chi2_at_reading_noise(r, fl.data, noise, k):.3f}; "
                  f"RMS v by window " + fmt(rms_by_window(r.residuals["v"], fl.data["v"].times))
                  + "; RMS h by window " + fmt(rms_by_window(r.residuals["h"], fl.data["h"].times), "{:.1f}"))
        if sigma:
            print(f"  sigmas: {joint.sigma}")
        try:
            se = dict(zip(joint.layout.names, joint.standard_errors))
            print("  shared: " + ", ".join(f"{n} {joint.theta[i]:.3g} +- {se[n]:.2g}"
                                           for i, n in enumerate(joint.layout.names) if n in joint.layout.shared))
        except ri.SensitivityError as exc:
            print("  shared: " + ", ".join(f"{n} {joint.theta[i]:.3g}" for i, n in enumerate(joint.layout.names)
                                           if n in joint.layout.shared) + f"; no standard errors: {exc}")
    print(joint.estimability().summary())


def variants(label: str = "CRS-11"):
    """One flight (CRS-11 by default) with the throttle (knots as the diagnosis finds them) under each model
    change."""
    data = falcon9_measurements(label)
    noise = reading_noise(data)
    knots = None
    for name, kw in VARIANTS.items():
        base = falcon9_model(data, **kw)
        if knots is None:
            spec, fit, knots = throttle_fit(label, data, base)
        else:
            spec = with_effects(base, [throttle_effect(knots)])
            fit = ri.estimate(spec, data, options={"max_iter": 500})
        cd = [fit.value(f"CD_{j}") for j in range(len(kw.get("mach_knots", MACH_KNOTS)))]
        print(f"\n-- {name}: chi2/dof (quantization sigma) {fit.chi2_per_dof:.3g}, at the reading noise "
              f"{chi2_at_reading_noise(fit, data, noise, len(spec.parameters)):.3f}; RMS v by window "
              + fmt(rms_by_window(fit.residuals['v'], data['v'].times))
              + "; RMS h by window " + fmt(rms_by_window(fit.residuals['h'], data['h'].times), "{:.1f}") + "; CD "
              + fmt(cd, "{:.2f}") + "; attitude knots at a bound: "
              + str(sum(1 for s, _ in fit.active_bounds() if str(s).startswith("alpha"))))


if __name__ == "__main__":
    args = sys.argv[1:]
    if "--variants" in args:
        variants(*[a for a in args if a.startswith("CRS-")][:1])
    else:
        main(LOAD_LIMIT if "--load-limit" in args else None)
