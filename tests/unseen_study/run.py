"""Run the unseen-vehicle evaluation: make each case's data, run ``rocketid diagnose`` on it from
the command line as a user would, and score the final model.

    python tests/unseen_study/run.py --json unseen.json [--cases NAME ...] [--docs docs/effects.md]

Data and reports go to ``$ROCKETID_UNSEEN_DIR`` (default ``/tmp/rocketid-unseen``): one CSV per
case and one report folder per case. One diagnosis at a time (``--workers`` is passed through,
default 1 so the two shared cores are not both taken). ``--rescore unseen.json`` re-scores stored
results and runs no diagnosis; ``--docs`` rewrites the table between the markers
``<!-- unseen-table:start -->`` and ``<!-- unseen-table:end -->`` (``--marker`` names others).

Outcome classes (``classify``):

- ``right & explained``: the final model holds every needed family and only right ones, the
  verdict is "explained";
- ``right but partly``: only right families, but the verdict is not "explained" or a needed
  family is missing;
- ``nothing found``: no effect added (correct for clean data and for an effect the base fit
  already absorbs to the noise);
- ``wrong, not called explained``: a family that is not right is in the final model, verdict not
  "explained";
- ``WRONG called explained``: a family that is not right is in the final model and the verdict
  is "explained" (the worst outcome).
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import subprocess
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

HERE = Path(__file__).resolve().parent
TESTS = HERE.parent
REPO = TESTS.parent
for extra in (TESTS, TESTS / "vehicles"):
    if str(extra) not in sys.path:
        sys.path.insert(0, str(extra))

import kestrel as K  # noqa: E402

from unseen_study.cases import ALL, BY_NAME, family  # noqa: E402

MODEL_FILE = TESTS / "vehicles" / "kestrel.py"
COEFFICIENTS = dict(K.truth(None))


def data_dir() -> Path:
    """Where data and reports go."""
    return Path(os.environ.get("ROCKETID_UNSEEN_DIR", "/tmp/rocketid-unseen"))


def make_data(case) -> Path:
    """The case's CSV (made once; the truth simulation is deterministic and the noise seeded)."""
    from unseen_study import truth

    path = data_dir() / f"{case.name}.csv"
    if not path.exists():
        path.parent.mkdir(parents=True, exist_ok=True)
        truth.measurements(case.hidden, case.seed).to_csv(path)
    return path


def diagnose_cli(case, workers: int = 1, timeout: float = 1800.0) -> dict:
    """Run ``rocketid diagnose`` on the case's CSV; return the report's diagnosis.json and the wall time."""
    csv = make_data(case)
    out = data_dir() / f"report-{case.name}"
    command = [sys.executable, "-c", "import sys; from rocketid.cli import main; sys.exit(main())",
               "diagnose", str(csv), "--model", str(MODEL_FILE), "--out", str(out), "--workers", str(workers)]
    start = time.perf_counter()
    done = subprocess.run(command, capture_output=True, text=True, timeout=timeout)
    wall = time.perf_counter() - start
    record = {"case": case.name, "command": "rocketid " + " ".join(command[3:]), "wall_s": wall,
              "exit": done.returncode, "stdout": done.stdout[-4000:], "stderr": done.stderr[-2000:]}
    diag = out / "diagnosis.json"
    if done.returncode in (0, 1) and diag.exists():
        d = json.loads(diag.read_text())
        record["final"] = d.get("final")
        record["base_chi2"] = d.get("comparison", {}).get("chi2_per_dof")
        record["band"] = d.get("noise_band", {}).get("upper")
        record["steps"] = [{"number": s.get("number"), "contenders": s.get("contenders"), "why": s.get("why")}
                           for s in d.get("steps", [])]
    return record


def classify(case, record) -> str:
    """The outcome class of one case (see the module docstring)."""
    final = record.get("final")
    if not final:
        return "diagnosis failed"
    families = {family(e) for e in final.get("effects", [])}
    explained = final.get("verdict") == "explained"
    if not families:
        return "nothing found"
    if not families <= case.right:
        return "WRONG called explained" if explained else "wrong, not called explained"
    if explained and case.needed and (families & case.needed):
        return "right & explained"
    return "right but partly"


def acceptable(case, record) -> bool:
    """What the evaluation asks: clean data add nothing; an effect the base fit does not show
    (base chi2/dof inside the noise band) may go unfound; a visible one is found and explained."""
    outcome = classify(case, record)
    if not case.right:
        if case.out_of_catalogue:                            # honest: anything but "explained"
            return outcome in ("nothing found", "wrong, not called explained")
        return outcome == "nothing found"                    # clean data
    if outcome == "nothing found":
        return record.get("base_chi2") is not None and record["base_chi2"] <= (record.get("band") or 1.0)
    return outcome == "right & explained"


def sizes(case, record) -> str:
    """The final model's effect parameters against the truth, and the largest coefficient deviation."""
    final = record.get("final") or {}
    params = final.get("parameters", {})
    truth_sizes = dict(case.sizes)
    parts = []
    for name, pv in params.items():
        if name in COEFFICIENTS:
            continue
        value, std = pv.get("value"), pv.get("std")
        text = f"{name} {value:.4g}" + (f" +- {std:.2g}" if std is not None else "")
        if name in truth_sizes:
            text += f" (truth {truth_sizes[name]:.4g})"
        parts.append(text)
    devs = []
    for name, true in COEFFICIENTS.items():
        if name in params and params[name].get("value") is not None:
            devs.append((abs(params[name]["value"] / true - 1), name, params[name]["value"], true))
    if devs:
        worst = max(devs)
        parts.append(f"worst coefficient {worst[1]} {worst[2]:.3g} (truth {worst[3]:.3g}, {100 * worst[0]:.0f} %)")
    return "; ".join(parts) if parts else "-"


def row(case, record) -> str:
    final = record.get("final") or {}
    effects = " + ".join(final.get("effects", [])) or "nothing"
    base = record.get("base_chi2")
    chi = final.get("chi2_per_dof")
    chi_text = (f"{base:.4g} -> {chi:.4g}" if base is not None and chi is not None else "-")
    return (f"| {case.name} | {case.truth} | {effects} | {chi_text} | {sizes(case, record)} | "
            f"{final.get('verdict', 'failed: exit ' + str(record.get('exit')))} | {classify(case, record)} | "
            f"{'yes' if acceptable(case, record) else '**no**'} | {record.get('wall_s', 0):.0f} |")


def table(records: dict, title: str) -> str:
    lines = [title, "",
             "| case | truth (hidden) | final effects | chi2/dof base -> final | sizes vs truth | verdict | outcome | acceptable | s |",
             "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for case in ALL:
        if case.name in records:
            lines.append(row(case, records[case.name]))
    counts: dict[str, int] = {}
    for case in ALL:
        if case.name in records:
            outcome = classify(case, records[case.name])
            counts[outcome] = counts.get(outcome, 0) + 1
    lines += ["", "Outcomes: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items())) + "."]
    return "\n".join(lines)


def git_commit() -> str:
    """The last commit that changed ``src/rocketid`` (what the diagnoses ran)."""
    try:
        return subprocess.run(["git", "-C", str(REPO), "log", "-1", "--format=%h", "--", "src/rocketid"],
                              capture_output=True, text=True, check=True).stdout.strip()
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="*", help="case names (default: all)")
    parser.add_argument("--json", required=True, help="results file (read and extended)")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--rescore", action="store_true", help="only re-score and print the stored results")
    parser.add_argument("--docs", help="rewrite the table in this markdown file")
    parser.add_argument("--marker", default="unseen-table", help="the table's markers in --docs (NAME:start, NAME:end)")
    args = parser.parse_args(argv)
    path = Path(args.json)
    stored = json.loads(path.read_text()) if path.exists() else {"records": {}}
    names = args.cases or [c.name for c in ALL]
    unknown = [n for n in names if n not in BY_NAME]
    if unknown:
        parser.error(f"unknown case(s) {', '.join(unknown)}; known: {', '.join(BY_NAME)}")
    if not args.rescore:
        stored["commit"] = git_commit()
        stored.setdefault("when", datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC"))
        stored["machine"] = platform.machine()
        for name in names:
            record = diagnose_cli(BY_NAME[name], workers=args.workers)
            stored["records"][name] = record
            path.write_text(json.dumps(stored, indent=1))
            print(row(BY_NAME[name], record), flush=True)
    title = (f"Kestrel-S, `rocketid diagnose` of src/rocketid at commit {stored.get('commit')}, {stored.get('when')}, "
             f"{stored.get('machine')}, one diagnosis at a time (`--workers {args.workers}`) on 2 shared cores.")
    text = table(stored["records"], title)
    print(text)
    if args.docs:
        doc = Path(args.docs)
        body = doc.read_text()
        start, end = f"<!-- {args.marker}:start -->", f"<!-- {args.marker}:end -->"
        if start not in body or end not in body:
            raise SystemExit(f"{doc}: no {start} ... {end} markers")
        head, rest = body.split(start, 1)
        _, tail = rest.split(end, 1)
        doc.write_text(f"{head}{start}\n{text}\n{end}{tail}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
