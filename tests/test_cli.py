"""The ``rocketid`` command line: simulate -> estimate round trips and bad input.

Round trips run both in-process (``click.testing.CliRunner``) and as a real
subprocess of the installed ``rocketid`` console script, on real files in
``tmp_path``. Bad input must give exit code 2 and one ``Error: ...`` line on
stderr that names the input.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import textwrap
from pathlib import Path

import click
import pytest
from click.testing import CliRunner

from rocketid import cli
from rocketid.cli import main

REQUIRED_KEYS = {"success", "parameters", "objective", "iterations", "timings"}
RA66_PARAMETERS = ["CD0", "CD1", "CD2", "CD3", "CD4", "CD5", "CD6", "CL"]


def _runner() -> CliRunner:
    try:
        return CliRunner(mix_stderr=False)  # click < 8.2
    except TypeError:
        return CliRunner()  # click >= 8.2 keeps stderr apart


def invoke(*args: str):
    result = _runner().invoke(main, [str(a) for a in args], catch_exceptions=False)
    return result


def error_line(result) -> str:
    """The stderr text, which must be exactly one ``Error: ...`` line."""
    lines = result.stderr.strip().splitlines()
    assert len(lines) == 1, f"expected one error line, got: {result.stderr!r}"
    assert lines[0].startswith("Error: "), lines[0]
    return lines[0]


def check_fit(payload: dict) -> None:
    assert REQUIRED_KEYS <= payload.keys(), payload.keys()
    assert payload["success"] is True
    assert list(payload["parameters"]) == RA66_PARAMETERS
    assert {"setup_s", "solve_s"} <= payload["timings"].keys()
    assert payload["iterations"] > 0
    assert payload["objective"] > 0
    p = payload["parameters"]
    assert all(abs(p[f"CD{k}"] - 0.5) < 0.01 for k in range(7)), p
    assert abs(p["CL"] - 0.1) < 1e-3, p


@pytest.fixture(scope="module")
def ra66_csv(tmp_path_factory) -> Path:
    """RA-66 measurements written once by ``rocketid simulate`` (in process)."""
    path = tmp_path_factory.mktemp("cli") / "ra66.csv"
    result = invoke("simulate", "--out", path)
    assert result.exit_code == 0, result.output + result.stderr
    return path


# ---------------------------------------------------------------------------
# Round trips
# ---------------------------------------------------------------------------


def test_simulate_writes_the_ra66_csv(ra66_csv):
    lines = ra66_csv.read_text().splitlines()
    assert lines[0] == "t,x,h,v"
    assert len(lines) == 6601
    assert float(lines[1].split(",")[0]) == pytest.approx(0.01)
    assert float(lines[-1].split(",")[0]) == pytest.approx(66.0)


def test_simulate_is_seeded(tmp_path, ra66_csv):
    again = tmp_path / "again.csv"
    other = tmp_path / "other.csv"
    assert invoke("simulate", "--out", again).exit_code == 0
    assert invoke("simulate", "--out", other, "--seed", 1).exit_code == 0
    assert again.read_text() == ra66_csv.read_text()
    assert other.read_text() != ra66_csv.read_text()


def test_simulate_no_noise_and_param(tmp_path):
    clean = tmp_path / "clean.csv"
    changed = tmp_path / "changed.csv"
    assert invoke("simulate", "--out", clean, "--no-noise").exit_code == 0
    assert invoke("simulate", "--out", changed, "--no-noise", "--param", "CD3=0.7").exit_code == 0
    first = clean.read_text().splitlines()[1].split(",")
    assert float(first[1]) == pytest.approx(0.0, abs=1e-3)  # x at 0.01 s, no noise
    last_clean = [float(v) for v in clean.read_text().splitlines()[-1].split(",")]
    last_changed = [float(v) for v in changed.read_text().splitlines()[-1].split(",")]
    assert last_changed[3] < last_clean[3] - 1.0  # more drag, lower final speed


def test_estimate_round_trip_in_process(ra66_csv, tmp_path):
    out = tmp_path / "fit.json"
    result = invoke("estimate", ra66_csv, "--out", out)
    assert result.exit_code == 0, result.output + result.stderr
    assert "rocketid estimation: RA-66" in result.output
    assert "converged" in result.output
    check_fit(json.loads(out.read_text()))


def test_estimate_options(ra66_csv, tmp_path):
    renamed = tmp_path / "renamed.csv"
    text = ra66_csv.read_text().splitlines()
    renamed.write_text("\n".join(["time,x,altitude,v", *text[1:]]) + "\n")
    out = tmp_path / "fit.json"
    result = invoke("estimate", renamed, "--time-column", "time", "--column", "h=altitude", "--sigma", "x=1.0",
                    "--elements", 132, "--K", 3, "--guess", "CL=0.11", "--ipopt", "max_iter=100",
                    "--ipopt", "tol=1e-9", "--out", out)
    assert result.exit_code == 0, result.output + result.stderr
    payload = json.loads(out.read_text())
    assert payload["mesh"] == {"n_elements": 132, "K": 3}
    assert payload["success"] is True
    assert abs(payload["parameters"]["CL"] - 0.1) < 2e-3


def test_not_converged_exits_1_and_still_writes_json(ra66_csv, tmp_path):
    out = tmp_path / "fit.json"
    result = invoke("estimate", ra66_csv, "--ipopt", "max_iter=1", "--out", out)
    assert result.exit_code == 1, result.output + result.stderr
    assert "did not converge" in result.output
    payload = json.loads(out.read_text())
    assert payload["success"] is False
    assert REQUIRED_KEYS <= payload.keys()


def _console_script() -> list[str]:
    exe = shutil.which("rocketid", path=os.pathsep.join([str(Path(sys.executable).parent), os.environ.get("PATH", "")]))
    if exe is None:
        pytest.skip("the rocketid console script is not on PATH (pip install .)")
    return [exe]


def test_round_trip_with_the_console_script(tmp_path):
    exe = _console_script()
    env = {**os.environ, "PYTHONWARNINGS": "ignore"}
    sim = subprocess.run([*exe, "simulate", "--out", "data.csv", "--seed", "3"], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=600)
    assert sim.returncode == 0, sim.stdout + sim.stderr
    assert (tmp_path / "data.csv").is_file()
    est = subprocess.run([*exe, "estimate", "data.csv", "--out", "out/fit.json"], cwd=tmp_path, env=env,
                         capture_output=True, text=True, timeout=600)
    assert est.returncode == 0, est.stdout + est.stderr
    assert "Parameters" in est.stdout
    check_fit(json.loads((tmp_path / "out" / "fit.json").read_text()))

    bad = subprocess.run([*exe, "estimate", "missing.csv"], cwd=tmp_path, env=env, capture_output=True, text=True,
                         timeout=600)
    assert bad.returncode == 2
    assert bad.stderr.strip().splitlines() == ["Error: data file 'missing.csv' does not exist"]


# ---------------------------------------------------------------------------
# Model files
# ---------------------------------------------------------------------------

DECAY = '''
from rocketid import Model


def build_model():
    m = Model("decay", t0=0.0, tf=2.0)
    y = m.state("y", initial=1.0)
    k = m.parameter("k", guess=0.5, bounds=(0.0, 10.0))
    m.ode({y: -k * y})
    m.output("y", y, sigma=0.01)
    return m.freeze()


def truth(spec):
    return {"k": 1.3}
'''


def test_model_file_round_trip(tmp_path):
    model = tmp_path / "decay.py"
    model.write_text(DECAY)
    data = tmp_path / "decay.csv"
    out = tmp_path / "decay.json"
    assert invoke("simulate", "--model", model, "--out", data).exit_code == 0
    assert data.read_text().splitlines()[0] == "t,y"
    result = invoke("estimate", data, "--model", model, "--out", out)
    assert result.exit_code == 0, result.output + result.stderr
    payload = json.loads(out.read_text())
    assert payload["model"] == "decay"
    assert payload["parameters"]["k"] == pytest.approx(1.3, abs=0.01)


def test_code_generation_is_announced_on_first_use_only(tmp_path, monkeypatch):
    """A long set-up says what it does: with -v, generating a new model's code is announced
    before it starts and timed after; the second run loads it from the cache silently."""
    monkeypatch.setenv("ROCKETID_CACHE_DIR", str(tmp_path / "cache"))
    model = tmp_path / "decay.py"
    model.write_text(DECAY)
    data = tmp_path / "decay.csv"
    assert invoke("simulate", "--model", model, "--out", data).exit_code == 0
    first = invoke("-v", "estimate", data, "--model", model, "--out", tmp_path / "a.json")
    assert first.exit_code == 0, first.stderr
    lines = first.stderr.splitlines()
    start = next(i for i, x in enumerate(lines) if x.startswith("generating the code of model 'decay'"))
    assert lines[start + 1].startswith("generated the code in "), lines
    assert any(x.startswith("building the NLP") for x in lines[start + 2:]), lines
    second = invoke("-v", "estimate", data, "--model", model, "--out", tmp_path / "b.json")
    assert second.exit_code == 0 and "generating the code" not in second.stderr, second.stderr
    assert "code from the cache" in second.stderr


def test_model_file_without_build_model(tmp_path):
    model = tmp_path / "nomodel.py"
    model.write_text("x = 1\n")
    result = invoke("simulate", "--model", model, "--out", tmp_path / "d.csv")
    assert result.exit_code == 2
    line = error_line(result)
    assert "nomodel.py" in line and "build_model()" in line


def test_model_file_that_fails_to_import(tmp_path):
    model = tmp_path / "broken.py"
    model.write_text("raise RuntimeError('boom')\n")
    result = invoke("simulate", "--model", model, "--out", tmp_path / "d.csv")
    assert result.exit_code == 2
    line = error_line(result)
    assert "broken.py" in line and "boom" in line


# ---------------------------------------------------------------------------
# Bad input: exit code 2, one line naming the input
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("args, named", [
    (["estimate", "{tmp}/missing.csv"], "missing.csv"),
    (["estimate", "{csv}", "--column", "h=altitude"], "altitude"),
    (["estimate", "{csv}", "--time-column", "time_s"], "time_s"),
    (["estimate", "{csv}", "--guess", "CD0"], "--guess"),
    (["estimate", "{csv}", "--guess", "CD0=abc"], "abc"),
    (["estimate", "{csv}", "--guess", "CD9=0.5"], "CD9"),
    (["estimate", "{csv}", "--guess", "CD0=2"], "CD0"),
    (["estimate", "{csv}", "--sigma", "q=1"], "q"),
    (["estimate", "{csv}", "--column", "x"], "--column"),
    (["estimate", "{csv}", "--ipopt", "maxiter=5"], "maxiter"),
    (["estimate", "{csv}", "--ipopt", "max_iter=many"], "max_iter"),
    (["estimate", "{csv}", "--ipopt", "tol=1e-8", "--ipopt", "tol=1e-9"], "tol"),
    (["estimate", "{csv}", "--model", "ra77"], "ra77"),
    (["estimate", "{csv}", "--model", "{tmp}/nofile.py"], "nofile.py"),
    (["estimate"], "DATA.csv"),
    (["simulate"], "--out"),
    (["simulate", "--out", "{tmp}/x.csv", "--param", "CL"], "--param"),
    (["simulate", "--out", "{tmp}/x.csv", "--param", "CDX=0.5"], "CDX"),
    (["frobnicate"], "frobnicate"),
])
def test_bad_input(args, named, ra66_csv, tmp_path):
    args = [a.format(tmp=tmp_path, csv=ra66_csv) for a in args]
    result = invoke(*args)
    assert result.exit_code == 2, (result.exit_code, result.output, result.stderr)
    line = error_line(result)
    assert named in line, line
    assert "Traceback" not in result.stderr


def test_bad_data_values(tmp_path):
    bad = tmp_path / "bad.csv"
    bad.write_text("t,x,h,v\n0.01,1,2,3\n0.02,1,oops,3\n")
    result = invoke("estimate", bad)
    assert result.exit_code == 2
    line = error_line(result)
    assert "bad.csv" in line and "oops" in line


def test_unwritable_output(ra66_csv, tmp_path):
    blocker = tmp_path / "file"
    blocker.write_text("")
    result = invoke("estimate", ra66_csv, "--out", blocker / "fit.json")
    assert result.exit_code == 2
    assert "fit.json" in error_line(result)


def test_os_errors_are_one_line(ra66_csv, monkeypatch):
    def deny(*args, **kwargs):
        raise PermissionError(13, "Permission denied", "secret.csv")

    monkeypatch.setattr(cli, "read_data", deny)
    result = invoke("estimate", ra66_csv)
    assert result.exit_code == 2
    assert error_line(result) == "Error: Permission denied: secret.csv"


def test_verbose_shows_the_traceback(tmp_path):
    from rocketid.errors import DataError

    with pytest.raises(DataError):
        _runner().invoke(main, ["--verbose", "estimate", str(tmp_path / "missing.csv")], catch_exceptions=False)
    with pytest.raises(DataError):
        _runner().invoke(main, ["estimate", str(tmp_path / "missing.csv"), "-v"], catch_exceptions=False)


# ---------------------------------------------------------------------------
# The group and its helpers
# ---------------------------------------------------------------------------


def test_help_lists_the_commands():
    result = invoke("--help")
    assert result.exit_code == 0
    assert "simulate" in result.output and "estimate" in result.output


def test_lazy_commands(monkeypatch):
    """A command registered by name is imported only when used."""
    calls = []

    @click.command("hello")
    def hello():
        calls.append(1)
        click.echo("hi")

    module = type(sys)("rocketid_test_lazy_command")
    module.command = hello
    monkeypatch.setitem(sys.modules, "rocketid_test_lazy_command", module)
    monkeypatch.setitem(cli.LAZY_COMMANDS, "hello", "rocketid_test_lazy_command:command")
    assert "hello" in invoke("--help").output
    result = invoke("hello")
    assert result.exit_code == 0 and result.output == "hi\n" and calls == [1]


def test_make_mesh_keeps_breakpoints_on_boundaries():
    spec = cli.load_model("ra66").spec
    assert cli.make_mesh(spec).n_elements == 66
    assert cli.make_mesh(spec, 132, K=3).n_elements == 132
    mesh = cli.make_mesh(spec, 33)  # 2 s elements would cut the CD knots every 11 s
    assert mesh.n_elements == 36
    assert all(min(abs(mesh.boundaries - knot)) < 1e-9 for knot in range(0, 67, 11))


def test_name_value_parsing():
    nv = cli.NameValue(float)
    assert nv.convert("CD0=0.5", None, None) == ("CD0", 0.5)
    assert nv.convert(" CL = 1e-1 ", None, None) == ("CL", 0.1)
    for bad in ("CD0", "=1", "CD0=", "CD0=x", "CD0=nan"):
        with pytest.raises(click.BadParameter):
            nv.convert(bad, None, None)
    assert cli.NameValue(str).convert("h=alt=1", None, None) == ("h", "alt=1")


def test_every_command_knows_the_same_builtin_models(tmp_path):
    """One registry (rocketid.cases.BUILTIN_MODELS) serves simulate, estimate, estimability
    and diagnose: ``estimate --model ra66m`` was refused while ``diagnose --model ra66m`` worked."""
    from rocketid.cases import BUILTIN_MODELS, ra66m, ra66m_truth, resolve_model
    from rocketid.diagnostics.api import resolve_model as diagnose_resolve

    assert set(BUILTIN_MODELS) >= {"ra66", "ra66m"}
    assert diagnose_resolve is resolve_model
    for name in BUILTIN_MODELS:
        assert cli.load_model(name).spec.fingerprint() == resolve_model(name)[0].fingerprint()
    src = cli.load_model("ra66m")
    assert src.spec.name == "RA-66M" and list(src.truth) == list(ra66m_truth(ra66m()))
    for command in ("simulate", "estimate", "estimability", "diagnose"):
        text = invoke(command, "--help").output
        assert "ra66|ra66m|PATH.py" in " ".join(text.split()), (command, text)
    data = tmp_path / "m.csv"
    assert invoke("simulate", "--model", "ra66m", "--out", data).exit_code == 0
    result = invoke("estimate", data, "--model", "ra66m", "--out", tmp_path / "fit.json")
    assert result.exit_code == 0, result.stderr
    fit = json.loads((tmp_path / "fit.json").read_text())
    assert fit["model"] == "RA-66M" and abs(fit["parameters"]["CL_alpha"] - 2.5) < 0.05, fit["parameters"]


def test_estimate_coloured_errors(ra66_csv, tmp_path):
    """--errors coloured prints and stores the standard errors corrected for correlated residuals (a joint
    fit's too: tests/test_joint.py)."""
    out = tmp_path / "fit.json"
    result = invoke("estimate", ra66_csv, "--errors", "coloured", "--out", out)
    assert result.exit_code == 0, result.output + result.stderr
    payload = json.loads(out.read_text())
    assert payload["std_err_residuals"] == "coloured" and set(payload["std_err"]) >= {"CL"}
    assert "coloured residuals" in result.output


def test_a_model_file_states_its_candidates(tmp_path):
    """``candidates()`` in a model file: the effects ``rocketid diagnose`` tries (an Earth rotation at the
    vehicle's own launch site; a user's effect); a bad return names the file and the function."""
    from rocketid.commands.diagnose import _file_candidates
    body = textwrap.dedent('''
        import rocketid as ri

        def build_model():
            return ri.ra66()

        def candidates():
            from rocketid.diagnostics import earth_rotation_effect
            return ["bias_h", earth_rotation_effect(37.84, 120.0)]
    ''')
    good = tmp_path / "wallops.py"
    good.write_text(body)
    found = _file_candidates(str(good))
    assert [e.name for e in found] == ["bias_h", "earth_rotation"] and "37.84" in found[1].description
    plain = tmp_path / "plain.py"
    plain.write_text(body.split("def candidates")[0])
    assert _file_candidates(str(plain)) is None and _file_candidates("ra66") is None
    bad = tmp_path / "bad.py"
    bad.write_text(body.replace('return ["bias_h", earth_rotation_effect(37.84, 120.0)]', "return [1]"))
    from rocketid.errors import ModelError
    with pytest.raises(ModelError, match=r"bad\.py.*candidates\(\)"):
        _file_candidates(str(bad))
