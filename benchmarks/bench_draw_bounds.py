"""Benchmark (issue 9): sampling draws whose predicted solution crosses a bound of p.

Run ``python3 benchmarks/bench_draw_bounds.py [--draws 300] [--seed 1]``. On RA-66 (noisy data,
seed 0, the study's settings), for each draw of one run: whether the predictor's solution stays
within the bounds, and for the draws whose solution crosses one, the (7.9) solve started three
ways: from the prediction held on the crossed bounds (``Prediction.active``, what the sampling
does), from the prediction across the bound (``hold=False``, the path before f825809), and from
the reference solution (the path from f825809 until the held prediction). Prints iterations,
wall times and the largest objective difference between the starts.
"""

from __future__ import annotations

import argparse
import collections
import math
import time
from dataclasses import replace

import numpy as np

import rocketid as ri
from rocketid.estimability import estimate_q1
from rocketid.sampling import SamplingSettings, prepare_sampling
from rocketid.sampling.worker import WorkerContext, trial_parameters
from rocketid.solve import fit_nlp


def ra66_worker() -> WorkerContext:
    """A sampling worker's context (reference solution, predictor) on RA-66's noisy data, seed 0, with the
    study's sampling settings: what the benchmarks of the draws measure."""
    spec = ri.ra66()
    data = ri.simulate_measurements(spec, ri.ra66_truth(spec), ri.ra66_times(), seed=0)
    prep = ri.prepare(spec, data)
    return WorkerContext.build(prepare_sampling(prep, settings=SamplingSettings()).recipe, prep)


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--draws", type=int, default=300)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args()
    ctx = ra66_worker()
    est, ref = ctx.recipe.estimability, ctx.reference
    rows = []
    within = collections.Counter()
    for k in range(1, args.draws + 1):
        q2 = est.q2_of(trial_parameters(ctx.recipe, args.seed, k))
        nlp = ref.nlp.with_offset(est.transform(q2).c)
        across = ctx.predictor.predict(nlp, hold=False)
        if across is None or across.feasible:
            within[across is not None] += 1
            continue
        held = ctx.predictor.predict(nlp)
        timed = []
        for pred in (held if held.feasible else None, across):
            t = time.perf_counter()
            if pred is None:
                timed.append((None, math.nan, math.nan))
                continue
            r = fit_nlp(ctx.prepared, nlp, pred.x, warm=replace(ref.solution, x=pred.x, mult_g=pred.mult_g))
            timed.append((r.iterations, time.perf_counter() - t, r.objective))
        t = time.perf_counter()
        b = estimate_q1(ctx.prepared, est, q2, warm_start=ref)
        timed.append((b.iterations, time.perf_counter() - t, b.objective))
        objs = [o for _, _, o in timed if math.isfinite(o)]
        rows.append((k, held.active, [i for i, _, _ in timed], [w for _, w, _ in timed],
                     (max(objs) - min(objs)) / min(objs)))
    print(f"draws {args.draws}; predictions within the bounds {within[True]}, none {within[False]}, "
          f"across a bound {len(rows)}")
    for k, active, its, ws, dobj in rows:
        print(f"  draw {k}: rows held {list(active)}; iterations held / across / reference {its}; "
              f"ms {', '.join(f'{1e3 * w:.1f}' for w in ws)}; objectives within {dobj:.1g} (relative)")
    if rows:
        its = np.array([r[2] for r in rows], dtype=float)
        ws = np.array([r[3] for r in rows], dtype=float)
        print("mean iterations held / across / reference: " + ", ".join(f"{v:.2f}" for v in np.nanmean(its, axis=0)))
        print("mean ms held / across / reference: " + ", ".join(f"{1e3 * v:.1f}" for v in np.nanmean(ws, axis=0)))
        print(f"largest relative objective difference {max(r[4] for r in rows):.2g}")


if __name__ == "__main__":
    main()
