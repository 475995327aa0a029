"""Wall time of ``diagnose`` with and without the refined shapes (``refine``, ``--refine/--no-refine``).

The data: the tutorial's clear case (docs/diagnose-tutorial.md), RA-66M with a vacuum back-pressure of
``A_e_vac`` 0.4 m^2 (10 % of the thrust), seed 0. Each repeat runs both settings one after the other in this
process (warm code cache after the first), so both see the same load; the verdicts, effects and chi2/dof are
printed beside the times.

Run::

    python3 benchmarks/bench_refine.py [--repeat 2] [--json out.json]
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from pathlib import Path


def main(argv=None) -> int:
    import rocketid as ri
    from rocketid.cases import ra66m, ra66m_truth
    from rocketid.diagnostics import diagnose, with_effects
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repeat", type=int, default=2)
    ap.add_argument("--json", type=Path, default=None)
    a = ap.parse_args(argv)
    truth = with_effects(ra66m(), "back_pressure_vacuum", {"A_e_vac": 0.4})
    data = ri.simulate_measurements(truth, ra66m_truth(truth), ri.ra66_times(), seed=0)
    diagnose(data, "ra66m", confirm_top=0)                     # the code cache warm for both
    rows = []
    for k in range(a.repeat):
        for refine in (True, False):
            with tempfile.TemporaryDirectory() as out:
                t0 = time.perf_counter()
                rep = diagnose(data, "ra66m", out=out, refine=refine)
                s = time.perf_counter() - t0
            rows.append({"repeat": k, "refine": refine, "seconds": s, "verdict": rep.final.verdict,
                         "effects": list(rep.final.effects), "chi2_per_dof": rep.final.chi2_per_dof})
            print(f"refine={refine!s:5}: {s:6.1f} s  {rep.final.verdict} {' + '.join(rep.final.effects)} "
                  f"chi2/dof {rep.final.chi2_per_dof:.10g}", flush=True)
    if a.json is not None:
        a.json.write_text(json.dumps(rows, indent=1))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
