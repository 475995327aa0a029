"""A sampled input at 10 ms: simulation and fit time (issue 11, item 6).

RA-66 with its attack-angle program given as samples every 10 ms (``m.input(times=, values=)``)
instead of an expression. The simulator used to restart the integrator at every sample (6600
segments); it restarts only at the samples where the input has a kink.

    PYTHONPATH=src python3 benchmarks/bench_sampled_input.py
"""

from __future__ import annotations

import importlib
import time

import numpy as np
import sympy as sp

import rocketid as ri
from rocketid.cases.ra66 import RA66_P0, ra66_alpha
from rocketid.cases.vehicle import RA66_VEHICLE
from rocketid.physics.ascent import ascent_dynamics, ascent_states, flight_conditions

rsim = importlib.import_module("rocketid.simulate")  # the module (rocketid.simulate is also the function)


def sampled_ra66(step: float = 0.01) -> ri.ModelSpec:
    """RA-66 with alpha sampled every ``step`` seconds."""
    m = ri.Model("RA-66, sampled alpha", 0.0, 66.0)
    st = ascent_states(m)
    fc = flight_conditions(m, st)
    tt = np.linspace(0.0, 66.0, int(round(66.0 / step)) + 1)
    f = sp.lambdify(m.t, ra66_alpha(m.t), modules="numpy")
    alpha = m.input("alpha", times=tt, values=np.array([float(f(x)) for x in tt]))
    terms = RA66_VEHICLE.declare(m)
    cd = m.piecewise_linear("CD", np.linspace(0, 66, 7), list(RA66_P0[:7]), bounds=(1e-4, 1.0), nominal=0.5)
    cl = m.parameter("CL", guess=RA66_P0[7], bounds=(1e-4, 1.0), nominal=0.1)
    ascent_dynamics(m, st, fc, thrust=terms.thrust, mass=terms.mass, area=terms.area, cd=cd, cl=cl, alpha=alpha)
    for s in (st.x, st.h, st.v):
        m.output(str(s), s, sigma=1.0)
    return m.freeze()


def best(fn, repeat=3):
    out = []
    for _ in range(repeat):
        t0 = time.perf_counter()
        value = fn()
        out.append(time.perf_counter() - t0)
    return min(out), value


def main():
    ref = ri.ra66()
    truth = ri.ra66_truth(ref)
    spec = sampled_ra66()
    p = spec.parameter_vector(dict(zip(ref.parameter_names, truth)))
    times = ri.ra66_times()
    for tol in (1e-8, 1e-12):
        s_ref, tr_ref = best(lambda: ri.simulate(ref, truth, times, rtol=tol, atol=tol))
        s, tr = best(lambda: ri.simulate(spec, p, times, rtol=tol, atol=tol))
        # the previous behaviour: a restart at every sample (every slope change counts as a kink)
        factor, rsim.KINK_FACTOR = rsim.KINK_FACTOR, 0.0
        try:
            s_old, tr_old = best(lambda: ri.simulate(spec, p, times, rtol=tol, atol=tol), repeat=1)
        finally:
            rsim.KINK_FACTOR = factor
        print(f"simulate rtol {tol:g}: sampled alpha {s:.3f} s (restarting at every sample: {s_old:.3f} s), "
              f"expression alpha {s_ref:.3f} s; max |state difference| to the restarting one "
              f"{np.max(np.abs(tr.states - tr_old.states)):.2e}, to the expression "
              f"{np.max(np.abs(tr.states - tr_ref.states)):.2e}")
    data = ri.simulate_measurements(ref, truth, times, seed=0)
    s, fit = best(lambda: ri.estimate(spec, data), repeat=2)
    s_ref, fit_ref = best(lambda: ri.estimate(ref, data), repeat=2)
    print(f"estimate: sampled alpha {s:.2f} s (IPOPT {fit.timings['solve_s']:.2f} s), expression alpha {s_ref:.2f} s "
          f"(IPOPT {fit_ref.timings['solve_s']:.2f} s); max |p difference| {np.max(np.abs(fit.p - fit_ref.p)):.2e}")


if __name__ == "__main__":
    main()
