"""Malformed and unusual input through the command line and the API, one table.

Every row is one input: the files it needs, the command (or API call), the exit code
and a fragment of the message that must name the input or the fix. A bad input must
give exit code 2 and exactly one ``Error: ...`` line on stderr, never a traceback (the
runner does not catch exceptions, so a traceback fails the test). Rows whose error
comes before any solve run in a fraction of a second; the few that need a solve say so.
"""

from __future__ import annotations

import json
import math
import shutil
from dataclasses import dataclass, field
from pathlib import Path
from typing import Callable

import numpy as np
import pytest
from click.testing import CliRunner

import rocketid as ri
from rocketid.cli import main
from rocketid.errors import RocketidError

HEADER = "t,x,h,v\n"
ROWS = "".join(f"{0.01 * k:.2f},{k}.0,{2 * k}.0,{3 * k}.0\n" for k in range(1, 13))

DECAY = '''
from rocketid import Model


def build_model():
    m = Model("decay", t0=0.0, tf=2.0)
    y = m.state("y", initial=1.0)
    k = m.parameter("k", guess=0.5, bounds=(0.0, 10.0))
    m.ode({y: -k * y})
    m.output("y", y, sigma=0.01)
    return m.freeze()
'''


@pytest.fixture(scope="module")
def ra66_csv(tmp_path_factory, ra66_noisy):
    return ra66_noisy.to_csv(tmp_path_factory.mktemp("data") / "ra66.csv")


def _write(folder: Path, name: str, content: str | bytes) -> Path:
    path = folder / name
    path.parent.mkdir(parents=True, exist_ok=True)
    if isinstance(content, bytes):
        path.write_bytes(content)
    else:
        path.write_text(content)
    return path


@dataclass
class Case:
    """One hostile input: ``files`` are written into the test's folder, ``args`` name them
    relative to it (``{ra66}`` is a full RA-66 data file)."""

    id: str
    args: list
    code: int
    fragment: str
    files: dict = field(default_factory=dict)


def _ra66_rows(n: int) -> str:
    return "".join(f"{0.01 * k:.2f},{k}.0,{k}.0,{k}.0\n" for k in range(1, n + 1))


CASES = [
    # ---- encodings and file formats
    Case("latin-1", ["estimate", "d.csv"], 2, "not UTF-8 text (byte 0xe9 on line 2",
         {"d.csv": (HEADER + "0.01,1,2,3 caf\xe9\n").encode("latin-1")}),
    Case("windows-1252 header", ["estimate", "d.csv"], 2, "save it as UTF-8",
         {"d.csv": "t,x,h,v,note\u2019\n0.01,1,2,3,a\n".encode("cp1252")}),
    Case("binary", ["estimate", "d.csv"], 2, "binary (it holds NUL bytes)", {"d.csv": b"\x89PNG\r\n\x1a\n\x00\x00\x00"}),
    Case("utf-16", ["estimate", "d.csv"], 2, "UTF-16", {"d.csv": (HEADER + ROWS).encode("utf-16")}),
    Case("BOM is read (then too few rows)", ["estimate", "d.csv"], 2, "the data have 3 values of x, h, v",
         {"d.csv": "\ufeff" + HEADER + "0.01,1,2,3\n"}),
    Case("semicolons detected (then too few rows)", ["estimate", "d.csv"], 2, "the data have 6 values",
         {"d.csv": "t;x;h;v\n0.01;1;2;3\n0.02;1;2;3\n"}),
    Case("semicolons with decimal commas", ["estimate", "d.csv"], 2, "decimal commas are not read",
         {"d.csv": "t;x;h;v\n0,01;1,5;2;3\n"}),
    Case("tabs detected", ["estimate", "d.csv"], 2, "line 3, column 'h': 'oops' is not a number",
         {"d.csv": "t\tx\th\tv\n0.01\t1\t2\t3\n0.02\t1\toops\t3\n"}),
    Case("spaces as separators", ["estimate", "d.csv"], 2, "the header has no commas",
         {"d.csv": "t x h v\n0.01 1 2 3\n"}),
    Case("duplicate column", ["estimate", "d.csv"], 2, "column(s) x appear more than once",
         {"d.csv": "t,x,h,v,x\n" + "".join(f"{0.01 * k:.2f},1,2,3,9\n" for k in range(1, 5))}),
    Case("duplicate time column", ["estimate", "d.csv"], 2, "column(s) t appear more than once",
         {"d.csv": "t,x,h,v,t\n0.01,1,2,3,5\n"}),
    Case("short row", ["estimate", "d.csv"], 2, "line 3: 2 cells, but the header has 4 columns",
         {"d.csv": HEADER + "0.01,1,2,3\n0.02,1\n"}),
    Case("line numbers count blank lines", ["estimate", "d.csv"], 2, "line 6, column 'v': 'x' is not a number",
         {"d.csv": HEADER + "0.01,1,2,3\n\n\n0.02,1,2,3\n0.03,1,2,x\n"}),
    Case("non-numeric cell", ["estimate", "d.csv"], 2, "'12 m/s' is not a number",
         {"d.csv": HEADER + "0.01,1,2,3\n0.02,1,12 m/s,3\n"}),
    Case("empty file", ["estimate", "d.csv"], 2, "the file is empty", {"d.csv": ""}),
    Case("blank lines only", ["estimate", "d.csv"], 2, "the file is empty", {"d.csv": "\n\n  \n"}),
    Case("header only", ["estimate", "d.csv"], 2, "no data rows", {"d.csv": HEADER}),
    Case("missing column", ["estimate", "d.csv"], 2, "missing column(s) h", {"d.csv": "t,x,alt,v\n0.01,1,2,3\n"}),
    Case("missing file", ["estimate", "nope.csv"], 2, "does not exist", {}),
    Case("data file is a folder", ["estimate", "folder"], 2, "is a directory", {"folder/keep": ""}),
    Case("NaN value", ["estimate", "d.csv"], 2, "value is NaN or infinite at t = 0.02",
         {"d.csv": HEADER + "0.01,1,2,3\n0.02,nan,2,3\n"}),
    # an empty cell is "not measured then" (multi-rate telemetry): these 5 values cannot fit 8 parameters
    Case("empty cell", ["estimate", "d.csv"], 2, "the data have 5 values of x, h, v",
         {"d.csv": HEADER + "0.01,1,2,3\n0.02,1,,3\n"}),
    Case("empty time cell", ["estimate", "d.csv"], 2, "line 3: the time cell ('t') is empty",
         {"d.csv": HEADER + "0.01,1,2,3\n,1,2,3\n"}),
    Case("a column with no values", ["estimate", "d.csv"], 2, "column(s) h have no values",
         {"d.csv": HEADER + "0.01,1,,3\n0.02,1,,3\n"}),
    Case("unsorted times", ["estimate", "d.csv"], 2, "not sorted", {"d.csv": HEADER + "0.02,1,2,3\n0.01,1,2,3\n"}),
    Case("duplicate times", ["estimate", "d.csv"], 2, "duplicate time t = 0.01",
         {"d.csv": HEADER + "0.01,1,2,3\n0.01,1,2,3\n"}),
    Case("one row: underdetermined", ["estimate", "d.csv"], 2, "the data have 3 values of x, h, v but model 'RA-66' "
         "estimates 8 parameters", {"d.csv": HEADER + _ra66_rows(1)}),
    Case("two rows: underdetermined", ["estimate", "d.csv"], 2, "a fit needs more values than parameters",
         {"d.csv": HEADER + _ra66_rows(2)}),
    Case("huge values", ["estimate", "d.csv"], 2, "is out of scale (|value| > 1e+150",
         {"d.csv": HEADER + "".join(f"{0.01 * k:.2f},1e300,2,3\n" for k in range(1, 5))}),
    Case("infinite value", ["estimate", "d.csv"], 2, "NaN or infinite", {"d.csv": HEADER + "0.01,inf,2,3\n"}),
    Case("samples after the horizon", ["estimate", "d.csv"], 2, "2 after tf = 66 (from t = 66.5) of 5 samples",
         {"d.csv": HEADER + "1,1,2,3\n2,1,2,3\n3,1,2,3\n66.5,1,2,3\n67,1,2,3\n"}),
    Case("samples before the horizon", ["estimate", "d.csv"], 2, "1 before t0 = 0 (from t = -1)",
         {"d.csv": HEADER + "-1,1,2,3\n1,1,2,3\n2,1,2,3\n3,1,2,3\n"}),
    # ---- data options
    Case("tiny sigma", ["estimate", "{ra66}", "--sigma", "x=1e-300"], 2, "sigma = 1e-300 is out of scale"),
    Case("huge sigma", ["estimate", "{ra66}", "--sigma", "x=1e300"], 2, "out of scale"),
    Case("zero sigma", ["estimate", "{ra66}", "--sigma", "x=0"], 2, "sigma must be positive"),
    Case("sigma of an unknown output", ["estimate", "{ra66}", "--sigma", "q=1"], 2, "has no output 'q'"),
    Case("sigma not a number", ["estimate", "{ra66}", "--sigma", "x=abc"], 2, "'abc' is not a number"),
    Case("sigma infinite", ["estimate", "{ra66}", "--sigma", "x=inf"], 2, "the value must be finite"),
    Case("column mapped to a missing column", ["estimate", "{ra66}", "--column", "h=alt"], 2, "missing column(s) alt"),
    Case("column of an unknown output", ["estimate", "{ra66}", "--column", "q=x"], 2, "has no output 'q'"),
    Case("column without a value", ["estimate", "{ra66}", "--column", "x"], 2, "is not NAME=VALUE"),
    Case("time column missing", ["estimate", "{ra66}", "--time-column", "time"], 2, "missing column(s) time"),
    Case("zero elements", ["estimate", "{ra66}", "--elements", "0"], 2, "0 is not in the range x>=1"),
    Case("K too large", ["estimate", "{ra66}", "--K", "6"], 2, "6 is not in the range 1<=x<=5"),
    Case("K zero", ["estimate", "{ra66}", "--K", "0"], 2, "1<=x<=5"),
    Case("guess outside its bounds", ["estimate", "{ra66}", "--guess", "CD0=2"], 2, "outside its bounds"),
    Case("guess of an unknown parameter", ["estimate", "{ra66}", "--guess", "CDX=1"], 2, "not a parameter"),
    Case("guess not a number", ["estimate", "{ra66}", "--guess", "CD0=abc"], 2, "'abc' is not a number"),
    Case("guess given twice", ["estimate", "{ra66}", "--guess", "CD0=0.5", "--guess", "CD0=0.6"], 2, "given twice"),
    Case("misspelt IPOPT option", ["estimate", "{ra66}", "--ipopt", "maxiter=5"], 2, "did you mean max_iter"),
    Case("IPOPT option of the wrong type", ["estimate", "{ra66}", "--ipopt", "max_iter=abc"], 2, "--ipopt"),
    # ---- models
    Case("unknown model", ["estimate", "{ra66}", "--model", "ra67"], 2, "unknown model 'ra67'"),
    Case("--model is a folder", ["estimate", "{ra66}", "--model", "models"], 2,
         "is a folder, not a model: give a built-in model (ra66, ra66m) or a model file, a Python file (.py) that "
         "defines build_model()", {"models/m.py": DECAY}),
    Case("simulate --model is a folder", ["simulate", "--model", "models", "--out", "o.csv"], 2, "is a folder, not a model",
         {"models/m.py": DECAY}),
    Case("missing model file", ["estimate", "{ra66}", "--model", "gone.py"], 2, "does not exist"),
    Case("model file without build_model", ["estimate", "{ra66}", "--model", "m.py"], 2,
         "does not define build_model()", {"m.py": "x = 1\n"}),
    Case("model file with a syntax error", ["estimate", "{ra66}", "--model", "m.py"], 2, "failed to import: SyntaxError",
         {"m.py": "def build_model(:\n"}),
    Case("model file calling sys.exit", ["estimate", "{ra66}", "--model", "m.py"], 2, "called sys.exit(3)",
         {"m.py": "import sys\nsys.exit(3)\n"}),
    Case("build_model calling sys.exit", ["estimate", "{ra66}", "--model", "m.py"], 2, "build_model() failed: SystemExit",
         {"m.py": "import sys\ndef build_model():\n    sys.exit(0)\n"}),
    Case("build_model raising", ["estimate", "{ra66}", "--model", "m.py"], 2, "build_model() failed: KeyError",
         {"m.py": "def build_model():\n    return {}['k']\n"}),
    Case("build_model returning a number", ["estimate", "{ra66}", "--model", "m.py"], 2, "returned int, not a ModelSpec",
         {"m.py": "def build_model():\n    return 3\n"}),
    Case("truth() raising", ["simulate", "--model", "m.py", "--out", "o.csv"], 2, "truth() failed: KeyError",
         {"m.py": DECAY + "\ndef truth(spec):\n    return {}['k']\n"}),
    Case("truth() of the wrong length", ["simulate", "--model", "m.py", "--out", "o.csv"], 2,
         "truth(spec) returned an unusable value", {"m.py": DECAY + "\ndef truth(spec):\n    return [1.0, 2.0]\n"}),
    Case("truth() not numbers", ["simulate", "--model", "m.py", "--out", "o.csv"], 2, "truth(spec) returned an unusable",
         {"m.py": DECAY + "\ndef truth(spec):\n    return 'abc'\n"}),
    Case("sample_times() unsorted", ["simulate", "--model", "m.py", "--out", "o.csv"], 2, "strictly increasing",
         {"m.py": DECAY + "\ndef sample_times():\n    return [0.5, 0.2]\n"}),
    Case("sample_times() not numbers", ["simulate", "--model", "m.py", "--out", "o.csv"], 2, "must return numbers",
         {"m.py": DECAY + "\ndef sample_times():\n    return ['a']\n"}),
    Case("a model's data for another model", ["estimate", "{ra66}", "--model", "m.py"], 2, "missing column(s) y",
         {"m.py": DECAY}),
    # ---- simulate
    Case("negative seed", ["simulate", "--seed", "-1", "--out", "o.csv"], 2, "-1 is not in the range x>=0"),
    Case("unknown --param", ["simulate", "--param", "CDX=1", "--out", "o.csv"], 2, "not a parameter"),
    Case("--param below its bounds", ["simulate", "--param", "CD0=-5", "--out", "o.csv"], 2,
         "--param CD0=-5 lies outside the bounds of CD0 in model 'RA-66', [0.0001, 1]"),
    Case("--param above its bounds", ["simulate", "--param", "CL=3", "--out", "o.csv"], 2, "outside the bounds of CL"),
    Case("--param outside a model file's bounds", ["simulate", "--model", "m.py", "--param", "k=11", "--out", "o.csv"],
         2, "[0, 10]; give a value within them", {"m.py": DECAY}),
    Case("simulate --out is a folder", ["simulate", "--out", "folder"], 2, "is a directory", {"folder/keep": ""}),
    Case("simulate --out below a file", ["simulate", "--out", "afile/o.csv"], 2, "is a file, not a folder",
         {"afile": "x"}),
    # ---- outputs, checked before the work
    Case("estimate --out below a file", ["estimate", "{ra66}", "--out", "afile/fit.json"], 2, "is a file, not a folder",
         {"afile": "x"}),
    Case("estimate --out is a folder", ["estimate", "{ra66}", "--out", "folder"], 2, "is a directory",
         {"folder/keep": ""}),
    Case("estimability --plot below a file", ["estimability", "{ra66}", "--out", "e.json", "--plot", "afile/e.png"], 2,
         "is a file, not a folder", {"afile": "x"}),
    Case("estimability threshold", ["estimability", "{ra66}", "--out", "e.json", "--threshold", "0.5"], 2,
         "--threshold"),
    Case("estimability --np", ["estimability", "{ra66}", "--out", "e.json", "--np", "9"], 2, "--np must be from 1 to 8"),
    Case("diagnose --out is a file", ["diagnose", "{ra66}", "--out", "afile"], 2, "is a file", {"afile": "x"}),
    Case("diagnose --out below a file", ["diagnose", "{ra66}", "--out", "afile/rep"], 2, "is a file, not a folder",
         {"afile": "x"}),
    Case("diagnose --level", ["diagnose", "{ra66}", "--out", "rep", "--level", "2"], 2, "--level must be between"),
    Case("diagnose --window", ["diagnose", "{ra66}", "--out", "rep", "--window", "-1"], 2, "--window must be a positive number"),
    Case("diagnose --column", ["diagnose", "{ra66}", "--out", "rep", "--column", "q=x"], 2, "has no output 'q'"),
    Case("diagnose --column to a missing column", ["diagnose", "{ra66}", "--out", "rep", "--column", "h=alt"], 2,
         "missing column(s) alt"),
    Case("reproduce dask without a scheduler", ["reproduce", "--out", "st", "--executor", "dask"], 2,
         "needs --scheduler"),
    Case("reproduce --scheduler without dask", ["reproduce", "--out", "st", "--scheduler", "tcp://x:1"], 2,
         "--scheduler is for --executor dask"),
    Case("reproduce --out is a file", ["reproduce", "--out", "afile"], 2, "is a file", {"afile": "x"}),
    Case("reproduce --runs 0", ["reproduce", "--out", "st", "--runs", "0"], 2, "0 is not in the range"),
    Case("unknown command", ["estimat", "{ra66}"], 2, "No such command"),
    Case("unknown option", ["estimate", "{ra66}", "--tol", "1"], 2, "No such option"),
]


@pytest.mark.parametrize("case", [pytest.param(c, id=c.id) for c in CASES])
def test_hostile_cli_input(case, tmp_path, ra66_csv, monkeypatch):
    for name, content in case.files.items():
        _write(tmp_path, name, content)
    monkeypatch.chdir(tmp_path)
    args = [str(a).replace("{ra66}", str(ra66_csv)) for a in case.args]
    result = CliRunner().invoke(main, args, catch_exceptions=False)
    text = result.stdout + result.stderr
    assert result.exit_code == case.code, text
    assert case.fragment in text, text
    if case.code == 2:
        lines = result.stderr.strip().splitlines()
        assert len(lines) == 1 and lines[0].startswith("Error: "), result.stderr
    # nothing half-written: no temporary files anywhere
    assert not list(tmp_path.rglob("*.tmp"))


# ---------------------------------------------------------------------------
# The API
# ---------------------------------------------------------------------------


def _checkpoint(tmp_path, edit: Callable[[dict], None]):
    from rocketid.sampling.checkpoint import RunState, read_checkpoint, write_checkpoint
    from rocketid.sampling.worker import DrawOutcome

    st = RunState(7)
    for k, eta in enumerate([5.0, 3.0, math.nan, 4.0], 1):
        ok = math.isfinite(eta)
        o = DrawOutcome(7, k, ok, 0 if ok else -2, "ok" if ok else "failed", eta, (0.1, 3.0, 0.1, 3.0), 1.0, 3,
                        (0.5, 0.1), (0.0,), (0.4, 0.2), 0.01)
        st.process(o, n_iter=50, max_draws=None)
    write_checkpoint(tmp_path, st, token="T", settings_key={"s": 1}, n_iter=50)
    path = tmp_path / "checkpoints" / "run_7.json"
    d = json.loads(path.read_text())
    edit(d)
    path.write_text(json.dumps(d))
    return lambda: read_checkpoint(tmp_path, 7, token="T", settings_key={"s": 1}, n_iter=50)


def _api_cases():
    spec = ri.ra66()
    data = ri.Measurements.from_arrays(np.arange(1, 31) * 0.1, {"x": np.zeros(30), "h": np.zeros(30),
                                                                 "v": np.zeros(30)})

    def model_with_sigma(s):
        m = ri.Model("m", 0.0, 1.0)
        y = m.state("y", 1.0)
        m.output("y", y, sigma=s)

    def drop(key):
        return lambda d: d.pop(key)

    def setitem(key, value):
        return lambda d: d.__setitem__(key, value)

    def best_eta(d):
        d["best"]["eta"] = 1.0

    return [
        ("estimate mesh=5", lambda tmp: ri.estimate(spec, data, mesh=5), "mesh must be a Mesh"),
        ("estimate guess='abc'", lambda tmp: ri.estimate(spec, data, guess="abc"), "parameter values 'abc'"),
        ("estimate guess of the wrong length", lambda tmp: ri.estimate(spec, data, guess=[1.0]), "has 1 values"),
        ("estimate guess mapping not numbers", lambda tmp: ri.estimate(spec, data, guess={"CD0": "x"}),
         "is not a number"),
        ("estimate underdetermined", lambda tmp: ri.estimate(spec, data.window(0.1, 0.2)),
         "the data have 6 values"),
        ("simulate_measurements seed=-1", lambda tmp: ri.simulate_measurements(spec, seed=-1),
         "seed must be a non-negative integer"),
        ("simulate_measurements seed=1.5", lambda tmp: ri.simulate_measurements(spec, seed=1.5),
         "seed must be a non-negative integer"),
        ("Channel sigma 1e-300", lambda tmp: ri.Measurements.from_arrays([0.1], {"x": [1.0]}, sigma={"x": 1e-300}),
         "out of scale"),
        ("model output sigma 1e-300", lambda tmp: model_with_sigma(1e-300), "sigma of output y = 1e-300"),
        ("checkpoint missing a key", lambda tmp: _checkpoint(tmp, drop("history"))(), "the field 'history' is missing"),
        ("checkpoint history edited", lambda tmp: _checkpoint(tmp, setitem("history", [5.0, "3", None, 4.0]))(),
         "neither numbers nor null"),
        ("checkpoint history shortened", lambda tmp: _checkpoint(tmp, setitem("history", [5.0, 3.0]))(),
         "2 history entries for 4 draws"),
        ("checkpoint best edited", lambda tmp: _checkpoint(tmp, best_eta)(), "not the history's least eta"),
        ("checkpoint improvements edited", lambda tmp: _checkpoint(tmp, setitem("improvements", [1]))(),
         "improvements do not match"),
        ("checkpoint since edited", lambda tmp: _checkpoint(tmp, setitem("since", 0))(), "since is 0"),
        ("checkpoint failures edited", lambda tmp: _checkpoint(tmp, setitem("failures", []))(),
         "failures do not match"),
        ("checkpoint draws as text", lambda tmp: _checkpoint(tmp, setitem("draws", "4"))(), "wrong type"),
    ]


@pytest.mark.parametrize("name, call, fragment", [pytest.param(*c, id=c[0]) for c in _api_cases()])
def test_hostile_api_input(name, call, fragment, tmp_path):
    with pytest.raises(RocketidError) as info:
        call(tmp_path)
    assert fragment in str(info.value), str(info.value)


def test_the_checkpoint_fixture_is_valid(tmp_path):
    """The unedited checkpoint of the table above reads back (so the failures are about the edits)."""
    st = _checkpoint(tmp_path, lambda d: None)()
    assert st.draws == 4 and st.best.draw == 2 and st.since == 2 and [f[0] for f in st.failures] == [3]


def test_a_bom_file_reads_like_a_plain_one(tmp_path):
    plain = ri.read_csv(_write(tmp_path, "a.csv", HEADER + ROWS))
    bom = ri.read_csv(_write(tmp_path, "b.csv", "\ufeff" + HEADER + ROWS))
    semi = ri.read_csv(_write(tmp_path, "c.csv", (HEADER + ROWS).replace(",", ";")))
    for name in ("x", "h", "v"):
        np.testing.assert_array_equal(bom[name].values, plain[name].values)
        np.testing.assert_array_equal(semi[name].values, plain[name].values)
    assert plain["v"].values[-1] == 36.0


def test_a_fit_that_overflows_fails_and_writes_null(tmp_path, ra66_noisy):
    """Values within range whose weighted squares overflow: the fit fails (exit 1), the summary
    does not claim J = 0, and FIT.json is strict JSON with null where a number is not finite."""
    big = ri.Measurements.from_arrays(ra66_noisy["x"].times, {c: ra66_noisy[c].values * 1e140 for c in "xhv"})
    data = big.to_csv(tmp_path / "big.csv")
    out = tmp_path / "fit.json"
    result = CliRunner().invoke(main, ["estimate", str(data), "--sigma", "x=1e-10", "--out", str(out)],
                                catch_exceptions=False)
    assert result.exit_code == 1, result.stdout + result.stderr
    assert "objective J   : 0\n" not in result.stdout
    assert "not finite" in result.stdout
    payload = json.loads(out.read_text(), parse_constant=lambda c: pytest.fail(f"{c} in FIT.json"))
    assert payload["success"] is False
    assert payload["objective"] is None or math.isfinite(payload["objective"])
    assert all(v is None or math.isfinite(v) for v in payload["rms"].values())


def test_write_json_refuses_non_finite_numbers(tmp_path):
    from rocketid.output import write_json
    with pytest.raises(ValueError, match=r"the value at fit\.rms\[1\] is not finite"):
        write_json(tmp_path / "a.json", {"fit": {"rms": [1.0, math.inf]}})
    assert not list(tmp_path.iterdir())


def test_estimate_accepts_the_builtin_ra66m(tmp_path, ra66_csv):
    """``estimate --model ra66m`` is accepted like estimability's and diagnose's (an error about
    the data, not about the model: RA-66M reads the same x, h, v)."""
    shutil.copy(ra66_csv, tmp_path / "d.csv")
    (tmp_path / "d.csv").write_text(HEADER + _ra66_rows(2))
    result = CliRunner().invoke(main, ["estimate", str(tmp_path / "d.csv"), "--model", "ra66m"],
                                catch_exceptions=False)
    assert result.exit_code == 2 and "model 'RA-66M'" in result.stderr, result.stderr


def test_the_table_is_large_enough():
    assert len(CASES) + len(_api_cases()) >= 60
