"""Several flights, one vehicle: a joint fit of shared parameters as one block-structured NLP.

Each flight ``f`` has its own model (its inputs: the attitude program, a throttle schedule;
its initial states), its own data and noise levels, and its own collocation NLP (7.5)
``x_f = [gamma_f, p_f]``. The flights share some parameters (the aerodynamics) and keep
others to themselves (sensor biases, free initial states, a flight's throttle levels). The
joint problem is

    min_X  sum_f J_f(B_f X) + 1/2 sum_i ((theta_i - mu_i) / s_i)^2
    s.t.   c_f(B_f X) = 0  for every flight f

with ``X = [gamma_1, ..., gamma_F, theta]``: every flight's node states, then the joint
parameters ``theta`` (shared ones first, then each flight's own, labelled ``name[flight]``).
``B_f`` picks flight f's states and maps ``theta`` to its parameter vector ``p_f = A_f theta``.
The constraint Jacobian is block diagonal in the states with the shared columns coupling the
blocks; the Lagrangian Hessian is the sum of the flights' Hessians mapped through ``B_f``
(entries of shared parameters added). Priors count once per joint parameter (the first flight
that declares one gives it). Set-up and each evaluation cost the sum of the flights' costs.

The covariance of ``theta`` is ``H^-1`` with ``H = sum_f A_f^T H_f A_f + H_prior`` (``H_f``
each flight's data information ``S_f^T Cy_f^-1 S_f`` at the joint estimate). The information
on the shared parameters that each flight brings (its own parameters eliminated: a Schur
complement) tells which directions each flight adds (:class:`JointEstimability`).

Notation
--------
==========  ================================================================
``f``       flight index, ``F`` flights
``X``       joint decision vector ``[gamma_1 .. gamma_F, theta]``
``theta``   joint parameters: shared, then per-flight (``name[label]``)
``A_f``     ``p_f = A_f theta`` (a selection)
``H_f``     flight f's data information on ``p_f`` (reduced Hessian, 7.6)
==========  ================================================================
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, replace
from functools import cached_property
from typing import Any, Mapping, Sequence

import numpy as np
import scipy.sparse as sps

from .collocation.transcription import Mesh
from .data import Measurements
from .errors import DataError, SensitivityError, SettingsError
from .model import ModelSpec, check_guess
from .output import finite_or_none
from .sensitivity import sensitivity_of
from .solve import EstimationResult, NLPSolution, prepare, result_of, solve_nlp
from .summary import Section, Summary, Table

__all__ = ["Flight", "JointLayout", "JointNLP", "JointResult", "JointEstimability", "joint_estimate",
           "joint_prepare", "joint_estimability"]


@dataclass(frozen=True)
class Flight:
    """One flight of a joint fit: its label, its model and its data.

    Attributes
    ----------
    label : str
        Names the flight in reports and in its own parameters (``b_h[CRS-11]``).
    spec : ModelSpec
        The flight's model (its own inputs and initial states).
    data : Measurements
        Its measurements (each channel with its own sigma, or the model's).
    mesh : Mesh, optional
        Its collocation mesh (default: :func:`rocketid.solve.default_mesh`).
    """

    label: str
    spec: ModelSpec
    data: Measurements
    mesh: Mesh | None = None

    def __post_init__(self):
        if not isinstance(self.label, str) or not self.label or any(c in self.label for c in "[]"):
            raise SettingsError(f"a flight's label must be a non-empty string without brackets, got {self.label!r}")
        if not isinstance(self.spec, ModelSpec):
            raise SettingsError(f"flight {self.label!r}: spec must be a ModelSpec (call Model.freeze()), got "
                                f"{type(self.spec).__name__}")
        if not isinstance(self.data, Measurements):
            raise SettingsError(f"flight {self.label!r}: data must be Measurements (rocketid.read_csv), got "
                                f"{type(self.data).__name__}")


@dataclass(frozen=True)
class JointLayout:
    """Owner of the joint parameter vector ``theta`` and of each flight's map ``p_f = A_f theta``.

    Attributes
    ----------
    labels : tuple of str
    names : tuple of str
        Joint parameter names: shared ones as the models name them, then per-flight ones
        as ``name[label]``.
    shared : tuple of str
        The shared parameters' names.
    owner : tuple
        Per joint parameter: None (shared) or the index of the flight it belongs to.
    index : tuple of ndarray
        Per flight: ``index[f][j]`` is the joint index of flight f's parameter j.
    guess, lower, upper, nominal : ndarray
    prior_mean, prior_weight : ndarray
        Joint priors (weight ``1/sd^2``, 0 where none).
    """

    labels: tuple
    names: tuple
    shared: tuple
    owner: tuple
    index: tuple
    guess: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    nominal: np.ndarray
    prior_mean: np.ndarray
    prior_weight: np.ndarray

    @property
    def n(self) -> int:
        return len(self.names)

    @property
    def shared_columns(self) -> np.ndarray:
        return np.array([i for i, o in enumerate(self.owner) if o is None], dtype=int)

    def own_columns(self, f: int) -> np.ndarray:
        """Joint indices of flight f's own parameters."""
        return np.array([i for i, o in enumerate(self.owner) if o == f], dtype=int)

    def flight_parameters(self, theta: np.ndarray, f: int) -> np.ndarray:
        """``p_f = A_f theta``."""
        return np.asarray(theta, float)[self.index[f]]

    def selection(self, f: int) -> np.ndarray:
        """``A_f`` as a dense matrix (n_pf, n)."""
        A = np.zeros((self.index[f].size, self.n))
        A[np.arange(self.index[f].size), self.index[f]] = 1.0
        return A


def _layout(flights: Sequence[Flight], per_flight: Sequence[str]) -> JointLayout:
    labels = tuple(fl.label for fl in flights)
    if len(set(labels)) != len(labels):
        raise SettingsError(f"flight labels must differ, got {', '.join(labels)}")
    per_flight = set(per_flight)
    known = {n for fl in flights for n in fl.spec.parameter_names}
    unknown = sorted(per_flight - known)
    if unknown:
        raise SettingsError(f"--per-flight {', '.join(unknown)}: not a parameter of any flight's model; the parameters "
                            f"are {', '.join(sorted(known))}")
    count: dict[str, int] = {}
    for fl in flights:
        for n in fl.spec.parameter_names:
            count[n] = count.get(n, 0) + 1
    initial = {str(s.initial_parameter) for fl in flights for s in fl.spec.states if s.free}

    def is_shared(name: str) -> bool:
        return count[name] > 1 and name not in per_flight and name not in initial

    names, owner, guess, lower, upper, nominal, pmean, pweight = [], [], [], [], [], [], [], []
    where: dict[str, int] = {}

    def add(name, f, ps, prior):
        where[name] = len(names)
        names.append(name)
        owner.append(f)
        guess.append(ps.guess)
        lower.append(ps.lower)
        upper.append(ps.upper)
        nominal.append(ps.nominal)
        pmean.append(prior.mean if prior else 0.0)
        pweight.append(1.0 / prior.sd ** 2 if prior else 0.0)

    priors = [{str(pr.symbol): pr for pr in fl.spec.priors} for fl in flights]
    for f, fl in enumerate(flights):  # shared parameters, in order of first appearance
        for ps in fl.spec.parameters:
            name = str(ps.symbol)
            if is_shared(name) and name not in where:
                prior = next((pr[name] for pr in priors if name in pr), None)
                add(name, None, ps, prior)
    for f, fl in enumerate(flights):
        for ps in fl.spec.parameters:
            name = str(ps.symbol)
            if not is_shared(name):
                add(f"{name}[{fl.label}]", f, ps, priors[f].get(name))
    index = []
    for f, fl in enumerate(flights):
        index.append(np.array([where[n] if is_shared(n) else where[f"{n}[{fl.label}]"]
                               for n in fl.spec.parameter_names], dtype=int))
    arr = lambda v: np.array(v, dtype=float)
    return JointLayout(labels, tuple(names), tuple(n for n, o in zip(names, owner) if o is None), tuple(owner),
                       tuple(index), arr(guess), arr(lower), arr(upper), arr(nominal), arr(pmean), arr(pweight))


@dataclass(frozen=True, eq=False)
class JointNLP:
    """The joint NLP: the flights' collocation NLPs side by side, coupled by the shared parameters.

    Its methods are a sparse NLP solver's callbacks (the contract of
    :class:`rocketid.nlp.CollocationNLP`); :func:`rocketid.solve.solve_nlp` solves it with IPOPT.

    Attributes
    ----------
    layout : JointLayout
    nlps : tuple of CollocationNLP
        Each flight's NLP (7.5) without priors (the joint priors are added once here).
    n, m : int
    x_lower, x_upper, c_lower, c_upper : ndarray
    """

    layout: JointLayout
    nlps: tuple

    def __post_init__(self):
        set_ = object.__setattr__
        lay = self.layout
        nsv = [nlp.layout.n_state_vars for nlp in self.nlps]
        state_start = np.concatenate([[0], np.cumsum(nsv)]).astype(int)
        n_states_total = int(state_start[-1])
        n = n_states_total + lay.n
        colmaps, rowstart = [], [0]
        for f, nlp in enumerate(self.nlps):
            cm = np.concatenate([state_start[f] + np.arange(nsv[f]), n_states_total + lay.index[f]])
            colmaps.append(cm)
            rowstart.append(rowstart[-1] + nlp.m)
        set_(self, "n", n)
        set_(self, "m", rowstart[-1])
        set_(self, "n_state_total", n_states_total)
        set_(self, "_colmaps", tuple(colmaps))
        set_(self, "_rows", tuple(slice(a, b) for a, b in zip(rowstart[:-1], rowstart[1:])))
        set_(self, "x_lower", np.concatenate([np.full(n_states_total, -np.inf), lay.lower]))
        set_(self, "x_upper", np.concatenate([np.full(n_states_total, np.inf), lay.upper]))
        set_(self, "c_lower", np.concatenate([nlp.c_lower for nlp in self.nlps]))
        set_(self, "c_upper", np.concatenate([nlp.c_upper for nlp in self.nlps]))
        jr, jc = [], []
        for f, nlp in enumerate(self.nlps):
            r, c = nlp.jacobianstructure()
            jr.append(r + self._rows[f].start)
            jc.append(colmaps[f][c])
        set_(self, "_jac", (np.concatenate(jr), np.concatenate(jc)))

    @cached_property
    def _hess(self):
        """Unique lower-triangle structure and the summing matrix from the flights' entries."""
        rows, cols = [], []
        for f, nlp in enumerate(self.nlps):
            r, c = nlp.hessianstructure()
            R, C = self._colmaps[f][r], self._colmaps[f][c]
            rows.append(np.maximum(R, C))
            cols.append(np.minimum(R, C))
        pw = self.layout.prior_weight
        prior_cols = self.n_state_total + np.flatnonzero(pw)
        rows.append(prior_cols)
        cols.append(prior_cols)
        R, C = np.concatenate(rows), np.concatenate(cols)
        key = R.astype(np.int64) * self.n + C
        uniq, inverse = np.unique(key, return_inverse=True)
        E = sps.csr_matrix((np.ones(key.size), (inverse, np.arange(key.size))), shape=(uniq.size, key.size))
        prior_vals = pw[np.flatnonzero(pw)]
        return (uniq // self.n).astype(np.int64), (uniq % self.n).astype(np.int64), E, prior_vals

    # ---------------------------------------------------------------- pieces of X
    def flight_x(self, X: np.ndarray, f: int) -> np.ndarray:
        """Flight f's NLP vector ``x_f = [gamma_f, p_f]``."""
        return np.asarray(X)[self._colmaps[f]]

    def theta(self, X: np.ndarray) -> np.ndarray:
        """The joint parameters."""
        return np.asarray(X)[self.n_state_total:]

    def pack(self, xs: Sequence[np.ndarray], theta: np.ndarray) -> np.ndarray:
        """``X`` from each flight's ``x_f`` (their parameter parts are ignored) and ``theta``."""
        X = np.empty(self.n)
        for f, x in enumerate(xs):
            states = self.nlps[f].layout.states(np.asarray(x))
            X[self._colmaps[f][: states.size]] = states
        X[self.n_state_total:] = theta
        return X

    def flight_rows(self, f: int) -> slice:
        return self._rows[f]

    def flight_columns(self, f: int) -> np.ndarray:
        return self._colmaps[f]

    # ---------------------------------------------------------------- callbacks
    def prior_objective(self, X: np.ndarray) -> float:
        d = self.theta(X) - self.layout.prior_mean
        return 0.5 * float(np.sum(self.layout.prior_weight * d * d))

    def objective(self, X: np.ndarray) -> float:
        return sum(nlp.objective(self.flight_x(X, f)) for f, nlp in enumerate(self.nlps)) + self.prior_objective(X)

    def gradient(self, X: np.ndarray) -> np.ndarray:
        g = np.zeros(self.n)
        for f, nlp in enumerate(self.nlps):
            np.add.at(g, self._colmaps[f], nlp.gradient(self.flight_x(X, f)))
        g[self.n_state_total:] += self.layout.prior_weight * (self.theta(X) - self.layout.prior_mean)
        return g

    def constraints(self, X: np.ndarray) -> np.ndarray:
        return np.concatenate([nlp.constraints(self.flight_x(X, f)) for f, nlp in enumerate(self.nlps)])

    def jacobianstructure(self):
        return self._jac

    def jacobian(self, X: np.ndarray) -> np.ndarray:
        return np.concatenate([nlp.jacobian(self.flight_x(X, f)) for f, nlp in enumerate(self.nlps)])

    def hessianstructure(self):
        r, c, _, _ = self._hess
        return r, c

    def hessian(self, X: np.ndarray, lagrange: np.ndarray, obj_factor: float) -> np.ndarray:
        _, _, E, prior_vals = self._hess
        lam = np.asarray(lagrange)
        vals = [nlp.hessian(self.flight_x(X, f), lam[self._rows[f]], obj_factor) for f, nlp in enumerate(self.nlps)]
        vals.append(obj_factor * prior_vals)
        return E @ np.concatenate(vals)


@dataclass(frozen=True)
class JointPrepared:
    """The flights collocated against their data and the joint NLP: ready to solve.

    Attributes
    ----------
    flights : tuple of Flight
    prepared : tuple of Prepared
        Each flight's model (without priors: they are the joint NLP's) on its mesh.
    nlp : JointNLP
    setup_s : float
    """

    flights: tuple
    prepared: tuple
    nlp: JointNLP
    setup_s: float

    @property
    def layout(self) -> JointLayout:
        return self.nlp.layout


def joint_prepare(flights: Sequence[Flight], *, per_flight: Sequence[str] = ()) -> JointPrepared:
    """Collocate every flight and assemble the joint NLP (set-up time linear in the flights).

    Parameters
    ----------
    flights : sequence of Flight
    per_flight : sequence of str
        Parameters every flight has but that differ between flights (sensor biases). Free
        initial states, and parameters only one flight's model has, are per-flight always.
    """
    flights = tuple(flights)
    if not flights:
        raise SettingsError("a joint fit needs at least one flight")
    for fl in flights:
        if not isinstance(fl, Flight):
            raise SettingsError(f"flights must be Flight values (rocketid.joint.Flight(label, spec, data)), got "
                                f"{type(fl).__name__}")
    t0 = time.perf_counter()
    layout = _layout(flights, per_flight)
    prepared = tuple(prepare(replace(fl.spec, priors=()), fl.data, mesh=fl.mesh) for fl in flights)
    nlp = JointNLP(layout, tuple(p.nlp for p in prepared))
    return JointPrepared(flights, prepared, nlp, time.perf_counter() - t0)


@dataclass(frozen=True)
class JointEstimability:
    """What each flight adds to the information on the shared parameters.

    Attributes
    ----------
    names : tuple of str
        The shared parameters.
    eigenvalues : ndarray, shape (n_s,)
        Of the joint information on the shared parameters (each flight's own parameters
        eliminated), descending.
    V : ndarray, shape (n_s, n_s)
        Its eigenvectors (columns).
    flight_eigenvalues : dict
        ``{label: eigenvalues of that flight's information alone}`` (descending).
    shares : dict
        ``{label: share of each joint direction's eigenvalue that the flight brings}``, and
        ``"prior"`` for the priors' share.
    D : ndarray
        The scaling (parameters divided by their nominal values: ``"nominal"``; else ones).
    """

    names: tuple
    eigenvalues: np.ndarray
    V: np.ndarray
    flight_eigenvalues: dict
    shares: dict
    D: np.ndarray

    @property
    def condition_number(self) -> float:
        lam = self.eigenvalues
        return float(lam[0] / lam[-1]) if lam[-1] > 0 else math.inf

    def flight_condition_numbers(self) -> dict:
        return {k: (float(v[0] / v[-1]) if v[-1] > 0 else math.inf) for k, v in self.flight_eigenvalues.items()}

    def table(self) -> Table:
        labels = list(self.shares)
        rows = []
        for k, lam in enumerate(self.eigenvalues):
            comp = self.V[:, k] ** 2
            order = np.argsort(comp)[::-1]
            parts = ", ".join(f"{self.names[i]} {100 * comp[i]:.0f}%" for i in order if comp[i] >= 0.05)
            rows.append((f"q{k + 1}", float(lam), *(f"{100 * self.shares[l][k]:.0f}%" for l in labels), parts))
        return Table(("dir", "joint eigenvalue", *(f"from {l}" for l in labels), "composition"), rows,
                     (None, ".4g") + (None,) * (len(labels) + 1))

    def summary(self) -> Summary:
        rows = [("joint", f"condition number {self.condition_number:.3g}")]
        for label, lam in self.flight_eigenvalues.items():
            cond = self.flight_condition_numbers()[label]
            rows.append((label, f"eigenvalues {', '.join(f'{v:.3g}' for v in lam)} (condition number {cond:.3g})"))
        return Summary("rocketid joint estimability (information on the shared parameters)",
                       (Section("Alone and together", rows), Section("Joint directions", (self.table(),))), rule=False)

    def to_dict(self) -> dict:
        return {"shared": list(self.names), "eigenvalues": [float(v) for v in self.eigenvalues],
                "condition_number": finite_or_none(self.condition_number),
                "flight_eigenvalues": {k: [float(x) for x in v] for k, v in self.flight_eigenvalues.items()},
                "flight_condition_numbers": {k: finite_or_none(v) for k, v in self.flight_condition_numbers().items()},
                "shares": {k: [finite_or_none(x) for x in v] for k, v in self.shares.items()},
                "directions": [{n: float(self.V[i, k]) for i, n in enumerate(self.names)}
                               for k in range(self.eigenvalues.size)]}


def _schur(H: np.ndarray, keep: np.ndarray, drop: np.ndarray) -> np.ndarray:
    """Information on ``keep`` with ``drop`` eliminated: ``H_kk - H_kd H_dd^+ H_dk``."""
    Hkk = H[np.ix_(keep, keep)]
    if drop.size == 0:
        return Hkk
    Hkd = H[np.ix_(keep, drop)]
    Hdd = H[np.ix_(drop, drop)]
    lam, U = np.linalg.eigh(0.5 * (Hdd + Hdd.T))
    keep_ev = lam > lam.max() * 1e-12 if lam.size and lam.max() > 0 else np.zeros(lam.size, bool)
    W = U[:, keep_ev] / np.sqrt(lam[keep_ev])       # the pseudo-inverse, directions of no information dropped
    S = Hkk - (Hkd @ W) @ (Hkd @ W).T
    return 0.5 * (S + S.T)


def joint_estimability(layout: JointLayout, flight_information: Sequence[np.ndarray], *,
                       scaling: str = "nominal") -> JointEstimability:
    """Eigenvalues of the information on the shared parameters, per flight and joint.

    Parameters
    ----------
    layout : JointLayout
    flight_information : sequence of ndarray
        Each flight's data information ``H_f`` on its own parameter vector ``p_f``.
    scaling : {"nominal", "none"}
        Divide the parameters by their nominal values before decomposing.
    """
    if scaling not in ("nominal", "none"):
        raise SettingsError(f"scaling must be 'nominal' or 'none', got {scaling!r}")
    sh = layout.shared_columns
    if sh.size == 0:
        raise SettingsError("the flights share no parameter: nothing to analyse jointly")
    # every joint parameter is divided by its nominal value before eliminating a flight's own ones
    # (their scales differ by orders of magnitude: kilograms beside throttle fractions), so that
    # the elimination is well conditioned; the shared ones are then rescaled as asked
    Dall = np.where(layout.nominal != 0, np.abs(layout.nominal), 1.0)
    D = Dall[sh] if scaling == "nominal" else np.ones(sh.size)
    back = D / Dall[sh]
    prior_full = np.diag(layout.prior_weight * Dall ** 2)
    per_flight = []
    for f, Hf in enumerate(flight_information):
        A = layout.selection(f)
        own = layout.own_columns(f)
        Hfull = Dall[:, None] * (A.T @ Hf @ A) * Dall[None, :]
        # the flight's own priors belong to its block (they change what it can say about the shared)
        Hfull[np.ix_(own, own)] += prior_full[np.ix_(own, own)]
        per_flight.append(back[:, None] * _schur(Hfull, sh, own) * back[None, :])
    prior_sh = back[:, None] * prior_full[np.ix_(sh, sh)] * back[None, :]
    Hj = sum(per_flight) + prior_sh
    lam, V = np.linalg.eigh(0.5 * (Hj + Hj.T))
    lam, V = lam[::-1], V[:, ::-1]
    sign = np.sign(V[np.argmax(np.abs(V), axis=0), np.arange(V.shape[1])])
    V = V * np.where(sign == 0, 1.0, sign)
    shares = {}
    with np.errstate(divide="ignore", invalid="ignore"):
        for label, If in zip(layout.labels, per_flight):
            shares[label] = np.einsum("ik,ij,jk->k", V, If, V) / lam
        if np.any(prior_sh):
            shares["prior"] = np.einsum("ik,ij,jk->k", V, prior_sh, V) / lam
    flight_eigs = {label: np.linalg.eigvalsh(0.5 * (If + If.T))[::-1] for label, If in zip(layout.labels, per_flight)}
    return JointEstimability(layout.shared, lam, V, flight_eigs, shares, D)


@dataclass(frozen=True)
class JointResult:
    """The result of a joint fit.

    Attributes
    ----------
    success : bool
    message : str
    theta : ndarray
        Joint parameters (:attr:`names`).
    objective : float
        J of the joint problem (the flights' data terms plus the priors).
    iterations : int
    flights : tuple of EstimationResult
        Each flight's view of the joint solution (its states, parameters, residuals, chi2/dof).
    prepared : JointPrepared
    solution : NLPSolution
    timings : dict
        ``setup_s``, ``solve_s``.
    notes : tuple of str
    sigma_iterations : int
        Joint fits of the noise-level relaxation (0 when no sigma was estimated).
    """

    success: bool
    message: str
    theta: np.ndarray
    objective: float
    iterations: int
    flights: tuple
    prepared: JointPrepared
    solution: NLPSolution
    timings: dict
    notes: tuple = ()
    sigma_iterations: int = 0

    @property
    def layout(self) -> JointLayout:
        return self.prepared.layout

    @property
    def sigma(self) -> dict[str, dict[str, float]]:
        """Each flight's noise standard deviation per channel, ``{label: {channel: sigma}}``
        (estimated ones included)."""
        return {l: r.sigma for l, r in zip(self.labels, self.flights)}

    @property
    def sigma_estimated(self) -> dict[str, tuple]:
        """The channels whose sigma was estimated, per flight: ``{label: (channel, ...)}`` (flights
        with none left out)."""
        return {l: r.sigma_estimated for l, r in zip(self.labels, self.flights) if r.sigma_estimated}

    @property
    def sigma_std(self) -> dict[str, dict[str, float]]:
        """Standard error of each estimated sigma, per flight (``sigma / sqrt(2 n)``)."""
        return {l: r.sigma_std for l, r in zip(self.labels, self.flights) if r.sigma_estimated}

    @property
    def names(self) -> tuple:
        return self.layout.names

    @property
    def labels(self) -> tuple:
        return self.layout.labels

    def value(self, name: str) -> float:
        """A joint parameter's estimate (shared: ``"CD_0"``; a flight's own: ``"b_h[F1]"``)."""
        if name not in self.names:
            raise SettingsError(f"{name!r} is not a joint parameter; they are {', '.join(self.names)}")
        return float(self.theta[self.names.index(name)])

    def flight(self, label: str) -> EstimationResult:
        """One flight's view of the joint fit."""
        if label not in self.labels:
            raise SettingsError(f"no flight {label!r}; the flights are {', '.join(self.labels)}")
        return self.flights[self.labels.index(label)]

    @property
    def prior_objective(self) -> float:
        return self.prepared.nlp.prior_objective(self.solution.x)

    @property
    def n_data(self) -> int:
        return sum(r.n_data for r in self.flights)

    @property
    def chi2_per_dof(self) -> float:
        """Over all flights: ``2 sum_f J_f / (n_data - n_theta)`` (priors excluded)."""
        data_J = sum(r.data_objective for r in self.flights)
        return 2.0 * data_J / max(1, self.n_data - self.layout.n)

    @cached_property
    def sensitivities(self) -> tuple:
        """Each flight's sensitivity analysis at the joint estimate (:func:`rocketid.sensitivity.sensitivity_of`)."""
        return tuple(sensitivity_of(r) for r in self.flights)

    @cached_property
    def information(self) -> tuple:
        """Each flight's data information ``H_f`` on its parameter vector, at the joint estimate."""
        return tuple(sens.H_data for sens in self.sensitivities)

    @cached_property
    def covariance(self) -> np.ndarray:
        """``(sum_f A_f^T H_f A_f + H_prior)^-1``, shape (n_theta, n_theta)."""
        lay = self.layout
        H = np.diag(lay.prior_weight).astype(float)
        for f, Hf in enumerate(self.information):
            A = lay.selection(f)
            H += A.T @ Hf @ A
        ev = np.linalg.eigvalsh(H)
        if not ev[0] > 0:
            raise SensitivityError("the joint information matrix is singular: some combination of the joint "
                                   "parameters has no effect on any flight's outputs")
        C = np.linalg.inv(H)
        return 0.5 * (C + C.T)

    @property
    def standard_errors(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.covariance), 0, None))

    @cached_property
    def coloured_covariance(self) -> np.ndarray:
        """The covariance corrected for residuals correlated in time: the sandwich ``H^-1 B H^-1`` with
        ``B = sum_f A_f^T B_f A_f + H_prior``, ``B_f`` the long-run covariance of flight ``f``'s score
        (:func:`~rocketid.estimability.coloured_score_covariance`: Bartlett weights over each channel's
        lags). Flights are independent of each other (their errors do not correlate across flights), as
        channels are within a flight. With white residuals at the fitted sigmas it gives
        :attr:`covariance` to sampling error."""
        from .estimability import coloured_score_covariance
        lay = self.layout
        B = np.diag(lay.prior_weight).astype(float)
        for f, (r, sens) in enumerate(zip(self.flights, self.sensitivities)):
            Bf, _ = coloured_score_covariance(r, sens)
            A = lay.selection(f)
            B += A.T @ (Bf - sens.H_prior) @ A              # the priors are the joint's, counted once above
        C = self.covariance @ B @ self.covariance
        return 0.5 * (C + C.T)

    @property
    def coloured_standard_errors(self) -> np.ndarray:
        """Standard errors from :attr:`coloured_covariance`."""
        return np.sqrt(np.clip(np.diag(self.coloured_covariance), 0, None))

    def estimability(self, scaling: str = "nominal") -> JointEstimability:
        """Which directions of the shared parameters each flight adds (at the joint estimate)."""
        return joint_estimability(self.layout, self.information, scaling=scaling)

    def flight_statistics(self) -> list[dict]:
        """Per flight: chi2/dof, RMS per channel, and the channel whose residuals are worst."""
        out = []
        for label, r in zip(self.labels, self.flights):
            out.append({"flight": label, "chi2_per_dof": r.chi2_per_dof, "n_data": r.n_data,
                        "rms": dict(r.rms), "objective": r.data_objective})
        return out

    def summary(self) -> Summary:
        lay = self.layout
        problem = Section("Problem", (
            ("flights", ", ".join(f"{l} ({r.n_data} values)" for l, r in zip(self.labels, self.flights))),
            ("NLP", f"{self.prepared.nlp.n} variables, {self.prepared.nlp.m} constraints"),
            ("parameters", f"{len(lay.shared)} shared, {lay.n - len(lay.shared)} per flight")))
        solver = Section("Solver", (
            ("status", f"{'converged' if self.success else 'FAILED'} ({self.solution.status}: {self.message})"),
            ("iterations", str(self.iterations)),
            ("time", f"setup {self.timings['setup_s']:.3f} s, IPOPT {self.timings['solve_s']:.3f} s")))
        try:
            se = self.standard_errors
        except SensitivityError:
            se = np.full(lay.n, np.nan)
        params = Section("Parameters", (Table(
            ("name", "estimate", "std error", "guess", "lower", "upper"),
            [(n, float(v), float(s), g, lo, hi) for n, v, s, g, lo, hi in
             zip(lay.names, self.theta, se, lay.guess, lay.lower, lay.upper)],
            (None, ".6g", ".3g", ".4g", ".3g", ".3g")),))
        fit_rows = [("chi2 / dof", f"{self.chi2_per_dof:.4f} (all flights)")]
        for st, r in zip(self.flight_statistics(), self.flights):
            fit_rows.append((st["flight"], f"chi2/dof {st['chi2_per_dof']:.4g}; RMS "
                                           + ", ".join(f"{k} {v:.4g}" for k, v in st["rms"].items())
                                           + f"; sigma {r._sigma_text()}"))
        notes = list(self.notes)
        if not self.success:
            notes.insert(0, f"IPOPT did not converge: {self.message.rstrip('.')}.")
        if self.sigma_estimated:
            notes.append("sigma estimated with the parameters, each flight's separately ("
                         + "; ".join(f"{l}: {', '.join(c)}" for l, c in self.sigma_estimated.items())
                         + f"; {self.sigma_iterations} joint fits): chi2/dof is then near 1 by construction and does "
                         "not test the fit; a model error shows as a larger sigma instead.")
        notes += self.flight_notes()
        return Summary(f"rocketid joint estimation: {len(self.flights)} flights",
                       (problem, solver, params, Section("Fit per flight", fit_rows)), notes)

    @cached_property
    def alone(self) -> tuple:
        """Each flight fitted alone (its own model with its priors, started from the joint estimate):
        tuple of :class:`~rocketid.solve.EstimationResult`. Costs one fit per flight."""
        from .solve import estimate
        out = []
        for f, fl in enumerate(self.prepared.flights):
            p0 = np.clip(self.layout.flight_parameters(self.theta, f), fl.spec.lower, fl.spec.upper)
            pr = self.prepared.prepared[f]  # its data carry the joint fit's sigmas (estimated ones too)
            out.append(estimate(fl.spec, pr.measurements, guess=p0, mesh=pr.transcription.mesh))
        return tuple(out)

    def consistency(self) -> Summary:
        """The diagnosis per flight and joint: each flight's chi2/dof alone and in the joint fit.

        A flight that does not fit to the noise *alone* has an effect of its own that the model
        lacks (present in that flight only); flights that each fit alone but not together disagree
        on the shared parameters (an effect that differs between them). The excess
        ``J_f(joint) - J_f(alone)`` is what joining costs each flight; for flights that agree their
        sum is about a chi-square with (flights - 1) x (shared parameters) degrees of freedom.
        """
        rows, bad_alone = [], []
        for label, joint_r, alone_r in zip(self.labels, self.flights, self.alone):
            excess = joint_r.data_objective - alone_r.data_objective
            rows.append((label, float(alone_r.chi2_per_dof), float(joint_r.chi2_per_dof), float(excess)))
            if alone_r.chi2_per_dof > 1.5:
                bad_alone.append(label)
        dof = (len(self.labels) - 1) * len(self.layout.shared)
        total = sum(r[3] for r in rows)
        notes = []
        if bad_alone and len(bad_alone) < len(self.labels):
            notes.append(f"flight(s) {', '.join(bad_alone)} do not fit to the noise even alone, the others do: an "
                         "effect present in that flight only (diagnose it alone: `rocketid diagnose` on its file)")
        elif bad_alone:
            notes.append("no flight fits to the noise alone: the model misses an effect in every flight")
        elif dof and total > dof + 4 * math.sqrt(2 * dof):
            notes.append(f"every flight fits alone, but joining them costs 2 x {total / 2:.4g} in J (a chi-square of "
                         f"{dof} degrees of freedom would be about {dof}): the flights disagree on the shared "
                         "parameters; make the ones that differ per flight (--per-flight)")
        table = Table(("flight", "chi2/dof alone", "chi2/dof joint", "J joint - J alone"), rows,
                      (None, ".4g", ".4g", ".4g"))
        return Summary("rocketid joint diagnosis: each flight alone and in the joint fit",
                       (Section("", (table,)),), notes, rule=False)

    def flight_notes(self) -> list[str]:
        """Notes on a misfit present in some flights only (per-flight chi2/dof)."""
        chi = {l: r.chi2_per_dof for l, r in zip(self.labels, self.flights)}
        bad = [l for l, c in chi.items() if c > 1.5]
        if bad and len(bad) < len(chi):
            good = [l for l in chi if l not in bad]
            return [f"the misfit is in flight(s) {', '.join(bad)} only (chi2/dof "
                    f"{', '.join(f'{chi[l]:.3g}' for l in bad)}; {', '.join(good)} fit to the noise): an effect "
                    "present in that flight only, or an input of that flight that is wrong; diagnose it alone"]
        if bad:
            return [f"no flight fits to the noise (chi2/dof {', '.join(f'{l} {c:.3g}' for l, c in chi.items())}): the "
                    "shared model misses an effect; diagnose each flight alone to see whether it is the same one"]
        return []

    def to_dict(self) -> dict:
        try:
            se = self.standard_errors
        except SensitivityError:
            se = np.full(self.layout.n, np.nan)
        return {
            "flights": list(self.labels),
            "success": bool(self.success),
            "message": self.message,
            "parameters": {n: finite_or_none(v) for n, v in zip(self.names, self.theta)},
            "standard_errors": {n: finite_or_none(v) for n, v in zip(self.names, se)},
            "shared": list(self.layout.shared),
            "objective": finite_or_none(self.objective),
            "chi2_per_dof": finite_or_none(self.chi2_per_dof),
            "iterations": int(self.iterations),
            "per_flight": {st["flight"]: {"chi2_per_dof": finite_or_none(st["chi2_per_dof"]),
                                          "n_data": int(st["n_data"]),
                                          "rms": {k: finite_or_none(v) for k, v in st["rms"].items()}}
                           for st in self.flight_statistics()},
            "sigma": {l: {k: finite_or_none(v) for k, v in d.items()} for l, d in self.sigma.items()},
            "sigma_estimated": {l: list(c) for l, c in self.sigma_estimated.items()},
            "sigma_std": {l: {k: finite_or_none(v) for k, v in d.items()} for l, d in self.sigma_std.items()},
            **({"sigma_per_sample": per} if (per := {l: r.sigma_per_sample for l, r in zip(self.labels, self.flights)
                                                    if r.sigma_per_sample}) else {}),
            "timings": {k: float(v) for k, v in self.timings.items()},
            "notes": list(self.notes) + self.flight_notes(),
        }

    def to_json(self, path):
        from .output import write_json
        return write_json(path, self.to_dict())


def joint_estimate(flights: Sequence[Flight], *, per_flight: Sequence[str] = (),
                   guess: Mapping[str, float] | None = None, options: Mapping[str, Any] | None = None,
                   prepared: JointPrepared | None = None,
                   sigma: str | Mapping[str, float | str] | None = None,
                   sigma_rtol: float = 1e-6, max_sigma_fits: int = 30) -> JointResult:
    """Fit several flights of one vehicle at once: shared parameters, per-flight ones, one NLP.

    Parameters
    ----------
    flights : sequence of Flight
        ``Flight(label, spec, data)``: each flight's own model (inputs, initial states) and data.
        Parameters with the same name in several flights' models are shared.
    per_flight : sequence of str
        Parameter names that every flight has but that each estimates for itself (sensor
        biases). Free initial states are per flight always.
    guess : mapping, optional
        ``{joint name: value}`` over the models' guesses (``"b_h[F2]"`` for a flight's own).
    options : mapping, optional
        IPOPT options.
    prepared : JointPrepared, optional
        Reuse an assembled problem.
    sigma : "estimate" or mapping, optional
        Noise levels, the same request for every flight: ``"estimate"`` estimates every
        channel's sigma of every flight, each flight's separately (a flight's sensors and
        conditions are its own); ``{channel: value or "estimate"}`` gives some and estimates
        others. Estimation is the output-error relaxation of :func:`rocketid.solve.relax_sigma`
        on the joint problem: each flight's sigmas from its residuals, then the joint fit again
        from the last solution, until no sigma changes by more than ``sigma_rtol`` relatively.
        Default: each flight's data's sigma, else the model's.
    sigma_rtol : float
        Convergence of the relaxation (the largest relative change of a sigma).
    max_sigma_fits : int
        Give up (with a note) after this many refits.

    Returns
    -------
    JointResult
        With the estimated sigmas in :attr:`JointResult.sigma` and the flights' data
        (``prepared.prepared[f].measurements``), so that the covariance uses them.
    """
    if prepared is None:
        flights = tuple(flights)
        _check_sigma_names(sigma, [fl.data for fl in flights if isinstance(fl, Flight)])
        requests = [_flight_sigma_request(fl.data, sigma, fl.label) if isinstance(fl, Flight) else ({}, ())
                    for fl in flights]
        flights = tuple(replace(fl, data=fl.data.with_sigma(g)) if g else fl for fl, (g, _) in zip(flights, requests))
        prepared = joint_prepare(flights, per_flight=per_flight)
    else:
        _check_sigma_names(sigma, [pr.measurements for pr in prepared.prepared])
        requests = [_flight_sigma_request(pr.measurements, sigma, fl.label)
                    for fl, pr in zip(prepared.flights, prepared.prepared)]
        if any(g for g, _ in requests):
            prepared = _with_sigmas(prepared, [g for g, _ in requests])
    estimated = {fl.label: e for fl, (_, e) in zip(prepared.flights, requests) if e}
    nlp = prepared.nlp
    lay = prepared.layout
    theta0 = lay.guess.copy()
    for name, value in (guess or {}).items():
        if name not in lay.names:
            raise SettingsError(f"guess {name}: not a joint parameter; they are {', '.join(lay.names)}")
        theta0[lay.names.index(name)] = float(value)
    notes = []
    xs = []
    for f, (fl, pr) in enumerate(zip(prepared.flights, prepared.prepared)):
        p0 = lay.flight_parameters(theta0, f)
        check_guess(pr.spec, p0, where=f"flight {fl.label}", error=SettingsError)
        S, note = pr.initial_states(p0)
        if note:
            notes.append(f"flight {fl.label}: {note}")
        xs.append(pr.nlp.initial_x(S, p0))
    X0 = nlp.pack(xs, theta0)
    result = _solve_joint(prepared, X0, options, notes)
    if estimated:
        result = _relax_joint_sigma(result, estimated, options=options, rtol=sigma_rtol, max_fits=max_sigma_fits)
    return result


def _check_sigma_names(sigma, datas: Sequence[Measurements]) -> None:
    """Refuse a ``sigma=`` mapping that names a channel no flight measures."""
    if not isinstance(sigma, Mapping):
        return
    names = {n for d in datas for n in d.names}
    unknown = [k for k in sigma if k not in names]
    if unknown:
        raise DataError(f"sigma {unknown[0]}: no flight has a channel {unknown[0]!r}; the channels are "
                        f"{', '.join(sorted(names))}")


def _flight_sigma_request(data: Measurements, sigma, label: str) -> tuple[dict, tuple]:
    """``(given, estimated)`` of a ``sigma=`` request for one flight's data (channels the flight
    does not measure are left out of a mapping)."""
    from .data import resolve_quantized, sigma_request
    from .solve import check_not_per_sample

    if isinstance(sigma, Mapping):
        sigma = {k: v for k, v in sigma.items() if k in data.names}
        sigma = resolve_quantized(sigma, data)
    try:
        given, estimated = sigma_request(sigma, data.names)
        check_not_per_sample(data, estimated)
    except DataError as exc:
        raise DataError(f"flight {label}: {exc}") from None
    return given, estimated


def _with_sigmas(prepared: JointPrepared, sigmas: Sequence[Mapping[str, float]]) -> JointPrepared:
    """The joint problem with each flight's channels at the noise levels ``sigmas[f]`` (the
    flights' transcriptions are kept; their NLPs and the joint NLP are rebuilt)."""
    t0 = time.perf_counter()
    prep = tuple(pr.with_sigma(s) if s else pr for pr, s in zip(prepared.prepared, sigmas))
    nlp = JointNLP(prepared.layout, tuple(p.nlp for p in prep))
    return replace(prepared, prepared=prep, nlp=nlp, setup_s=prepared.setup_s + time.perf_counter() - t0)


def _solve_joint(prepared: JointPrepared, X0: np.ndarray, options, notes: Sequence[str]) -> JointResult:
    """Solve the joint NLP from ``X0`` and split the solution into the flights' results."""
    nlp = prepared.nlp
    sol = solve_nlp(nlp, X0, options=options)
    flights_out = []
    for f, pr in enumerate(prepared.prepared):
        cols = nlp.flight_columns(f)
        rows = nlp.flight_rows(f)
        xf = nlp.flight_x(sol.x, f)
        sub = NLPSolution(xf, sol.mult_g[rows], sol.mult_x_L[cols], sol.mult_x_U[cols], sol.status, sol.message,
                          sol.iterations, float(pr.nlp.objective(xf)), sol.solve_s)
        flights_out.append(result_of(pr, pr.nlp, sub, setup_s=prepared.setup_s))
    finite = bool(np.all(np.isfinite(sol.x)))
    return JointResult(sol.success and finite, sol.message, nlp.theta(sol.x).copy(), float(sol.objective),
                       sol.iterations, tuple(flights_out), prepared, sol,
                       {"setup_s": prepared.setup_s, "solve_s": sol.solve_s}, tuple(notes))


def _relax_joint_sigma(result: JointResult, estimated: Mapping[str, tuple], *, options, rtol: float,
                       max_fits: int) -> JointResult:
    """The output-error relaxation on the joint problem (:func:`rocketid.solve.relax_sigma`):
    each flight's estimated sigmas from its residuals at the joint fit, the joint fit again with
    them (from the last solution), until no sigma changes by more than ``rtol`` relatively."""
    from .solve import ml_sigma, relaxation

    labels = result.labels
    notes = list(result.notes)

    def sigmas_of(last):
        return {(l, c): s for l, chans in estimated.items() for c, s in ml_sigma(last.flight(l), chans).items()}

    def refit(last, new):
        per_flight = [{c: s for (fl, c), s in new.items() if fl == l} for l in labels]
        return _solve_joint(_with_sigmas(last.prepared, per_flight), last.solution.x, options, last.notes)

    current = {(l, c): result.flight(l).sigma[c] for l, chans in estimated.items() for c in chans}
    result, fits, solve_s, note = relaxation(result, sigmas_of, refit, current, rtol=rtol, max_fits=max_fits,
                                            what="joint fit")
    if note:
        notes.append(note)
    flights_out = tuple(replace(r, sigma_estimated=estimated.get(l, ()), sigma_iterations=fits if l in estimated else 0)
                        for l, r in zip(labels, result.flights))
    return replace(result, flights=flights_out, notes=tuple(notes), sigma_iterations=fits,
                   timings={"setup_s": result.prepared.setup_s, "solve_s": solve_s})
