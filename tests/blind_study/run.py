"""Run the blind study: verify the truth, then diagnose every case with the CLI, one at a time.

    python tests/blind_study/run.py verify           # truth vs rocketid simulate, fit of clean truth data
    python tests/blind_study/run.py run [CASE ...]   # make CSVs, run `rocketid diagnose`, classify
    python tests/blind_study/run.py report           # rebuild results.json / results.md from the case folders

Data, reports and results go to ``$ROCKETID_BLIND_DIR`` (default /tmp/rocketid-blind/). Each
diagnosis is ``rocketid diagnose CASE.csv --model tests/vehicles/halcyon.py --out DIR/CASE
--workers 1`` (the sigmas come from the model file), with a 15-minute timeout.

The study was written by a team member from the user documentation alone (the vehicle file, the
truth simulator and the cases, with the right catalogue families decided before any diagnosis
ran), without reading rocketid's diagnostics or the other studies' truth models.
"""

from __future__ import annotations

import json
import math
import os
import subprocess
import sys
import time

import numpy as np

HERE = os.path.dirname(os.path.abspath(__file__))
sys.path.insert(0, HERE)
import cases as C  # noqa: E402
import truth  # noqa: E402

ROOT = os.path.abspath(os.path.join(HERE, "..", ".."))
MODEL = os.path.join(ROOT, "tests", "vehicles", "halcyon.py")
OUT = os.environ.get("ROCKETID_BLIND_DIR", "/tmp/rocketid-blind")
#: The command line, run by this interpreter (the installed ``rocketid`` script may be another's).
CLI = [sys.executable, "-c", "from rocketid.cli import main; main()"]
TIMES = 0.1 * np.arange(1, 801)
TIMEOUT = 900
BASE_PARAMS = tuple(f"CD_{j}" for j in range(8)) + ("CL_alpha",)  # the model's own coefficients


def verify():
    os.makedirs(OUT, exist_ok=True)
    sim = os.path.join(OUT, "verify_rocketid_sim.csv")
    subprocess.run(CLI + ["simulate", "--model", MODEL, "--out", sim, "--no-noise"], check=True)
    d = np.genfromtxt(sim, delimiter=",", names=True)
    o = truth.simulate(d["t"])
    res = {}
    for c in "xhv":
        r = o[c] - d[c]
        res[c] = {"max_abs_diff": float(np.abs(r).max()), "rms_diff": float(np.sqrt(np.mean(r ** 2)))}
    fits = {}
    for seed in (11, 12):
        path = os.path.join(OUT, f"verify_truth_s{seed}.csv")
        truth.write_csv(path, truth.measurements(TIMES, {}, seed=seed))
        fj = os.path.join(OUT, f"verify_fit_s{seed}.json")
        subprocess.run(CLI + ["estimate", path, "--model", MODEL, "--out", fj], check=True,
                       stdout=subprocess.DEVNULL)
        f = json.load(open(fj))
        fits[seed] = {"chi2_per_dof": f["chi2_per_dof"], "parameters": f["parameters"], "std_err": f["std_err"]}
    payload = {"truth_minus_rocketid_simulate": res, "fits_of_clean_truth_data": fits}
    with open(os.path.join(OUT, "verify.json"), "w") as fh:
        json.dump(payload, fh, indent=1)
    print(json.dumps(payload, indent=1))


def _family_hits(effects, right):
    return [any(C.matches(e, fam) for e in effects) for fam in right]


def classify(effects, verdict, right):
    effects = list(effects)
    if right is None:                                           # clean
        if verdict == "nothing missing" and not effects:
            return "right: nothing missing"
        if verdict == "explained":
            return "WRONG called explained"
        return "false alarm, not called explained"
    union = set().union(*right)
    wrong = [e for e in effects if not C.matches(e, union)]
    hits = _family_hits(effects, right)
    if verdict == "explained":
        if wrong:
            return "WRONG called explained"
        return "right & explained" if all(hits) else "right but partly (explained, a component missed)"
    if verdict == "nothing missing" or not effects:
        return "nothing found"
    if any(hits):
        return "right but partly" + (" (with a wrong effect)" if wrong else "")
    return "wrong, not called explained"


#: Outcomes that meet the bar (as for the unseen study): the right answer, clean data left alone,
#: or nothing found for an effect the base fit does not show (its chi2/dof at most 1.1). A partial
#: or wrong answer that is not called explained is honest but does not meet it; a wrong effect
#: called explained is the worst outcome.
ACCEPTABLE = ("right: nothing missing", "right & explained")


def acceptable(rec) -> bool:
    """Whether a case's outcome meets the bar (:data:`ACCEPTABLE`)."""
    out = rec.get("outcome", "")
    if out == "nothing found":
        return (rec.get("chi2_base") or math.inf) <= 1.1
    return out in ACCEPTABLE


def _sizes(final):
    out = []
    base = set(BASE_PARAMS)
    for k, v in (final.get("parameters") or {}).items():
        if k in base:
            continue
        if isinstance(v, dict):
            val, sd = v.get("value"), v.get("std")
            out.append(f"{k} {val:.4g}" + (f" +- {sd:.2g}" if isinstance(sd, (int, float)) else ""))
        else:
            out.append(f"{k} {v}")
    return ", ".join(out)


def _base_chi2(diag):
    for key in ("base", "fit", "base_fit"):
        v = diag.get(key)
        if isinstance(v, dict) and "chi2_per_dof" in v:
            return v["chi2_per_dof"]
    hist = diag.get("history")
    if isinstance(hist, list) and hist and isinstance(hist[0], dict) and "chi2_per_dof" in hist[0]:
        return hist[0]["chi2_per_dof"]
    return None


def run_case(name):
    text, effects, seed, right = C.CASES[name]
    os.makedirs(OUT, exist_ok=True)
    csv = os.path.join(OUT, f"{name}.csv")
    truth.write_csv(csv, truth.measurements(TIMES, effects, seed=seed))
    out = os.path.join(OUT, name)
    cmd = CLI + ["diagnose", csv, "--model", MODEL, "--out", out, "--workers", "1"]
    t0 = time.time()
    try:
        p = subprocess.run(cmd, capture_output=True, text=True, timeout=TIMEOUT, cwd=ROOT)
        rc, err = p.returncode, p.stderr[-2000:]
    except subprocess.TimeoutExpired:
        rc, err = "timeout", ""
    secs = time.time() - t0
    rec = {"case": name, "truth": text, "seed": seed, "returncode": rc, "seconds": round(secs, 1),
           "stderr_tail": err, "right": None if right is None else [sorted(f) for f in right]}
    with open(os.path.join(OUT, f"{name}.run.json"), "w") as fh:
        json.dump(rec, fh, indent=1)
    return rec


def collect(name, rec=None):
    if rec is None:
        p = os.path.join(OUT, f"{name}.run.json")
        if not os.path.exists(p):
            return None
        rec = json.load(open(p))
    text, effects, seed, right = C.CASES[name]
    dj = os.path.join(OUT, name, "diagnosis.json")
    rec = dict(rec)
    if os.path.exists(dj):
        diag = json.load(open(dj))
        final = diag.get("final", {})
        rec.update({"final_effects": list(final.get("effects", [])), "verdict": final.get("verdict"),
                    "chi2_final": final.get("chi2_per_dof"), "chi2_base": _base_chi2(diag),
                    "sizes": _sizes(final),
                    "outcome": classify(final.get("effects", []), final.get("verdict"), right),
                    "diagnosis_json": dj, "summary_txt": os.path.join(OUT, name, "summary.txt")})
    else:
        rec.update({"outcome": f"no diagnosis ({rec.get('returncode')})"})
    return rec


def report():
    rows = [r for r in (collect(n) for n in C.CASES) if r]
    with open(os.path.join(OUT, "results.json"), "w") as fh:
        json.dump(rows, fh, indent=1)
    f = lambda v: "-" if v is None else f"{v:.4g}"  # noqa: E731
    lines = ["| case | truth | final effects | chi2/dof base -> final | sizes | verdict | outcome | s |",
             "| --- | --- | --- | --- | --- | --- | --- | --- |"]
    for r in rows:
        lines.append(f"| {r['case']} | {r['truth']} | {', '.join(r.get('final_effects') or []) or '-'} | "
                     f"{f(r.get('chi2_base'))} -> {f(r.get('chi2_final'))} | {r.get('sizes') or '-'} | "
                     f"{r.get('verdict')} | {r['outcome']} | {r['seconds']} |")
    md = "\n".join(lines) + "\n"
    with open(os.path.join(OUT, "results.md"), "w") as fh:
        fh.write(md)
    print(md)


if __name__ == "__main__":
    what = sys.argv[1] if len(sys.argv) > 1 else "run"
    if what == "verify":
        verify()
    elif what == "report":
        report()
    else:
        names = sys.argv[2:] or list(C.CASES)
        for n in names:
            rec = run_case(n)
            print(f"{n}: rc {rec['returncode']} {rec['seconds']} s", flush=True)
            report()
