"""Run the high-site evaluation (Petrel-V): make each case's data, run ``rocketid diagnose`` on it from
the command line as a user would, and score the final model.

    python tests/petrel_study/run.py --json petrel.json [--cases NAME ...] [--docs docs/effects.md]

Data and reports go to ``$ROCKETID_PETREL_DIR`` (default ``/tmp/rocketid-petrel``): one CSV per case
and one report folder per case. One diagnosis at a time (``--workers`` is passed through, default 1 so
the two shared cores are not both taken). ``--rescore`` (with ``--json``) re-scores stored results and
runs no diagnosis; ``--docs`` rewrites the table between the markers ``<!-- petrel-table:start -->``
and ``<!-- petrel-table:end -->`` (``--marker`` names others).

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

import petrel as V  # noqa: E402
from study_harness import Study, family  # noqa: E402

from petrel_study.cases import ALL  # noqa: E402


STUDY = Study("Petrel-V (high-site liquid booster)", TESTS / "vehicles" / "petrel.py", dict(V.truth(None)), ALL,
              family, "petrel_study.truth", "ROCKETID_PETREL_DIR", "/tmp/rocketid-petrel", "petrel-table",
              timeout=3600.0)


def main(argv=None) -> int:
    return STUDY.main(argv, __doc__)


if __name__ == "__main__":
    sys.exit(main())
