"""Run the booster evaluation: make each case's data, run ``rocketid diagnose`` on it from the
command line as a user would, and score the final model.

    python tests/auk_study/run.py --json auk.json [--cases NAME ...] [--docs docs/effects.md]

Auk-B (``tests/vehicles/auk.py``), a liquid core with two strap-on solid boosters jettisoned at 40 s.
Data and reports go to ``$ROCKETID_AUK_DIR`` (default ``/tmp/rocketid-auk``): one CSV per case and
one report folder per case. One diagnosis at a time (``--workers`` is passed through, default 1 so
the two shared cores are not both taken). ``--rescore`` (with ``--json``) re-scores stored results
and runs no diagnosis; ``--docs`` rewrites the table between the markers
``<!-- auk-table:start -->`` and ``<!-- auk-table:end -->`` (``--marker`` names others).

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

import auk as A  # noqa: E402
from study_harness import Study, family  # noqa: E402

from auk_study.cases import ALL  # noqa: E402

STUDY = Study("Auk-B (strap-on boosters, jettison at 40 s)", TESTS / "vehicles" / "auk.py", dict(A.truth(None)), ALL,
              family, "auk_study.truth", "ROCKETID_AUK_DIR", "/tmp/rocketid-auk", "auk-table", timeout=3600.0)


def main(argv=None) -> int:
    return STUDY.main(argv, __doc__)


if __name__ == "__main__":
    sys.exit(main())
