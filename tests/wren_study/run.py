"""Run the hybrid sounding-rocket evaluation: make each case's GPS log, run ``rocketid diagnose`` on it from the
command line as a user would (``--sigma estimate``), and score the final model.

    python tests/wren_study/run.py --json wren.json [--cases NAME ...] [--docs docs/effects.md]

Wren-H (``tests/vehicles/wren.py``), a university team's N2O / paraffin hybrid sounding rocket declared from
its static firing's table (thrust and consumed propellant every 0.1 s), launched from a 6.1 m rail at a
site 1200 m above sea level, flown to apogee (10.2 km, 44 s); a GPS log at 10 Hz from T+2 s with 2 % of the
fixes lost, the noise not stated. Data and reports go to ``$ROCKETID_WREN_DIR`` (default
``/tmp/rocketid-wren``): one CSV per case and one report folder per case. One diagnosis at a time
(``--workers`` is passed through, default 1). ``--rescore`` (with ``--json``) re-scores stored results and
runs no diagnosis; ``--docs`` rewrites the table between the markers ``<!-- wren-table:start -->`` and
``<!-- wren-table:end -->``.

The harness and the outcome classes are ``tests/study_harness.py``'s (:class:`study_harness.Study`); a case's
``visible`` decides whether "nothing found" passes (every case here is visible: ``cases.MEASURED_2J``).
"""

from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
TESTS = HERE.parent
for extra in (TESTS, TESTS / "vehicles"):
    if str(extra) not in sys.path:
        sys.path.insert(0, str(extra))

import wren as V  # noqa: E402
from study_harness import Study, family  # noqa: E402

from wren_study.cases import ALL  # noqa: E402

#: What the regime asks of the command line: the noise levels estimated (from the data alone). No window:
#: the model starts at rail exit, whose states the team declares; the GPS log starts later, at T+2 s.
EXTRA_ARGS = ("--sigma", "estimate")

STUDY = Study("Wren-H (hybrid sounding rocket, GPS log, noise unknown)", TESTS / "vehicles" / "wren.py",
              dict(V.truth(None)), ALL, family, "wren_study.truth", "ROCKETID_WREN_DIR", "/tmp/rocketid-wren",
              "wren-table", timeout=3600.0, extra_args=EXTRA_ARGS)


def main(argv=None) -> int:
    return STUDY.main(argv, __doc__)


if __name__ == "__main__":
    sys.exit(main())
