"""Interrupts, kills and concurrent runs of real ``rocketid`` processes.

``rocketid reproduce`` (a short study, two worker processes) is interrupted with
SIGINT and killed with SIGKILL once its first checkpoint is on disk: no worker
process may outlive it, no temporary file may stay, SIGINT must exit 130 and say
``--resume``, and ``--resume`` must then give tables byte-identical to an
uninterrupted run. A second run into a folder that a running study holds is
refused with the holder's PID. ``rocketid simulate`` killed while it writes its
CSV leaves the previous file (or none), never a partial one.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from pathlib import Path

import pytest
from click.testing import CliRunner

from rocketid.cli import main

psutil = pytest.importorskip("psutil")

SRC = Path(__file__).resolve().parents[1] / "src"
STUDY = ["--runs", "2", "--n-iter", "40", "--batch-size", "4", "--perturbations", "1", "--no-plots", "-q",
         "--executor", "processes", "--workers", "2"]
TABLES = ("table_7_1.csv", "table_7_2.csv", "table_7_3.csv")
TIMEOUT = 300


def _env() -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(SRC) + os.pathsep + env.get("PYTHONPATH", "")
    return env


def _start(*args: str) -> subprocess.Popen:
    return subprocess.Popen([sys.executable, "-c", "from rocketid.cli import main; main()", *args],
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=_env())


def _run(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", "from rocketid.cli import main; main()", *args],
                          capture_output=True, text=True, env=_env(), timeout=TIMEOUT)


def _wait_for(predicate, proc: subprocess.Popen, what: str) -> None:
    end = time.monotonic() + TIMEOUT
    while not predicate():
        if proc.poll() is not None:
            out, err = proc.communicate()
            pytest.fail(f"the process ended (code {proc.returncode}) before {what}: {err[-2000:]}")
        if time.monotonic() > end:
            proc.kill()
            pytest.fail(f"timed out waiting for {what}")
        time.sleep(0.05)


def _alive(procs) -> list:
    out = []
    for p in procs:
        try:
            if p.is_running() and p.status() != psutil.STATUS_ZOMBIE:
                out.append(p)
        except psutil.NoSuchProcess:
            pass
    return out


def _assert_no_survivors(procs) -> None:
    end = time.monotonic() + 30
    while _alive(procs) and time.monotonic() < end:
        time.sleep(0.2)
    left = _alive(procs)
    for p in left:  # do not leave them behind for the next test
        p.kill()
    assert not left, f"processes outlived their parent: {[(p.pid, p.cmdline()[-3:]) for p in left]}"


@pytest.fixture(scope="module")
def reference(tmp_path_factory):
    """The tables of an uninterrupted run."""
    out = tmp_path_factory.mktemp("reference") / "study"
    done = _run("reproduce", "--out", str(out), *STUDY)
    assert done.returncode == 0, done.stderr
    return {name: (out / name).read_bytes() for name in TABLES}


def _interrupt(out: Path, sig: int) -> tuple[subprocess.Popen, str]:
    """Start a study, send ``sig`` once a worker exists and a checkpoint is on disk."""
    proc = _start("reproduce", "--out", str(out), *STUDY)
    _wait_for(lambda: any(out.glob("checkpoints/run_*.json")), proc, "the first checkpoint")
    family = psutil.Process(proc.pid).children(recursive=True)
    assert len(family) >= 2, "expected the worker processes to be running"
    os.kill(proc.pid, sig)
    try:
        _, err = proc.communicate(timeout=TIMEOUT)
    except subprocess.TimeoutExpired:  # the pipes stay open while an orphan holds them
        proc.kill()
        _, err = proc.communicate()
        _assert_no_survivors(family)
        pytest.fail("the command did not end after the signal")
    _assert_no_survivors(family)
    return proc, err


def _finish_and_compare(out: Path, reference: dict, *, killed: bool = False) -> None:
    left = sorted(map(str, out.rglob("*.tmp")))
    if killed:  # SIGKILL gives no chance to clean up: a worker may die mid-write, its file must be stale
        writers = [int(name.rsplit(".", 2)[-2]) for name in left]
        assert not any(psutil.pid_exists(pid) for pid in writers), left
    else:
        assert not left, left
    assert not (out / "table_7_1.csv").exists(), "tables were written by an interrupted study"
    done = _run("reproduce", "--out", str(out), *STUDY, "--resume")
    assert done.returncode == 0, done.stderr
    assert not any(out.rglob("*.tmp")), sorted(map(str, out.rglob("*.tmp")))
    runs = json.loads((out / "study.json").read_text())["sampling"]["runs"]
    assert any(r["resumed_from"] > 0 for r in runs), "the study did not resume from its checkpoints"
    for name in TABLES:
        assert (out / name).read_bytes() == reference[name], f"{name} differs after --resume"


def test_sigint_exits_130_says_resume_and_resumes_byte_identically(tmp_path, reference):
    out = tmp_path / "study"
    proc, err = _interrupt(out, signal.SIGINT)
    assert proc.returncode == 130, err
    assert "interrupted; continue with --resume" in err
    assert "Traceback" not in err
    _finish_and_compare(out, reference)


def test_sigkill_leaves_no_orphan_workers_and_resumes_byte_identically(tmp_path, reference):
    out = tmp_path / "study"
    proc, _ = _interrupt(out, signal.SIGKILL)
    assert proc.returncode == -signal.SIGKILL
    _finish_and_compare(out, reference, killed=True)


def test_sigterm_shuts_the_pool_down(tmp_path):
    out = tmp_path / "study"
    proc, err = _interrupt(out, signal.SIGTERM)
    assert proc.returncode == 128 + signal.SIGTERM, err
    assert "interrupted; continue with --resume" in err


def test_a_second_run_into_a_busy_folder_is_refused_with_the_holders_pid(tmp_path):
    out = tmp_path / "study"
    first = _start("reproduce", "--out", str(out), *STUDY)
    try:
        _wait_for(lambda: any(out.glob("checkpoints/run_*.json")), first, "the first checkpoint")
        before = {p: p.read_bytes() for p in out.glob("checkpoints/*.json")}
        second = CliRunner().invoke(main, ["reproduce", "--out", str(out), *STUDY, "--resume"],
                                    catch_exceptions=False)
        assert second.exit_code == 2
        assert f"is in use by another rocketid run (PID {first.pid})" in second.stderr, second.stderr
        assert first.poll() is None, "the first run must be unaffected"
        # the refused run wrote nothing: the checkpoints it saw are the first run's (or newer ones of it)
        assert all(p.exists() for p in before)
    finally:
        os.kill(first.pid, signal.SIGINT)
        first.communicate(timeout=TIMEOUT)
    assert first.returncode == 130
    assert not (out / ".rocketid.lock").exists()


SLOW_WRITE_MODEL = '''
import numpy as np
from rocketid import Model


def build_model():
    m = Model("ramp", t0=0.0, tf=1.0)
    y = m.state("y", initial=0.0)
    a = m.parameter("a", guess=1.0, bounds=(0.0, 10.0))
    m.ode({y: a})
    m.output("y", y, sigma=0.1)
    return m.freeze()


def sample_times():
    return np.linspace(1e-6, 1.0, 3_000_000)
'''


@pytest.mark.parametrize("sig", [signal.SIGKILL, signal.SIGINT], ids=["SIGKILL", "SIGINT"])
def test_simulate_killed_while_writing_leaves_the_previous_file(tmp_path, sig):
    model = tmp_path / "ramp.py"
    model.write_text(SLOW_WRITE_MODEL)
    target = tmp_path / "data.csv"
    target.write_text("t,y\n0.5,1.0\n")
    previous = target.read_bytes()
    proc = _start("simulate", "--model", str(model), "--out", str(target))
    _wait_for(lambda: any(p.stat().st_size > 0 for p in tmp_path.glob(".data.csv.*.tmp")), proc,
              "the CSV being written")
    os.kill(proc.pid, sig)
    _, err = proc.communicate(timeout=TIMEOUT)
    assert proc.returncode == (130 if sig == signal.SIGINT else -signal.SIGKILL), err
    assert target.read_bytes() == previous, "the previous file was replaced by a partial one"
    if sig == signal.SIGINT:
        assert not list(tmp_path.glob(".data.csv.*.tmp")), "the temporary file was not removed"
    else:
        # a killed writer cannot clean up; the next write of the same file removes its leftover
        assert list(tmp_path.glob(".data.csv.*.tmp"))
        target.unlink()
        done = _run("simulate", "--out", str(target))
        assert done.returncode == 0, done.stderr
        assert not list(tmp_path.glob(".data.csv.*.tmp"))
        assert target.read_text().startswith("t,x,h,v\n")
