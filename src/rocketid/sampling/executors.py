"""Where batches of draws are evaluated: in-process, in a process pool, or on dask.

Each executor takes batches ``(seed, k0, k1)`` and returns
:class:`~rocketid.sampling.worker.BatchResult` values through handles; the
coordinator (:mod:`rocketid.sampling.runner`) decides what to submit and
processes the outcomes in draw order.

=============  ===================================================================
``serial``     in this process, one batch at a time (no look-ahead, no waste)
``processes``  ``concurrent.futures.ProcessPoolExecutor`` with ``spawn`` workers;
               each worker rebuilds the NLP once from the recipe (initializer)
``dask``       a ``distributed.Client`` (yours, or one connected to ``address``);
               the recipe is scattered to every worker once
=============  ===================================================================
"""

from __future__ import annotations

import os
import signal
import sys
import threading
import time
from typing import Any

from ..errors import SettingsError, SolverError
from .worker import BatchResult, Recipe, WorkerContext, evaluate_batch, install

__all__ = ["EXECUTORS", "make_executor", "default_workers", "die_with_parent"]

EXECUTORS = ("serial", "processes", "dask")


def die_with_parent(parent_pid: int) -> None:
    """Make this (worker) process end when ``parent_pid``, its parent, ends, however
    the parent ends (``SIGKILL`` included), and leave Ctrl-C to the parent.

    On Linux the kernel sends ``SIGKILL`` on the parent's death
    (``prctl(PR_SET_PDEATHSIG)``); elsewhere a daemon thread polls the parent
    once a second. A parent that died before this call ends the process at once.

    ``SIGINT`` is ignored (the parent shuts its workers down on Ctrl-C) and
    ``SIGTERM`` gets its default action, so that the parent's ``terminate()``
    ends a worker at once and silently: a forked worker would otherwise inherit
    the command's handler (SIGTERM raised as an interrupt, see
    ``rocketid.cli``) and print a traceback while it dies. A forked worker also
    stops writing the parent's signal wake-up file descriptor.
    """
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent shuts the pool down on Ctrl-C
    signal.signal(signal.SIGTERM, signal.SIG_DFL)  # terminate() ends the worker, without a traceback
    try:
        signal.set_wakeup_fd(-1)  # inherited by a fork: the parent's interrupt watchdog reads it
    except ValueError:  # pragma: no cover - not the main thread
        pass
    armed = False
    if sys.platform.startswith("linux"):
        try:
            import ctypes
            libc = ctypes.CDLL(None, use_errno=True)
            PR_SET_PDEATHSIG = 1
            armed = libc.prctl(PR_SET_PDEATHSIG, int(signal.SIGKILL), 0, 0, 0) == 0
        except (OSError, AttributeError):  # pragma: no cover - no prctl
            armed = False
    if os.getppid() != parent_pid:
        os._exit(1)
    if not armed:  # pragma: no cover - not Linux
        def watch():
            while True:
                time.sleep(1.0)
                if os.getppid() != parent_pid:
                    os._exit(1)
        threading.Thread(target=watch, name="rocketid-parent-watch", daemon=True).start()


def _start_worker(parent_pid: int, recipe: Recipe) -> None:
    """Initializer of a pool process: tie it to its parent, then install the recipe."""
    die_with_parent(parent_pid)
    install(recipe)


def default_workers() -> int:
    """Processes to use by default: the CPUs this process may run on."""
    try:
        return max(1, len(os.sched_getaffinity(0)))
    except AttributeError:  # pragma: no cover - not Linux
        return max(1, os.cpu_count() or 1)


class _Done:
    """A finished handle (serial executor)."""

    def __init__(self, value: BatchResult):
        self.value = value


class SerialExecutor:
    """Evaluate each batch when it is submitted, in this process."""

    name = "serial"
    speculative = False

    def __init__(self, ctx: WorkerContext):
        self.ctx = ctx
        self.workers = 1

    def submit(self, seed: int, k0: int, k1: int) -> _Done:
        return _Done(evaluate_batch(self.ctx.recipe.token, seed, k0, k1))

    def wait(self, handles) -> list:
        return list(handles)

    def result(self, handle) -> BatchResult:
        return handle.value

    def cancel(self, handle) -> bool:
        return False

    def close(self, cancel: bool = False) -> None:
        pass


class ProcessExecutor:
    """A pool of ``spawn`` processes; each installs the recipe once."""

    name = "processes"
    speculative = True

    def __init__(self, recipe: Recipe, workers: int):
        import concurrent.futures as cf
        import multiprocessing as mp
        self._cf = cf
        self.workers = int(workers)
        self.token = recipe.token
        self.pool = cf.ProcessPoolExecutor(max_workers=self.workers, mp_context=mp.get_context("spawn"),
                                           initializer=_start_worker, initargs=(os.getpid(), recipe))

    def submit(self, seed: int, k0: int, k1: int):
        return self.pool.submit(evaluate_batch, self.token, seed, k0, k1)

    def wait(self, handles) -> list:
        while True:
            done, _ = self._cf.wait(list(handles), timeout=2.0, return_when=self._cf.FIRST_COMPLETED)
            if done:
                return list(done)
            # a worker that dies while starting can leave the pool waiting forever
            procs = dict(getattr(self.pool, "_processes", None) or {})
            dead = [p for p in procs.values() if p.exitcode is not None]
            if dead:
                raise SolverError(
                    f"a sampling worker process exited while starting (exit code {dead[0].exitcode}). Worker "
                    "processes are started with 'spawn', which imports your main script again: put the code "
                    "that runs the study under `if __name__ == \"__main__\":`, or use executor='serial'")

    def result(self, handle) -> BatchResult:
        try:
            return handle.result()
        except self._cf.process.BrokenProcessPool as exc:
            raise SolverError(f"a sampling worker process died ({exc}); its checkpoints are on disk: "
                              "resume to continue") from exc

    def cancel(self, handle) -> bool:
        return handle.cancel()

    def close(self, cancel: bool = False) -> None:
        self.pool.shutdown(wait=True, cancel_futures=cancel)


class DaskExecutor:
    """Batches as tasks on a ``distributed`` cluster (optional dependency)."""

    name = "dask"
    speculative = True

    def __init__(self, recipe: Recipe, client: Any = None, address: str | None = None):
        try:
            import distributed
        except ImportError as exc:
            raise SettingsError("executor 'dask' needs dask.distributed: pip install 'rocketid[distributed]'") from exc
        self._distributed = distributed
        self._own = client is None
        if client is None:
            if address is None:
                raise SettingsError("executor 'dask' needs a distributed.Client (client=...) or a scheduler "
                                    "address (address='tcp://host:8786')")
            client = distributed.Client(address)
        self.client = client
        info = client.scheduler_info()
        n = sum(int(w.get("nthreads", 1)) for w in info.get("workers", {}).values())
        if n < 1:
            raise SettingsError("the dask cluster has no workers")
        self.workers = n
        self.recipe = client.scatter(recipe, broadcast=True, hash=False)
        self._outstanding: set = set()

    def submit(self, seed: int, k0: int, k1: int):
        future = self.client.submit(evaluate_batch, self.recipe, seed, k0, k1, pure=False)
        self._outstanding.add(future)
        return future

    def wait(self, handles) -> list:
        done, _ = self._distributed.wait(list(handles), return_when="FIRST_COMPLETED")
        return list(done)

    def result(self, handle) -> BatchResult:
        self._outstanding.discard(handle)
        return handle.result()

    def cancel(self, handle) -> bool:
        """False: a dask task may already run on a worker, and a cancel request does not
        stop it. The coordinator then waits for its result and counts it as waste, so that
        no task still runs when :func:`~rocketid.sampling.sample` returns (a task still
        running while its cluster shut down made that shutdown fail now and then)."""
        return False

    def close(self, cancel: bool = False) -> None:
        if cancel and self._outstanding:
            try:
                self.client.cancel(list(self._outstanding), force=True)
            except Exception:  # pragma: no cover - a closed or lost client
                pass
        self._outstanding.clear()
        try:
            self.recipe.release()  # the scattered recipe leaves the workers' memory
        except Exception:  # pragma: no cover - a closed or lost client
            pass
        if self._own:
            self.client.close()


def make_executor(kind: str, recipe: Recipe, ctx: WorkerContext | None, *, workers: int | None = None,
                  client: Any = None, address: str | None = None):
    """An executor by name (see :data:`EXECUTORS`)."""
    if kind not in EXECUTORS:
        raise SettingsError(f"unknown executor {kind!r}; choose one of {', '.join(EXECUTORS)}")
    if kind == "serial":
        if ctx is None:
            ctx = install(recipe)
        return SerialExecutor(ctx)
    if kind == "processes":
        n = default_workers() if workers is None else int(workers)
        if n < 1:
            raise SettingsError(f"workers must be a positive integer, got {workers!r}")
        return ProcessExecutor(recipe, n)
    return DaskExecutor(recipe, client=client, address=address)
