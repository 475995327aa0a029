"""One draw of the sampling algorithm (steps 5-7), and what a worker needs to make it.

A draw is a pure function of the run's seed ``s``, the draw index ``k`` and
the problem (data, model, mesh, settings, the estimability analysis at p0 and
the reference solution of (7.9) at ``q2 = V2^T p0``)::

    rng      = numpy.random.default_rng([s, k])
    p_trial  = distribution(rng, lower, upper, nominal)        step 5
    q2       = V2^T D^-1 p_trial
    fit      = (7.9) with q2 fixed, IPOPT started from the solution   step 6
               that the reference's KKT factors predict
    eta      = (7.10) of fit's residuals                        step 7

Every solve of every run starts from the same reference solution (never from
the previous draw), so the outcome does not depend on which process made it
or in which order: serial, process-parallel and dask runs agree to the bit.

A :class:`Recipe` is everything a worker process needs, small enough to
pickle (about 0.5 MB for RA-66): the model, the data, the mesh, the
settings, the estimability analysis without its sensitivity matrices, and
the reference solution. A worker rebuilds the NLP from it once (code
generation is cached on disk by content hash, so no SymPy work is repeated)
and keeps the result in a per-process cache keyed by the recipe's token.
"""

from __future__ import annotations

import functools
import hashlib
import math
import os
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any

import numpy as np

from ..collocation.transcription import Mesh
from ..data import Measurements
from ..errors import RocketidError, SensitivityError
from ..estimability import Estimability, estimate_q1
from ..model import ModelSpec
from ..sensitivity import SolutionPredictor
from ..solve import EstimationResult, NLPSolution, Prepared, prepare, result_of
from .criterion import criterion_of
from .settings import SamplingSettings

__all__ = ["DrawOutcome", "Recipe", "WorkerContext", "evaluate_draw", "evaluate_batch", "install"]

_FAILURE_EXCEPTIONS = (RocketidError, ArithmeticError, ValueError, np.linalg.LinAlgError, RuntimeError)

#: The stages whose code decides a draw's outcome (rocketid subpackages and modules).
_DRAW_STAGES = ("errors", "data", "model", "simulate", "physics", "symbolic", "codegen", "collocation", "cases",
                "nlp", "solve", "sensitivity", "estimability", "sampling")


@functools.lru_cache(maxsize=None)
def code_fingerprint() -> str:
    """A hash of the source of every stage a draw runs through, read once per process on
    first use: when the coordinator makes a recipe, and when a worker process installs one
    (right after it starts, so it describes the code that process runs)."""
    root = Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for name in _DRAW_STAGES:
        d = root / name
        files = sorted(d.rglob("*.py")) if d.is_dir() else [root / f"{name}.py"]
        for f in files:
            if f.is_file():
                h.update(f.relative_to(root).as_posix().encode())
                h.update(f.read_bytes())
    return h.hexdigest()[:16]


def __getattr__(name: str):
    # ``CODE_FINGERPRINT``: this process's :func:`code_fingerprint` (read lazily). A recipe records
    # the coordinator's; a worker whose code differs refuses to evaluate draws.
    if name == "CODE_FINGERPRINT":
        return code_fingerprint()
    raise AttributeError(f"module {__name__!r} has no attribute {name!r}")


def _num(v: float | None) -> float | None:
    """A float for JSON (NaN and infinities become None)."""
    return float(v) if v is not None and math.isfinite(v) else None


def _unnum(v: float | None) -> float:
    return math.nan if v is None else float(v)


@dataclass(frozen=True)
class DrawOutcome:
    """The outcome of one draw (steps 5-7) or of the reference solve (draw 0).

    Attributes
    ----------
    seed : int
        The run's seed ``s``.
    draw : int
        ``k``; 0 is the reference solve at ``q2 = V2^T p0``.
    success : bool
        IPOPT converged (status 0 or 1) and eta is finite.
    status : int or None
        IPOPT's return status (None when the solve raised).
    message : str
        IPOPT's message, or why the draw failed.
    eta : float
        (7.10); NaN for a failed draw.
    moments : tuple of float
        ``(s1, k1, s2, k2)``.
    objective : float
        J of (7.9) at the solution.
    iterations : int
    p : tuple of float
        The full physical parameter vector of the solution.
    q2 : tuple of float
        The fixed transformed parameters.
    p_trial : tuple of float
        The drawn parameter vector.
    solve_s : float
        Wall time of the draw (solve and eta).
    retried : bool
        The warm-started solve failed and was repeated from a simulation.
    """

    seed: int
    draw: int
    success: bool
    status: int | None
    message: str
    eta: float
    moments: tuple
    objective: float
    iterations: int
    p: tuple
    q2: tuple
    p_trial: tuple
    solve_s: float
    retried: bool = False

    @property
    def terms(self) -> tuple[float, float, float, float]:
        """``(|s1|, |k1 - 3|, |s1 - s2|, |k1 - k2|)``."""
        s1, k1, s2, k2 = self.moments
        return (abs(s1), abs(k1 - 3.0), abs(s1 - s2), abs(k1 - k2))

    def to_dict(self) -> dict:
        return {"seed": self.seed, "draw": self.draw, "success": self.success, "status": self.status,
                "message": self.message, "eta": _num(self.eta), "moments": [_num(m) for m in self.moments],
                "objective": _num(self.objective), "iterations": self.iterations,
                "p": [_num(v) for v in self.p], "q2": [_num(v) for v in self.q2],
                "p_trial": [_num(v) for v in self.p_trial], "solve_s": self.solve_s, "retried": self.retried}

    @classmethod
    def from_dict(cls, d: dict) -> "DrawOutcome":
        return cls(int(d["seed"]), int(d["draw"]), bool(d["success"]),
                   None if d["status"] is None else int(d["status"]), str(d["message"]), _unnum(d["eta"]),
                   tuple(_unnum(m) for m in d["moments"]), _unnum(d["objective"]), int(d["iterations"]),
                   tuple(_unnum(v) for v in d["p"]), tuple(_unnum(v) for v in d["q2"]),
                   tuple(_unnum(v) for v in d["p_trial"]), float(d["solve_s"]), bool(d.get("retried", False)))


@dataclass(frozen=True)
class Recipe:
    """Everything a worker needs to evaluate draws (picklable).

    Attributes
    ----------
    token : str
        Content hash: data, model fingerprint, mesh, p0, settings, V, the
        reference solution and the code (:func:`code_fingerprint`).
        Checkpoints record it.
    code : str
        The coordinator's :func:`code_fingerprint`.
    spec, measurements, mesh, settings
    estimability : Estimability
        Steps 2-3 at p0 (its sensitivity matrices removed).
    reference : NLPSolution
        The (7.9) solve at ``q2 = V2^T p0`` that warm-starts every draw.
    reference_p : ndarray, shape (n_p,)
    reference_q2 : ndarray
    """

    token: str
    code: str
    spec: ModelSpec
    measurements: Measurements
    mesh: Mesh
    settings: SamplingSettings
    estimability: Estimability
    reference: NLPSolution
    reference_p: np.ndarray
    reference_q2: np.ndarray

    @classmethod
    def make(cls, prepared: Prepared, settings: SamplingSettings, estimability: Estimability,
             reference: EstimationResult, q2_ref: np.ndarray) -> "Recipe":
        est = replace(estimability, sensitivity=None)
        h = hashlib.sha256()
        h.update(prepared.spec.fingerprint().encode())
        for ch in prepared.measurements.channels:
            h.update(ch.name.encode())
            h.update(np.ascontiguousarray(ch.times).tobytes())
            h.update(np.ascontiguousarray(ch.values).tobytes())
            h.update(np.ascontiguousarray(ch.sigma).tobytes() if ch.per_sample else repr(ch.sigma).encode())
        mesh = prepared.transcription.mesh
        h.update(np.ascontiguousarray(mesh.boundaries).tobytes())
        h.update(str(mesh.K).encode())
        for a in (prepared.spec.lower, prepared.spec.upper, prepared.spec.nominal, est.evaluated_at, est.V, est.D,
                  np.asarray(q2_ref), reference.solution.x, reference.solution.mult_g):
            h.update(np.ascontiguousarray(a, dtype=float).tobytes())
        h.update(repr(sorted(settings.key().items())).encode())
        code = code_fingerprint()
        h.update(code.encode())
        return cls(h.hexdigest()[:24], code, prepared.spec, prepared.measurements, mesh, settings, est,
                   reference.solution, np.asarray(reference.p, float), np.asarray(q2_ref, float))


@dataclass(frozen=True)
class WorkerContext:
    """A recipe made ready to solve: the prepared NLP and the reference result.

    Attributes
    ----------
    recipe : Recipe
    prepared : Prepared
    reference : EstimationResult
        The reference solution as a result object, whose transformed NLP
        every draw re-offsets (``CollocationNLP.with_offset``).
    setup_s : float
        Wall time to rebuild (NLP from the recipe, code from the disk cache, the predictor).
    codegen_cached : bool
    pid : int
    predictor : SolutionPredictor or None
        The KKT matrix factorized at the reference solution: each draw starts IPOPT from its
        predicted solution (``estimate_q1(predictor=)``). None when the reference did not
        converge or its KKT matrix is singular; draws then start from the reference itself.
    """

    recipe: Recipe
    prepared: Prepared
    reference: EstimationResult
    setup_s: float
    codegen_cached: bool
    pid: int
    predictor: SolutionPredictor | None = None

    @classmethod
    def build(cls, recipe: Recipe, prepared: Prepared | None = None) -> "WorkerContext":
        """Rebuild the NLP (or reuse ``prepared``, which must come from the same
        spec, data and mesh) and the reference result."""
        t0 = time.perf_counter()
        if prepared is None:
            prepared = prepare(recipe.spec, recipe.measurements, mesh=recipe.mesh)
        est = recipe.estimability
        tf = est.transform(recipe.reference_q2)
        nlp = prepared.nlp.with_transform(tf)
        sol = recipe.reference
        ref = result_of(prepared, nlp, sol)
        try:
            predictor = SolutionPredictor.at(nlp, sol) if ref.success else None
        except SensitivityError:
            predictor = None
        if predictor is not None:
            predictor = predictor.learn(learning_offsets(recipe))
        return cls(recipe, prepared, ref, time.perf_counter() - t0, bool(prepared.codegen_cached), os.getpid(),
                   predictor)


def trial_parameters(recipe: Recipe, seed: int, draw: int) -> np.ndarray:
    """``p_trial`` of draw ``draw`` of the run with seed ``seed`` (step 5)."""
    spec = recipe.spec
    rng = np.random.default_rng([int(seed), int(draw)])
    p = np.asarray(recipe.settings.draw(rng, spec.lower, spec.upper, spec.nominal), dtype=float)
    if p.shape != spec.lower.shape:
        raise RocketidError(f"the sampling distribution returned shape {p.shape}; expected "
                            f"{spec.lower.shape} (one value per parameter)")
    return p


#: Offsets from which each worker's predictor learns the solution surface.
LEARNING_DRAWS = 100


def learning_offsets(recipe: Recipe, n: int = LEARNING_DRAWS) -> np.ndarray:
    """Offsets ``c`` of (7.9) drawn like the draws' (the settings' distribution, ``q2 =
    V2^T p_trial``) from a stream of their own (not any run's), shape (n, n_p): the
    predictor learns the solution's polynomial surface from them
    (:meth:`~rocketid.sensitivity.SolutionPredictor.learn`). They only move IPOPT's start;
    every draw's solution is IPOPT's."""
    spec, est = recipe.spec, recipe.estimability
    rng = np.random.default_rng(np.random.SeedSequence(0x5EED, spawn_key=(9,)))
    out = []
    for _ in range(int(n)):
        p = np.asarray(recipe.settings.draw(rng, spec.lower, spec.upper, spec.nominal), dtype=float)
        out.append(est.transform(est.q2_of(p)).c)
    return np.array(out)


def evaluate_draw(ctx: WorkerContext, seed: int, draw: int) -> DrawOutcome:
    """Steps 5-7 for draw ``draw`` of the run with seed ``seed``.

    A solve that fails (IPOPT status other than 0 or 1, a non-finite eta,
    or a solver error) gives an outcome with ``success=False`` and the
    reason; it never raises for those.
    """
    recipe = ctx.recipe
    est = recipe.estimability
    t0 = time.perf_counter()
    p_trial = trial_parameters(recipe, seed, draw)
    q2 = est.q2_of(p_trial)
    try:
        fit = estimate_q1(ctx.prepared, est, q2, warm_start=ctx.reference, options=recipe.settings.ipopt_options,
                          predictor=ctx.predictor)
    except _FAILURE_EXCEPTIONS as exc:
        return draw_outcome(seed, draw, None, q2, p_trial, time.perf_counter() - t0,
                            error=f"{type(exc).__name__}: {exc}")
    return draw_outcome(seed, draw, fit, q2, p_trial, time.perf_counter() - t0)


def draw_outcome(seed: int, draw: int, fit: EstimationResult | None, q2, p_trial, solve_s: float, *,
                 error: str = "") -> DrawOutcome:
    """The :class:`DrawOutcome` of a (7.9) fit (steps 6-7: eta of its residuals), or of a
    solve that raised (``fit`` None, ``error`` the reason)."""
    eta, moments, message = math.nan, (math.nan,) * 4, error
    if fit is not None:
        message = fit.message
        if fit.success:
            crit = criterion_of(fit)
            eta, moments = crit.eta, (crit.s1, crit.k1, crit.s2, crit.k2)
            if not math.isfinite(eta):
                message = f"eta is not finite ({fit.message})"
    ok = fit is not None and fit.success and math.isfinite(eta)
    n_p = len(p_trial)
    return DrawOutcome(int(seed), int(draw), bool(ok), None if fit is None else int(fit.status), message, float(eta),
                       tuple(map(float, moments)), math.nan if fit is None else float(fit.objective),
                       0 if fit is None else int(fit.iterations),
                       (math.nan,) * n_p if fit is None else tuple(map(float, fit.p)),
                       tuple(map(float, q2)), tuple(map(float, p_trial)), float(solve_s),
                       fit is not None and fit.retried)


# ---------------------------------------------------------------------------
# Per-process cache of contexts (worker processes and dask workers)
# ---------------------------------------------------------------------------

_CONTEXTS: dict[str, WorkerContext] = {}
_MAX_CONTEXTS = 2


def install(recipe: Recipe, prepared: Prepared | None = None) -> WorkerContext:
    """Build (once per process) and cache the context of ``recipe``; a process
    pool's initializer."""
    code_fingerprint()  # read this process's code now, before anything can change on disk
    ctx = _CONTEXTS.get(recipe.token)
    if ctx is None:
        ctx = WorkerContext.build(recipe, prepared)
        while len(_CONTEXTS) >= _MAX_CONTEXTS:
            _CONTEXTS.pop(next(iter(_CONTEXTS)))
        _CONTEXTS[recipe.token] = ctx
    return ctx


@dataclass(frozen=True)
class BatchResult:
    """Outcomes of draws ``k0 .. k1 - 1`` of one run, and where they were made
    (``setup_s``: the time that process took to build its context)."""

    seed: int
    k0: int
    outcomes: tuple
    pid: int
    setup_s: float
    wall_s: float


def evaluate_batch(recipe: Recipe | str, seed: int, k0: int, k1: int) -> BatchResult:
    """Draws ``k0 .. k1 - 1`` of the run with seed ``seed``.

    ``recipe`` is the recipe itself (dask: a scattered object) or its token
    (process pools install the recipe in their initializer).
    """
    t0 = time.perf_counter()
    if isinstance(recipe, str):
        ctx = _CONTEXTS.get(recipe)
        if ctx is None:
            raise RocketidError("this worker process has no sampling problem installed (internal error: the pool's "
                                "initializer did not run)")
    else:
        ctx = install(recipe)
    if ctx.recipe.code != code_fingerprint():
        raise RocketidError(
            f"worker process {os.getpid()} runs other rocketid code (fingerprint {code_fingerprint()}) than the "
            f"coordinator ({ctx.recipe.code}): its draws would not reproduce the serial result. Install the same "
            "rocketid everywhere (and restart workers started before a change)")
    outs = tuple(evaluate_draw(ctx, seed, k) for k in range(k0, k1))
    return BatchResult(int(seed), int(k0), outs, os.getpid(), ctx.setup_s, time.perf_counter() - t0)


def worker_info(recipe: Recipe | str) -> dict[str, Any]:
    """``{"pid", "setup_s", "codegen_cached"}`` of this process's context."""
    token = recipe if isinstance(recipe, str) else recipe.token
    ctx = _CONTEXTS.get(token) if isinstance(recipe, str) else install(recipe)
    if ctx is None:
        return {"pid": os.getpid(), "setup_s": math.nan, "codegen_cached": False}
    return {"pid": ctx.pid, "setup_s": ctx.setup_s, "codegen_cached": ctx.codegen_cached}
