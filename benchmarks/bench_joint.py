"""Joint fit of F flights (issue 11): set-up and solve time against the number of flights.

Each flight is RA-66M's vehicle with its own attack-angle program (RA-66M's pitch-over, then an
excitation of its own amplitude and period) and its own altimeter bias (per flight), simulated by
the high-accuracy integrator at the truth with N(0, 1) noise; the aerodynamics (7 CD(Mach) knots,
CL_alpha) are shared. Reports, for F = 1, 2, 4, 8: set-up (code generation cached, collocation of
every flight, assembly of the joint NLP), IPOPT time and iterations, NLP size, and the per-flight
ratios.

Run: ``nice python3 benchmarks/bench_joint.py [--flights 1 2 4 8]``.
"""

from __future__ import annotations

import argparse
import time

import sympy as sp

import rocketid as ri
from rocketid.cases.ra66 import ra66_alpha, ra66_times, ra66_vehicle_model
from rocketid.cases.ra66m import RA66M_MACH_KNOTS, ra66m_truth
from rocketid.diagnostics import with_effects
from rocketid.joint import Flight, joint_estimate, joint_prepare


def _flight(k: int):
    amp, period = 1.0 + 0.25 * k, 10.0 + 2.0 * k

    def alpha(t):
        exc = amp * sp.pi / 180 * sp.sin(2 * sp.pi * (t - 24) / period)
        return sp.Piecewise((ra66_alpha(t), t <= 24), (exc, True))

    def aero(m, fc, a):
        cd = m.table("CD_M", fc.mach, RA66M_MACH_KNOTS, 0.4, bounds=(0.01, 2.0), nominal=0.4)
        cla = m.parameter("CL_alpha", 2.0, bounds=(0.0, 10.0), nominal=2.5)
        return cd, cla * a

    spec = with_effects(ra66_vehicle_model(f"F{k}", "bench flight", alpha, aero).freeze(), ["bias_h"])
    truth = ra66m_truth(spec)
    truth[spec.parameter_names.index("b_h")] = 3.0 * (k % 3 - 1)
    data = ri.simulate_measurements(spec, truth, ra66_times(), seed=100 + k)
    return Flight(f"F{k}", spec, data)


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--flights", type=int, nargs="+", default=[1, 2, 4, 8])
    args = ap.parse_args()
    all_flights = [_flight(k) for k in range(max(args.flights))]
    joint_prepare(all_flights[:1], per_flight=["b_h"])  # warm the code cache
    print("| flights | NLP variables | set-up s | IPOPT s | iterations | set-up per flight | IPOPT per flight |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for F in args.flights:
        t0 = time.perf_counter()
        prep = joint_prepare(all_flights[:F], per_flight=["b_h"])
        setup = time.perf_counter() - t0
        res = joint_estimate(all_flights[:F], per_flight=["b_h"], prepared=prep)
        assert res.success, res.message
        ipopt = res.timings["solve_s"]
        print(f"| {F} | {prep.nlp.n} | {setup:.2f} | {ipopt:.2f} | {res.iterations} | {setup / F:.2f} | "
              f"{ipopt / F:.2f} |", flush=True)


if __name__ == "__main__":
    main()
