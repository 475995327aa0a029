"""Which diagnoses' first screen scans the located shapes of non-significant families (``screen.WIDE_SHARE``).

Reads report folders written by ``rocketid diagnose`` (``diagnosis.json`` and ``candidates.json``) under the
given directories and, for each, compares the significant candidates' largest predicted fall of ``J`` at the
base fit with the fall to the noise band's upper edge, ``(chi2/dof - upper) dof / 2``: the first screen scans
wide when the former is less than ``WIDE_SHARE`` of the latter. Later steps' screens are not in the reports.

Usage::

    python3 benchmarks/wide_scan_reports.py DIR [DIR ...]
"""

from __future__ import annotations

import argparse
import json
from pathlib import Path

from rocketid.diagnostics.screen import WIDE_SHARE


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("dirs", nargs="+", type=Path)
    args = parser.parse_args(argv)
    wide = total = 0
    for root in args.dirs:
        for diag in sorted(root.rglob("diagnosis.json")):
            cand = diag.parent / "candidates.json"
            try:
                d, c = json.loads(diag.read_text()), json.loads(cand.read_text())
            except (OSError, ValueError):
                continue
            band, chi2 = d.get("noise_band") or {}, (d.get("comparison") or {}).get("chi2_per_dof")
            if not band or chi2 is None:
                continue
            excess = max(0.0, 0.5 * (chi2 - band["upper"]) * band["dof"])
            lead = max((x["statistic"] / 2 for x in c.get("candidates", []) if x.get("significant")), default=0.0)
            scans = lead < WIDE_SHARE * excess
            total += 1
            wide += scans
            print(f"{diag.parent}: chi2/dof {chi2:.4g}, leader's fall {lead:.4g} of {excess:.4g}"
                  f"{' -> wide scan' if scans else ''}")
    print(f"{wide} of {total} first screens scan wide")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
