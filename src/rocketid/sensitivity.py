"""Sensitivities and the reduced Hessian (7.6) from the KKT blocks, with one sparse LU.

At a point ``(gamma, p)`` that satisfies the collocation equations, the
equality constraints of (7.5) are ``c(gamma, p) = 0`` and ``h(gamma, p) - y = 0``.
With ``w = (gamma, y)``, the Jacobian ``J_w`` of these constraints with
respect to ``w`` is square and (for a well-posed model) non-singular::

    J_w = [ c_gamma   0 ]       J_p = [ c_p ]
          [ h_gamma  -I ]             [ h_p ]

and the null-space basis of the constraint Jacobian, ordered ``(p, gamma, y)``,
is ``Z = [I ; -J_w^{-1} J_p]`` (7.6). The reduced Hessian of the Lagrangian of
(7.5) is ``H_r = Z^T diag(0, 0, Cy^-1) Z``; the ``y`` rows of ``Z`` are the
output sensitivity ``S = dy/dp``, so ``H_r = S^T Cy^-1 S``.

:func:`sensitivity_at` factors ``J_w`` once with ``scipy.sparse.linalg.splu``
and back-solves for all parameter columns at once. It refuses, with a
:class:`~rocketid.errors.SensitivityError` that says why, where ``J_w`` is
singular or the point does not satisfy the collocation equations.

Notation
--------
===============  ===========================================================
``gamma``        state values at all nodes (the collocation variables)
``y``            outputs at all samples, all channels stacked
``S``            ``dy/dp``, shape (ny, n_p)
``dgamma/dp``    state sensitivities, shape (n_nodes, n_states, n_p)
``Cy``           diagonal noise covariance, ``diag(sigma^2)``
``H_r``          reduced Hessian (Fisher information), (n_p, n_p)
===============  ===========================================================
"""

from __future__ import annotations

import time
from dataclasses import dataclass

import numpy as np
import scipy.sparse as sps
import scipy.sparse.linalg as spla

from .errors import SensitivityError
from .nlp import CollocationNLP, ParameterTransform
from .solve import EstimationResult, Prepared

__all__ = ["Sensitivity", "sensitivity_at", "sensitivity_of", "solve_collocation"]


@dataclass(frozen=True)
class Sensitivity:
    """Output and state sensitivities and the reduced Hessian at one point.

    Attributes
    ----------
    p : ndarray, shape (n_p,)
        Where it was formed.
    parameter_names : tuple of str
    S : ndarray, shape (ny, n_p)
        Output sensitivity ``dy/dp``, channels stacked in the NLP's order.
    state_sensitivity : ndarray, shape (n_nodes, n_states, n_p)
        ``dgamma/dp`` at the mesh nodes.
    Z : ndarray, shape (n_p + n_gamma + ny, n_p)
        The null-space basis of (7.6), ordered ``(p, gamma, y)``.
    sigma : ndarray, shape (ny,)
        Noise standard deviation of each output value.
    H_r : ndarray, shape (n_p, n_p)
        Reduced Hessian ``Z^T diag(0, 0, Cy^-1) Z`` plus the priors' information: ``H_data + H_prior``.
    channel_slices : dict
        ``{channel: slice}`` into the rows of ``S``.
    gamma : ndarray
        The collocation state values used.
    formed_s : float
        Wall time of forming ``J_w``, the LU and the back-solves.
    notes : tuple of str
    H_data : ndarray, shape (n_p, n_p)
        The data's share of ``H_r``: ``S^T Cy^-1 S``.
    H_prior : ndarray, shape (n_p, n_p)
        The priors' share: ``diag(1 / sd^2)`` on the parameters with a prior (zero without priors).
    """

    p: np.ndarray
    parameter_names: tuple
    S: np.ndarray
    state_sensitivity: np.ndarray
    Z: np.ndarray
    sigma: np.ndarray
    H_r: np.ndarray
    channel_slices: dict
    gamma: np.ndarray
    formed_s: float
    notes: tuple = ()
    H_data: np.ndarray | None = None
    H_prior: np.ndarray | None = None

    def __post_init__(self):
        if self.H_data is None:
            object.__setattr__(self, "H_data", self.H_r)
        if self.H_prior is None:
            object.__setattr__(self, "H_prior", np.zeros_like(self.H_r))

    @property
    def n_parameters(self) -> int:
        return self.p.size

    def output_sensitivity(self, channel: str) -> np.ndarray:
        """Rows of ``S`` for one channel, shape (n_samples, n_p)."""
        return self.S[self.channel_slices[channel]]

    @property
    def condition_number(self) -> float:
        """``lambda_max / lambda_min`` of ``H_r`` (inf when singular)."""
        ev = np.linalg.eigvalsh(self.H_r)
        return float(ev[-1] / ev[0]) if ev[0] > 0 else float("inf")


def _full(nlp: CollocationNLP) -> CollocationNLP:
    """The untransformed NLP (7.5) of the same transcription."""
    if nlp.transform.is_identity:
        return nlp
    return nlp.with_transform(ParameterTransform.identity(nlp.spec.parameter_names))


def solve_collocation(nlp: CollocationNLP, p: np.ndarray, gamma0: np.ndarray, *, tol: float = 1e-9,
                      max_iter: int = 30) -> np.ndarray:
    """Newton's method on ``c(gamma, p) = 0`` for fixed ``p`` (a feasible point of (7.5)).

    Parameters
    ----------
    nlp : CollocationNLP
        Untransformed NLP.
    p : ndarray, shape (n_p,)
    gamma0 : ndarray, shape (n_gamma,)
        Starting state values (e.g. from a simulation at ``p``).

    Returns
    -------
    ndarray
        ``gamma`` with ``max |c| <= tol * (1 + max |gamma|)``.
    """
    lay = nlp.layout
    eq, states = lay.equality_rows, lay.state_columns
    x = lay.pack(gamma0, p)
    scale = 1.0 + np.max(np.abs(gamma0))
    for it in range(max_iter):
        c = nlp.constraints(x)[eq]
        if not np.all(np.isfinite(c)):
            raise SensitivityError("the collocation equations are not finite at this point (the trajectory left "
                                   "the model's domain); start from a feasible trajectory")
        if np.max(np.abs(c)) <= tol * scale:
            return lay.states(x)
        J = nlp.jacobian_matrix(x)[eq, states].tocsc()
        try:
            dx = spla.splu(J).solve(-c)
        except RuntimeError as exc:
            raise SensitivityError(f"the collocation Jacobian d c / d gamma is singular ({exc}); the "
                                   "discretized model has no unique trajectory at these parameters") from None
        # damped step when far away
        step = 1.0
        for _ in range(20):
            xn = lay.pack(lay.states(x) + step * dx, lay.reduced(x))
            cn = nlp.constraints(xn)[eq]
            if np.all(np.isfinite(cn)) and np.max(np.abs(cn)) < np.max(np.abs(c)) * (1 - 1e-4 * step) + tol * scale:
                break
            step *= 0.5
        x = xn
    raise SensitivityError(f"Newton's method on the collocation equations did not converge in {max_iter} "
                           "iterations: the parameters give no trajectory close to the starting one")


def sensitivity_at(prepared: Prepared, p: np.ndarray | None = None, *, gamma: np.ndarray | None = None,
                   solve: bool = True) -> Sensitivity:
    """Form ``S``, ``Z`` and ``H_r`` at parameters ``p`` (7.6).

    Parameters
    ----------
    prepared : Prepared
        The model collocated against the data (``rocketid.prepare``).
    p : ndarray, optional
        Parameters (default: the model's guess).
    gamma : ndarray, optional
        Collocation state values at ``p``; by default from a simulation at
        ``p`` refined by Newton's method on the collocation equations.
    solve : bool
        Refine ``gamma`` by Newton's method (set False only when ``gamma``
        already satisfies the equations, e.g. at a converged fit).

    Returns
    -------
    Sensitivity

    Raises
    ------
    SensitivityError
        Singular ``J_w``, or a point that does not satisfy the collocation equations.
    """
    nlp = _full(prepared.nlp)
    spec = prepared.spec
    p = spec.guess if p is None else spec.parameter_vector(p)
    if gamma is None:
        S0, _ = prepared.initial_states(p)
        gamma = S0.ravel()
    gamma = np.asarray(gamma, float)
    if solve:
        gamma = solve_collocation(nlp, p, gamma)
    else:
        c = nlp.constraints(nlp.layout.pack(gamma, p))[nlp.layout.equality_rows]
        worst = float(np.max(np.abs(c))) if c.size else 0.0
        if not worst <= 1e-6 * (1.0 + np.max(np.abs(gamma))):
            raise SensitivityError(f"the given gamma does not satisfy the collocation equations at p (max |c| = "
                                   f"{worst:.3g}): the sensitivities would be meaningless; pass solve=True to "
                                   "refine it by Newton's method")
    return _form(nlp, p, gamma)


def sensitivity_of(fit: EstimationResult) -> Sensitivity:
    """Sensitivities at a converged fit's solution (full parameter vector)."""
    nlp = _full(fit.nlp)
    gamma = fit.nlp.layout.states(fit.x)  # the transform maps only the parameters
    gamma = solve_collocation(nlp, fit.p, gamma)
    return _form(nlp, fit.p, gamma)


def _form(nlp: CollocationNLP, p: np.ndarray, gamma: np.ndarray) -> Sensitivity:
    t0 = time.perf_counter()
    lay = nlp.layout
    states, params = lay.state_columns, lay.parameter_columns
    n_p = p.size
    x = lay.pack(gamma, p)
    J = nlp.jacobian_matrix(x)[lay.equality_rows].tocsc()
    c_g, c_p = J[:, states], J[:, params]
    Hy = nlp.output_jacobian(x).tocsc()
    h_g, h_p = Hy[:, states], Hy[:, params]
    ny = Hy.shape[0]
    # the square Jacobian of (c, h - y) with respect to w = (gamma, y), and J_p
    Jw = sps.bmat([[c_g, None], [h_g, -sps.identity(ny, format="csc")]], format="csc")
    Jp = sps.vstack([c_p, h_p], format="csc")
    try:
        lu = spla.splu(Jw)
    except RuntimeError as exc:
        raise SensitivityError(
            f"the Jacobian of the collocation equations with respect to the states is singular ({exc}); "
            "the model has no unique trajectory for these parameters, so the reduced Hessian (7.6) does not exist") from None
    sol = -lu.solve(Jp.toarray())
    if not np.all(np.isfinite(sol)):
        raise SensitivityError("the back-solve with the LU factors of J_w gave non-finite values "
                               "(numerically singular Jacobian)")
    dgamma = sol[states]
    S = sol[lay.n_state_vars:]  # the rows of J_w after the states are the outputs
    Z = np.vstack([np.eye(n_p), sol])
    sigma = nlp.sigma_vector()
    Sw = S / sigma[:, None]
    H_data = Sw.T @ Sw
    H_data = 0.5 * (H_data + H_data.T)
    _, _, weight = nlp.spec.prior_arrays()
    H_prior = np.diag(weight)
    H_r = H_data + H_prior
    slices = nlp.channel_slices()
    notes = []
    colnorm = np.linalg.norm(Sw, axis=0)
    for name, cn in zip(nlp.spec.parameter_names, colnorm):
        if cn == 0 or cn < 1e-12 * max(colnorm.max(), 1e-300):
            notes.append(f"parameter {name} has no effect on the outputs (its sensitivity column is zero): "
                         "it does not enter the model's equations or outputs, or is masked")
    return Sensitivity(
        p=np.asarray(p, float).copy(), parameter_names=nlp.spec.parameter_names, S=S,
        state_sensitivity=dgamma.reshape(lay.layout.n_nodes, lay.layout.n_states, n_p), Z=Z, sigma=sigma, H_r=H_r,
        channel_slices=slices, gamma=gamma, formed_s=time.perf_counter() - t0, notes=tuple(notes), H_data=H_data,
        H_prior=H_prior)
