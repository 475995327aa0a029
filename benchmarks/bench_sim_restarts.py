"""Restarting the integrator at a sampled input's samples: time and accuracy (issue 8, speed).

The simulator restarts ``solve_ivp`` only where a sampled input has a kink (``simulate.KINK_FACTOR``), so that a
10 ms table is not 6600 integrations. A coarse table (Stage-30's attitude program every 0.5 s) has a small kink at
every sample, and DOP853 rejects steps at each: this benchmark times the simulation of Stage-30 over its horizon
with the rule as it is (``KINK_FACTOR`` 10) against a restart at every sample (``KINK_FACTOR`` 0), at the two
tolerances the diagnosis uses (1e-10 for hold-out predictions and the noise band, 1e-8 for starting states), for
attitude tables of several steps, best of ``--repeat`` runs, with each run's largest downrange error against a
restart-at-every-sample run at 1e-12 (the reference).

    PYTHONPATH=src python3 benchmarks/bench_sim_restarts.py [--steps 0.5 0.25 0.1 0.05 0.02] [--repeat 2]
"""

from __future__ import annotations

import argparse
import importlib
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "vehicles"))

import rocketid as ri  # noqa: E402
import stage30 as S  # noqa: E402

rsim = importlib.import_module("rocketid.simulate")  # the module (rocketid.simulate is also the function)


def one(spec, p, times, rtol: float, kink_factor: float, repeat: int) -> tuple[float, np.ndarray]:
    rsim.KINK_FACTOR = kink_factor
    best, traj = np.inf, None
    for _ in range(repeat):
        t0 = time.perf_counter()
        traj = ri.simulate(spec, p, times, rtol=rtol, atol=rtol)
        best = min(best, time.perf_counter() - t0)
    return best, traj.states


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--steps", type=float, nargs="*", default=[0.5, 0.25, 0.1, 0.05, 0.02])
    ap.add_argument("--repeat", type=int, default=2)
    args = ap.parse_args(argv)
    default = rsim.KINK_FACTOR
    print("| table step s | rtol | kinks only: s, x error m | every sample: s, x error m | ratio |")
    print("| --- | --- | --- | --- | --- |")
    try:
        for step in args.steps:
            S.PROGRAM_STEP = step
            spec = S.build_model()
            spec = spec.freeze() if hasattr(spec, "freeze") else spec
            p = spec.parameter_vector(None)
            times = np.linspace(spec.t0, spec.tf, 400)
            _, ref = one(spec, p, times, 1e-12, 0.0, 1)
            for rtol in (1e-10, 1e-8):
                a, sa = one(spec, p, times, rtol, default, args.repeat)
                b, sb = one(spec, p, times, rtol, 0.0, args.repeat)
                ea, eb = (float(np.max(np.abs(s[:, 0] - ref[:, 0]))) for s in (sa, sb))
                print(f"| {step:g} | {rtol:g} | {a:.3f}, {ea:.1e} | {b:.3f}, {eb:.1e} | {b / a:.2f} |", flush=True)
    finally:
        rsim.KINK_FACTOR = default
    return 0


if __name__ == "__main__":
    sys.exit(main())
