"""The hidden-effect study of ``rocketid diagnose`` on independent data (issue 8).

Runs every case of ``tests/discovery_study/cases.py`` -- data from truth models written
independently of the effect catalogue, on RA-66, RA-66M and the user's Stage-30 -- through
:func:`rocketid.diagnostics.diagnose`, and writes

* a Markdown table (the one quoted in docs/effects.md): per case the truth, what the final model
  holds, chi2/dof (base -> final), the sizes against the truth, the verdict, pass/fail, time;
* a JSON file with every record (``harness.run_case``).

Generated data are cached as CSV under ``$ROCKETID_STUDY_DIR`` (default ``<tmp>/rocketid-study``).
One case at a time, in this process (the machine's cores go to the diagnosis's own workers).

Run::

    python benchmarks/discovery_study.py                       # every case
    python benchmarks/discovery_study.py --cases s30-wind m-wind
    python benchmarks/discovery_study.py --group single --md study.md --json study.json
    python benchmarks/discovery_study.py --json study.json --docs docs/effects.md   # the docs table
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

ROOT = Path(__file__).resolve().parents[1]
sys.path.insert(0, str(ROOT / "tests"))

from discovery_study import cases as C  # noqa: E402
from discovery_study import harness as H  # noqa: E402

from rocketid.output import environment, environment_line  # noqa: E402

GROUPS = {"single": C.SINGLE, "pairs": C.PAIRS, "clean-ref": C.CLEAN_REF, "clean": C.CLEAN, "varied": C.VARIED}


def _fmt(x, digits=4):
    if x is None:
        return "-"
    ax = abs(x)
    return f"{x:.{digits}g}" if ax >= 1e-3 or ax == 0 else f"{x:.3e}"


def sizes_text(rec: dict) -> str:
    out = []
    for par, v in rec["score"]["sizes"].items():
        if v["estimate"] is None:
            est = "not estimated"
        elif isinstance(v["estimate"], list):     # a profile's knots stand for a constant (harness.PROFILE_OF)
            est = "as a profile " + ", ".join(f"{_fmt(e)} +- {_fmt(sd, 2)}" for e, sd in zip(v["estimate"], v["std"]))
        else:
            est = f"{_fmt(v['estimate'])} +- {_fmt(v['std'], 2)}"
        out.append(f"{par} {est} (truth {_fmt(v['truth'])})")
    known = set(rec["score"]["sizes"]) | set(rec["score"].get("coefficients", {}))
    known |= {k for par in rec["score"]["sizes"] if isinstance(rec["score"]["sizes"][par]["estimate"], list)
              for k in rec["final"]["parameters"] if k.startswith(H.PROFILE_OF.get(par, "\0"))}
    bad = [f"{k} {_fmt(c['estimate'])} (truth {_fmt(c['truth'])})"
           for k, c in rec["score"].get("coefficients", {}).items() if not c["ok"]]
    if bad:
        out.append("coefficients off: " + ", ".join(bad))
    extra = [f"{k} {_fmt(p['value'])}" for k, p in rec["final"]["parameters"].items() if k not in known]
    if extra:
        out.append(("estimated " if out else "") + ", ".join(extra[:8]) + (" ..." if len(extra) > 8 else ""))
    if rec["profile"]:
        out.append(f"truth {rec['profile']}")
    return "; ".join(out) or "-"


def table(records: list[dict]) -> str:
    rows = ["| case | vehicle | truth | found (final model) | chi2/dof base -> final | sizes vs truth | verdict "
            "| pass | s |",
            "| --- | --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in records:
        f, s = r["final"], r["score"]
        found = " + ".join(f["effects"]) or "nothing"
        flag = (("yes (data limit, named)" if s.get("at_data_limit") else "yes") if s["passed"] else
                ("**WRONG EXPLAINED**" if s["wrong_explained"] else "no"))
        rows.append(f"| {r['case']}{r.get('run', '')} | {r['vehicle']} | {r['truth']} | {found} | {r['base']['chi2_per_dof']:.4f} -> "
                    f"{f['chi2_per_dof']:.4f} | {sizes_text(r)} | {f['verdict']} | {flag} | {r['seconds']:.0f} |")
    return "\n".join(rows)


def summary(records: list[dict]) -> str:
    eff = [r for r in records if r["true_effects"]]
    clean = [r for r in records if not r["true_effects"]]
    lines = [f"- cases with hidden effects: {sum(r['score']['passed'] for r in eff)} of {len(eff)} pass "
             "(true effects held and nothing else, chi2/dof < 1.05, verdict explained, scalar sizes within 25 % or 3 std, "
             "CD and CL within 10 % or 3 std of the truth; for a case at the limit of what its data can show, "
             "harness.DATA_LIMITS: nothing outside the truth and every true effect named in the explanation), "
             f"{sum(bool(r['score'].get('at_data_limit')) for r in eff)} of them at that limit",
             f"- wrong effect reported as explained: {sum(r['score']['wrong_explained'] for r in records)}"]
    if clean:
        lines.append(f"- clean data: {sum(bool(r['final']['effects']) for r in clean)} of {len(clean)} add an effect")
    return "\n".join(lines)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--cases", nargs="*", help="case ids (default: all)")
    ap.add_argument("--group", choices=sorted(GROUPS), action="append", help="only these groups")
    ap.add_argument("--md", type=Path, help="write the Markdown table here")
    ap.add_argument("--json", type=Path, help="write the records here")
    ap.add_argument("--rescore", type=Path, help="no diagnosis: re-score the final models stored in this JSON "
                    "(written by --json) with the current scoring, and write the table")
    ap.add_argument("--update", type=Path, nargs="*", default=[], help="with --rescore: records of later runs "
                    "(JSON) that replace the stored ones case by case; the table marks them")
    ap.add_argument("--docs", type=Path, help="replace the study table in this Markdown file (between the markers "
                    "<!-- study-table:start --> and <!-- study-table:end -->)")
    args = ap.parse_args(argv)
    if args.cases:
        unknown = [c for c in args.cases if c not in C.BY_ID]
        if unknown:
            ap.error(f"unknown case(s) {unknown}; cases are {', '.join(C.BY_ID)}")
        todo = [C.BY_ID[c] for c in args.cases]
    elif args.group:
        todo = [c for g in args.group for c in GROUPS[g]]
    else:
        todo = C.ALL
    # a frozen tree (``git archive``) is no checkout: its commit is given, as for the other studies
    head = os.environ.get("ROCKETID_STUDY_COMMIT", "")
    try:
        head = head or subprocess.run(["git", "-C", str(ROOT), "rev-parse", "--short", "HEAD"], capture_output=True,
                                      text=True).stdout.strip()
    except OSError:
        head = "?"
    records = []
    t0 = time.perf_counter()
    if args.rescore:
        stored = json.loads(args.rescore.read_text())
        head, records = stored["commit"], stored["records"]
        for i, upd in enumerate(args.update, 1):
            later = json.loads(upd.read_text())
            mark = f" (re-run {i})" if len(args.update) > 1 else " (re-run)"
            by_id = {r["case"]: dict(r, run=mark) for r in later["records"]}
            records = [by_id.get(r["case"], r) for r in records]
            stored["rocketid"] = (f"{stored.get('rocketid', '?')}; rows marked{mark}: "
                                  f"{later.get('rocketid', '?')} (study commit {later['commit']})")
        for r in records:
            if r["source"] != "error":
                r["score"] = H.score(C.BY_ID[r["case"]], r["final"])
        todo = []
        elapsed = sum(r["seconds"] for r in records if r["seconds"] == r["seconds"])
    for case in todo:
        try:
            rec = H.run_case(case)
        except Exception as exc:  # noqa: BLE001 - one failing case is a result, the study goes on
            print(f"{case.id}: ERROR {type(exc).__name__}: {exc}", flush=True)
            rec = H.error_record(case, exc)
        records.append(rec)
        f = rec["final"]
        print(f"{case.id}: {' + '.join(f['effects']) or 'nothing'}, {f['verdict']}, chi2/dof "
              f"{rec['base']['chi2_per_dof']:.4f} -> {f['chi2_per_dof']:.4f}, pass {rec['score']['passed']}, "
              f"{rec['seconds']:.0f} s", flush=True)
        if args.json:
            args.json.write_text(json.dumps({"commit": head, "rocketid": _code(), "environment": environment(),
                                             "records": records}, indent=1, default=str))
    stamp = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
    code = _code()
    if args.rescore:
        code = f"{stored.get('rocketid', '?')}; re-scored from {args.rescore.name}"
    else:
        elapsed = time.perf_counter() - t0
    env = stored.get("environment") if args.rescore else environment()
    packages = f" Packages: {environment_line(env)}." if env else ""
    md = (f"Study of commit {head} ({code}), {stamp}, {platform.machine()}; {len(records)} cases in "
          f"{elapsed:.0f} s.{packages}\n\n{summary(records)}\n\n{table(records)}\n")
    print(md)
    if args.md:
        args.md.write_text(md)
    if args.docs:
        replace_table(args.docs, md)
    return 0


def _code() -> str:
    """Which rocketid ran: this checkout's src, or another path."""
    import rocketid
    where = Path(rocketid.__file__).resolve().parents[1]
    if os.environ.get("ROCKETID_STUDY_COMMIT"):
        return f"a frozen tree of {os.environ['ROCKETID_STUDY_COMMIT']}"
    return "this checkout" if where == ROOT / "src" else f"rocketid from {where}"


START, END = "<!-- study-table:start -->", "<!-- study-table:end -->"


def replace_table(path: Path, md: str) -> None:
    """Put ``md`` between the study-table markers of ``path``."""
    text = path.read_text()
    if START not in text or END not in text:
        raise SystemExit(f"{path}: no {START} ... {END} markers; add them where the table goes")
    head, rest = text.split(START, 1)
    _, tail = rest.split(END, 1)
    path.write_text(f"{head}{START}\n{md}{END}{tail}")


if __name__ == "__main__":
    raise SystemExit(main())
