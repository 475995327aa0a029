"""Throttle events on Halcyon-8 written after the throttle window was added (docs/effects.md).

Not a blind test: the team that built ``throttle_window`` wrote these four cases afterwards, with the
blind study's truth simulator (``tests/blind_study/truth.py``: its own vector dynamics and atmosphere),
to see whether the window generalizes beyond the bucket it was checked on: a throttle-*up* window, a
bucket with an altimeter bias, a short deep bucket, and a late step. Each is diagnosed from the command
line as the blind study does (``rocketid diagnose CASE.csv --model tests/vehicles/halcyon.py --workers 1``).

Run: ``python3 benchmarks/throttle_checks.py [CASE ...]`` (about 2-4 minutes a case; output under
``$ROCKETID_THROTTLE_DIR``, default /tmp/rocketid-throttle; a case already diagnosed there is re-read).
"""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests" / "blind_study"))
import run  # noqa: E402
import truth  # noqa: E402

OUT = Path(os.environ.get("ROCKETID_THROTTLE_DIR", "/tmp/rocketid-throttle"))
CASES = {
    "throttle_up_window": ({"throttle": {"depth": -0.08, "t_on": 40.0, "t_off": 52.0, "ramp": 1.0}}, 21),
    "bucket+bias_h": ({"throttle": {"depth": 0.15, "t_on": 25.0, "t_off": 38.0, "ramp": 2.0}, "b_h": 8.0}, 22),
    "short_deep_bucket": ({"throttle": {"depth": 0.3, "t_on": 35.0, "t_off": 41.0, "ramp": 1.5}}, 23),
    "late_step": ({"throttle": {"depth": 0.1, "t_on": 60.0, "t_off": 200.0, "ramp": 1.0}}, 24),
}


def main(names) -> None:
    OUT.mkdir(parents=True, exist_ok=True)
    for name in names or list(CASES):
        hidden, seed = CASES[name]
        csv = OUT / f"{name}.csv"
        truth.write_csv(str(csv), truth.measurements(run.TIMES, hidden, seed=seed))
        t0 = time.time()
        if not (OUT / name / "diagnosis.json").exists():
            subprocess.run(run.CLI + ["diagnose", str(csv), "--model", run.MODEL, "--out", str(OUT / name),
                                      "--workers", "1"], stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL,
                           timeout=1200)
        final = json.loads((OUT / name / "diagnosis.json").read_text())["final"]
        sizes = {k: v["value"] for k, v in final["parameters"].items() if not k.startswith(("CD_", "CL_"))}
        print(f"| {name} | {hidden} | {', '.join(final['effects']) or '-'} | {final['chi2_per_dof']:.4g} | "
              f"{final['verdict']} | " + ", ".join(f"{k} {v:.4g}" for k, v in list(sizes.items())[:6])
              + f" | {time.time() - t0:.0f} |", flush=True)


if __name__ == "__main__":
    main(sys.argv[1:])
