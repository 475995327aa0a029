"""Benchmark: the chapter's full study on RA-66 (10 runs, n_iter = 2000) and the parallel speed-up.

Run (it takes many minutes; put it in the background)::

    nohup python3 benchmarks/bench_study.py > /tmp/bench_study.log 2>&1 &

Measures, on this machine:

1. the worker set-up: rebuilding the NLP from the recipe in a worker process
   (generated code from the disk cache), against generating the code from
   scratch (an empty cache, in a subprocess);
2. the full study, ``rocketid.study.reproduce`` with the process pool:
   wall time, solves per second, draws, waste, Tables 7.1-7.3 (written to
   ``--out``/full);
3. the parallel speed-up on a shorter setting (``--speedup-n-iter``): the same
   runs with the serial executor and with the process pool, whose results
   must agree to the bit.

The machine's load average is recorded before and after each part: on a
shared machine other jobs slow every figure down.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np


def loadavg() -> list[float]:
    try:
        return [round(v, 2) for v in os.getloadavg()]
    except OSError:  # pragma: no cover
        return []


def git_state() -> dict:
    """The commit and the files changed in the working tree (the code measured)."""
    root = Path(__file__).resolve().parents[1]
    try:
        head = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=root, capture_output=True, text=True,
                              check=True).stdout.strip()
        dirty = subprocess.run(["git", "status", "--porcelain", "--untracked-files=no"], cwd=root,
                               capture_output=True, text=True, check=True).stdout.split("\n")
        return {"commit": head, "modified": [l[3:] for l in dirty if l.strip()]}
    except (OSError, subprocess.CalledProcessError):
        return {}


def cold_codegen_s() -> float:
    """``prepare`` for RA-66 with an empty code cache, in a fresh process."""
    code = ("import time, rocketid as ri\n"
            "spec = ri.ra66(); data = ri.simulate_measurements(spec, ri.ra66_truth(spec), ri.ra66_times(), seed=0)\n"
            "t = time.perf_counter(); p = ri.prepare(spec, data); print(time.perf_counter() - t, p.codegen_cached)\n")
    with tempfile.TemporaryDirectory() as d:
        env = dict(os.environ, ROCKETID_CACHE_DIR=d)
        out = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True, check=True)
    secs, cached = out.stdout.split()
    assert cached == "False"
    return float(secs)


def same(a, b) -> bool:
    return all(ra.best.draw == rb.best.draw and ra.best.eta == rb.best.eta and ra.n_draws == rb.n_draws
               for ra, rb in zip(a.runs, b.runs))


def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    ap.add_argument("--runs", type=int, default=10)
    ap.add_argument("--n-iter", type=int, default=2000)
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--speedup-n-iter", type=int, default=200)
    ap.add_argument("--skip-full", action="store_true")
    ap.add_argument("--skip-speedup", action="store_true")
    ap.add_argument("--out", default="/tmp/rocketid_bench_study")
    args = ap.parse_args()

    import rocketid as ri
    from rocketid.sampling import SamplingSettings, default_workers, prepare_sampling, sample
    from rocketid.study import reproduce, run_seeds

    workers = args.workers or default_workers()
    out = Path(args.out)
    report = {"machine": {"cpus": os.cpu_count(), "workers": workers, "python": platform.python_version(),
                          "numpy": np.__version__, "loadavg_start": loadavg()},
              "command": " ".join([Path(sys.executable).name, *sys.argv]), "git": git_state()}
    print(json.dumps(report["machine"]), flush=True)

    # 1. code generation from scratch vs the worker rebuild (measured in the workers below)
    report["cold_prepare_s"] = cold_codegen_s()
    print(f"prepare with an empty code cache: {report['cold_prepare_s']:.2f} s", flush=True)

    # 2. the full study
    if not args.skip_full:
        full = out / "full"
        shutil.rmtree(full, ignore_errors=True)
        la0 = loadavg()
        t0 = time.perf_counter()
        res = reproduce(full, runs=args.runs, n_iter=args.n_iter, executor="processes", workers=workers,
                        progress=False)
        wall = time.perf_counter() - t0
        smp = res.sampling
        report["full"] = {
            "runs": args.runs, "n_iter": args.n_iter, "wall_s": wall, "timings": res.timings,
            "sampling_wall_s": smp.wall_s, "solves": smp.n_evaluated, "draws": smp.n_draws,
            "wasted": smp.n_wasted, "failures": smp.n_failures, "solves_per_s": smp.solves_per_s,
            "summed_draw_s": sum(r.solve_s for r in smp.runs), "worker_setup_s": list(smp.worker_setup_s),
            "startup_s": smp.startup_s, "np": smp.estimability.n_estimated, "best_index": res.best_index,
            "errors": res.errors.tolist(), "mean_run_errors": res.mean_run_errors.tolist(),
            "improvement": res.improvement, "best_improvement": res.best_improvement,
            "eta": res.eta.tolist(), "draws_per_run": [r.n_draws for r in smp.runs],
            "loadavg_before": la0, "loadavg_after": loadavg(), "out": str(full)}
        print(res.summary(), flush=True)
        print(json.dumps(report["full"], indent=1, default=float), flush=True)

    # 3. parallel speed-up on a shorter setting: serial vs the process pool, same runs
    if not args.skip_speedup:
        spec = ri.ra66()
        data = ri.simulate_measurements(spec, ri.ra66_truth(spec), ri.ra66_times(), seed=0)
        problem = prepare_sampling(ri.prepare(spec, data), settings=SamplingSettings(n_iter=args.speedup_n_iter))
        seeds = run_seeds(0, args.runs)
        la0 = loadavg()
        ser = sample(problem, seeds=seeds, executor="serial", progress=False)
        la1 = loadavg()
        par = sample(problem, seeds=seeds, executor="processes", workers=workers, progress=False)
        report["speedup"] = {
            "runs": args.runs, "n_iter": args.speedup_n_iter, "draws": ser.n_draws,
            "serial_wall_s": ser.wall_s, "serial_solves_per_s": ser.solves_per_s,
            "parallel_wall_s": par.wall_s, "parallel_solves_per_s": par.solves_per_s, "workers": workers,
            "speedup": ser.wall_s / par.wall_s, "parallel_startup_s": par.startup_s,
            "speedup_after_startup": ser.wall_s / (par.wall_s - par.startup_s), "parallel_wasted": par.n_wasted,
            "worker_setup_s": list(par.worker_setup_s), "identical": same(ser, par),
            "loadavg_before_serial": la0, "loadavg_before_parallel": la1, "loadavg_after": loadavg()}
        print(json.dumps(report["speedup"], indent=1), flush=True)

    report["machine"]["loadavg_end"] = loadavg()
    out.mkdir(parents=True, exist_ok=True)
    (out / "bench_study.json").write_text(json.dumps(report, indent=1, default=float) + "\n")
    print(f"wrote {out / 'bench_study.json'}", flush=True)


if __name__ == "__main__":
    main()
