"""Benchmark (issue 9): sampling draws whose predicted solution crosses a bound of p.

Run ``python3 benchmarks/bench_draw_bounds.py [--draws 300] [--seed 1]``. On RA-66 (noisy data,
seed 0, the study's settings), for each draw of one run: whether the predictor's solution stays
within the bounds (``Prediction.feasible``), and the (7.9) solve started from the prediction and
from the reference solution (iterations, wall time, objective). Prints the counts and means: the
reason the sampling starts a draw whose prediction crosses a bound from the reference.
"""

from __future__ import annotations

import argparse
import collections
import time
from dataclasses import replace

import numpy as np

import rocketid as ri
from rocketid.estimability import estimate_q1
from rocketid.sampling import SamplingSettings, prepare_sampling
from rocketid.sampling.worker import WorkerContext, trial_parameters
from rocketid.solve import fit_nlp


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--draws", type=int, default=300)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    spec = ri.ra66()
    data = ri.simulate_measurements(spec, ri.ra66_truth(spec), ri.ra66_times(), seed=0)
    prep = ri.prepare(spec, data)
    ctx = WorkerContext.build(prepare_sampling(prep, settings=SamplingSettings()).recipe, prep)
    est, ref = ctx.recipe.estimability, ctx.reference
    rows = []
    for k in range(1, args.draws + 1):
        q2 = est.q2_of(trial_parameters(ctx.recipe, args.seed, k))
        nlp = ref.nlp.with_offset(est.transform(q2).c)
        pred = ctx.predictor.predict(nlp)
        t = time.perf_counter()
        # IPOPT from the prediction whatever it is (the path before the fix)
        a = fit_nlp(ctx.prepared, nlp, pred.x, warm=replace(ref.solution, x=pred.x, mult_g=pred.mult_g))
        ta = time.perf_counter() - t
        t = time.perf_counter()
        b = estimate_q1(ctx.prepared, est, q2, warm_start=ref)
        tb = time.perf_counter() - t
        rows.append((pred.feasible, a.iterations, b.iterations, ta, tb, abs(a.objective - b.objective) / b.objective))
    r = np.array(rows, dtype=float)
    f = r[:, 0] == 1
    print(f"draws {len(r)}; predictions within the bounds {int(f.sum())}, across a bound {int((~f).sum())}")
    print("iterations from the prediction, within:", dict(collections.Counter(r[f, 1].astype(int))),
          "across:", dict(collections.Counter(r[~f, 1].astype(int))))
    print("iterations from the reference, across:", dict(collections.Counter(r[~f, 2].astype(int))))
    if (~f).any():
        print(f"ms per solve across a bound: from the prediction {r[~f, 3].mean() * 1e3:.1f}, "
              f"from the reference {r[~f, 4].mean() * 1e3:.1f}")
    print(f"ms per solve within: from the prediction {r[f, 3].mean() * 1e3:.1f}")
    print(f"largest relative objective difference {r[:, 5].max():.2g}")


if __name__ == "__main__":
    main()
