"""Estimability: eigen-decomposition of H_r (7.7), transformed parameters (7.8),
the modified E-optimal selection, estimation with q2 fixed (7.9), and uncertainty.

With a parameter scaling ``D`` (identity, or ``diag(nominal values)``), the
scaled reduced Hessian ``D H_r D = V diag(lambda_1 >= ... >= lambda_n) V^T``
is decomposed; the transformed parameters are ``q = V^T D^-1 p`` and
``p = D V q = D V1 q1 + D V2 q2`` (7.8). The modified E-optimal criterion
keeps ``np`` = the largest ``k`` with ``lambda_1 / lambda_k <= threshold``
(docs/estimability.md); ``q1`` (the first ``np`` directions) is estimated and
``q2`` fixed (7.9). The bounds on ``p`` become linear inequalities on ``q1``,
handled exactly by IPOPT.

Uncertainty (beyond the chapter): at a (7.9) solution, the covariance of
``q1`` is ``(P^T H_r P)^-1`` with ``P = D V1`` and ``H_r`` formed at the
estimate; ``Cov(p) = P Cov(q1) P^T`` (rank ``np``: the fixed directions
carry no statistical uncertainty, only the bias of their fixed values).
"""

from __future__ import annotations

import enum
import math
import time
from dataclasses import dataclass, replace
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from .errors import SensitivityError, SettingsError
from .nlp import ParameterTransform
from .output import finite_or_none
from .sensitivity import Sensitivity, SolutionPredictor, sensitivity_at, sensitivity_of
from .solve import DEFAULT_IPOPT, EstimationResult, Prepared, fit_nlp
from .summary import Section, Summary, Table, Text

__all__ = ["Scaling", "Estimability", "analyze", "estimate_q1", "Uncertainty", "uncertainty",
           "DEFAULT_THRESHOLD"]

DEFAULT_THRESHOLD = 3000.0


class Scaling(str, enum.Enum):
    """Parameter scaling before the eigen-decomposition (an explicit, reported setting)."""

    NONE = "none"
    NOMINAL = "nominal"

    @classmethod
    def parse(cls, value: "Scaling | str") -> "Scaling":
        if isinstance(value, cls):
            return value
        try:
            return cls(str(value).lower())
        except ValueError:
            raise SettingsError(f"unknown scaling {value!r}; choose one of "
                                f"{', '.join(s.value for s in cls)}") from None


@dataclass(frozen=True)
class Estimability:
    """The estimability analysis at one point: eigenvalues, directions, np.

    Attributes
    ----------
    eigenvalues : ndarray, shape (n_p,)
        Of the (scaled) reduced Hessian, descending.
    V : ndarray, shape (n_p, n_p)
        Orthonormal eigenvectors (columns), in scaled coordinates.
    D : ndarray, shape (n_p,)
        The scaling: ``p = D * p_scaled``.
    ratios : ndarray, shape (n_p,)
        ``lambda_1 / lambda_k``.
    n_estimated : int
        ``np``.
    threshold : float
    scaling : Scaling
    parameter_names : tuple of str
    evaluated_at : ndarray, shape (n_p,)
        The point where H_r was formed.
    sensitivity : Sensitivity
    notes : tuple of str
    """

    eigenvalues: np.ndarray
    V: np.ndarray
    D: np.ndarray
    ratios: np.ndarray
    n_estimated: int
    threshold: float
    scaling: Scaling
    parameter_names: tuple
    evaluated_at: np.ndarray
    sensitivity: Sensitivity
    notes: tuple = ()

    # ---- transformed parameters (7.8)
    @property
    def V1(self) -> np.ndarray:
        """Physical directions of the estimated ``q1``: ``p = P1 q1 + P2 q2``, ``P1 = D V1``."""
        return self.D[:, None] * self.V[:, : self.n_estimated]

    @property
    def V2(self) -> np.ndarray:
        """``P2 = D V2``: physical directions of the fixed ``q2``."""
        return self.D[:, None] * self.V[:, self.n_estimated:]

    def q_of(self, p: Sequence[float]) -> np.ndarray:
        """``q = V^T D^-1 p`` (7.8)."""
        return self.V.T @ (np.asarray(p, float) / self.D)

    def p_of(self, q: Sequence[float]) -> np.ndarray:
        """``p = D V q``."""
        return self.D * (self.V @ np.asarray(q, float))

    def q2_of(self, p: Sequence[float]) -> np.ndarray:
        """The fixed part ``q2 = V2^T D^-1 p`` of a parameter vector (step 5 of the algorithm)."""
        return self.q_of(p)[self.n_estimated:]

    def transform(self, q2: Sequence[float]) -> ParameterTransform:
        """``p = D V1 q1 + D V2 q2``: the parameter transform of (7.9) for fixed ``q2``."""
        q2 = np.asarray(q2, float)
        if q2.shape != (self.eigenvalues.size - self.n_estimated,):
            raise SettingsError(f"q2 must have {self.eigenvalues.size - self.n_estimated} values, got {q2.shape}")
        return ParameterTransform(self.V1, self.V2 @ q2, tuple(f"q{i + 1}" for i in range(self.n_estimated)))

    def composition(self) -> np.ndarray:
        """Share of each physical parameter in each direction: ``V[i, k]^2``
        (columns sum to 1), shape (n_p, n_p)."""
        return self.V ** 2

    # ---- reports
    def table(self) -> str:
        """Eigenvalues, ratios, and each direction's main parameters (text of :meth:`directions_table`)."""
        return "\n".join(self.directions_table().text_lines())

    @property
    def has_priors(self) -> bool:
        """Whether priors contribute to H_r (then :meth:`data_share` tells the data's part)."""
        return bool(np.any(self.sensitivity.H_prior))

    def data_share(self) -> np.ndarray:
        """The data's share of each direction's information: ``v_k^T D H_data D v_k / lambda_k``
        (1 without priors; near 0 where the direction is known from the priors alone), shape (n_p,)."""
        Hd = self.D[:, None] * self.sensitivity.H_data * self.D[None, :]
        num = np.einsum("ik,ij,jk->k", self.V, Hd, self.V)
        with np.errstate(divide="ignore", invalid="ignore"):
            return np.where(self.eigenvalues > 0, num / self.eigenvalues, np.nan)

    def directions_table(self) -> Table:
        """Eigenvalues, ratios, and each direction's main parameters, as a :class:`~rocketid.summary.Table`
        (with the data's share of each eigenvalue when the model has priors)."""
        comp = self.composition()
        share = self.data_share() if self.has_priors else None
        rows = []
        for k, (lam, r) in enumerate(zip(self.eigenvalues, self.ratios)):
            order = np.argsort(comp[:, k])[::-1]
            parts = [f"{self.parameter_names[i]} {100 * comp[i, k]:.0f}%{'-' if self.V[i, k] < 0 else '+'}"
                     for i in order if comp[i, k] >= 0.05][:4]
            row = (f"q{k + 1}", float(lam), float(r), "estimated" if k < self.n_estimated else "fixed")
            if share is not None:
                row += (f"{100 * share[k]:.0f}%",)
            rows.append(row + (", ".join(parts),))
        head = ("dir", "eigenvalue", "ratio", "") + (("data share",) if share is not None else ())
        return Table(head + ("composition (share of each parameter)",), rows, (None, ".4g", ".4g"))

    def summary(self) -> Summary:
        """Setting, np, table, numbered notes."""
        setting = Section("", (
            ("scaling", self.scaling.value + (" (p divided by its nominal value)" if self.scaling is Scaling.NOMINAL
                                              else " (physical units)")),
            ("threshold", f"{self.threshold:g} (np = largest k with lambda_1/lambda_k <= threshold)"),
            ("np", f"{self.n_estimated} of {self.eigenvalues.size} directions estimated"),
            ("evaluated at", ", ".join(f"{n}={v:.4g}" for n, v in zip(self.parameter_names, self.evaluated_at))),
            ("H_r formed in", f"{self.sensitivity.formed_s:.3f} s")))
        return Summary("rocketid estimability (reduced Hessian, modified E-optimal criterion)",
                       (setting, Section("Directions", (self.directions_table(),))), self.notes)

    def to_dict(self) -> dict:
        return {
            "eigenvalues": [float(v) for v in self.eigenvalues],
            # lambda_1 / lambda_k is infinite where lambda_k <= 0: null, not NaN (invalid JSON)
            "ratios": [float(v) if np.isfinite(v) else None for v in self.ratios],
            "np": int(self.n_estimated),
            "scaling": self.scaling.value,
            "threshold": float(self.threshold),
            "evaluated_at": {n: float(v) for n, v in zip(self.parameter_names, self.evaluated_at)},
            "parameter_names": list(self.parameter_names),
            "directions": [{"name": f"q{k + 1}", "estimated": k < self.n_estimated,
                            "vector": {n: float(self.V[i, k]) for i, n in enumerate(self.parameter_names)}}
                           for k in range(self.eigenvalues.size)],
            "notes": list(self.notes),
            **({"data_share": [finite_or_none(v) for v in self.data_share()]} if self.has_priors else {}),
        }

    def to_json(self, path) -> Path:
        from .output import write_json
        return write_json(path, self.to_dict())

    def plot_spectrum(self, ax=None):
        """The eigenvalues of H_r (estimated directions in blue) and the threshold line.

        Parameters
        ----------
        ax : matplotlib Axes, optional
            Where to draw (default: a new figure's axes).

        Returns
        -------
        matplotlib Axes
        """
        ax = _axes(ax, (5.5, 4.2))
        k = np.arange(1, self.eigenvalues.size + 1)
        colors = ["tab:blue" if i < self.n_estimated else "tab:gray" for i in range(k.size)]
        ax.bar(k, self.eigenvalues, color=colors)
        ax.set_yscale("log")
        ax.axhline(self.eigenvalues[0] / self.threshold, color="tab:red", ls="--",
                   label=f"lambda_1 / {self.threshold:g}")
        ax.set_xlabel("direction k")
        ax.set_ylabel("eigenvalue of H_r" + (" (scaled)" if self.scaling is Scaling.NOMINAL else ""))
        ax.set_title(f"np = {self.n_estimated} (scaling: {self.scaling.value})")
        ax.legend()
        return ax

    def plot_directions(self, ax=None):
        """The directions ``V[i, k]`` as a heat map (parameters by directions), with a colour bar.

        Parameters
        ----------
        ax : matplotlib Axes, optional

        Returns
        -------
        matplotlib Axes
        """
        ax = _axes(ax, (5.5, 4.2))
        n = self.eigenvalues.size
        im = ax.imshow(self.V, cmap="RdBu_r", vmin=-1, vmax=1, aspect="auto")
        ax.set_xticks(range(n), [f"q{i}" for i in range(1, n + 1)])
        ax.set_yticks(range(n), self.parameter_names)
        ax.set_title("directions: V[i, k]")
        ax.figure.colorbar(im, ax=ax)
        return ax

    def plot(self, path=None):
        """Eigenvalue spectrum with the threshold, and the composition of each direction
        (:meth:`plot_spectrum` and :meth:`plot_directions` side by side); returns the
        figure, saved to ``path`` when given. The matplotlib backend is left alone."""
        from matplotlib.figure import Figure
        fig = Figure(figsize=(11, 4.2))
        a1, a2 = fig.subplots(1, 2)
        self.plot_spectrum(a1)
        self.plot_directions(a2)
        fig.tight_layout()
        if path is not None:
            from .output import save_figure
            save_figure(fig, path, dpi=120)
        return fig


def _axes(ax, figsize):
    """``ax``, or the axes of a new figure (not registered with pyplot: no backend is touched)."""
    if ax is not None:
        return ax
    from .output import new_axes
    return new_axes(figsize)


def select_np(eigenvalues: np.ndarray, threshold: float) -> int:
    """The modified E-optimal criterion: largest k with lambda_1/lambda_k <= threshold."""
    threshold = float(threshold)
    if not threshold > 1 or math.isnan(threshold):
        raise SettingsError(f"the threshold of the modified E-optimal criterion must exceed 1, got {threshold:g} "
                            "(the chapter uses 3000)")
    lam = np.asarray(eigenvalues, float)
    if lam[0] <= 0:
        return 0
    ok = (lam > 0) & (lam[0] / np.where(lam > 0, lam, np.inf) <= threshold)
    return int(np.max(np.flatnonzero(ok)) + 1)


def analyze(prepared: Prepared, p: Sequence[float] | Mapping | None = None, *, threshold: float = DEFAULT_THRESHOLD,
            scaling: Scaling | str = Scaling.NONE, n_estimated: int | None = None,
            sensitivity: Sensitivity | None = None) -> Estimability:
    """Steps 2-3 of the algorithm: H_r at ``p``, eigen-decomposition, ``np``.

    Parameters
    ----------
    prepared : Prepared
    p : optional
        Where to form H_r (default: the model's guess p0).
    threshold : float
        Condition-number threshold (> 1), default 3000.
    scaling : {"none", "nominal"}
        Scale parameters by their nominal values before decomposing.
    n_estimated : int, optional
        Force ``np`` (1 .. n_p) instead of the criterion.
    sensitivity : Sensitivity, optional
        Reuse sensitivities already formed at ``p``.
    """
    scaling = Scaling.parse(scaling)
    spec = prepared.spec
    n_p = len(spec.parameters)
    pv = spec.parameter_vector(p)
    if n_estimated is not None and not (isinstance(n_estimated, (int, np.integer)) and 1 <= n_estimated <= n_p):
        raise SettingsError(f"np must be an integer from 1 to {n_p} (the number of parameters), got {n_estimated!r}")
    sens = sensitivity if sensitivity is not None else sensitivity_at(prepared, pv)
    D = spec.nominal.copy() if scaling is Scaling.NOMINAL else np.ones(n_p)
    if np.any(D == 0):
        raise SettingsError("nominal scaling needs non-zero nominal values for every parameter")
    Hs = D[:, None] * sens.H_r * D[None, :]
    lam, V = np.linalg.eigh(Hs)
    lam, V = lam[::-1], V[:, ::-1]
    # deterministic sign: the largest-magnitude component of each direction is positive
    sign = np.sign(V[np.argmax(np.abs(V), axis=0), np.arange(n_p)])
    V = V * np.where(sign == 0, 1.0, sign)
    lam_pos = np.where(lam > 0, lam, np.nan)
    ratios = lam[0] / lam_pos
    chosen = select_np(lam, threshold) if n_estimated is None else int(n_estimated)
    notes = list(sens.notes)
    if lam[-1] <= max(lam[0], 1e-300) * 1e-14:
        notes.append(f"H_r is singular (smallest eigenvalue {lam[-1]:.3g}): some direction of the parameters has "
                     "no effect on the outputs")
    if n_estimated is not None:
        notes.append(f"np = {chosen} was forced (the criterion with threshold {threshold:g} gives "
                     f"{select_np(lam, threshold)})")
    if chosen == 0:
        notes.append("no direction passes the criterion: nothing can be estimated from these data")
    return Estimability(lam, V, D, ratios, chosen, float(threshold), scaling, spec.parameter_names, pv, sens,
                        tuple(notes))


def estimate_q1(prepared: Prepared, est: Estimability, q2: Sequence[float], *,
                warm_start: EstimationResult | None = None, options: Mapping[str, Any] | None = None,
                nlp=None, predictor: SolutionPredictor | None = None) -> EstimationResult:
    """Solve (7.9): estimate ``q1`` with ``q2`` fixed; ``p = D V1 q1 + D V2 q2``.

    Parameters
    ----------
    prepared : Prepared
    est : Estimability
    q2 : sequence of float
        The fixed transformed parameters (``est.q2_of(p_trial)``).
    warm_start : EstimationResult, optional
        A previous (7.9) solution with the same ``V1``: its primal and dual
        values start IPOPT (the sampling loop's fast path).
    nlp : CollocationNLP, optional
        A transformed NLP with the same ``V1`` to re-offset (saves set-up).
    predictor : SolutionPredictor, optional
        The KKT factors at ``warm_start``'s solution (``SolutionPredictor.at(warm_start.nlp,
        warm_start.solution)``): IPOPT starts from the predicted solution of the new problem
        (primal and multipliers) instead of the previous one, and usually accepts it at once.
        A solution that crosses a bound of ``p`` is predicted with that bound held active (1
        IPOPT iteration from it, against 4-8 from ``warm_start``); a prediction that still
        leaves the bounds is not used (IPOPT starts from ``warm_start``). The estimate is
        IPOPT's either way; ignored without ``warm_start``.

    Returns
    -------
    EstimationResult
        Its ``p`` is the full physical vector implied by ``q1`` and ``q2``.
    """
    t0 = time.perf_counter()
    tf = est.transform(q2)
    if nlp is None:
        if warm_start is not None and warm_start.nlp.transform.P.shape == tf.P.shape \
                and np.array_equal(warm_start.nlp.transform.P, tf.P):
            nlp = warm_start.nlp.with_offset(tf.c)
        else:
            nlp = prepared.nlp.with_transform(tf)
    else:
        nlp = nlp.with_offset(tf.c)
    setup = time.perf_counter() - t0
    spec = prepared.spec
    notes = []
    if warm_start is not None:
        # keep the states, move q1 to the least-squares fit of the previous p
        x0 = nlp.layout.with_parameters(warm_start.x, warm_start.p)
        warm = warm_start.solution
        if predictor is not None:
            if predictor.solution is not warm:
                raise SettingsError("the predictor was formed at another solution than warm_start's")
            pred = predictor.predict(nlp, tol=float((options or {}).get("tol", DEFAULT_IPOPT["tol"])))
            if pred is not None and pred.feasible:  # else from the reference: fewer iterations
                x0 = pred.x
                warm = replace(warm, x=pred.x, mult_g=pred.mult_g)

        def cold_start():
            p = np.clip(nlp.layout.parameters(x0), spec.lower, spec.upper)
            S, _ = prepared.initial_states(p)
            return nlp.initial_x(S, p)
    else:
        p_start = est.p_of(np.concatenate([est.q_of(est.evaluated_at)[: est.n_estimated], q2]))
        S, note = prepared.initial_states(np.clip(p_start, spec.lower, spec.upper))
        if note:
            notes.append(note)
        x0 = nlp.initial_x(S, p_start)
        warm = cold_start = None
    return fit_nlp(prepared, nlp, x0, options=options, warm=warm, cold_start=cold_start, setup_s=setup, notes=notes)


@dataclass(frozen=True)
class Uncertainty:
    """Covariance, standard errors and correlations of an estimate.

    Attributes
    ----------
    names : tuple of str
        Estimated quantities (``q1..`` or the parameter names).
    covariance : ndarray
        Of the estimated quantities.
    parameter_covariance : ndarray, shape (n_p, n_p)
        Of the physical parameters they imply (rank ``np``).
    standard_errors : ndarray, shape (n_p,)
        Of the physical parameters.
    correlations : ndarray, shape (n_p, n_p)
    condition_number : float
        Of the restricted H_r.
    notes : tuple of str
    """

    names: tuple
    covariance: np.ndarray
    parameter_names: tuple
    parameter_covariance: np.ndarray
    standard_errors: np.ndarray
    correlations: np.ndarray
    condition_number: float
    estimates: np.ndarray
    notes: tuple = ()

    def interval(self, level: float = 0.95) -> np.ndarray:
        """Two-sided confidence intervals of the physical parameters, shape (n_p, 2)."""
        from scipy.stats import norm
        z = norm.ppf(0.5 + level / 2)
        return np.stack([self.estimates - z * self.standard_errors, self.estimates + z * self.standard_errors], 1)

    def summary(self) -> Summary:
        """The estimates with standard errors and 95 % intervals; numbered notes."""
        table = Table(("name", "estimate", "std err", "95% interval"),
                      [(n, float(v), float(s), f"[{a:.5g}, {b:.5g}]") for n, v, s, (a, b) in
                       zip(self.parameter_names, self.estimates, self.standard_errors, self.interval())],
                      (None, ".6g", ".3g"))
        return Summary("Uncertainty (from the reduced Hessian at the estimate)",
                       (Section("", (table, Text(f"condition number of the restricted H_r: "
                                                 f"{self.condition_number:.3g}"))),), self.notes, rule=False)


def coloured_score_covariance(fit: EstimationResult, sens: Sensitivity) -> tuple[np.ndarray, dict[str, int]]:
    """The long-run covariance of the likelihood's score, for residuals correlated in time.

    Per channel, with the weighted sensitivities ``s_i = S_i / sigma_i`` and residuals ``e_i = r_i /
    sigma_i`` at its samples in time order, the score terms ``g_i = s_i e_i`` are summed with Bartlett
    weights over lags ``|k| <= L``: ``B_c = sum_k (1 - |k|/(L+1)) sum_i g_i g_{i+k}'`` (Newey and West 1987;
    positive semi-definite). ``L`` follows Andrews' (1991) AR(1) plug-in for the Bartlett kernel,
    ``L = 1.1447 (4 rho^2 / (1 - rho^2)^2 n)^(1/3)``, ``rho`` the channel's lag-1 residual autocorrelation,
    at most ``n / 4``. Channels are taken as independent of each other (they are different sensors); the
    priors' information is added as it is (a prior is a pseudo-measurement with white noise). With
    white residuals at the stated sigma, ``B`` estimates ``H_data`` (the information); Morelli and Klein's
    correction of output-error bounds for coloured residuals is the same sandwich with all lags.

    Returns
    -------
    B : ndarray, shape (n_p, n_p)
    lags : dict
        ``{channel: L}``.
    """
    n_p = sens.S.shape[1]
    B = np.zeros((n_p, n_p))
    lags = {}
    res = fit.residuals
    for name, rows in sens.channel_slices.items():
        e = np.asarray(res[name], float) / sens.sigma[rows]      # a channel's samples are in time order
        s = sens.S[rows] / sens.sigma[rows][:, None]
        n = e.size
        g = s * e[:, None]
        rho = float(np.dot(e[:-1], e[1:]) / np.dot(e, e)) if n > 2 and np.dot(e, e) > 0 else 0.0
        rho = min(max(rho, 0.0), 0.99)
        L = int(min(n // 4, np.floor(1.1447 * (4 * rho ** 2 / (1 - rho ** 2) ** 2 * n) ** (1 / 3)))) if rho > 0 else 0
        Bc = g.T @ g
        for k in range(1, L + 1):
            G = g[:-k].T @ g[k:]
            Bc += (1 - k / (L + 1)) * (G + G.T)
        B += Bc
        lags[name] = L
    B += sens.H_prior                                        # zeros without priors
    return 0.5 * (B + B.T), lags


def uncertainty(fit: EstimationResult, *, sensitivity: Sensitivity | None = None,
                ill_conditioned: float = 1e10, coloured: bool = False) -> Uncertainty:
    """Covariance of the estimated quantities and of the physical parameters.

    For a full estimation ``Cov(p) = H_r^-1``; for (7.9) ``Cov(q1) =
    (P^T H_r P)^-1`` with ``P = D V1`` and ``Cov(p) = P Cov(q1) P^T``. H_r is
    formed at the estimate. A note is added where a bound is active (the
    interval is then not valid on that side) or the restricted H_r is
    ill-conditioned.

    ``coloured=True``: the covariance corrected for residuals correlated in time (a broadcast readout's
    errors that last a second, turbulence, a sensor's filter), the sandwich ``H^-1 B H^-1`` with ``B`` the
    long-run covariance of the score (:func:`coloured_score_covariance`) in place of ``H``. With white
    residuals at the stated sigma it gives the same standard errors to sampling error; with coloured ones
    the white-noise errors are too small by about the square root of the residuals' correlation time in
    samples.
    """
    sens = sensitivity if sensitivity is not None else sensitivity_of(fit)
    P = fit.nlp.transform.P
    Hq = P.T @ sens.H_r @ P
    notes = []
    ev = np.linalg.eigvalsh(Hq) if Hq.size else np.array([1.0])
    cond = float(ev[-1] / ev[0]) if ev[0] > 0 else float("inf")
    if not np.isfinite(cond) or ev[0] <= 0:
        raise SensitivityError("the reduced Hessian restricted to the estimated directions is singular: the "
                               "estimated quantities are not identifiable from these data")
    if cond > ill_conditioned:
        notes.append(f"the restricted reduced Hessian is ill-conditioned (condition number {cond:.3g}): the "
                     "standard errors of the weakest directions are unreliable")
    Cq = np.linalg.inv(Hq)
    Cq = 0.5 * (Cq + Cq.T)
    if coloured:
        B, lags = coloured_score_covariance(fit, sens)
        Cq = Cq @ (P.T @ B @ P) @ Cq
        Cq = 0.5 * (Cq + Cq.T)
        notes.append("standard errors corrected for coloured residuals (sandwich H^-1 B H^-1, B the long-run "
                     "covariance of the score with Bartlett weights over " +
                     ", ".join(f"{lag} lags of {c}" for c, lag in lags.items()) + ")")
    Cp = P @ Cq @ P.T
    se = np.sqrt(np.clip(np.diag(Cp), 0, None))
    with np.errstate(invalid="ignore", divide="ignore"):
        corr = Cp / np.outer(se, se)
    spec = fit.spec
    for s, side in fit.active_bounds():
        notes.append(f"{s} is at its {side} bound: its interval is not valid on that side")
    if not fit.nlp.transform.is_identity:
        # linear bound rows of (7.9) that are active
        lo, hi = spec.lower, spec.upper
        for name, v, a, b in zip(spec.parameter_names, fit.p, lo, hi):
            if (np.isfinite(a) and v - a < 1e-7 * max(1, abs(a))) or (np.isfinite(b) and b - v < 1e-7 * max(1, abs(b))):
                note = f"{name} is at a bound in (7.9): its linear bound constraint is active"
                if note not in notes:
                    notes.append(note)
    if not coloured and (fit.chi2_per_dof > 1.5 or fit.chi2_per_dof < 0.67):
        notes.append(f"chi2/dof = {fit.chi2_per_dof:.3g}: the stated noise sigma does not match the residuals, "
                     "so these standard errors (which assume the stated sigma) are off by about "
                     f"sqrt({fit.chi2_per_dof:.3g})")
    return Uncertainty(tuple(fit.nlp.transform.names), Cq, spec.parameter_names, Cp, se, corr, cond,
                       np.asarray(fit.p, float), tuple(notes))
