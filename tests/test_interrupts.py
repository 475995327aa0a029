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
        # a killed writer cannot clean up; the next command that checks the same file (here one that
        # is then refused) removes its leftover, and the next write leaves none
        assert list(tmp_path.glob(".data.csv.*.tmp"))
        refused = _run("simulate", "--out", str(target), "--param", "CD0=-5")
        assert refused.returncode == 2, refused.stderr
        assert not list(tmp_path.glob(".data.csv.*.tmp")), "the dead writer's temporary file is still there"
        assert target.read_bytes() == previous
        target.unlink()
        done = _run("simulate", "--out", str(target))
        assert done.returncode == 0, done.stderr
        assert not list(tmp_path.glob(".data.csv.*.tmp"))
        assert target.read_text().startswith("t,x,h,v\n")


# ---------------------------------------------------------------------------
# rocketid diagnose: its forked figure and refit workers
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def ra66_csv(tmp_path_factory):
    path = tmp_path_factory.mktemp("data") / "ra66.csv"
    done = _run("simulate", "--out", str(path))
    assert done.returncode == 0, done.stderr
    return path


def _family(proc: subprocess.Popen) -> list:
    try:
        return psutil.Process(proc.pid).children(recursive=True)
    except psutil.NoSuchProcess:
        return []


def _workers(proc: subprocess.Popen) -> list:
    """The command's worker processes (not its interrupt watchdog, a `python -S -E -c` process)."""
    return [p for p in _family(proc) if "-S" not in p.cmdline()[1:3]]


def _diagnose_and_signal(ra66_csv: Path, out: Path, sig: int, after_worker: float | None, after_start: float = 0.0):
    """Start `diagnose`, send ``sig`` ``after_worker`` s after its first forked worker appears (or
    ``after_start`` s after the start), return (process, stderr, the family seen at the signal)."""
    t0 = time.monotonic()
    proc = _start("diagnose", str(ra66_csv), "--out", str(out))
    if after_worker is not None:
        _wait_for(lambda: bool(_workers(proc)), proc, "a forked worker")
        time.sleep(after_worker)
    else:
        # the interrupt watchdog starts once the command has imported and set its handlers: a signal before
        # that is Python's own KeyboardInterrupt in an import (measured: at load average 6 the imports took
        # longer than 2.5 s and the test saw a traceback from scipy's import)
        _wait_for(lambda: bool(_family(proc)), proc, "the interrupt watchdog")
        time.sleep(max(0.0, t0 + after_start - time.monotonic()))
    family = _family(proc)
    if proc.poll() is not None:
        pytest.skip("diagnose ended before the signal")  # pragma: no cover - a very fast machine
    os.kill(proc.pid, sig)
    try:
        _, err = proc.communicate(timeout=60)
    except subprocess.TimeoutExpired:
        proc.kill()
        _, err = proc.communicate()
        _assert_no_survivors(family)
        pytest.fail("diagnose did not end after the signal")
    _assert_no_survivors(family)
    return proc, err, family


@pytest.mark.parametrize("after_worker, after_start", [(None, 2.5), (0.0, 0.0), (0.3, 0.0), (1.0, 0.0)],
                         ids=["fitting", "worker-started", "worker-0.3s", "worker-1s"])
def test_sigint_to_diagnose_exits_130_without_traceback_or_leftovers(tmp_path, ra66_csv, after_worker, after_start):
    out = tmp_path / "rep"
    proc, err, _ = _diagnose_and_signal(ra66_csv, out, signal.SIGINT, after_worker, after_start)
    if proc.returncode == 0:  # pragma: no cover - the run finished before the signal landed
        assert (out / "report.html").exists()
    else:
        assert proc.returncode == 130, err
        assert "interrupted" in err
    assert "Traceback" not in err, err
    assert "KeyboardInterrupt" not in err and "Interrupted" not in err, err
    assert not list(tmp_path.rglob("*.tmp")), sorted(map(str, tmp_path.rglob("*.tmp")))
    assert not (out / ".rocketid.lock").exists()


def test_sigkill_of_diagnose_leaves_no_orphan(tmp_path, ra66_csv):
    proc, _, family = _diagnose_and_signal(ra66_csv, tmp_path / "rep", signal.SIGKILL, 0.2)
    assert proc.returncode == -signal.SIGKILL
    assert family, "expected a forked worker"


def test_a_second_diagnose_into_the_same_folder_is_refused_with_the_holders_pid(tmp_path, ra66_csv):
    out = tmp_path / "rep"
    first = _start("diagnose", str(ra66_csv), "--out", str(out))
    try:
        _wait_for(lambda: (out / ".rocketid.lock").exists(), first, "the folder's lock")
        second = _run("diagnose", str(ra66_csv), "--out", str(out))
        assert second.returncode == 2, second.stderr
        assert f"is in use by another rocketid run (PID {first.pid})" in second.stderr, second.stderr
        assert "Traceback" not in second.stderr
        assert first.poll() is None or first.returncode == 0, "the first run must be unaffected"
    finally:
        if first.poll() is None:
            os.kill(first.pid, signal.SIGINT)
        first.communicate(timeout=TIMEOUT)
    assert first.returncode in (0, 130)
    assert not (out / ".rocketid.lock").exists()


# ---------------------------------------------------------------------------
# Ctrl-C during a long IPOPT factorization (Python gets no chance to act on it)
# ---------------------------------------------------------------------------

LONG_SOLVE = ["-v", "estimate", "--elements", "5000"]  # minutes of MUMPS factorizations


def _start_long_solve(ra66_csv: Path, out: Path) -> tuple[subprocess.Popen, list]:
    """Start a fit that spends minutes inside MUMPS; return it once IPOPT runs (plus 4 s)."""
    lines: list = []
    proc = _start(*LONG_SOLVE, str(ra66_csv), "--out", str(out))
    import threading

    def read():
        for line in proc.stderr:
            lines.append(line)
    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    _wait_for(lambda: any("solving with IPOPT" in x for x in lines), proc, "the solve")
    time.sleep(4.0)
    assert proc.poll() is None, "".join(lines)
    proc._reader = reader  # joined by _ended
    return proc, lines


def _ended(proc: subprocess.Popen, lines: list, limit: float) -> float:
    t0 = time.monotonic()
    try:
        proc.wait(timeout=limit)
    except subprocess.TimeoutExpired:
        proc.kill()
        proc.wait()
        pytest.fail(f"the process ran on {limit:.0f} s after the interrupt")
    proc._reader.join(5.0)
    return time.monotonic() - t0


def test_ctrl_c_during_a_long_factorization_ends_the_command(tmp_path, ra66_csv):
    out = tmp_path / "fit.json"
    proc, lines = _start_long_solve(ra66_csv, out)
    family = _family(proc)
    os.kill(proc.pid, signal.SIGINT)
    took = _ended(proc, lines, 15.0)
    err = "".join(lines)
    # 130: the main thread acted on the signal; killed by SIGINT (the shell's 130): the watchdog
    # ended a main thread stuck in MUMPS, after INTERRUPT_GRACE_S
    assert proc.returncode in (130, -signal.SIGINT), err
    assert "Error: interrupted" in err and "Traceback" not in err, err
    assert not out.exists() and not list(tmp_path.glob(".*.tmp"))
    _assert_no_survivors(family)
    print(f"ended {took:.1f} s after SIGINT with {proc.returncode}")


def test_a_second_ctrl_c_ends_the_command_at_once(tmp_path, ra66_csv):
    proc, lines = _start_long_solve(ra66_csv, tmp_path / "fit.json")
    family = _family(proc)
    os.kill(proc.pid, signal.SIGINT)
    time.sleep(0.5)
    t0 = time.monotonic()
    if proc.poll() is None:
        os.kill(proc.pid, signal.SIGINT)
    _ended(proc, lines, 10.0)
    took = time.monotonic() - t0
    assert proc.returncode in (130, -signal.SIGINT), "".join(lines)
    assert took < 3.0, f"ended {took:.1f} s after the second Ctrl-C"
    _assert_no_survivors(family)


def test_a_mesh_far_finer_than_the_data_is_warned_about_before_the_work(tmp_path, ra66_csv):
    """``--elements 20000`` once printed nothing for minutes while growing to 2.3 GB: the size
    warning with the expected memory comes first, then the progress line, both before the NLP
    is built; the command is then interrupted (it would take minutes)."""
    lines: list = []
    proc = _start("-v", "estimate", "--elements", "20000", str(ra66_csv), "--out", str(tmp_path / "fit.json"))
    import threading

    reader = threading.Thread(target=lambda: lines.extend(proc.stderr), daemon=True)
    reader.start()
    try:
        _wait_for(lambda: any("building the NLP" in x for x in lines), proc, "the progress line")
    finally:
        os.kill(proc.pid, signal.SIGINT)
        proc.wait(timeout=30)
        reader.join(5.0)
    err = "".join(lines)
    warning = next((x for x in lines if x.startswith("Warning: 200")), None)  # 20004: knots on boundaries
    assert warning is not None, err
    assert "6600 sample times" in warning and "use fewer --elements" in warning, warning
    memory = float(warning.split("Expect about ")[1].split(" MB")[0])
    assert 400 < memory < 2000, warning                      # 20000 x K = 4: about 620 MB before IPOPT
    assert err.index(warning) < err.index("building the NLP"), err
    assert proc.returncode in (130, -signal.SIGINT), err


# ---------------------------------------------------------------------------
# rocketid reproduce --executor dask: the client's tasks end with it
# ---------------------------------------------------------------------------


def test_sigkill_of_a_dask_client_leaves_nothing_processing(tmp_path):
    """distributed's scheduler releases a client's tasks when its connection closes: a killed
    `reproduce --executor dask` leaves no task of its on the cluster (a batch already running on a
    worker runs to its end, a few seconds, and its result is dropped)."""
    distributed = pytest.importorskip("distributed")
    out = tmp_path / "study"
    # STUDY on dask, with enough draws to be still running when it is killed
    args = ["--runs", "2", "--n-iter", "400", "--batch-size", "4", "--perturbations", "1", "--no-plots", "-q",
            "--executor", "dask"]
    with distributed.LocalCluster(n_workers=2, threads_per_worker=1, processes=True, host="127.0.0.1",
                                  dashboard_address=None) as cluster, distributed.Client(cluster) as client:
        proc = _start("reproduce", "--out", str(out), *args, "--scheduler", cluster.scheduler_address)
        _wait_for(lambda: any(client.processing().values()), proc, "tasks on the cluster")
        time.sleep(1.0)
        clients_before = set(client.run_on_scheduler(lambda dask_scheduler: list(dask_scheduler.clients)))
        os.kill(proc.pid, signal.SIGKILL)
        proc.communicate(timeout=60)
        end = time.monotonic() + 30

        def busy():
            on_scheduler = client.run_on_scheduler(lambda dask_scheduler: len(dask_scheduler.tasks))
            on_workers = client.run(lambda dask_worker: sum(
                ts.state in ("executing", "cancelled", "ready", "waiting", "constrained", "fetch")
                for ts in dask_worker.state.tasks.values()))
            return any(client.processing().values()) or on_scheduler or any(on_workers.values())

        while busy() and time.monotonic() < end:
            time.sleep(0.5)
        assert not busy(), (client.processing(), client.run(lambda dask_worker: dict(
            (str(k), ts.state) for k, ts in dask_worker.state.tasks.items())))
        clients = set(client.run_on_scheduler(lambda dask_scheduler: list(dask_scheduler.clients)))
        assert len(clients) < len(clients_before), "the killed client is still known to the scheduler"


def test_an_interrupt_wrapped_by_python_is_still_an_interrupt():
    """A Ctrl-C that lands while a class is being created (matplotlib's first import, in the report's
    figures) comes back from Python 3.11 as ``RuntimeError`` whose cause is the KeyboardInterrupt (measured in
    the suite: a traceback and exit 1 instead of 130). The command line reads the cause; a RuntimeError
    without one is not swallowed."""
    import click
    from rocketid.cli import RocketidGroup

    @click.group(cls=RocketidGroup)
    def group():
        pass

    @group.command("wrapped")
    def wrapped():
        try:
            raise KeyboardInterrupt()
        except KeyboardInterrupt as exc:
            raise RuntimeError("Error calling __set_name__ on '_deprecated_property'") from exc

    @group.command("plain")
    def plain():
        raise RuntimeError("a bug")

    res = CliRunner().invoke(group, ["wrapped"])
    assert res.exit_code == 130 and "interrupted" in res.stderr, (res.exit_code, res.stderr)
    res = CliRunner().invoke(group, ["plain"])
    assert res.exit_code == 1 and isinstance(res.exception, RuntimeError)
