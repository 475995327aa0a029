"""Run the fleet evaluation (Petrel-V, three flights a campaign, noise unknown): write each campaign's CSVs,
run ``rocketid diagnose A.csv B.csv C.csv --sigma estimate`` from the command line as a user would, and score
each flight and the joint model.

    python tests/fleet_study/run.py --json fleet.json [--cases NAME ...] [--timeout SECONDS] [--rescore]

Data and reports go to ``$ROCKETID_FLEET_DIR`` (default ``/tmp/rocketid-fleet``): ``<campaign>/A.csv``,
``B.csv``, ``C.csv`` and the report folder ``<campaign>/diag/`` (``diagnosis.json``, one folder per flight).
One diagnosis at a time with ``--workers 1`` (the machine's two cores are shared). The table is printed between
``<!-- fleet-table:start -->`` and ``<!-- fleet-table:end -->``; ``--json`` is read and extended per campaign.

Scoring (``score``). Per flight: its final families must all be right for it (the campaign's shared property and
the flight's own effects), its own effects found, its verdict "explained" when it added anything, a clean flight
adds nothing (and nothing is carried into it). The shared vehicle property must be in every flight's model --
found by the flight's own search or carried to it by the joint step -- and, for a vehicle effect, shared in the
joint model with one value close to the truth (10 % or 3 standard errors); the 40 kg adapter (rocketid's rule: a
flight's loading) must be found per flight with each value close to 40 kg. The joint model must reach the noise.
A wrong family in any flight's final model called "explained" is the worst outcome.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import sys
import time
from datetime import datetime, timezone
from pathlib import Path

HERE = Path(__file__).resolve().parent
TESTS = HERE.parent
for extra in (TESTS, TESTS / "vehicles"):
    if str(extra) not in sys.path:
        sys.path.insert(0, str(extra))

from study_harness import family, git_commit, run_command  # noqa: E402

from rocketid.output import environment, environment_line  # noqa: E402

from fleet_study.cases import BY_NAME, CAMPAIGNS, write_campaign  # noqa: E402

MODEL = TESTS / "vehicles" / "petrel.py"
ENV = "ROCKETID_FLEET_DIR"
DEFAULT_DIR = "/tmp/rocketid-fleet"
MARKER = "fleet-table"
#: A campaign that outlasts this is recorded as a timeout and the study moves on (s). (900 s until 2026-11-28:
#: nozzle+C-wind, whose flight C now also tries its wind's finer shapes, ran past it with one worker beside
#: another study; it had taken 651 s before.)
TIMEOUT = 1800.0
#: "Close to the truth": within this fraction of it, or within 3 standard errors.
CLOSE = 0.10


def data_dir() -> Path:
    return Path(os.environ.get(ENV, DEFAULT_DIR))


def _read(path: Path):
    try:
        return json.loads(path.read_text())
    except (OSError, ValueError):
        return None


def _flight_detail(d: dict | None) -> dict:
    """What a flight's own diagnosis.json says that the score and the trace need."""
    if not d:
        return {}
    return {"final": d.get("final"),
            "base_chi2": (d.get("comparison") or {}).get("chi2_per_dof"),
            "band": (d.get("noise_band") or {}).get("upper"),
            "noise_from_data": d.get("noise_from_data"),
            "steps": [{**{k: s.get(k) for k in ("number", "contenders", "chosen", "why", "dropped", "effects",
                                                "chi2_per_dof") if k in s},
                       "refits": [{"effects": r.get("effects"), "chi2_per_dof": r.get("chi2_per_dof"),
                                   "accepted": r.get("accepted"),
                                   "estimates": {n: (e or {}).get("value") for n, e in (r.get("estimates") or {}).items()},
                                   "failed": [n for n, c in (r.get("checks") or {}).items() if not (c or {}).get("passed")]}
                                  for r in s.get("refits") or []]}
                      for s in d.get("steps") or []],
            "search_stopped": d.get("search_stopped"),
            "notes": d.get("notes") or []}


def diagnose_campaign(campaign, root: Path | None = None, workers: int = 1, timeout: float = TIMEOUT) -> dict:
    """Write the campaign's CSVs and run ``rocketid diagnose`` on them; return the record (the command, exit code,
    wall time, the top-level diagnosis.json and each flight's own)."""
    folder = Path(root or data_dir()) / campaign.name
    csvs = write_campaign(campaign, folder)
    out = folder / "diag"
    if out.exists():                       # a previous run's report (and any checkpoints): start afresh
        shutil.rmtree(out)
    command = [sys.executable, "-c", "import sys; from rocketid.cli import main; sys.exit(main())", "diagnose",
               *[str(p) for p in csvs], "--model", str(MODEL), "--sigma", "estimate", "--out", str(out),
               "--workers", str(workers)]
    start = time.perf_counter()
    code, stdout, stderr = run_command(command, timeout)
    record = {"campaign": campaign.name, "command": "rocketid " + " ".join(command[3:]),
              "wall_s": time.perf_counter() - start, "exit": code, "stdout": stdout[-6000:], "stderr": stderr[-3000:]}
    top = _read(out / "diagnosis.json") if code in (0, 1) else None
    if top:
        record["diagnosis"] = {k: top.get(k) for k in ("flights", "common", "joint_final", "verdict", "timings")}
        record["joint"] = {k: (top.get("joint") or {}).get(k) for k in ("success", "chi2_per_dof", "noise_from_data",
                                                                         "consistency", "notes")}
    record["flight_detail"] = {d.label: _flight_detail(_read(out / d.label / "diagnosis.json")) for d in campaign.days}
    return record


# ---------------------------------------------------------------- scoring

def _param(params: dict, name: str):
    """(value, std) of a parameter in a diagnosis.json parameters mapping (either {"value", "std"} or a pair)."""
    pv = (params or {}).get(name)
    if pv is None:
        return None
    if isinstance(pv, dict):
        return pv.get("value"), pv.get("std")
    if isinstance(pv, (list, tuple)):
        return pv[0], (pv[1] if len(pv) > 1 else None)
    return float(pv), None


def close(value, std, true) -> bool:
    if value is None:
        return False
    return abs(value - true) <= max(CLOSE * abs(true), 3 * (std or 0.0))


def _fmt(name, pv, true=None) -> str:
    value, std = pv
    text = f"{name} {value:.4g}" + (f" +- {std:.2g}" if std is not None else "")
    return text + (f" (truth {true:.4g})" if true is not None else "")


def _joint_effects(jf: dict | None, label: str) -> list:
    return list(((jf or {}).get("effects") or {}).get(label) or [])


def score(campaign, record) -> dict:
    """Per-flight classes, the joint model's findings, the problems, the outcome and whether it is acceptable."""
    diag = record.get("diagnosis") or {}
    flights = diag.get("flights") or {}
    jf = diag.get("joint_final")
    problems, wrong_explained, wrong_any, per_flight = [], [], [], {}
    if not flights:
        return {"outcome": "diagnosis failed", "acceptable": False, "per_flight": {},
                "problems": [f"no diagnosis.json (exit {record.get('exit')})"]}
    for day in campaign.days:
        f = flights.get(day.label) or {}
        effects = list(f.get("final_effects") or [])
        verdict = f.get("verdict")
        fams = {family(e) for e in effects}
        right = campaign.right(day)
        joint_effects = _joint_effects(jf, day.label)
        joint_fams = {family(e) for e in joint_effects}
        wrong = sorted(fams - right)
        wrong_joint = sorted(joint_fams - right - fams)
        if not fams:
            cls = "nothing found"
        elif wrong:
            cls = "WRONG called explained" if verdict == "explained" else "wrong, not called explained"
        elif verdict == "explained" and all(fams & s for s in campaign.needed_each(day)):
            cls = "right & explained"
        else:
            cls = "right but partly"
        per_flight[day.label] = cls
        if wrong:
            (wrong_explained if verdict == "explained" else wrong_any).append(f"{day.label}: {', '.join(wrong)}")
            problems.append(f"{day.label} took {', '.join(wrong)} ({verdict})")
        if wrong_joint:
            wrong_any.append(f"{day.label} (joint): {', '.join(wrong_joint)}")
            problems.append(f"joint model gives {day.label} {', '.join(wrong_joint)}")
        if not campaign.right(day):                      # a clean flight
            if effects or joint_effects:
                problems.append(f"clean flight {day.label} adds {', '.join(effects or joint_effects)}")
            continue
        for need in day.needed_each:                     # the flight's own effects: found by its own search
            if not fams & need:
                problems.append(f"{day.label} misses its own {'/'.join(sorted(need))}")
        if campaign.shared_needed and not (fams | joint_fams) & campaign.shared_needed:
            problems.append(f"{day.label}: the shared {'/'.join(sorted(campaign.shared_needed))} neither found nor "
                            "carried")
        if effects and verdict != "explained":
            problems.append(f"{day.label} {verdict}")
    # the joint model
    params = (jf or {}).get("parameters") or {}
    shared = list((jf or {}).get("shared") or [])
    if campaign.shared_nature == "vehicle":
        if not jf:
            problems.append("no joint model with the effects")
        else:
            shared_fams = {family(e) for e in shared}
            if not shared_fams & campaign.shared_needed:
                problems.append(f"{'/'.join(sorted(campaign.shared_needed))} not shared in the joint model "
                                f"(shared: {', '.join(shared) or 'none'})")
        for name, true in campaign.shared_sizes:
            pv = _param(params, name)
            if pv is None:
                own = [n for n in params if n.startswith(name + "[")]
                problems.append(f"no single {name} in the joint model" + (f" ({', '.join(own)} per flight)" if own else ""))
            elif not close(pv[0], pv[1], true):
                problems.append(f"joint {_fmt(name, pv, true)} not close")
    elif campaign.shared_nature == "flight":
        for name, true in campaign.shared_sizes:
            if _param(params, name) is not None:
                problems.append(f"{name} shared in the joint model, against the documented rule (a flight's loading)")
            for day in campaign.days:
                pv = _param(params, f"{name}[{day.label}]") or _param(
                    ((record.get("flight_detail") or {}).get(day.label, {}).get("final") or {}).get("parameters"), name)
                if pv is None:
                    problems.append(f"no {name} for {day.label}")
                elif not close(pv[0], pv[1], true):
                    problems.append(f"{day.label}: {_fmt(name, pv, true)} not close")
    for day in campaign.days:
        for name, true in day.sizes:
            pv = _param(params, f"{name}[{day.label}]") or _param(params, name)
            if pv is None:
                pv = _param(((record.get("flight_detail") or {}).get(day.label, {}).get("final") or {})
                            .get("parameters"), name)
            if pv is None:
                problems.append(f"no {name} for {day.label}")
            elif not close(pv[0], pv[1], true):
                problems.append(f"{day.label}: {_fmt(name, pv, true)} not close")
    if jf and jf.get("fits_to_noise") is False:
        chi = jf.get("chi2_per_dof")
        problems.append(f"joint model not at the noise (chi2/dof {chi if chi is None else f'{chi:.4g}'})")
    if jf and jf.get("failed"):
        problems.append(f"joint model failed: {jf.get('failed')}")
    anything = any(flights.get(d.label, {}).get("final_effects") for d in campaign.days) or bool(
        jf and any((jf.get("effects") or {}).values()))
    if wrong_explained:
        outcome = "WRONG called explained"
    elif wrong_any:
        outcome = "wrong, not called explained"
    elif not anything:
        outcome = "nothing found"
    elif not problems:
        outcome = "right & explained"
    else:
        outcome = "right but partly"
    if campaign.clean:
        acceptable = outcome == "nothing found" and not problems
    else:
        acceptable = outcome == "right & explained"
    if record.get("exit") not in (0, 1):
        problems.append(f"exit {record.get('exit')}")
        acceptable = False
    return {"outcome": outcome, "acceptable": acceptable, "per_flight": per_flight, "problems": problems,
            "wrong_explained": wrong_explained}


# ---------------------------------------------------------------- the table

def _flights_cell(campaign, record) -> str:
    flights = (record.get("diagnosis") or {}).get("flights") or {}
    detail = record.get("flight_detail") or {}
    parts = []
    for day in campaign.days:
        f = flights.get(day.label) or {}
        eff = " + ".join(f.get("final_effects") or []) or "nothing"
        noise = (detail.get(day.label) or {}).get("noise_from_data") or {}
        sig = "/".join(f"{(noise.get(ch) or {}).get('sigma', float('nan')):.3g}" for ch in ("x", "h", "v")) if noise else "?"
        base, fin = f.get("base_chi2_per_dof"), f.get("chi2_per_dof")
        chi = f"{base:.4g} -> {fin:.4g}" if base is not None and fin is not None else "-"
        true_sig = "/".join(f"{day.sigma[ch]:.3g}" for ch in ("x", "h", "v"))
        words = day.words if day.own else ("the shared property only" if campaign.shared else "clean")
        parts.append(f"**{day.label}** ({words}; sigma {sig} for {true_sig}): {eff}, {chi}, {f.get('verdict')}")
    return "<br>".join(parts)


def _joint_cell(campaign, record) -> str:
    jf = (record.get("diagnosis") or {}).get("joint_final")
    if not jf:
        return "no joint model (null)"
    parts = [f"shared: {', '.join(jf.get('shared') or []) or 'none'}"]
    carried = [c for c in jf.get("carried") or []]
    for c in carried:
        parts.append(f"carry {c.get('effect')} from {','.join(c.get('found_in') or [])} to {','.join(c.get('to') or [])}: "
                     f"{'carried' if c.get('carried') else 'not carried'}"
                     + (f", p {c['p_value']:.3g}" if c.get("p_value") is not None else "")
                     + (f", dropped {c['dropped']}" if c.get("dropped") else ""))
    truths = dict(campaign.shared_sizes)
    for day in campaign.days:
        truths.update({f"{n}[{day.label}]": v for n, v in day.sizes})
        if campaign.shared_nature == "flight":
            truths.update({f"{n}[{day.label}]": v for n, v in campaign.shared_sizes})
    params = jf.get("parameters") or {}
    shown = [_fmt(n, _param(params, n), truths.get(n)) for n in params
             if n in truths or n.split("[")[0] in dict(campaign.shared_sizes)]
    if shown:
        parts.append("; ".join(shown))
    per = jf.get("per_flight") or {}
    chis = ", ".join(f"{k} {v.get('chi2_per_dof'):.4g}" for k, v in per.items() if v.get("chi2_per_dof") is not None)
    base, final = jf.get("base_chi2_per_dof"), jf.get("chi2_per_dof")
    parts.append(f"chi2/dof {base if base is None else f'{base:.4g}'} -> {final if final is None else f'{final:.4g}'} "
                 f"({chis}); "
                 f"at the noise: {jf.get('fits_to_noise')}")
    return "<br>".join(parts)


def row(campaign, record) -> str:
    s = score(campaign, record)
    outcome = s["outcome"] + (": " + "; ".join(s["problems"]) if s["problems"] else "")
    return (f"| {campaign.name} | {campaign.truth} | {_flights_cell(campaign, record)} | {_joint_cell(campaign, record)} "
            f"| {outcome} | {'yes' if s['acceptable'] else '**no**'} | {record.get('wall_s', 0):.0f} |")


def table(records: dict, title: str) -> str:
    lines = [title, "",
             "| campaign | truth (hidden) | per flight (sigma from data vs made; x/h/v): final effects, chi2/dof base -> "
             "final, verdict | joint: shared / carried, values vs truth | outcome | acceptable | s |",
             "| --- | --- | --- | --- | --- | --- | --- |"]
    counts: dict = {}
    for c in CAMPAIGNS:
        if c.name in records:
            lines.append(row(c, records[c.name]))
            o = score(c, records[c.name])
            counts[o["outcome"]] = counts.get(o["outcome"], 0) + 1
            counts["acceptable"] = counts.get("acceptable", 0) + int(o["acceptable"])
    acc = counts.pop("acceptable", 0)
    lines += ["", "Outcomes: " + ", ".join(f"{k} {v}" for k, v in sorted(counts.items()))
              + f"; acceptable {acc} of {sum(counts.values())}."]
    return "\n".join(lines)


def main(argv=None) -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--cases", nargs="*", help="campaign names (default: all)")
    parser.add_argument("--json", required=True, help="results file (read and extended)")
    parser.add_argument("--workers", type=int, default=1)
    parser.add_argument("--timeout", type=float, default=TIMEOUT, help="seconds per campaign")
    parser.add_argument("--rescore", action="store_true", help="only re-score and print the stored results")
    args = parser.parse_args(argv)
    path = Path(args.json)
    stored = json.loads(path.read_text()) if path.exists() else {"records": {}}
    names = args.cases or [c.name for c in CAMPAIGNS]
    unknown = [n for n in names if n not in BY_NAME]
    if unknown:
        parser.error(f"unknown campaign(s) {', '.join(unknown)}; known: {', '.join(BY_NAME)}")
    if not args.rescore:
        stored["commit"] = git_commit()
        stored["when"] = datetime.now(timezone.utc).strftime("%Y-%m-%d %H:%M UTC")
        stored["machine"] = platform.machine()
        stored["environment"] = environment()
        for name in names:
            record = diagnose_campaign(BY_NAME[name], workers=args.workers, timeout=args.timeout)
            stored["records"][name] = record
            path.parent.mkdir(parents=True, exist_ok=True)
            path.write_text(json.dumps(stored, indent=1))
            print(row(BY_NAME[name], record), flush=True)
    for name, record in stored["records"].items():
        if name in BY_NAME:
            record["score"] = score(BY_NAME[name], record)
    path.write_text(json.dumps(stored, indent=1))
    title = (f"Petrel-V fleet (3 flights a campaign, `--sigma estimate`), `rocketid diagnose` of src/rocketid at commit "
             f"{stored.get('commit')}, {stored.get('when')}, {stored.get('machine')}, one diagnosis at a time "
             f"(`--workers {args.workers}`) on 2 shared cores."
             + (f" Packages: {environment_line(stored['environment'])}." if stored.get("environment") else ""))
    print(f"<!-- {MARKER}:start -->")
    print(table(stored["records"], title))
    print(f"<!-- {MARKER}:end -->")
    return 0


if __name__ == "__main__":
    sys.exit(main())
