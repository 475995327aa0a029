"""Run the unseen-vehicle evaluation: make each case's data, run ``rocketid diagnose`` on it from
the command line as a user would, and score the final model.

    python tests/unseen_study/run.py --json unseen.json [--cases NAME ...] [--docs docs/effects.md]

Data and reports go to ``$ROCKETID_UNSEEN_DIR`` (default ``/tmp/rocketid-unseen``): one CSV per
case and one report folder per case. One diagnosis at a time (``--workers`` is passed through,
default 1 so the two shared cores are not both taken). ``--rescore`` (with ``--json``) re-scores stored
results and runs no diagnosis; ``--docs`` rewrites the table between the markers
``<!-- unseen-table:start -->`` and ``<!-- unseen-table:end -->`` (``--marker`` names others).

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

import kestrel as K  # noqa: E402
from study_harness import Study, family  # noqa: E402

from unseen_study.cases import ALL  # noqa: E402

STUDY = Study("Kestrel-S", TESTS / "vehicles" / "kestrel.py", dict(K.truth(None)), ALL, family,
              "unseen_study.truth", "ROCKETID_UNSEEN_DIR", "/tmp/rocketid-unseen", "unseen-table", timeout=1800.0)


def main(argv=None) -> int:
    return STUDY.main(argv, __doc__)


if __name__ == "__main__":
    sys.exit(main())
