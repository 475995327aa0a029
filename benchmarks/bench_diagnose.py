"""Wall time of ``rocketid diagnose`` with every contender refitted (issue 8, item 9).

Three rows, each a real ``rocketid diagnose`` process on a CSV file (start-up, imports,
fit, compare, locate, plausibility, the score screen, every contender refitted in parallel
workers, the acceptance tests, the stepwise search, the final confirmation with its hold-out
check, the report files):

* a **new user model** (a model file with ``build_model()``, ``truth(spec)`` and
  ``sample_times()``; default ``tests/vehicles/stage30.py``) with an **empty code cache**
  (a fresh ``ROCKETID_CACHE_DIR``: every model and augmented model generated);
* the same with the **warm cache** left by the first run;
* **RA-66** (``--model ra66``, the chapter's time-knot model) on a warm cache (run once
  before timing; with the Mach-indexed variant when the time-knot model is not explained).

Each data set hides a +2 % thrust error (``thrust_level``), seed 0.

``--resume`` adds, for this tree, the warm new-model diagnosis stopped at half its time
(``--budget``) and then continued (``--resume``, no budget): what an interrupted or budgeted
run costs against the whole one, and that it ends with the same model.

``--against SRC`` times another source tree (``SRC`` holds its ``rocketid`` package, e.g. an
older commit unpacked with ``git archive``) in the same run: each row runs both trees one
after the other (each with its own empty code cache), so that both see the same load.

Run::

    python benchmarks/bench_diagnose.py [--model tests/vehicles/stage30.py] [--json out.json]
                                        [--against /tmp/before/src]
"""

from __future__ import annotations

import argparse
import importlib.util
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def _data(model: str, out: Path) -> Path:
    import rocketid as ri
    from rocketid.diagnostics import with_effects
    if model == "ra66":
        base = ri.ra66()
        spec = with_effects(base, "thrust_level", {"eps_thrust": 0.02})
        p, times = ri.ra66_truth(spec), ri.ra66_times()
        p[spec.parameter_names.index("eps_thrust")] = 0.02       # ra66_truth sets every non-CL parameter to 0.5
    else:
        mod_spec = importlib.util.spec_from_file_location("user_model", model)
        mod = importlib.util.module_from_spec(mod_spec)
        mod_spec.loader.exec_module(mod)
        base = mod.build_model()
        base = base.freeze() if hasattr(base, "freeze") else base
        spec = with_effects(base, "thrust_level", {"eps_thrust": 0.02})
        p, times = mod.truth(spec), mod.sample_times()
        p[spec.parameter_names.index("eps_thrust")] = 0.02
    data = ri.simulate_measurements(spec, p, times, seed=0)
    return data.to_csv(out)


def _run(csv: Path, model: str, cache: str, out: Path, src: str | None = None, extra: tuple = ()) -> tuple[float, str]:
    env = dict(os.environ, ROCKETID_CACHE_DIR=cache)
    if src is not None:
        env["PYTHONPATH"] = os.pathsep.join([src] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    t0 = time.perf_counter()
    cmd = [sys.executable, "-c", "from rocketid.cli import main; main()", "diagnose", str(csv), "--out", str(out),
           "--model", model, *extra]
    res = subprocess.run(cmd, env=env, capture_output=True, text=True)
    dt = time.perf_counter() - t0
    if res.returncode not in (0, 1):
        raise RuntimeError(f"rocketid diagnose failed ({res.returncode}): {res.stderr[-2000:]}")
    final = json.loads((out / "diagnosis.json").read_text()).get("final") or {}
    return dt, f"{final.get('verdict')} {final.get('effects')} chi2/dof {final.get('chi2_per_dof')}"


def _rows(args, tmp: Path, trees: dict, csvs: dict) -> dict:
    """``{tree: {row: (seconds, verdict)}}``; each step runs every tree in turn (``trees``: tag -> src)."""
    rows = {tag: {} for tag in trees}

    def each(label, csv, model, out):
        for tag, src in trees.items():
            res = _run(csv, model, str(tmp / f"cache-{tag}"), tmp / f"{tag}-{out}", src)
            if label:
                rows[tag][label] = res

    if not args.only_ra66:
        each("new model, empty cache", csvs["user"], args.model, "r1")
        each("new model, warm cache", csvs["user"], args.model, "r2")
    each(None, csvs["ra66"], "ra66", "r3")                                   # warm the cache
    each("RA-66, warm cache", csvs["ra66"], "ra66", "r4")
    if args.resume and not args.only_ra66:
        whole = rows["this"]["new model, warm cache"][0]
        cache, out = str(tmp / "cache-this"), tmp / "this-r5"
        budget = 0.5 * whole
        cut = _run(csvs["user"], args.model, cache, out, None, ("--budget", f"{budget:.1f}"))
        stopped = json.loads((out / "diagnosis.json").read_text()).get("search_stopped")
        kept = len(list((out / "checkpoints").glob("*.pkl")))
        again = _run(csvs["user"], args.model, cache, out, None, ("--resume",))
        rows["this"][f"new model, warm cache, stopped at --budget {budget:.1f} ({stopped}; {kept} refits kept)"] = cut
        rows["this"]["... then --resume"] = again
    return rows


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default=str(ROOT / "tests" / "vehicles" / "stage30.py"))
    ap.add_argument("--json", default=None)
    ap.add_argument("--only-ra66", action="store_true", help="only the RA-66 row")
    ap.add_argument("--against", default=None, help="another source tree to time in the same run (its src folder)")
    ap.add_argument("--resume", action="store_true", help="add the budget-stopped and resumed rows (this tree)")
    args = ap.parse_args(argv)
    load0 = os.getloadavg()[0]
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        csvs = {"ra66": _data("ra66", tmp / "ra66.csv")}
        if not args.only_ra66:
            csvs["user"] = _data(args.model, tmp / "user.csv")
        trees = {"against": str(Path(args.against).resolve())} if args.against else {}
        trees["this"] = None
        # interleaved: each step of the other tree, then of this one, so that both see the same load
        out = _rows(args, tmp, trees, csvs)
        before, rows = out.get("against", {}), out["this"]
    load = os.getloadavg()[0]
    for k, (dt, verdict) in rows.items():
        if k in before:
            print(f"| {k} | {before[k][0]:.1f} s -> {dt:.1f} s | {before[k][1]} -> {verdict} |")
        else:
            print(f"| {k} | {dt:.1f} s | {verdict} |")
    print(f"(load average {load0:.1f} before, {load:.1f} after; {os.cpu_count()} cores)")
    result = {k: {"seconds": dt, "final": v} for k, (dt, v) in rows.items()}
    if before:
        result["against"] = {"src": args.against, **{k: {"seconds": dt, "final": v} for k, (dt, v) in before.items()}}
    result["load_average"] = [load0, load]
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=2))
    return result


if __name__ == "__main__":
    main()
