"""Benchmark (issue 9): the rounding level of the predictor's dual residual, and what IPOPT does
from the predictions.

Run ``python3 benchmarks/bench_predictor_floor.py [--draws 100] [--seed 7] [--steps 16]``. On
RA-66 (noisy data, seed 0, the study's settings), for each draw of one run the simplified
Newton steps of :class:`rocketid.sensitivity.SolutionPredictor` are taken from the reference
solution ``--steps`` times whatever they reach, and the largest dual residual ``|grad f + J^T
lambda|`` is recorded at each step. Once the steps have converged (primal residual below a
tenth of IPOPT's tolerance) the residual no longer falls: the level it jitters at is the
rounding level of its evaluation, printed against the predictor's dual aim (a tenth of IPOPT's
scaled tolerance) and IPOPT's own. Then, for the same draws, the prediction as the sampling
makes it (:meth:`~rocketid.sensitivity.SolutionPredictor.predict`): how many converge, how
many stopped at the rounding level instead of the aim, and IPOPT's iterations from them.
"""

from __future__ import annotations

import argparse
from dataclasses import replace

import numpy as np

from bench_draw_bounds import ra66_worker
from rocketid.sampling.worker import evaluate_draw, trial_parameters


def main() -> None:
    ap = argparse.ArgumentParser()
    ap.add_argument("--draws", type=int, default=100)
    ap.add_argument("--seed", type=int, default=7)
    ap.add_argument("--steps", type=int, default=16)
    args = ap.parse_args()
    ctx = ra66_worker()
    est, ref, pr = ctx.recipe.estimability, ctx.reference, ctx.predictor
    plain = replace(pr, surface=None)
    dual_aim, primal_aim = pr._tolerances(1e-8)
    floors, reach, first = [], [], []
    stats = {"converged": 0, "at aim": 0, "stalled": 0, "none": 0}
    iterations = []
    for k in range(1, args.draws + 1):
        q2 = est.q2_of(trial_parameters(ctx.recipe, args.seed, k))
        nlp = ref.nlp.with_offset(est.transform(q2).c)
        x, lam = np.array(pr.solution.x, dtype=float), np.array(pr.solution.mult_g, dtype=float)
        meq = nlp.layout.equality_rows.stop
        duals, primals = [], []
        for _ in range(args.steps + 1):
            r_dual, r_primal = pr.residual(nlp, x, lam)
            duals.append(float(np.max(np.abs(r_dual))))
            primals.append(float(np.max(np.abs(r_primal))))
            d = pr.lu.solve(-np.concatenate([r_dual, r_primal]))
            x, lam = x + d[:nlp.n], lam.copy()
            lam[:meq] += d[nlp.n:]
        at = [i for i, p in enumerate(primals) if p <= primal_aim]
        if at:
            tail = duals[at[0] + 2:] or duals[at[0]:]           # two steps past the primal aim: the jitter
            floors.append(float(np.median(tail)))
            reach.append(min(duals[at[0]:]))
            first.append(at[0])
        got = plain.predict(nlp)
        if got is None:
            stats["none"] += 1
        elif got.converged:
            stats["converged"] += 1
            stats["at aim" if got.dual <= dual_aim else "stalled"] += 1
        iterations.append(evaluate_draw(ctx, args.seed, k).iterations)
    floors, reach = np.array(floors), np.array(reach)
    print(f"RA-66 noisy seed 0, run seed {args.seed}, draws 1-{args.draws}, {args.steps} steps from the reference")
    print(f"dual aim {dual_aim:.3g} (a tenth of IPOPT's {10 * dual_aim:.3g}), primal aim {primal_aim:.3g}")
    print(f"primal aim reached after {min(first)}-{max(first)} steps in {len(floors)} draws")
    print(f"dual residual after it (median of the later steps): median {np.median(floors):.2g}, "
          f"5-95 % {np.percentile(floors, 5):.2g}-{np.percentile(floors, 95):.2g}, max {floors.max():.2g}; "
          f"above the aim in {int(np.sum(floors > dual_aim))} draws")
    print(f"lowest dual residual any step reached: median {np.median(reach):.2g}, max {reach.max():.2g}; "
          f"never at the aim in {int(np.sum(reach > dual_aim))} draws")
    print(f"predict() from the reference: converged {stats['converged']} of {args.draws} "
          f"({stats['at aim']} at the aim, {stats['stalled']} stopped at the rounding level), none {stats['none']}")
    its = np.array(iterations)
    print(f"IPOPT iterations per draw from the sampling's predictions: mean {its.mean():.2f}, max {its.max()}, "
          f"0 in {int(np.sum(its == 0))}")


if __name__ == "__main__":
    main()
