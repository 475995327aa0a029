"""Run the real-telemetry evaluation: make each case's data, run ``rocketid diagnose`` on it from the command
line as a user would (``--sigma estimate --window 12:``), and score the final model.

    python tests/telemetry_study/run.py --json telemetry.json [--cases NAME ...] [--docs FILE.md]

Corvid-L (``tests/vehicles/corvid.py``), a guided liquid first stage with a commanded throttle bucket and a
stored pitch program, telemetry acquired from T+12 s: speed 10 Hz, altitude 2 Hz, downrange 1 Hz with gaps,
quantized, the noise not stated. Data and reports go to ``$ROCKETID_TELEMETRY_DIR`` (default
``/tmp/rocketid-telemetry``): one multi-rate CSV per case (empty cells where a channel has no sample) and one
report folder per case. One diagnosis at a time (``--workers`` is passed through, default 1).
``--rescore`` (with ``--json``) re-scores stored results and runs no diagnosis; ``--docs`` rewrites the
table between the markers ``<!-- telemetry-table:start -->`` and ``<!-- telemetry-table:end -->``.

The harness and the outcome classes are ``tests/study_harness.py``'s (:class:`study_harness.Study`); a case's
``visible`` decides whether "nothing found" passes (the base chi2/dof is ~1 by construction when the sigma is
estimated).
"""

from __future__ import annotations

import sys
from pathlib import Path

HERE = Path(__file__).resolve().parent
TESTS = HERE.parent
for extra in (TESTS, TESTS / "vehicles"):
    if str(extra) not in sys.path:
        sys.path.insert(0, str(extra))

import corvid as V  # noqa: E402
from study_harness import Study, family  # noqa: E402

from telemetry_study.cases import ALL  # noqa: E402

#: What the regime asks of the command line: the noise levels estimated, the fit cut to the telemetry's span.
EXTRA_ARGS = ("--sigma", "estimate", "--window", f"{V.T_ACQUIRE:g}:")

STUDY = Study("Corvid-L (real telemetry: unknown noise, multi-rate, from T+12 s)", TESTS / "vehicles" / "corvid.py",
              dict(V.truth(None)), ALL, family, "telemetry_study.truth", "ROCKETID_TELEMETRY_DIR",
              "/tmp/rocketid-telemetry", "telemetry-table", timeout=3600.0, extra_args=EXTRA_ARGS)


def main(argv=None) -> int:
    return STUDY.main(argv, __doc__)


if __name__ == "__main__":
    sys.exit(main())
