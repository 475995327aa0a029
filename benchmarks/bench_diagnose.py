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

Run::

    python benchmarks/bench_diagnose.py [--model tests/vehicles/stage30.py] [--json out.json]
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


def _run(csv: Path, model: str, cache: str, out: Path) -> tuple[float, str]:
    env = dict(os.environ, ROCKETID_CACHE_DIR=cache)
    t0 = time.perf_counter()
    cmd = [sys.executable, "-c", "from rocketid.cli import main; main()", "diagnose", str(csv), "--out", str(out),
           "--model", model]
    res = subprocess.run(cmd, env=env, capture_output=True, text=True)
    dt = time.perf_counter() - t0
    if res.returncode not in (0, 1):
        raise RuntimeError(f"rocketid diagnose failed ({res.returncode}): {res.stderr[-2000:]}")
    final = json.loads((out / "diagnosis.json").read_text()).get("final") or {}
    return dt, f"{final.get('verdict')} {final.get('effects')} chi2/dof {final.get('chi2_per_dof')}"


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--model", default=str(ROOT / "tests" / "vehicles" / "stage30.py"))
    ap.add_argument("--json", default=None)
    ap.add_argument("--only-ra66", action="store_true", help="only the RA-66 row")
    args = ap.parse_args(argv)
    rows = {}
    with tempfile.TemporaryDirectory() as tmp:
        tmp = Path(tmp)
        cold = tmp / "cache"
        if not args.only_ra66:
            user_csv = _data(args.model, tmp / "user.csv")
            rows["new model, empty cache"] = _run(user_csv, args.model, str(cold), tmp / "r1")
            rows["new model, warm cache"] = _run(user_csv, args.model, str(cold), tmp / "r2")
        ra_csv = _data("ra66", tmp / "ra66.csv")
        _run(ra_csv, "ra66", str(cold), tmp / "r3")                  # warm the cache
        rows["RA-66, warm cache"] = _run(ra_csv, "ra66", str(cold), tmp / "r4")
    load = os.getloadavg()[0]
    for k, (dt, verdict) in rows.items():
        print(f"| {k} | {dt:.1f} s | {verdict} |")
    print(f"(load average {load:.1f}, {os.cpu_count()} cores)")
    result = {k: {"seconds": dt, "final": v} for k, (dt, v) in rows.items()}
    result["load_average"] = load
    if args.json:
        Path(args.json).write_text(json.dumps(result, indent=2))
    return result


if __name__ == "__main__":
    main()
