"""Benchmark (issue 9): one draw of the statistic-criterion sampling against the CasADi peer's warm re-solve.

Run ``nice python3 benchmarks/bench_draw.py`` (about a minute; ``--draws D`` draws per mesh,
default 40; ``--json PATH`` to keep the numbers). Prints Markdown tables with the machine
load (``uptime``) beside each.

For each mesh (rocketid's default, 66 elements with K = 4, which the study uses; and 66
elements with K = 3, the issue's CasADi figure), on RA-66 with noisy data (seed 0, the same
arrays for both tools) and the study's settings (nominal scaling, np = 5):

* **rocketid, draw** -- ``evaluate_draw`` (steps 5-7: p_trial, q2, the (7.9) solve, eta)
  with the worker's context, whose predictor starts IPOPT from the solution that the KKT
  factors at the reference predict;
* **rocketid, draw without the predictor** -- the same context with ``predictor=None``:
  IPOPT warm-started from the reference solution (the path before the predictor);
* **peer, warm re-solve with CD0, CD6, CL fixed** -- ``CasadiRA66.resolve_fixed(P_TRUE,
  (0, 6, 7), res)``: the peer has no (7.9); fixing three parameters at other values and
  re-solving from its solution is the comparable step (three fixed directions, like q2);
* **peer, warm re-solve of the same problem** -- ``resolve_fixed(p_hat, [], res)``.

The four alternate within each draw index, so that their ratios are measured under the
same load. Times are medians over the draws: wall (``perf_counter``) and CPU
(``process_time``) of the whole call; for rocketid also the IPOPT call alone, the
prediction, and the NLP's re-offset (``with_offset``). The IPOPT timing statistics
(``print_timing_statistics``) of one draw with and without the predictor are printed too.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_core import FIXED_IDX, ipopt_log, make_data, med, mesh_for, uptime, versions  # noqa: E402

SEED = 1


def timed(fn):
    t0, c0 = time.perf_counter(), time.process_time()
    out = fn()
    return out, time.perf_counter() - t0, time.process_time() - c0


def bench_mesh(label, N, K, spec, data, times, Y, n_draws, log) -> dict:
    import peer_casadi as pc

    import rocketid as ri
    from rocketid.estimability import estimate_q1
    from rocketid.sampling import SamplingSettings, prepare_sampling
    from rocketid.sampling.worker import WorkerContext, evaluate_draw, trial_parameters

    row = {"label": label, "load_start": uptime()}
    mesh = mesh_for(spec, N, K)
    prep = ri.prepare(spec, data, mesh=mesh)
    problem = prepare_sampling(prep, settings=SamplingSettings())
    ctx, t_ctx, _ = timed(lambda: WorkerContext.build(problem.recipe, prep))
    plain = replace(ctx, predictor=None)
    row.update(mesh=mesh.describe(), n=prep.nlp.n, m=prep.nlp.m, context_s=t_ctx,
               predictor_formed_s=None if ctx.predictor is None else ctx.predictor.formed_s,
               reference_iterations=problem.reference.iterations)
    peer = pc.CasadiRA66(times, Y, N=mesh.n_elements, K=K)
    res = peer.solve(pc.P0)
    est, ref = ctx.recipe.estimability, ctx.reference
    cols = {k: [] for k in ("draw", "draw_plain", "peer_fixed", "peer_same")}
    parts = {k: [] for k in ("solve_s", "solve_s_plain", "predict_s", "offset_s", "eta_s")}
    for k in range(1, n_draws + 1):
        d, w, c = timed(lambda: evaluate_draw(ctx, SEED, k))
        cols["draw"].append((w, c, d.iterations, d.success))
        d0, w, c = timed(lambda: evaluate_draw(plain, SEED, k))
        cols["draw_plain"].append((w, c, d0.iterations, d0.success))
        r, w, c = timed(lambda: peer.resolve_fixed(pc.P_TRUE, list(FIXED_IDX), res))
        cols["peer_fixed"].append((r["solve_s"], c, r["iterations"], r["success"]))
        r, w, c = timed(lambda: peer.resolve_fixed(res["p"], [], res))
        cols["peer_same"].append((r["solve_s"], c, r["iterations"], r["success"]))
        # the parts of a draw, outside the alternation
        q2 = est.q2_of(trial_parameters(ctx.recipe, SEED, k))
        nlp, t_off, _ = timed(lambda: ref.nlp.with_offset(est.transform(q2).c))
        _, t_pred, _ = timed(lambda: ctx.predictor.predict(nlp))
        fit = estimate_q1(ctx.prepared, est, q2, warm_start=ref, predictor=ctx.predictor)
        fit0 = estimate_q1(ctx.prepared, est, q2, warm_start=ref)
        from rocketid.sampling.criterion import criterion_of
        _, t_eta, _ = timed(lambda: criterion_of(fit))
        parts["solve_s"].append(fit.timings["solve_s"])
        parts["solve_s_plain"].append(fit0.timings["solve_s"])
        parts["predict_s"].append(t_pred)
        parts["offset_s"].append(t_off)
        parts["eta_s"].append(t_eta)
    for name, v in cols.items():
        row[name] = {"wall_s": med(a[0] for a in v), "cpu_s": med(a[1] for a in v),
                     "iterations_mean": float(np.mean([a[2] for a in v])), "iterations_max": int(max(a[2] for a in v)),
                     "failures": int(sum(not a[3] for a in v))}
    row["parts"] = {k: med(v) for k, v in parts.items()}
    row["ratio_draw_to_peer_fixed"] = row["draw"]["wall_s"] / row["peer_fixed"]["wall_s"]
    row["ratio_draw_plain_to_peer_fixed"] = row["draw_plain"]["wall_s"] / row["peer_fixed"]["wall_s"]
    row["ratio_cpu_draw_to_peer_fixed"] = row["draw"]["cpu_s"] / row["peer_fixed"]["cpu_s"]
    # IPOPT's timing statistics of one draw, with and without the predictor
    logdir = tempfile.mkdtemp(prefix="ipopt_draw_")
    q2 = est.q2_of(trial_parameters(ctx.recipe, SEED, 1))
    for name, pred in (("breakdown", ctx.predictor), ("breakdown_plain", None)):
        logfile = os.path.join(logdir, f"{name}.txt")
        estimate_q1(ctx.prepared, est, q2, warm_start=ref, predictor=pred,
                    options={"print_timing_statistics": "yes", "output_file": logfile, "file_print_level": 5})
        lg = ipopt_log(logfile)
        row[name] = {"iterations": lg["iterations"], "cpu": lg["cpu"]}
    row["load_end"] = uptime()
    log(f"[{label}] draw {row['draw']['wall_s'] * 1e3:.1f} ms ({row['draw']['iterations_mean']:.1f} it), "
        f"without predictor {row['draw_plain']['wall_s'] * 1e3:.1f} ms ({row['draw_plain']['iterations_mean']:.1f} it), "
        f"peer fixed {row['peer_fixed']['wall_s'] * 1e3:.1f} ms ({row['peer_fixed']['iterations_mean']:.1f} it): "
        f"ratio {row['ratio_draw_to_peer_fixed']:.2f}")
    return row


def tables(result: dict) -> str:
    out = [f"Versions: {json.dumps(result['versions'])}", ""]
    out.append("| mesh | n × m | rocketid draw ms (it mean/max) | without predictor ms (it) | peer, CD0 CD6 CL fixed ms (it) "
               "| peer, same problem ms (it) | **ratio** draw / peer fixed | without predictor / peer fixed "
               "| CPU ratio draw / peer fixed | failures |")
    out.append("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")

    def cell(d):
        return f"{d['wall_s'] * 1e3:.1f} ({d['iterations_mean']:.1f}/{d['iterations_max']})"
    for r in result["rows"]:
        out.append(f"| {r['label']}: {r['mesh']} | {r['n']} × {r['m']} | {cell(r['draw'])} | {cell(r['draw_plain'])} "
                   f"| {cell(r['peer_fixed'])} | {cell(r['peer_same'])} | **{r['ratio_draw_to_peer_fixed']:.2f}** "
                   f"| {r['ratio_draw_plain_to_peer_fixed']:.2f} | {r['ratio_cpu_draw_to_peer_fixed']:.2f} "
                   f"| {r['draw']['failures']} / {r['draw_plain']['failures']} |")
    out += ["", "Parts of a rocketid draw (median ms): the IPOPT call with / without the predictor, the prediction, "
            "the NLP's re-offset, eta; the predictor's factorization once per worker.", "",
            "| mesh | IPOPT call | IPOPT call without predictor | prediction | re-offset | eta | KKT factorization (once) |",
            "| --- | --- | --- | --- | --- | --- | --- |"]
    for r in result["rows"]:
        p = r["parts"]
        out.append(f"| {r['label']} | {p['solve_s'] * 1e3:.1f} | {p['solve_s_plain'] * 1e3:.1f} | "
                   f"{p['predict_s'] * 1e3:.1f} | {p['offset_s'] * 1e3:.1f} | {p['eta_s'] * 1e3:.1f} | "
                   f"{(r['predictor_formed_s'] or float('nan')) * 1e3:.1f} |")
    keys = ("OverallAlgorithm", "Function Evaluations", "InitializeIterates", "LinearSystemSymbolicFactorization",
            "LinearSystemFactorization", "PDSystemSolverTotal", "CheckConvergence")
    out += ["", "IPOPT's timing statistics of draw 1 (CPU ms):", "",
            "| mesh | start | iterations | " + " | ".join(keys) + " |", "| --- | --- | --- |" + " --- |" * len(keys)]
    for r in result["rows"]:
        for name, lab in (("breakdown", "predicted"), ("breakdown_plain", "reference")):
            b = r[name]
            out.append(f"| {r['label']} | {lab} | {b['iterations']} | "
                       + " | ".join(f"{b['cpu'].get(k, float('nan')) * 1e3:.1f}" for k in keys) + " |")
    out += ["", f"Load: `{result['rows'][0]['load_start']}` … `{result['rows'][-1]['load_end']}`"]
    return "\n".join(out)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--draws", type=int, default=40)
    parser.add_argument("--json", default=None)
    args = parser.parse_args()

    def log(msg):
        print(msg, file=sys.stderr, flush=True)
    spec, data, times, Y, _ = make_data()
    rows = [bench_mesh("default", None, 4, spec, data, times, Y, args.draws, log),
            bench_mesh("N = 66, K = 3", 66, 3, spec, data, times, Y, args.draws, log)]
    result = {"versions": versions(), "rows": rows}
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=1))
    print(tables(result))


if __name__ == "__main__":
    main()
