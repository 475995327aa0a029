"""Wall time of one ``burn_rate`` refit on a vehicle declared from a static firing's table (issue 9).

``burn_rate`` runs the motor's sampled curves on a faster clock, ``P(t_i + k (t - t_i))``: the table is
evaluated at an expression of the estimated ``eps_burn``. Wren-H (``tests/vehicles/wren.py``) has a
249-sample thrust table and a consumed-propellant table; the data are its hot-tank case (N2O at 26 C,
``tests/wren_study``: the truth's own motor), noise from the data's differences as ``diagnose --sigma
estimate`` takes it. Each tree runs in its own process with its own empty code cache: the base fit, the
refit with an empty cache for the augmented model, the same refit again (its code cached).

``--against SRC`` times another source tree (its ``src`` folder, e.g. ``git archive`` of an older commit)
in the same run, before this one.

Run::

    python benchmarks/bench_table_refit.py [--against /tmp/before/src]
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

CHILD = r"""
import json, sys, time
sys.path[:0] = [{tests!r}, {vehicles!r}]
t0 = time.perf_counter()
import rocketid as ri
from rocketid.cases.files import load_model_file
from rocketid.diagnostics import burn_rate_effect
from rocketid.diagnostics.accept import noise_band
from rocketid.diagnostics.api import _noise_from_data
from rocketid.diagnostics.refit import run_refit
from rocketid.diagnostics.screen import vehicle_of
from rocketid.diagnostics.step import _Search
from wren_study import truth
from wren_study.cases import BY_NAME
case = BY_NAME["hot-tank"]
spec, _ = load_model_file({model!r})
data = truth.measurements(case.hidden, case.seed)
sigma, _ = _noise_from_data("estimate", data, [], {{}})
fit = ri.estimate(spec, data, sigma=sigma, mesh=ri.default_mesh(spec, refine_first=3))
ctx = _Search(spec, noise_band(fit), vehicle_of(fit), 0.05, None, 1800.0, 1, False, None)
t1 = time.perf_counter()
cold, _ = run_refit(ctx.task(fit, [burn_rate_effect()], ("burn_rate",)))
t2 = time.perf_counter()
warm, _ = run_refit(ctx.task(fit, [burn_rate_effect()], ("burn_rate",)))
t3 = time.perf_counter()
print(json.dumps({{"base_s": t1 - t0, "cold_s": t2 - t1, "warm_s": t3 - t2, "chi2_per_dof": cold.chi2_per_dof,
                  "eps_burn": cold.estimate("eps_burn")[0], "objective": cold.objective}}))
"""


def _run(src: str | None, cache: str) -> dict:
    env = dict(os.environ, ROCKETID_CACHE_DIR=cache)
    if src is not None:
        env["PYTHONPATH"] = os.pathsep.join([src] + [p for p in env.get("PYTHONPATH", "").split(os.pathsep) if p])
    code = CHILD.format(tests=str(ROOT / "tests"), vehicles=str(ROOT / "tests" / "vehicles"),
                        model=str(ROOT / "tests" / "vehicles" / "wren.py"))
    res = subprocess.run([sys.executable, "-c", code], env=env, capture_output=True, text=True)
    if res.returncode != 0:
        raise RuntimeError(f"the refit failed ({res.returncode}): {res.stderr[-2000:]}")
    return json.loads(res.stdout.strip().splitlines()[-1])


def main(argv=None) -> dict:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--against", default=None, help="another source tree to time in the same run (its src folder)")
    args = ap.parse_args(argv)
    load0 = os.getloadavg()[0]
    out = {}
    with tempfile.TemporaryDirectory() as tmp:
        if args.against:
            out["against"] = _run(str(Path(args.against).resolve()), str(Path(tmp) / "cache-against"))
        out["this"] = _run(None, str(Path(tmp) / "cache-this"))
    for tag, r in out.items():
        print(f"{tag}: base fit {r['base_s']:.1f} s, burn_rate refit empty cache {r['cold_s']:.1f} s, cached "
              f"{r['warm_s']:.1f} s; chi2/dof {r['chi2_per_dof']:.6f}, eps_burn {r['eps_burn']:.8f}")
    print(f"(load average {load0:.1f} before, {os.getloadavg()[0]:.1f} after; {os.cpu_count()} cores)")
    return out


if __name__ == "__main__":
    main()
