"""Atomic writes and the output folder's lock (``rocketid.output``)."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest

from rocketid.output import LOCK_NAME, atomic_open, check_file, folder_lock, remove_stale_tree, write_text


def _dead_pid() -> int:
    """The PID of a process that has ended (and been reaped)."""
    proc = subprocess.Popen([sys.executable, "-c", "pass"])
    proc.wait()
    return proc.pid


def test_a_failed_write_keeps_the_previous_file(tmp_path):
    target = tmp_path / "table.csv"
    write_text(target, "old\n")
    with pytest.raises(RuntimeError):
        with atomic_open(target) as fh:
            fh.write("half a ta")
            raise RuntimeError("killed mid-write")
    assert target.read_text() == "old\n"
    assert [p.name for p in tmp_path.iterdir()] == ["table.csv"]


def test_taking_the_lock_sweeps_temporary_files_of_dead_writers_only(tmp_path):
    dead = _dead_pid()
    sub = tmp_path / "checkpoints"
    sub.mkdir()
    stale = [tmp_path / f".study.json.{dead}.tmp", sub / f".run_2.json.{dead}.tmp"]
    with subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"]) as live_proc:
        try:
            live = sub / f".run_3.json.{live_proc.pid}.tmp"
            unrelated = sub / ".notes.tmp"  # not a name rocketid writes: never touched
            for p in (*stale, live, unrelated):
                p.write_text("partial")
            with folder_lock(tmp_path) as folder:
                assert (folder / LOCK_NAME).read_text().strip() == str(os.getpid())
                assert not any(p.exists() for p in stale)
                assert live.exists() and unrelated.exists()
        finally:
            live_proc.kill()
    assert not (tmp_path / LOCK_NAME).exists()


def test_remove_stale_tree_on_a_clean_folder_changes_nothing(tmp_path):
    write_text(tmp_path / "a" / "b.json", "{}")
    remove_stale_tree(tmp_path)
    assert sorted(p.name for p in tmp_path.rglob("*")) == ["a", "b.json"]


def test_a_second_run_is_refused_with_the_holders_pid(tmp_path):
    with folder_lock(tmp_path):
        code = ("import sys; from rocketid.output import folder_lock\n"
                f"with folder_lock({str(tmp_path)!r}): pass")
        done = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)
        assert done.returncode != 0
        assert f"PID {os.getpid()}" in done.stderr
    with folder_lock(tmp_path):  # released: the next run takes it
        pass


def test_checking_a_target_sweeps_its_temporary_files_of_dead_writers_only(tmp_path):
    dead = _dead_pid()
    stale = tmp_path / f".data.csv.{dead}.tmp"
    other = tmp_path / f".other.csv.{dead}.tmp"  # another target's: left to its own check
    with subprocess.Popen([sys.executable, "-c", "import time; time.sleep(60)"]) as live_proc:
        try:
            live = tmp_path / f".data.csv.{live_proc.pid}.tmp"
            for p in (stale, other, live):
                p.write_text("partial")
            assert check_file(tmp_path / "data.csv") == tmp_path / "data.csv"
            assert not stale.exists()
            assert other.exists() and live.exists()
        finally:
            live_proc.kill()


def test_the_environment_names_the_numerical_stack_a_result_depends_on():
    """The versions a report and a study table record, read back from the packages themselves (a refit's optimum
    moved with a release of the stack: 2026-11-28, flight C of the Petrel-V nozzle campaign)."""
    import platform

    import cyipopt
    import numpy
    import scipy
    import sympy

    from rocketid.output import environment, environment_line
    env = environment()
    assert (env["numpy"], env["scipy"], env["sympy"]) == (numpy.__version__, scipy.__version__, sympy.__version__)
    assert env["ipopt"] == ".".join(map(str, cyipopt.IPOPT_VERSION)) and env["machine"] == platform.machine()
    assert env["cyipopt"] != "?" and env["rocketid"] != "?"
    line = environment_line(env)
    assert line.startswith(f"rocketid {env['rocketid']}, numpy {numpy.__version__}, scipy ") and "ipopt " in line
    # a stored environment is printed as stored, keys it lacks left out
    assert environment_line({"numpy": "1.26.4", "ipopt": "3.14.16"}) == "numpy 1.26.4, ipopt 3.14.16"
