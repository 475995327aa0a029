"""Time to rank the whole catalogue of candidate effects at a fit, as a ratio to one refit (ISSUE 5).

At a base fit of RA-66M (data with a hidden altitude bias, seed 0, mesh ``default_mesh(spec,
refine_first=3)``), three things are timed, each the median of ``--repeat`` runs:

* ``rank (first)``: :func:`rocketid.diagnostics.rank_candidates` over the whole catalogue --
  build the augmented model (13 effects, 27 parameters), collocate it, one sparse LU for all
  sensitivities, the statistics. Generated code is cached on disk (run once before timing);
* ``rank (reused)``: the same with ``augmented=`` from an earlier ranking (same model, mesh and
  sample times: the sampling of many seeds, or a ranking after new data of the same flight);
* ``one refit``: what :func:`rocketid.diagnostics.confirm` does before its checks -- the model
  with one effect (:func:`with_effects`), collocated and fitted from nominal values; the median
  over the effects ``--effects``.

The ratio ``rank / refit`` is the figure of merit (goal: below 1). With ``--cold`` the code
generation of the augmented model is timed too, in an empty cache folder.

Run::

    python benchmarks/bench_diagnose_rank.py                 # Markdown table
    python benchmarks/bench_diagnose_rank.py --json out.json --cold
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import tempfile
import time

import rocketid as ri
from rocketid.cases import ra66m, ra66m_truth
from rocketid.diagnostics import rank_candidates, with_effects


def one_refit(fit, effect) -> float:
    """Seconds for the refit of ``confirm``: extend, collocate, fit from nominal values."""
    t0 = time.perf_counter()
    spec = with_effects(fit.spec, [effect])
    new = ri.estimate(spec, fit.prepared.measurements, mesh=fit.prepared.transcription.mesh)
    dt = time.perf_counter() - t0
    if not new.success:
        raise RuntimeError(f"the refit with {effect} failed: {new.message}")
    return dt


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=5)
    ap.add_argument("--effects", nargs="+", default=["bias_h", "back_pressure", "earth_rotation", "misalignment"])
    ap.add_argument("--cold", action="store_true", help="also time the code generation of the augmented model")
    ap.add_argument("--json", default=None)
    args = ap.parse_args(argv)

    base = ra66m()
    mesh = ri.default_mesh(base, refine_first=3)
    spec = with_effects(base, ["bias_h"], {"b_h": 5.0})
    data = ri.simulate_measurements(spec, ra66m_truth(spec), ri.ra66_times(), seed=0)
    fit = ri.estimate(base, data, mesh=mesh)

    out = {"case": "RA-66M, hidden altitude bias 5 m, seed 0", "mesh": mesh.describe(), "repeat": args.repeat}
    if args.cold:
        old = os.environ.get("ROCKETID_CACHE_DIR")
        with tempfile.TemporaryDirectory() as tmp:
            os.environ["ROCKETID_CACHE_DIR"] = tmp
            t0 = time.perf_counter()
            r = rank_candidates(fit)
            out["rank_cold_s"] = time.perf_counter() - t0
            out["rank_cold_prepare_s"] = r.timings["prepare_s"]
        if old is None:
            os.environ.pop("ROCKETID_CACHE_DIR", None)
        else:
            os.environ["ROCKETID_CACHE_DIR"] = old

    warm = rank_candidates(fit)                        # fills the code cache
    for e in args.effects:                             # and the effects' models
        one_refit(fit, e)
    firsts, reused, parts = [], [], []
    for _ in range(args.repeat):
        t0 = time.perf_counter()
        r = rank_candidates(fit)
        firsts.append(time.perf_counter() - t0)
        parts.append(r.timings)
        t0 = time.perf_counter()
        rank_candidates(fit, augmented=warm.augmented)
        reused.append(time.perf_counter() - t0)
    refits = {e: statistics.median(one_refit(fit, e) for _ in range(args.repeat)) for e in args.effects}
    refit = statistics.median(refits.values())
    out.update({
        "rank_first_s": statistics.median(firsts),
        "rank_reused_s": statistics.median(reused),
        "rank_parts_s": {k: statistics.median(p[k] for p in parts)
                         for k in ("build_s", "prepare_s", "sensitivity_s", "score_s")},
        "refit_s": refit, "refit_by_effect_s": refits,
        "ratio_first": statistics.median(firsts) / refit,
        "ratio_reused": statistics.median(reused) / refit,
        "n_candidates": len(warm.candidates),
        "n_parameters_augmented": len(warm.augmented.spec.parameters),
        "top": warm.candidates[0].name,
    })
    lines = ["| quantity | seconds | ratio to one refit |", "| --- | --- | --- |",
             f"| rank {out['n_candidates']} candidates, first (augmented model built, code cached) | "
             f"{out['rank_first_s']:.2f} | {out['ratio_first']:.2f} |",
             f"| rank, augmented model reused | {out['rank_reused_s']:.2f} | {out['ratio_reused']:.2f} |",
             f"| one refit (median over {', '.join(args.effects)}) | {refit:.2f} | 1 |"]
    if args.cold:
        lines.append(f"| rank, cold code cache (code generation of the augmented model) | {out['rank_cold_s']:.1f} | "
                     f"{out['rank_cold_s'] / refit:.0f} |")
    p = out["rank_parts_s"]
    lines.append(f"\nfirst ranking: build {p['build_s']:.2f} s, collocate {p['prepare_s']:.2f} s, one LU for "
                 f"{out['n_parameters_augmented']} sensitivities {p['sensitivity_s']:.2f} s, statistics "
                 f"{p['score_s']:.2f} s; top candidate: {out['top']}")
    print("\n".join(lines))
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(out, fh, indent=2)
    return out


if __name__ == "__main__":
    main()
