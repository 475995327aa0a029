"""The statistic-criterion sampling algorithm (steps 1-10), serial or parallel, resumable.

Steps 1-4 (:func:`prepare_sampling`): the reduced Hessian H_r and its
eigenvectors V at p0, np by the modified E-optimal criterion, and the
reference solve of (7.9) with ``q2 = V2^T p0`` (draw 0; its solution
warm-starts every draw). Steps 5-10 (:func:`sample`): for each run (one seed
each), draws ``k = 1, 2, ...`` (see :mod:`rocketid.sampling.worker`) are
processed in draw order; a draw with a smaller eta than the best so far
becomes the best; a run stops after ``n_iter`` draws in a row without
improvement (failed draws count as no improvement).

Parallel and exact
------------------
The coordinator hands out batches of draws to an executor and processes the
returned outcomes strictly in draw order per run, so the stopping rule is
applied exactly as in a serial loop. It first hands out *certain* work: with
``since`` draws already without improvement, a run needs at least its next
``n_iter - since`` draws whatever they give. Only when no run has certain
work left does a parallel executor evaluate draws past that point
(speculatively); the outcomes of draws past a run's stopping point are
discarded and counted as waste (:attr:`SamplingResult.n_wasted`). Runs are
independent and interleaved over the workers, so with several runs there is
almost always certain work and the waste is a few batches at the very end.
"""

from __future__ import annotations

import logging
import math
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Callable, Mapping, Sequence

import numpy as np

from ..errors import SettingsError
from ..estimability import Estimability, analyze, estimate_q1
from ..solve import EstimationResult, Prepared
from ..summary import Section, Summary, Table, Text
from .checkpoint import RunState, checkpoint_path, read_checkpoint, write_checkpoint
from .criterion import TERM_NAMES
from .executors import make_executor
from .scheduler import Batch, Scheduler
from .settings import SamplingSettings
from .worker import DrawOutcome, Recipe, draw_outcome, install

__all__ = ["SamplingProblem", "prepare_sampling", "sample", "RunResult", "SamplingResult"]

log = logging.getLogger("rocketid.sampling")


# ---------------------------------------------------------------------------
# Steps 1-4
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class SamplingProblem:
    """Steps 1-4 done: what every run shares.

    Attributes
    ----------
    prepared : Prepared
    p0 : ndarray, shape (n_p,)
    settings : SamplingSettings
    estimability : Estimability
        H_r, V and np at p0.
    reference : EstimationResult
        (7.9) with ``q2 = V2^T p0`` solved from a simulation at p0 (draw 0).
    reference_outcome : DrawOutcome
        The reference as a draw outcome (eta and its terms).
    recipe : Recipe
        What worker processes need.
    setup_s : float
    """

    prepared: Prepared
    p0: np.ndarray
    settings: SamplingSettings
    estimability: Estimability
    reference: EstimationResult
    reference_outcome: DrawOutcome
    recipe: Recipe
    setup_s: float


def prepare_sampling(prepared: Prepared, p0: Sequence[float] | Mapping | None = None,
                     settings: SamplingSettings | None = None) -> SamplingProblem:
    """Steps 1-4: estimability at p0 and the reference (7.9) solve.

    Raises
    ------
    SolverError, SensitivityError
        When H_r cannot be formed at p0; a reference solve that does not
        converge is reported in its outcome (and every draw starts from it).
    """
    settings = settings or SamplingSettings()
    t0 = time.perf_counter()
    spec = prepared.spec
    p0 = spec.parameter_vector(p0)
    est = analyze(prepared, p0, threshold=settings.threshold, scaling=settings.scaling,
                  n_estimated=settings.n_estimated)
    if est.n_estimated == 0:
        raise SettingsError("no direction passes the modified E-optimal criterion at p0: nothing to estimate")
    if est.n_estimated == est.eigenvalues.size:
        raise SettingsError(f"all {est.n_estimated} directions pass the criterion (threshold "
                            f"{settings.threshold:g}): there is no q2 to sample; estimate all parameters directly")
    q2_ref = est.q2_of(p0)
    ref = estimate_q1(prepared, est, q2_ref, options=settings.ipopt_options)
    outcome = draw_outcome(0, 0, ref, q2_ref, p0, ref.timings.get("solve_s", math.nan))
    recipe = Recipe.make(prepared, settings, est, ref, q2_ref)
    return SamplingProblem(prepared, p0, settings, est, ref, outcome, recipe, time.perf_counter() - t0)


# ---------------------------------------------------------------------------
# Results
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class RunResult:
    """One run of the algorithm (one seed).

    Attributes
    ----------
    seed : int
    best : DrawOutcome or None
        The least-eta draw (None if every draw failed).
    n_draws : int
        Draws processed (the last improving draw plus ``n_iter``, when
        stopped by the rule).
    stopped_by : str
        ``"n_iter"`` (the rule) or ``"max_draws"`` (the cap).
    failures : tuple of (draw, status, message)
    history : ndarray, shape (n_draws,)
        eta of draws 1..n_draws (NaN: failed).
    improvements : tuple of int
        Draws that improved eta.
    solve_s : float
        Summed wall time of the draws (all processes).
    n_retried : int
        Draws whose warm-started solve failed and was repeated cold.
    iterations : int
        IPOPT iterations summed over the draws.
    resumed_from : int
        Draws loaded from a checkpoint.
    """

    seed: int
    best: DrawOutcome | None
    n_draws: int
    stopped_by: str
    failures: tuple
    history: np.ndarray
    improvements: tuple
    solve_s: float
    n_retried: int
    iterations: int
    resumed_from: int

    @property
    def n_failures(self) -> int:
        return len(self.failures)

    @property
    def eta(self) -> float:
        return self.best.eta if self.best is not None else math.nan

    @property
    def running_best(self) -> np.ndarray:
        """Best eta after each draw, shape (n_draws,)."""
        h = np.where(np.isfinite(self.history), self.history, np.inf)
        out = np.minimum.accumulate(h) if h.size else h
        return np.where(np.isfinite(out), out, np.nan)

    @classmethod
    def from_state(cls, st: RunState) -> "RunResult":
        h = np.array(st.history, dtype=float)
        h.flags.writeable = False
        return cls(st.seed, st.best, st.draws, st.stopped_by or "interrupted", tuple(st.failures), h,
                   tuple(st.improvements), st.solve_s, st.n_retried, st.iterations, st.resumed_from)

    def to_dict(self) -> dict:
        return {"seed": self.seed, "best": None if self.best is None else self.best.to_dict(),
                "n_draws": self.n_draws, "stopped_by": self.stopped_by, "n_failures": self.n_failures,
                "failures": [list(f) for f in self.failures], "improvements": list(self.improvements),
                "solve_s": self.solve_s, "n_retried": self.n_retried, "iterations": self.iterations,
                "mean_iterations": self.iterations / max(1, self.n_draws), "resumed_from": self.resumed_from}


@dataclass(frozen=True)
class SamplingResult:
    """The outcome of :func:`sample`: the reference, every run, and how it ran.

    Attributes
    ----------
    settings : SamplingSettings
    estimability : Estimability
    reference : DrawOutcome
        Draw 0: (7.9) with ``q2 = V2^T p0``.
    runs : tuple of RunResult
    executor : str
    workers : int
    wall_s : float
        Wall time of steps 5-10 (this call; a resumed call counts its own time).
    setup_s : float
        Steps 1-4.
    n_evaluated : int
        Draws evaluated in this call (processed or wasted).
    n_wasted : int
        Draws evaluated past a run's stopping point and discarded.
    n_cancelled : int
        Draws submitted past a stopping point and cancelled (dask; perhaps partly evaluated).
    worker_setup_s : tuple of float
        Per worker process: wall time to rebuild the NLP from the recipe.
    startup_s : float
        From the start of steps 5-10 to the first batch's start (for a
        process pool: spawning the workers, importing rocketid, rebuilding).
    token : str
    parameter_names : tuple of str
    """

    settings: SamplingSettings
    estimability: Estimability
    reference: DrawOutcome
    runs: tuple
    executor: str
    workers: int
    wall_s: float
    setup_s: float
    n_evaluated: int
    n_wasted: int
    n_cancelled: int
    worker_setup_s: tuple
    startup_s: float
    token: str
    parameter_names: tuple

    @property
    def best_run(self) -> RunResult | None:
        """The run with the least eta (ties: the first)."""
        ok = [r for r in self.runs if r.best is not None]
        return min(ok, key=lambda r: r.best.eta) if ok else None

    @property
    def n_draws(self) -> int:
        return sum(r.n_draws for r in self.runs)

    @property
    def n_failures(self) -> int:
        return sum(r.n_failures for r in self.runs)

    @property
    def solves_per_s(self) -> float:
        """Draws evaluated per second of wall time in this call."""
        return self.n_evaluated / self.wall_s if self.wall_s > 0 else math.nan

    def summary(self) -> Summary:
        """Settings, reference, runs; numbered notes."""
        est = self.estimability
        s = self.settings
        settings = Section("Settings", (
            ("n_iter", f"{s.n_iter} draws in a row without improvement"
                       + (f" (cap {s.max_draws} draws)" if s.max_draws else "")),
            ("distribution", f"{s.distribution_name} within the bounds"),
            ("scaling", f"{s.scaling}; threshold {s.threshold:g}; np = {est.n_estimated} of {est.eigenvalues.size}"),
            ("executor", f"{self.executor} ({self.workers} worker{'s' if self.workers != 1 else ''}), "
                         f"batches of {s.batch_size}")))
        reference = Section("Reference (draw 0: q2 fixed at V2^T p0)", (
            ("eta", f"{self.reference.eta:.6g}  ({self._terms(self.reference)})"),))
        runs = Section("Runs", (Table(
            ("seed", "draws", "best at", "eta", "failed", "stopped by"),
            [(r.seed, r.n_draws, r.best.draw if r.best is not None else "-", r.eta, r.n_failures, r.stopped_by)
             for r in self.runs], (None, None, None, ".6g")),))
        sections = [settings, reference, runs]
        b = self.best_run
        if b is not None:
            sections.append(Section("Least-eta run", (Text(f"seed {b.seed}: " + ", ".join(
                f"{n}={v:.4g}" for n, v in zip(self.parameter_names, b.best.p))),)))
        its = sum(r.iterations for r in self.runs) / max(1, self.n_draws)
        retried = sum(r.n_retried for r in self.runs)
        perf = [("IPOPT", f"{its:.2f} iterations per draw (warm-started from draw 0)"
                          + (f"; {retried} warm starts failed and were repeated cold" if retried else "")),
                ("wall time", f"{self.wall_s:.2f} s for {self.n_evaluated} solves ({self.solves_per_s:.1f} per s); "
                              f"steps 1-4 {self.setup_s:.2f} s, executor start-up {self.startup_s:.2f} s"),
                ("wasted", f"{self.n_wasted} draws evaluated past a stopping point"
                           + (f", {self.n_cancelled} cancelled" if self.n_cancelled else ""))]
        if self.worker_setup_s:
            perf.append(("worker set-up", ", ".join(f"{t:.2f}" for t in self.worker_setup_s)
                         + " s (NLP rebuilt from the recipe, generated code from the disk cache)"))
        sections.append(Section("Performance", perf))
        return Summary("rocketid statistic-criterion sampling (steps 1-10)", sections, self._notes())

    def _notes(self) -> list[str]:
        s = self.settings
        notes = []
        if not self.reference.success:
            notes.append(f"the reference solve (draw 0) failed: {self.reference.message}; every draw is "
                         "warm-started from it, so expect slow or failed draws")
        for r in self.runs:
            if r.best is None:
                notes.append(f"run {r.seed}: every draw failed; it has no result")
            if r.n_failures:
                first = r.failures[0]
                notes.append(f"run {r.seed}: {r.n_failures} of {r.n_draws} draws failed (first: draw {first[0]}, "
                             f"status {first[1]}: {first[2]}); failed draws never win and count as no improvement")
            if r.stopped_by == "max_draws":
                notes.append(f"run {r.seed} was stopped by the cap of {s.max_draws} draws, not by the n_iter rule")
            if r.stopped_by == "interrupted":
                notes.append(f"run {r.seed} was interrupted after {r.n_draws} draws; resume it from its checkpoint")
            if r.resumed_from:
                notes.append(f"run {r.seed} resumed from a checkpoint at draw {r.resumed_from}")
        return notes

    @staticmethod
    def _terms(o: DrawOutcome) -> str:
        return ", ".join(f"{n} {v:.3g}" for n, v in zip(TERM_NAMES, o.terms))

    def to_dict(self) -> dict:
        b = self.best_run
        return {"settings": self.settings.to_dict(), "np": int(self.estimability.n_estimated),
                "estimability": self.estimability.to_dict() if self.estimability.sensitivity is not None else None,
                "parameter_names": list(self.parameter_names), "reference": self.reference.to_dict(),
                "runs": [r.to_dict() for r in self.runs], "best_seed": None if b is None else b.seed,
                "executor": self.executor, "workers": self.workers, "wall_s": self.wall_s, "setup_s": self.setup_s,
                "n_evaluated": self.n_evaluated, "n_wasted": self.n_wasted, "n_cancelled": self.n_cancelled,
                "solves_per_s": self.solves_per_s, "worker_setup_s": list(self.worker_setup_s),
                "startup_s": self.startup_s, "token": self.token}


# ---------------------------------------------------------------------------
# Progress bars
# ---------------------------------------------------------------------------


class _Progress:
    """tqdm bars on stderr: one for the study (solves/s), one per run."""

    def __init__(self, enabled: bool, states: Sequence[RunState], n_iter: int, max_draws: int | None):
        self.enabled = enabled
        self.n_iter, self.max_draws = n_iter, max_draws
        self.bars = {}
        self.total = None
        if not enabled:
            return
        from tqdm import tqdm
        self.total = tqdm(desc="solves", unit="solve", file=sys.stderr, position=0, leave=True, dynamic_ncols=True)
        for i, st in enumerate(states, 1):
            self.bars[st.seed] = tqdm(desc=f"run seed {st.seed}", unit="draw", file=sys.stderr, position=i,
                                      leave=True, initial=st.draws, total=self._min_total(st), dynamic_ncols=True)
            self.update(st, 0)

    def _min_total(self, st: RunState) -> int:
        return st.certain_end(self.n_iter, self.max_draws) - 1 if st.stopped_by is None else st.draws

    def evaluated(self, n: int, runs_done: int, n_runs: int) -> None:
        if self.enabled:
            self.total.update(n)
            self.total.set_postfix_str(f"runs done {runs_done}/{n_runs}", refresh=False)

    def update(self, st: RunState, n: int) -> None:
        if not self.enabled:
            return
        bar = self.bars[st.seed]
        bar.total = self._min_total(st)
        bar.update(n)
        best = f"{st.best.eta:.5g} @ {st.best.draw}" if st.best is not None else "-"
        bar.set_postfix_str(f"best eta {best}, since {st.since}, failed {len(st.failures)}"
                            + (f", {st.stopped_by}" if st.stopped_by else ""), refresh=True)

    def close(self) -> None:
        for bar in self.bars.values():
            bar.close()
        if self.total is not None:
            self.total.close()


# ---------------------------------------------------------------------------
# Steps 5-10, for several runs
# ---------------------------------------------------------------------------


def _auto_progress() -> bool:
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


def sample(prepared: Prepared | SamplingProblem, *, p0: Sequence[float] | Mapping | None = None,
           seeds: Sequence[int] = (1,), settings: SamplingSettings | None = None, executor: str = "serial",
           workers: int | None = None, client: Any = None, address: str | None = None,
           checkpoint_dir: str | Path | None = None, resume: bool = False, progress: bool | None = None,
           callback: Callable[[int, int], None] | None = None) -> SamplingResult:
    """Run the sampling algorithm (steps 1-10) once per seed.

    Parameters
    ----------
    prepared : Prepared or SamplingProblem
        The model collocated against the data (``rocketid.prepare``), or the
        output of :func:`prepare_sampling` (steps 1-4 already done).
    p0 : optional
        The initial guess (default: the model's); ignored with a SamplingProblem.
    seeds : sequence of int
        One run per seed (non-negative integers); draw ``k`` of run ``s`` uses
        ``numpy.random.default_rng([s, k])``.
    settings : SamplingSettings, optional
    executor : {"serial", "processes", "dask"}
    workers : int, optional
        Processes for ``"processes"`` (default: the CPUs available).
    client : distributed.Client, optional
        For ``"dask"`` (or give ``address``).
    checkpoint_dir : path, optional
        Write ``checkpoint_dir/checkpoints/run_<seed>.json`` after every batch.
    resume : bool
        Continue runs from their checkpoints (runs without one start afresh).
    progress : bool, optional
        tqdm bars on stderr (default: when stderr is a terminal).
    callback : callable, optional
        ``callback(seed, draws_processed)`` after every processed batch (after
        its checkpoint); an exception raised there stops everything and
        propagates (the checkpoints stay).

    Returns
    -------
    SamplingResult
        Identical (runs, best draws, eta) for every executor, worker count
        and batch size, and for a run resumed from a checkpoint.

    Raises
    ------
    SettingsError
        Bad seeds or settings; unfinished checkpoints without ``resume``; a
        checkpoint of another problem.
    """
    problem = prepared if isinstance(prepared, SamplingProblem) else prepare_sampling(prepared, p0, settings)
    if settings is not None and isinstance(prepared, SamplingProblem) and settings.key() != problem.settings.key():
        raise SettingsError("settings differ from the SamplingProblem's in what draws depend on (scaling, threshold, "
                            "distribution, np, IPOPT options); prepare the problem with these settings")
    settings = settings or problem.settings
    seeds = _checked_seeds(seeds)
    states = _run_states(problem.recipe, settings, seeds, checkpoint_dir, resume)
    ctx = install(problem.recipe, problem.prepared) if executor == "serial" else None
    t0 = time.perf_counter()
    ex = make_executor(executor, problem.recipe, ctx, workers=workers, client=client, address=address)
    sched = Scheduler(states, n_iter=settings.n_iter, max_draws=settings.max_draws, batch_size=settings.batch_size,
                      max_inflight=2 * ex.workers if ex.speculative else 1, speculative=ex.speculative)
    bars = _Progress(_auto_progress() if progress is None else bool(progress), states, settings.n_iter,
                     settings.max_draws)

    def save(st: RunState) -> None:
        if checkpoint_dir is not None:
            write_checkpoint(checkpoint_dir, st, token=problem.recipe.token, settings_key=settings.key(),
                             n_iter=settings.n_iter)

    try:
        timing = _drive(sched, ex, bars, save, callback, t0)
    except BaseException:
        ex.close(cancel=True)
        bars.close()
        raise
    ex.close()
    bars.close()
    return SamplingResult(settings, problem.estimability, problem.reference_outcome,
                          tuple(RunResult.from_state(st) for st in states), ex.name, ex.workers,
                          time.perf_counter() - t0, problem.setup_s, sched.n_evaluated, sched.n_wasted,
                          sched.n_cancelled, timing.worker_setup_s if executor != "serial" else (), timing.startup_s,
                          problem.recipe.token, problem.prepared.spec.parameter_names)


def _checked_seeds(seeds: Sequence[int]) -> list[int]:
    seeds = list(seeds)
    for s in seeds:
        if isinstance(s, bool) or not isinstance(s, (int, np.integer)) or s < 0:
            raise SettingsError(f"seeds must be non-negative integers, got {s!r}")
    if len(set(seeds)) != len(seeds):
        raise SettingsError(f"seeds must be distinct, got {seeds}")
    if not seeds:
        raise SettingsError("give at least one seed")
    return [int(s) for s in seeds]


def _run_states(recipe: Recipe, settings: SamplingSettings, seeds: list[int], checkpoint_dir, resume: bool
                ) -> list[RunState]:
    """One state per run: fresh, or continued from its checkpoint (``resume``); refuses to
    overwrite a checkpoint of an unfinished run of the same problem without ``resume``."""
    key, n_iter, max_draws = settings.key(), settings.n_iter, settings.max_draws
    states = []
    for s in seeds:
        st = None
        if checkpoint_dir is not None:
            if resume:
                st = read_checkpoint(checkpoint_dir, s, token=recipe.token, settings_key=key, n_iter=n_iter)
            elif checkpoint_path(checkpoint_dir, s).is_file():
                try:
                    old = read_checkpoint(checkpoint_dir, s, token=recipe.token, settings_key=key, n_iter=n_iter)
                except SettingsError:
                    old = None
                if old is not None and old.stopped_by is None:
                    raise SettingsError(f"{str(checkpoint_path(checkpoint_dir, s))!r} holds a run that is unfinished "
                                        f"under these settings ({old.draws} draws); continue it with resume=True "
                                        "(--resume) or remove the checkpoints folder")
                log.warning("replacing the checkpoint %s (a finished run, or one of another problem)",
                            checkpoint_path(checkpoint_dir, s))
        st = st or RunState(s)
        if st.stopped_by is None and max_draws is not None and st.draws >= max_draws:
            st.stopped_by = "max_draws"
        states.append(st)
    return states


@dataclass(frozen=True)
class _Timing:
    startup_s: float
    worker_setup_s: tuple


def _drive(sched: Scheduler, ex, bars: "_Progress", save: Callable[[RunState], None],
           callback: Callable[[int, int], None] | None, t0: float) -> _Timing:
    """Run the scheduler on the executor until every run has stopped: submit what it hands
    out, feed back what returns (in seed and draw order), cancel what it offers, checkpoint
    and report every batch that moved a run."""
    handles: dict[Any, Batch] = {}
    setup_by_pid: dict[int, float] = {}
    startup = math.nan
    n_runs = len(sched.states)
    while True:
        for b in sched.hand_out():
            handles[ex.submit(b.seed, b.k0, b.k1)] = b
        if not handles:
            break
        done = sorted(ex.wait(list(handles)), key=lambda h: sched.sort_key(handles[h]))
        for h in done:
            res = ex.result(h)
            if math.isnan(startup):
                startup = max(0.0, time.perf_counter() - t0 - res.wall_s)
            setup_by_pid.setdefault(res.pid, res.setup_s)
            got = sched.receive(handles.pop(h), res.outcomes)
            for b in got.to_cancel:
                hb = next(k for k, v in handles.items() if v == b)
                if hb not in done and ex.cancel(hb):  # one that has finished comes back as waste
                    handles.pop(hb)
                    sched.cancelled(b)
            st = sched.states[got.seed]
            if got.processed:
                save(st)
                bars.update(st, got.processed)
            bars.evaluated(len(res.outcomes), n_runs - len(sched.active), n_runs)
            if got.processed and callback is not None:
                callback(got.seed, st.draws)
    return _Timing(0.0 if math.isnan(startup) else startup, tuple(setup_by_pid[p] for p in sorted(setup_by_pid)))
