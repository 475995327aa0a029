"""Run the sounding-rocket evaluation: make each case's data, run ``rocketid diagnose`` on it from the
command line as a user would, and score the final model.

    python tests/sounding_study/run.py --json sounding.json [--cases NAME ...] [--docs docs/effects.md]

Tern-2 (``tests/vehicles/tern.py``), a fin-stabilized sounding rocket: a 10 s solid burn from rail
exit, then a 50 s coast. Data and reports go to ``$ROCKETID_SOUNDING_DIR`` (default
``/tmp/rocketid-sounding``): one CSV per case and one report folder per case. One diagnosis at a
time (``--workers`` is passed through, default 1 so the two shared cores are not both taken).
``--rescore`` (with ``--json``) re-scores stored results and runs no diagnosis; ``--docs`` rewrites
the table between the markers ``<!-- sounding-table:start -->`` and ``<!-- sounding-table:end -->``
(``--marker`` names others).

The harness and the outcome classes are ``tests/study_harness.py``'s (:class:`study_harness.Study`).
"""

from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
TESTS = HERE.parent
for extra in (TESTS, TESTS / "vehicles"):
    if str(extra) not in sys.path:
        sys.path.insert(0, str(extra))

import tern as V  # noqa: E402
from study_harness import Study, family  # noqa: E402

from sounding_study.cases import ALL  # noqa: E402

STUDY = Study("Tern-2 (sounding rocket)", TESTS / "vehicles" / "tern.py", dict(V.truth(None)), ALL, family,
              "sounding_study.truth", "ROCKETID_SOUNDING_DIR", "/tmp/rocketid-sounding", "sounding-table",
              timeout=3600.0)


def main(argv=None) -> int:
    return STUDY.main(argv, __doc__)


if __name__ == "__main__":
    sys.exit(main())
