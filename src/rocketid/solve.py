"""Solving the NLP with IPOPT through cyipopt, and the estimation result.

The adapter composes with the solver: it holds a
:class:`~rocketid.nlp.CollocationNLP` and builds a ``cyipopt.Problem`` from
it (the binding is not subclassed). IPOPT options pass through one checked
mapping, :func:`check_ipopt_options`, which knows the options' types and
names the close matches of a misspelt one.

:func:`estimate` runs the pipeline from a model and data to an
:class:`EstimationResult`: generate code (cached), transcribe, build the NLP,
initialize the states from a simulation at the initial guess, solve.
"""

from __future__ import annotations

import difflib
import math
import time
from dataclasses import dataclass, replace
from functools import cached_property
from typing import Any, Callable, Mapping, Sequence

import numpy as np
import sympy as sp

from .codegen import generate
from .collocation.transcription import Mesh, Transcription, transcribe
from .data import Measurements, resolve_quantized, sigma_request
from .errors import DataError, ModelError, SettingsError, SolverError
from .model import ModelSpec, check_guess
from .nlp import CollocationNLP, build_nlp
from .output import finite_or_none
from .summary import Section, Summary, Table

__all__ = ["IPOPT_OPTIONS", "check_ipopt_options", "NLPSolution", "solve_nlp", "EstimationResult",
           "estimate", "prepare", "default_mesh", "Prepared", "relax_sigma", "ml_sigma", "relaxation"]

_S, _I, _F = "str", "int", "float"
IPOPT_OPTIONS: dict[str, str] = {
    # termination
    "tol": _F, "max_iter": _I, "max_wall_time": _F, "max_cpu_time": _F, "dual_inf_tol": _F,
    "constr_viol_tol": _F, "compl_inf_tol": _F, "acceptable_tol": _F, "acceptable_iter": _I,
    "acceptable_constr_viol_tol": _F, "acceptable_dual_inf_tol": _F, "acceptable_obj_change_tol": _F,
    # output
    "print_level": _I, "print_user_options": _S, "print_options_documentation": _S, "print_timing_statistics": _S,
    "output_file": _S, "file_print_level": _I, "sb": _S, "print_frequency_iter": _I,
    # NLP
    "bound_relax_factor": _F, "honor_original_bounds": _S, "nlp_lower_bound_inf": _F, "nlp_upper_bound_inf": _F,
    "fixed_variable_treatment": _S, "jac_c_constant": _S, "jac_d_constant": _S, "hessian_constant": _S,
    "check_derivatives_for_naninf": _S, "nlp_scaling_method": _S, "obj_scaling_factor": _F,
    "nlp_scaling_max_gradient": _F,
    # initialization and warm start
    "bound_push": _F, "bound_frac": _F, "slack_bound_push": _F, "slack_bound_frac": _F,
    "constr_mult_init_max": _F, "bound_mult_init_val": _F, "bound_mult_init_method": _S,
    "warm_start_init_point": _S, "warm_start_bound_push": _F, "warm_start_bound_frac": _F,
    "warm_start_slack_bound_push": _F, "warm_start_slack_bound_frac": _F, "warm_start_mult_bound_push": _F,
    "warm_start_mult_init_max": _F,
    # barrier
    "mu_strategy": _S, "mu_oracle": _S, "mu_init": _F, "mu_min": _F, "mu_target": _F,
    "mehrotra_algorithm": _S, "adaptive_mu_globalization": _S,
    # line search, restoration
    "accept_every_trial_step": _S, "max_soc": _I, "watchdog_shortened_iter_trigger": _I,
    "expect_infeasible_problem": _S, "start_with_resto": _S, "required_infeasibility_reduction": _F,
    "alpha_for_y": _S, "recalc_y": _S,
    # linear solver, Hessian
    "linear_solver": _S, "mumps_mem_percent": _I, "mumps_pivtol": _F, "mumps_pivtolmax": _F,
    "mumps_permuting_scaling": _I, "mumps_scaling": _I, "mumps_dep_tol": _F,
    "least_square_init_duals": _S, "least_square_init_primal": _S,
    "hessian_approximation": _S, "limited_memory_max_history": _I,
    "derivative_test": _S, "derivative_test_tol": _F, "derivative_test_perturbation": _F,
    "derivative_test_print_all": _S, "timing_statistics": _S,
}

# mumps_pivtol 1e-4, not IPOPT's 1e-6: with 1e-6 and MUMPS 5.5.1 (cyipopt-wheels) IPOPT corrects the
# inertia (regularizes the Hessian) in 4-5 of 7 iterations on RA-66 from N = 264 on, and RA-66 at N = 528,
# K = 4 took 695 s; with 1e-4: 5 iterations, none regularized, the same estimates (docs/performance.md).
DEFAULT_IPOPT = {"tol": 1e-8, "print_level": 0, "sb": "yes", "max_iter": 500, "mu_strategy": "adaptive",
                 "mumps_pivtol": 1e-4}


def check_ipopt_options(options: Mapping[str, Any] | None) -> dict[str, Any]:
    """Validate IPOPT options against the known table; returns a typed copy.

    Raises
    ------
    SettingsError
        For an unknown name (with close matches) or a value of the wrong type.
    """
    out: dict[str, Any] = {}
    for name, value in (options or {}).items():
        kind = IPOPT_OPTIONS.get(name)
        if kind is None:
            close = difflib.get_close_matches(name, list(IPOPT_OPTIONS), n=3)
            hint = f"; did you mean {', '.join(close)}?" if close else ""
            raise SettingsError(f"unknown IPOPT option {name!r}{hint} (rocketid passes only the options it knows: "
                                "see rocketid.solve.IPOPT_OPTIONS)")
        try:
            if kind == _I:
                if isinstance(value, bool) or float(value) != int(value):
                    raise ValueError
                value = int(value)
            elif kind == _F:
                value = float(value)
                if math.isnan(value):
                    raise ValueError
            else:
                if not isinstance(value, str):
                    raise ValueError
        except (TypeError, ValueError):
            raise SettingsError(f"IPOPT option {name!r} takes a{'n' if kind == _I else ''} {kind}, got {value!r}") from None
        out[name] = value
    return out


@dataclass(frozen=True)
class NLPSolution:
    """What IPOPT returned for one NLP solve.

    Attributes
    ----------
    x : ndarray
        Primal solution (the NLP's decision vector).
    mult_g : ndarray
        Constraint multipliers.
    mult_x_L, mult_x_U : ndarray
        Bound multipliers.
    status : int
        IPOPT's return status (0: solved, 1: solved to acceptable level).
    message : str
    iterations : int
    objective : float
    solve_s : float
        Wall time of the IPOPT call alone.
    """

    x: np.ndarray
    mult_g: np.ndarray
    mult_x_L: np.ndarray
    mult_x_U: np.ndarray
    status: int
    message: str
    iterations: int
    objective: float
    solve_s: float

    @property
    def success(self) -> bool:
        return self.status in (0, 1)


class _IpoptAdapter:
    """The callbacks cyipopt calls, delegating to the NLP; counts iterations."""

    def __init__(self, nlp: CollocationNLP):
        self.nlp = nlp
        self.iterations = 0
        self.objective = nlp.objective
        self.gradient = nlp.gradient
        self.constraints = nlp.constraints
        self.jacobian = nlp.jacobian
        self.jacobianstructure = nlp.jacobianstructure
        self.hessian = nlp.hessian
        self.hessianstructure = nlp.hessianstructure

    def intermediate(self, alg_mod, iter_count, *args):
        self.iterations = int(iter_count)
        return True


def solve_nlp(nlp: CollocationNLP, x0: np.ndarray, *, options: Mapping[str, Any] | None = None,
              warm: NLPSolution | None = None) -> NLPSolution:
    """Solve ``nlp`` from ``x0`` with IPOPT (through cyipopt).

    Parameters
    ----------
    nlp : CollocationNLP
    x0 : ndarray, shape (nlp.n,)
    options : mapping, optional
        IPOPT options (checked by :func:`check_ipopt_options`), over rocketid's defaults.
    warm : NLPSolution, optional
        A previous solution of a problem with the same structure: its
        multipliers warm-start IPOPT (``warm_start_init_point = yes``).

    Returns
    -------
    NLPSolution
    """
    try:
        import cyipopt
    except ImportError as exc:  # pragma: no cover - depends on the installation
        raise SolverError("cyipopt is not installed: `pip install cyipopt-wheels` (bundled Ipopt) or "
                          "`pip install cyipopt` with a system Ipopt (see docs/install.md)") from exc
    opts = dict(DEFAULT_IPOPT)
    if warm is not None:
        opts.update({"warm_start_init_point": "yes", "warm_start_bound_push": 1e-9, "warm_start_bound_frac": 1e-9,
                     "warm_start_slack_bound_push": 1e-9, "warm_start_slack_bound_frac": 1e-9,
                     "warm_start_mult_bound_push": 1e-9, "mu_init": 1e-6, "mu_strategy": "monotone",
                     # IPOPT caps warm-start multipliers at 1e6 by default; the collocation rows' reach
                     # 3e11 on RA-66 (weights 1/sigma^2 on 19 800 residuals), and the cap turned the
                     # exact multipliers of a re-solve into an inf_du of 1e8 at iteration 0
                     "warm_start_mult_init_max": 1e300})
    user = check_ipopt_options(options)
    opts.update(user)
    x0 = np.asarray(x0, dtype=float)
    if x0.shape != (nlp.n,):
        raise SettingsError(f"x0 has shape {x0.shape}; the NLP has {nlp.n} variables")
    adapter = _IpoptAdapter(nlp)
    prob = cyipopt.Problem(n=nlp.n, m=nlp.m, problem_obj=adapter, lb=nlp.x_lower, ub=nlp.x_upper,
                           cl=nlp.c_lower, cu=nlp.c_upper)
    for k, v in opts.items():
        try:
            prob.add_option(k, v)
        except TypeError:
            if k.startswith("mumps_") and k not in user:
                continue  # rocketid's MUMPS default, and this Ipopt was built without MUMPS
            raise
    if warm is not None:
        if warm.mult_g.shape != (nlp.m,) or warm.mult_x_L.shape != (nlp.n,):
            raise SettingsError("the warm-start solution comes from a problem of another size")
        lagrange, zl, zu = warm.mult_g, warm.mult_x_L, warm.mult_x_U
    else:
        lagrange, zl, zu = [], [], []
    # keep x0 strictly inside bounds (IPOPT would push it anyway)
    x0 = np.clip(x0, nlp.x_lower, nlp.x_upper)
    t0 = time.perf_counter()
    x, info = prob.solve(x0, lagrange=lagrange, zl=zl, zu=zu)
    solve_s = time.perf_counter() - t0
    msg = info["status_msg"]
    msg = msg.decode() if isinstance(msg, bytes) else str(msg)
    prob.close()
    return NLPSolution(np.asarray(x), np.asarray(info["mult_g"]), np.asarray(info["mult_x_L"]),
                       np.asarray(info["mult_x_U"]), int(info["status"]), msg, adapter.iterations,
                       float(info["obj_val"]), solve_s)


# ---------------------------------------------------------------------------
# Pipeline: model + data -> result
# ---------------------------------------------------------------------------


SHARP_CORNER = 0.1
"""A sampled input's sample is a sharp corner, put on an element boundary by :func:`default_mesh`, when its
slope changes there by more than this share of the input's range per element length."""


def _sharp_corners(spec: ModelSpec, h: float) -> set[float]:
    """Sample times of sampled inputs where the slope changes by more than :data:`SHARP_CORNER` of the input's
    range over an element of length ``h`` (an ignition transient, a tail-off), inside the horizon."""
    out = set()
    for u in spec.inputs:
        if u.expr is not None or len(u.times) < 3:
            continue
        t, v = np.asarray(u.times, float), np.asarray(u.values, float)
        span = float(v.max() - v.min())
        if span <= 0:
            continue
        jump = np.abs(np.diff(np.diff(v) / np.diff(t))) * h / span
        out.update(float(c) for c in t[1:-1][jump > SHARP_CORNER] if spec.t0 < c < spec.tf)
    return out


def default_mesh(spec: ModelSpec, K: int = 4, element_length: float | None = None, refine_first: int = 0) -> Mesh:
    """A mesh of about 1 s elements (or ``element_length``, at most 1/20 of the
    horizon) that puts every family breakpoint, every event time (``Model.event``)
    and every sharp corner of a sampled input on an element boundary, with K
    Radau points; ``refine_first`` splits the first element geometrically.

    A sharp corner is a sample where the input's slope changes by more than
    :data:`SHARP_CORNER` (10 %) of its range per element length: a thrust table's
    ignition transient or tail-off. Every sample is not a boundary (an attitude
    program sampled every 0.5 s would halve the elements for nothing), and a gentle
    corner inside an element costs little: on a sounding rocket with a 0.25 s thrust
    table (``tests/vehicles/tern.py`` without its events), noise-free data fitted to
    2J = 54 on the 1 s mesh and 4.3 with its seven sharp corners on it.

    RA-66 gets 66 elements of 1 s with K = 4: the collocation error at the true
    parameters is 1.6e-3 m, within the required 0.01 m (K = 3 gives 0.045 m,
    and grading the first element does not bring K = 3 under 0.01 m; see
    docs/accuracy.md).
    """
    span = spec.tf - spec.t0
    h = element_length if element_length is not None else min(1.0, span / 20)
    # a model cut to a window keeps its families' breakpoints outside it
    fam_bps = sorted({float(b) for f in spec.families for b in f.breakpoints if spec.t0 < b < spec.tf}
                     | {spec.t0, spec.tf} | {float(e) for e in spec.events if spec.t0 < e < spec.tf}
                     | _sharp_corners(spec, h))
    bounds = [fam_bps[0]]
    for a, b in zip(fam_bps[:-1], fam_bps[1:]):
        n = max(1, int(math.ceil((b - a) / h - 1e-9)))
        bounds.extend(np.linspace(a, b, n + 1)[1:])
    return Mesh(np.array(bounds), K).refine_first(refine_first)


@dataclass(frozen=True)
class Prepared:
    """A model collocated on a mesh against data: ready to solve.

    Attributes
    ----------
    spec, measurements, transcription, nlp
    setup_s : float
        Wall time from the model to the ready NLP (code generation included).
    codegen_cached : bool
    """

    spec: ModelSpec
    measurements: Measurements
    transcription: Transcription
    nlp: CollocationNLP
    setup_s: float
    codegen_cached: bool

    def initial_states(self, p: np.ndarray) -> tuple[np.ndarray, str]:
        """Node states from a simulation at ``p`` (falls back to the initial state
        where the simulation fails); returns (states, note)."""
        from .simulate import simulate
        times = self.transcription.mesh.node_times
        traj = simulate(self.spec, p, times, rtol=1e-8, atol=1e-8)
        S = traj.states.copy()
        note = ""
        if not traj.success or not np.all(np.isfinite(S)):
            good = np.all(np.isfinite(S), axis=1)
            last = S[good][-1] if good.any() else self.spec.initial_state(p)
            S[~good] = last
            note = f"the initial-guess simulation failed ({traj.message}); states initialized by holding its last value"
        return S, note

    def with_sigma(self, sigma: Mapping[str, float]) -> "Prepared":
        """The same collocation with the channels' noise levels ``sigma`` (``{channel: value}``):
        the NLP is rebuilt on the same transcription (code generation is not repeated)."""
        data = self.measurements.with_sigma(sigma)
        t0 = time.perf_counter()
        nlp = build_nlp(self.transcription, generate(self.spec), data)
        return replace(self, measurements=data, nlp=nlp, setup_s=self.setup_s + time.perf_counter() - t0)


def prepare(spec: ModelSpec, data: Measurements, *, mesh: Mesh | None = None) -> Prepared:
    """Generate code, transcribe, and build the NLP (7.5) for ``spec`` and ``data``."""
    if not isinstance(spec, ModelSpec):
        raise ModelError(f"expected a ModelSpec (call Model.freeze()), got {type(spec).__name__}")
    if not isinstance(data, Measurements):
        raise DataError(f"expected Measurements (rocketid.data.read_csv or Measurements.from_arrays), got "
                        f"{type(data).__name__}")
    if mesh is not None and not isinstance(mesh, Mesh):
        raise SettingsError(f"mesh must be a Mesh (for example rocketid.default_mesh(spec, K=4)), got "
                            f"{type(mesh).__name__} {mesh!r}")
    t0 = time.perf_counter()
    gen = generate(spec)
    mesh = mesh if mesh is not None else default_mesh(spec)
    tr = transcribe(spec, data, mesh)
    nlp = build_nlp(tr, gen, data)
    return Prepared(spec, data, tr, nlp, time.perf_counter() - t0, gen.cached)


@dataclass(frozen=True)
class EstimationResult:
    """The result of an estimation.

    Attributes
    ----------
    success : bool
    status : int
        IPOPT's return status.
    message : str
    p : ndarray, shape (n_p,)
        Estimated parameters (full physical vector).
    objective : float
        J at the solution (7.5).
    iterations : int
    x : ndarray
        NLP solution vector.
    solution : NLPSolution
    prepared : Prepared
    timings : dict
        ``setup_s`` (model to ready NLP) and ``solve_s`` (the IPOPT call alone).
    notes : tuple of str
    retried : bool
        A warm-started solve failed and this is the cold solve that repeated it.
    sigma_estimated : tuple of str
        Channels whose noise level was estimated with the parameters (:func:`relax_sigma`);
        their sigma in :attr:`sigma` is the maximum-likelihood estimate.
    sigma_iterations : int
        Fits of the relaxation (0 when no sigma was estimated).
    """

    success: bool
    status: int
    message: str
    p: np.ndarray
    objective: float
    iterations: int
    x: np.ndarray
    solution: NLPSolution
    prepared: Prepared
    timings: dict
    notes: tuple = ()
    retried: bool = False
    sigma_estimated: tuple = ()
    sigma_iterations: int = 0

    @property
    def spec(self) -> ModelSpec:
        return self.prepared.spec

    @property
    def nlp(self) -> CollocationNLP:
        return self.prepared.nlp

    @property
    def parameters(self) -> dict[sp.Symbol, float]:
        """``{symbol: estimate}``."""
        return self.spec.parameter_dict(self.p)

    def value(self, symbol: sp.Symbol | str) -> float | np.ndarray:
        """A parameter's estimate, or a state's values at the mesh nodes."""
        sym = self.spec.symbol(symbol)
        if sym in self.spec.parameter_symbols:
            return float(self.p[self.spec.parameter_symbols.index(sym)])
        if sym in self.spec.state_symbols:
            return self.state_trajectories[:, self.spec.state_symbols.index(sym)]
        raise ModelError(f"{sym} is not a parameter or state of model {self.spec.name!r}")

    @property
    def node_times(self) -> np.ndarray:
        return self.prepared.transcription.mesh.node_times

    @cached_property
    def state_trajectories(self) -> np.ndarray:
        """States at the mesh nodes, shape (n_nodes, n_states)."""
        S, _ = self.prepared.transcription.layout.unpack(self.nlp.full_vector(self.x))
        return S

    def states_at(self, times: Sequence[float]) -> np.ndarray:
        """The collocation polynomial's states at ``times``, shape (n, n_states)."""
        return self.prepared.transcription.states_at(self.nlp.full_vector(self.x), np.asarray(times, float))

    @property
    def unmeasured_outputs(self) -> tuple[str, ...]:
        """The model's outputs that the data do not measure (predicted, not fitted)."""
        return tuple(n for n in self.spec.output_names if n not in self.nlp.channel_names)

    def predict(self, output: str, times: Sequence[float] | None = None) -> np.ndarray:
        """An output's values along the fitted trajectory (the collocation polynomial) at
        ``times`` (default: the mesh nodes); works for outputs the data do not measure.

        Raises
        ------
        ModelError
            ``output`` is not an output of the model.
        """
        from .simulate import evaluate_along

        expr = next((o.expr for o in self.spec.outputs if o.name == output), None)
        if expr is None:
            raise ModelError(f"model {self.spec.name!r} has no output {output!r}; its outputs are "
                             f"{', '.join(self.spec.output_names)}")
        times = self.node_times if times is None else np.asarray(times, float)
        tr = self.prepared.transcription
        w = self.nlp.full_vector(self.x)
        ns = tr.layout.n_states
        S = (tr.interpolation_matrix(times) @ w).reshape(times.size, ns)
        dS = (tr.interpolation_matrix(times, derivative=True) @ w).reshape(times.size, ns)
        return evaluate_along(self.spec, expr, times, S, self.p, dS)

    @cached_property
    def residuals(self) -> dict[str, np.ndarray]:
        """Model minus measurement at each channel's samples."""
        return dict(zip(self.nlp.channel_names, self.nlp.residuals(self.x)))

    @cached_property
    def predictions(self) -> dict[str, np.ndarray]:
        """Model outputs at each channel's samples."""
        return dict(zip(self.nlp.channel_names, self.nlp.outputs(self.x)))

    @property
    def n_data(self) -> int:
        return self.nlp.n_residuals

    @property
    def n_estimated(self) -> int:
        return self.nlp.transform.P.shape[1]

    @property
    def prior_objective(self) -> float:
        """The priors' share of J (``sum ((p - mean) / sd)^2 / 2``; 0 without priors)."""
        return self.nlp.prior_objective(self.x) if self.spec.priors else 0.0

    @property
    def data_objective(self) -> float:
        """The data's share of J: the weighted residuals' ``1/2 sum ((y - y_meas)/sigma)^2``."""
        return self.objective - self.prior_objective

    @property
    def chi2_per_dof(self) -> float:
        """``2 J_data / (n_data - n_estimated)``: near 1 when the model fits to the noise (``J_data``
        is J without the priors' penalty, :attr:`data_objective`)."""
        return 2.0 * self.data_objective / max(1, self.n_data - self.n_estimated)

    @property
    def sigma(self) -> dict[str, float]:
        """The noise standard deviation of each channel used in the fit (estimated ones included);
        for a channel with per-sample sigmas, the one with the same total weight
        (:func:`rocketid.data.equivalent_sigma`; see :attr:`sigma_per_sample`)."""
        return {k: float(v) for k, v in zip(self.nlp.channel_names, self.nlp.channel_sigmas)}

    @property
    def sigma_per_sample(self) -> dict[str, dict[str, float]]:
        """Channels with per-sample sigmas: ``{channel: {"n", "min", "median", "max", "equivalent"}}``
        (empty when every channel has one sigma)."""
        arrays = self.nlp.channel_sigma_arrays()
        return {k: {"n": int(arrays[k].size), "min": float(np.min(arrays[k])), "median": float(np.median(arrays[k])),
                    "max": float(np.max(arrays[k])), "equivalent": self.sigma[k]}
                for k in self.nlp.per_sample_channels}

    @cached_property
    def normalized_residuals(self) -> dict[str, np.ndarray]:
        """Residuals divided by each sample's sigma (``(model - measured) / sigma_i``); N(0, 1) for a
        correct model and correct sigmas, per-sample sigmas included."""
        arrays = self.nlp.channel_sigma_arrays()
        return {k: r / arrays[k] for k, r in self.residuals.items()}

    @property
    def sigma_std(self) -> dict[str, float]:
        """Standard error of each estimated sigma, ``sigma / sqrt(2 n)`` (the inverse Fisher
        information of a Gaussian channel's sigma with ``n`` samples; the parameters' and the
        sigmas' information are uncorrelated, so the parameters do not change it)."""
        n = {k: r.size for k, r in self.residuals.items()}
        return {k: self.sigma[k] / math.sqrt(2.0 * n[k]) for k in self.sigma_estimated}

    @cached_property
    def rms(self) -> dict[str, float]:
        """Root-mean-square residual per channel."""
        with np.errstate(over="ignore", invalid="ignore"):
            return {k: float(np.sqrt(np.mean(r ** 2))) for k, r in self.residuals.items()}

    def active_bounds(self, rtol: float = 1e-6) -> list[tuple[sp.Symbol, str]]:
        """Parameters at (or within ``rtol`` of the span of) a bound."""
        out = []
        for s, v, lo, hi in zip(self.spec.parameter_symbols, self.p, self.spec.lower, self.spec.upper):
            span = (hi - lo) if np.isfinite(hi - lo) else max(1.0, abs(v))
            if np.isfinite(lo) and v - lo <= rtol * span:
                out.append((s, "lower"))
            elif np.isfinite(hi) and hi - v <= rtol * span:
                out.append((s, "upper"))
        return out

    def summary(self) -> Summary:
        """Fixed sections: problem, solver, parameters, fit; then numbered notes."""
        tr = self.prepared.transcription
        nlp = self.nlp
        problem = Section("Problem", (
            ("mesh", tr.mesh.describe()),
            ("NLP", f"{nlp.n} variables, {nlp.m} constraints, {len(nlp.jacobianstructure()[0])} Jacobian and "
                    f"{len(nlp.hessianstructure()[0])} Hessian non-zeros"),
            ("data", f"{self.n_data} values in {len(nlp.channel_names)} channels ({', '.join(nlp.channel_names)})")))
        solver = Section("Solver", (
            ("status", f"{self._status_word()} ({self.status}: {self.message})"),
            ("iterations", str(self.iterations)),
            ("time", f"setup {self.timings['setup_s']:.3f} s, IPOPT {self.timings['solve_s']:.3f} s")))
        parameters = Section("Parameters", (Table(
            ("name", "estimate", "guess", "lower", "upper"),
            [(str(ps.symbol), float(v), ps.guess, ps.lower, ps.upper) for ps, v in zip(self.spec.parameters, self.p)],
            (None, ".6g", ".4g", ".3g", ".3g")),))
        fit = Section("Fit", (
            ("objective J", f"{self.objective:.6g}"),
            ("chi2 / dof", f"{self.chi2_per_dof:.4f}  (2J / ({self.n_data} - {self.n_estimated}))"),
            ("RMS residual", ", ".join(f"{k} {v:.4g}" for k, v in self.rms.items())),
            ("sigma", self._sigma_text()),
            *((("priors", f"{len(self.spec.priors)} Gaussian priors, their share of J {self.prior_objective:.4g} "
                          f"(data {self.data_objective:.6g})"),) if self.spec.priors else ())))
        notes = list(self.notes)
        if not self.success:
            notes.insert(0, f"IPOPT did not converge: {self.message.rstrip('.')}. The estimates are the last iterate, "
                            "not an optimum.")
        if self.success:
            notes.extend(f"NOT CREDIBLE: {n}." for n in self.sanity)
        for s, side in self.active_bounds():
            notes.append(f"{s} is at its {side} bound: the estimate is limited by the bound, not by the data.")
        if self.unmeasured_outputs:
            notes.append(f"output(s) {', '.join(self.unmeasured_outputs)} are not in the data: predicted "
                         "(EstimationResult.predict), not fitted.")
        if self.sigma_estimated:
            notes.append(f"sigma of {', '.join(self.sigma_estimated)} estimated with the parameters (maximum "
                         "likelihood): chi2/dof is then near 1 by construction and does not test the fit; a model "
                         "error shows as a larger sigma instead. Compare the estimated sigma with what the sensor "
                         "or the data's resolution allows.")
        if self.success and self.chi2_per_dof > 1.5:
            notes.append(f"chi2/dof = {self.chi2_per_dof:.3g} is well above 1: the model does not fit to the noise "
                         "level (a missing effect or wrong sigma); see `rocketid diagnose`.")
        return Summary(f"rocketid estimation: {self.spec.name}", (problem, solver, parameters, fit), notes)

    @cached_property
    def sanity(self) -> tuple[str, ...]:
        """What makes this result not credible even if IPOPT converged (every parameter at a
        bound, chi2/dof above 1e4, a fitted trajectory that descends where the data climb or
        turns through more than 90 degrees); empty when nothing is wrong."""
        from .start import result_checks
        return tuple(result_checks(self))

    def _status_word(self) -> str:
        if not self.success:
            return "FAILED"
        if self.sanity:
            return "IPOPT stopped at an optimum, but the result is NOT CREDIBLE (see the notes)"
        return "converged"

    def _sigma_text(self) -> str:
        std = self.sigma_std
        per = self.sigma_per_sample
        return ", ".join(f"{k} {v:.4g} +- {std[k]:.2g} (estimated)" if k in std else
                         f"{k} per sample {per[k]['min']:.3g} .. {per[k]['median']:.3g} .. {per[k]['max']:.3g} "
                         "(min .. median .. max)" if k in per else f"{k} {v:.4g}"
                         for k, v in self.sigma.items())

    def to_dict(self) -> dict:
        """A JSON-ready dictionary (``success``, ``parameters``, ``objective``, ...);
        a number that is not finite is ``None`` (the notes say why)."""
        return {
            "model": self.spec.name,
            "success": bool(self.success),
            "status": self.status,
            "message": self.message,
            "parameters": {str(k): finite_or_none(v) for k, v in self.parameters.items()},
            "objective": finite_or_none(self.objective),
            "chi2_per_dof": finite_or_none(self.chi2_per_dof),
            "iterations": int(self.iterations),
            "rms": {k: finite_or_none(v) for k, v in self.rms.items()},
            "sigma": {k: finite_or_none(v) for k, v in self.sigma.items()},
            "sigma_estimated": list(self.sigma_estimated),
            "sigma_std": {k: finite_or_none(v) for k, v in self.sigma_std.items()},
            **({"sigma_per_sample": {k: {kk: vv if kk == "n" else finite_or_none(vv) for kk, vv in d.items()}
                                     for k, d in self.sigma_per_sample.items()}} if self.sigma_per_sample else {}),
            "unmeasured_outputs": list(self.unmeasured_outputs),
            "sanity": list(self.sanity) if self.success else [],
            "n_data": int(self.n_data),
            "mesh": {"n_elements": int(self.prepared.transcription.mesh.n_elements),
                     "K": int(self.prepared.transcription.mesh.K)},
            "timings": {k: float(v) for k, v in self.timings.items()},
            "notes": list(self.notes),
            **({"priors": {str(pr.symbol): {"mean": pr.mean, "sd": pr.sd, "source": pr.source}
                           for pr in self.spec.priors},
                "prior_objective": finite_or_none(self.prior_objective)} if self.spec.priors else {}),
        }

    def to_json(self, path) -> None:
        """Write :meth:`to_dict` as JSON."""
        from .output import write_json
        write_json(path, self.to_dict())


def estimate(spec: ModelSpec, data: Measurements, *, guess: Mapping | Sequence[float] | None = None,
             mesh: Mesh | None = None, options: Mapping[str, Any] | None = None,
             warm_start: "EstimationResult | NLPSolution | None" = None, prepared: Prepared | None = None,
             sigma: str | Mapping[str, float | str] | None = None,
             window: Sequence[float] | None = None) -> EstimationResult:
    """Estimate all parameters of ``spec`` from ``data`` (the NLP (7.5)).

    Parameters
    ----------
    spec : ModelSpec
    data : Measurements
    guess : mapping or sequence, optional
        Initial guess (default: the model's p0).
    mesh : Mesh, optional
        Discretization (default: :func:`default_mesh`).
    options : mapping, optional
        IPOPT options.
    warm_start : EstimationResult or NLPSolution, optional
        Start from a previous solution of the same problem (primal and dual): a fit, or the
        solution IPOPT returned for it (what a refit's worker process hands back).
    prepared : Prepared, optional
        Reuse an already built NLP (same spec, data and mesh).
    sigma : "estimate" or mapping, optional
        Noise levels: ``"estimate"`` estimates every channel's sigma with the
        parameters (:func:`relax_sigma`); a mapping ``{channel: value or
        "estimate"}`` gives some and estimates others; ``"quantized"`` (or
        ``"quantized:STEP"``) sets a channel's sigma to its rounding error
        ``STEP / sqrt(12)``, the step found in its values unless given. Default: the data's sigma,
        else the model's.
    window : (float, float), optional
        A flight window ``(T0, T1)`` (s): the data and the model are cut to it
        (:func:`rocketid.start.apply_window`); a window that starts after the model's
        ``t0`` estimates the initial states the data determine (parameters ``<state>_0``,
        guessed from the data). The result's ``spec`` is the windowed model.

    Returns
    -------
    EstimationResult
        ``success`` is False (with a note) when IPOPT fails; never raises for
        a non-converged solve.
    """
    notes = []
    if window is not None:
        from .start import apply_window, window_guess
        if prepared is not None:
            raise SettingsError("window= cuts the model and the data: it cannot be combined with prepared=")
        if not isinstance(spec, ModelSpec) or not isinstance(data, Measurements):
            prepare(spec, data)  # names the wrong type
        p_full = spec.parameter_vector(guess)
        spec_w, data, wnotes = apply_window(spec, data, window, p_full)
        notes += wnotes
        guess = window_guess(spec, spec_w, p_full)
        spec = spec_w
    check_determined(spec, data)
    if isinstance(data, Measurements):
        sigma = resolve_quantized(sigma, data)
    given, estimated = sigma_request(sigma, data.names if isinstance(data, Measurements) else ())
    if isinstance(data, Measurements):
        check_not_per_sample(data, estimated, "sigma")
    if given:
        data = data.with_sigma(given)
    if prepared is None:
        prepared = prepare(spec, data, mesh=mesh)
    elif given:
        prepared = prepared.with_sigma(given)
    nlp = prepared.nlp
    p0 = spec.parameter_vector(guess)
    check_guess(spec, p0)
    p0 = np.clip(p0, spec.lower, spec.upper)         # a guess within GUESS_SLACK past a bound: onto it
    warm = None
    if warm_start is not None:
        warm = warm_start if isinstance(warm_start, NLPSolution) else warm_start.solution
        x0 = np.array(warm.x, float)
        if x0.shape != (nlp.n,):
            raise SettingsError(f"warm_start: a solution of {x0.size} variables cannot start this problem of "
                                f"{nlp.n} (another model, data or mesh); start it from the model's guesses instead "
                                "(no warm_start)")
        if guess is not None:
            x0 = nlp.layout.with_reduced(x0, p0)  # (7.5): the reduced parameters are p
    else:
        from .start import start_states
        start = start_states(spec, prepared.measurements, prepared.transcription.mesh.node_times, p0)
        notes.extend(start.notes)
        x0 = nlp.initial_x(start.states, p0)
    fit = fit_nlp(prepared, nlp, x0, options=options, warm=warm, setup_s=prepared.setup_s, notes=notes)
    if estimated:
        fit = relax_sigma(fit, estimated, options=options)
    return fit


def check_not_per_sample(data: Measurements, estimated: Sequence[str], where: str = "sigma") -> None:
    """Refuse to estimate the sigma of a channel that has per-sample sigmas (it would replace them).

    Raises
    ------
    DataError
        Names the channels and the fix.
    """
    clash = [c for c in estimated if c in data.names and data[c].per_sample]
    if clash:
        others = [c for c in data.names if c not in clash and c in estimated]
        hint = (f"; estimate only the others (CLI: {' '.join(f'--sigma {c}=estimate' for c in others)}; API: "
                f"sigma={ {c: 'estimate' for c in others} })" if others else "")
        raise DataError(f"{where}: channel(s) {', '.join(clash)} have per-sample sigmas (a sigma column), which "
                        f"estimating would replace; drop the sigma column or do not estimate their sigma{hint}")


def ml_sigma(fit: EstimationResult, channels: Sequence[str]) -> dict[str, float]:
    """The maximum-likelihood noise level of each channel at ``fit``'s parameters,
    ``sqrt(mean(residual^2))``.

    Raises
    ------
    DataError
        A channel whose residuals are all zero (sigma cannot be estimated: give it).
    """
    out = {}
    for c in channels:
        r = fit.residuals[c]
        with np.errstate(over="ignore", invalid="ignore"):
            s = float(np.sqrt(np.mean(r ** 2)))
        if not (s > 0 and math.isfinite(s)):
            raise DataError(f"the noise level of channel {c!r} cannot be estimated: its residuals are "
                            f"{'all zero' if s == 0 else 'not finite'} at the fit; give its sigma (--sigma {c}=VALUE)")
        out[c] = s
    return out


def relax_sigma(fit: EstimationResult, channels: Sequence[str], *, options: Mapping[str, Any] | None = None,
                rtol: float = 1e-6, max_fits: int = 30) -> EstimationResult:
    """Maximum likelihood with the noise levels of ``channels`` unknown: the output-error
    method's relaxation.

    With ``n_k`` samples and residuals ``r_k`` in channel ``k``, the likelihood is largest over
    ``sigma_k`` at ``sigma_k^2 = r_k . r_k / n_k`` for given parameters. The relaxation
    alternates: sigma from the residuals of the last fit, then the parameters again with those
    sigmas (starting from the last solution), until no sigma changes by more than ``rtol``
    relatively. The fixed point is a stationary point of the concentrated likelihood
    ``sum_k n_k / 2 log(r_k . r_k / n_k)``.

    Parameters
    ----------
    fit : EstimationResult
        A fit with any starting sigmas (the model's or the data's).
    channels : sequence of str
        The channels whose sigma is estimated; the others keep theirs.
    options : mapping, optional
        IPOPT options of the refits.
    rtol : float
        Convergence: the largest relative change of a sigma between two fits.
    max_fits : int
        Give up (with a note) after this many refits.

    Returns
    -------
    EstimationResult
        The last fit, with the estimated sigmas in its data (``fit.sigma``,
        ``fit.prepared.measurements``) so that the covariance, the statistic criterion
        and the score test use them; ``sigma_estimated`` names the channels.
    """
    channels = tuple(channels)
    if not channels:
        return fit
    unknown = [c for c in channels if c not in fit.nlp.channel_names]
    if unknown:
        raise DataError(f"sigma of {', '.join(map(repr, unknown))} cannot be estimated: not a fitted channel "
                        f"({', '.join(fit.nlp.channel_names)})")
    check_not_per_sample(fit.prepared.measurements, channels)
    notes = list(fit.notes)

    def refit(last, new):
        prepared = last.prepared.with_sigma(new)
        return fit_nlp(prepared, prepared.nlp, last.x, options=options)

    fit, fits, solve_s, note = relaxation(fit, lambda last: ml_sigma(last, channels), refit,
                                         {c: fit.sigma[c] for c in channels}, rtol=rtol, max_fits=max_fits)
    if note:
        notes.append(note)
    notes.extend(n for n in fit.notes if n not in notes)
    return replace(fit, notes=tuple(notes), sigma_estimated=channels, sigma_iterations=fits,
                   timings={"setup_s": fit.prepared.setup_s, "solve_s": solve_s})


def relaxation(fit, sigmas_of: Callable, refit: Callable, current: Mapping, *, rtol: float, max_fits: int,
               what: str = "fit"):
    """The output-error relaxation's loop, shared by one flight (:func:`relax_sigma`) and several
    (:func:`rocketid.joint.joint_estimate`): sigmas from the last fit's residuals, a refit with
    them, until no sigma changes by more than ``rtol`` relatively.

    Parameters
    ----------
    fit : EstimationResult or JointResult
        The first fit (``success``, ``timings["solve_s"]``).
    sigmas_of : callable
        ``sigmas_of(fit) -> {key: sigma}``, the maximum-likelihood sigmas at a fit.
    refit : callable
        ``refit(fit, sigmas) -> fit``: the fit again with those sigmas, from ``fit``'s solution.
    current : mapping
        ``{key: sigma}`` the first fit was made with.
    rtol, max_fits : float, int
        Convergence, and the refits after which to give up.
    what : str
        The fit's name in the note ("fit", "joint fit").

    Returns
    -------
    (fit, fits, solve_s, note)
        The last fit, the number of fits, their IPOPT time and a note when the relaxation failed
        or did not settle (else None).
    """
    fits, solve_s, converged, change = 1, fit.timings.get("solve_s", 0.0), False, math.inf
    while fit.success:
        new = sigmas_of(fit)
        change = max(abs(new[k] / current[k] - 1.0) for k in new)
        if change <= rtol:
            converged = True
            break
        if fits > max_fits:
            break
        fit = refit(fit, new)
        solve_s += fit.timings["solve_s"]
        fits += 1
        current = new
    note = None
    if not fit.success:
        note = (f"the {what} failed while the noise levels were being estimated ({what} {fits}); the sigmas are "
                f"those of the last {what}")
    elif not converged:
        note = (f"the noise levels did not settle within {max_fits} refits (last relative change {change:.2g}); "
                "the estimates are the last ones")
    return fit, fits, solve_s, note


def fit_nlp(prepared: Prepared, nlp: CollocationNLP, x0: np.ndarray, *, options: Mapping[str, Any] | None = None,
            warm: NLPSolution | None = None, cold_start: Callable[[], np.ndarray] | None = None,
            setup_s: float = 0.0, notes: Sequence[str] = ()) -> EstimationResult:
    """The one fitting path: solve ``nlp`` from ``x0`` and make the :class:`EstimationResult`.

    Parameters
    ----------
    prepared : Prepared
        The model collocated against the data; the result holds it with ``nlp``.
    nlp : CollocationNLP
        The problem: ``prepared.nlp`` (7.5) or a transformed one (7.9).
    x0 : ndarray, shape (nlp.n,)
    options : mapping, optional
        IPOPT options.
    warm : NLPSolution, optional
        Multipliers to warm-start IPOPT.
    cold_start : callable, optional
        ``cold_start() -> x0``: a warm-started solve that fails is repeated once from
        this start without multipliers (the result's ``retried`` is then True).
    setup_s : float
        The set-up time to report.
    notes : sequence of str
        Notes gathered before the solve.

    Returns
    -------
    EstimationResult
        ``success`` is False when IPOPT fails or returns non-finite values.
    """
    notes = list(notes)
    sol = solve_nlp(nlp, x0, options=options, warm=warm)
    retried = False
    if warm is not None and cold_start is not None and not sol.success:
        sol = solve_nlp(nlp, cold_start(), options=options)
        retried = True
        notes.append("the warm-started solve failed and was repeated from a simulation")
    return result_of(prepared, nlp, sol, setup_s=setup_s, notes=notes, retried=retried)


def result_of(prepared: Prepared, nlp: CollocationNLP, sol: NLPSolution, *, setup_s: float = 0.0,
              notes: Sequence[str] = (), retried: bool = False) -> EstimationResult:
    """The :class:`EstimationResult` of a solution ``sol`` of ``nlp`` (no solve)."""
    notes = list(notes)
    finite = bool(np.all(np.isfinite(sol.x)))
    objective = sol.objective
    if not finite:
        notes.append("the solver returned non-finite values")
    elif sol.status == INVALID_NUMBER or not math.isfinite(objective):
        with np.errstate(over="ignore", invalid="ignore"):
            objective = float(nlp.objective(sol.x))  # IPOPT reports 0 when it met an invalid number
        if not math.isfinite(objective):
            finite = False
            notes.append("the objective is not finite at the returned point: the data are far out of scale for the "
                         "model and sigma (check the units of the data and of --sigma)")
    if prepared.nlp is not nlp:
        prepared = replace(prepared, nlp=nlp)
    return EstimationResult(
        success=sol.success and finite, status=sol.status, message=sol.message, p=nlp.layout.parameters(sol.x),
        objective=objective, iterations=sol.iterations, x=sol.x, solution=sol, prepared=prepared,
        timings={"setup_s": setup_s, "solve_s": sol.solve_s}, notes=tuple(notes), retried=retried)


#: IPOPT's status "Invalid_Number_Detected" (NaN or infinity from the NLP's functions).
INVALID_NUMBER = -13


def check_determined(spec: ModelSpec, data: Measurements) -> None:
    """Refuse a fit with no more measured values than estimated parameters.

    Raises
    ------
    DataError
        The data's values of the model's outputs are at most the number of
        parameters (the fit would pass through them, and chi2/dof is undefined).
    """
    if not isinstance(data, Measurements) or not isinstance(spec, ModelSpec):
        return  # prepare() names the wrong type
    n = sum(c.times.size for c in data.channels if c.name in spec.output_names)
    n_p = len(spec.parameters)
    if n <= n_p:
        raise DataError(f"the data have {n} values of {', '.join(spec.output_names)} but model {spec.name!r} "
                        f"estimates {n_p} parameters; a fit needs more values than parameters (give more samples "
                        "or fewer parameters)")
