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
from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sps
import scipy.sparse.linalg as spla

from .errors import SensitivityError
from .nlp import CollocationNLP, ParameterTransform
from .solve import EstimationResult, NLPSolution, Prepared

__all__ = ["Sensitivity", "sensitivity_at", "sensitivity_of", "solve_collocation", "SolutionPredictor", "Prediction",
           "SolutionSurface"]


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


# ---------------------------------------------------------------------------
# Parametric sensitivity of a solution to the offset: the sampling draw's predictor
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class Prediction:
    """A predicted primal-dual point of a re-offset NLP (:meth:`SolutionPredictor.predict`).

    Attributes
    ----------
    x : ndarray, shape (n,)
        Primal point.
    mult_g : ndarray, shape (m,)
        Constraint multipliers (IPOPT's sign: the Lagrangian is ``f + mult_g^T c``).
    steps : int
        Back-solves with the reference factors (1: the first-order prediction alone).
    primal, dual : float
        ``max |c_eq|`` and ``max |grad f + J^T mult_g|`` at ``x``.
    converged : bool
        Both are within the tolerances IPOPT applies (:meth:`SolutionPredictor.predict`).
    feasible : bool
        ``x`` is within the variable bounds and the inequality rows (the bounds of ``p`` as
        linear rows in (7.9)) within theirs. A prediction that crosses a bound is a poor start
        (IPOPT needed 10-18 iterations from it against 4-8 from the reference solution: RA-66,
        10 of 300 draws); :meth:`SolutionPredictor.predict` then predicts again with the crossed
        rows held on their bounds (``active``), and only a point that still leaves the bounds is
        not feasible (the sampling starts such a draw from the reference).
    from_surface : bool
        The steps started from the learnt solution surface (:meth:`SolutionPredictor.learn`),
        not from the reference solution.
    active : tuple of int
        Inequality rows (indices within ``layout.linear_rows``) held on their bounds: the
        prediction with an active set (empty: none crossed).
    """

    x: np.ndarray
    mult_g: np.ndarray
    steps: int
    primal: float
    dual: float
    converged: bool
    feasible: bool = True
    from_surface: bool = False
    active: tuple = ()


@dataclass(frozen=True, eq=False)
class SolutionPredictor:
    """The KKT matrix of an NLP factorized at a converged solution, to predict the solution
    of the same NLP with another offset ``c`` (:meth:`~rocketid.nlp.CollocationNLP.with_offset`).

    The sampling loop re-solves (7.9) for many values of the fixed ``q2``, that is of the
    offset ``c = D V2 q2``. At the reference solution ``z = (x, lambda)`` the KKT conditions
    of the equality-constrained problem ``r(z; c) = [grad f + J^T lambda ; c_eq(x)] = 0`` hold;
    for a new offset the first-order change of the solution is ``dz = -K^{-1} r(z; c_new)``
    with the KKT matrix ``K = [[H, J^T], [J, 0]]`` (``H`` the Lagrangian Hessian, ``J`` the
    equality rows of the Jacobian): the parametric sensitivity (sIPOPT's) to ``c``, up to
    terms of second order in ``c_new - c``. :meth:`predict` takes that step and repeats it
    with the same factors (a simplified Newton iteration on the new KKT conditions) until
    the point meets IPOPT's tolerances. IPOPT then starts from it (primal and multipliers)
    and makes the solution of record: it stops at iteration 0 when its own test accepts the
    prediction, and iterates from it otherwise.

    The inequality rows (the bounds of ``p`` as linear rows in (7.9)) keep their multipliers
    from the reference: away from the bounds they are of the order of IPOPT's final barrier
    parameter. A prediction that crosses a bound is predicted again with the crossed rows held
    on their bounds (an active set: the rows as equalities, their multipliers solved for).

    Attributes
    ----------
    nlp : CollocationNLP
        The NLP at the reference offset.
    solution : NLPSolution
        Its converged solution.
    lu : object
        Factors of ``K`` at the solution, with a ``solve(b)`` method: banded LU with the
        parameters as a border where ``K`` is banded in the reverse Cuthill-McKee order of
        the other unknowns (collocation is: about 50 for RA-66), else SuperLU.
    formed_s : float
        Wall time of forming and factorizing ``K``.
    surface : SolutionSurface or None
        The solution as a polynomial in the offset, learnt from solutions at sample offsets
        (:meth:`learn`): where it applies, the steps start from its value instead of from the
        reference solution.
    """

    nlp: CollocationNLP
    solution: NLPSolution
    lu: object
    formed_s: float
    surface: "SolutionSurface | None" = None

    #: Back-solves at most per prediction.
    MAX_STEPS = 8

    @classmethod
    def at(cls, nlp: CollocationNLP, solution: NLPSolution) -> "SolutionPredictor":
        """Factorize the KKT matrix of ``nlp`` at ``solution``.

        Raises
        ------
        SensitivityError
            The solution did not converge, or ``K`` is singular (no unique nearby solution).
        """
        if not solution.success:
            raise SensitivityError(f"the reference solve did not converge ({solution.message}): its KKT matrix "
                                   "predicts nothing")
        t0 = time.perf_counter()
        x, lam = solution.x, solution.mult_g
        n, eq = nlp.n, nlp.layout.equality_rows
        hr, hc = nlp.hessianstructure()
        H = sps.csr_matrix((nlp.hessian(x, lam, 1.0), (hr, hc)), shape=(n, n))
        H = H + sps.tril(H, -1).T
        J = nlp.jacobian_matrix(x)[eq]
        K = sps.bmat([[H, J.T], [J, None]], format="csc")
        p_cols = np.arange(n)[nlp.layout.parameter_columns]
        lu = _BorderedBanded.factor(K, p_cols)
        if lu is None:
            try:
                lu = spla.splu(K)
            except RuntimeError as exc:
                raise SensitivityError(f"the KKT matrix at the reference solution is singular ({exc}): the solution "
                                       "is not an isolated minimum, so it cannot predict nearby ones") from None
        return cls(nlp, solution, lu, time.perf_counter() - t0)

    def residual(self, nlp: CollocationNLP, x: np.ndarray, mult_g: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(grad f + J^T mult_g, c_eq)`` of ``nlp`` at ``(x, mult_g)``: the KKT residual."""
        st = nlp.structure
        jac = nlp.jacobian(x)
        dual = nlp.gradient(x) + np.bincount(st.jac_cols, weights=jac * mult_g[st.jac_rows], minlength=nlp.n)
        eq = nlp.layout.equality_rows
        primal = nlp.constraints(x)[eq] - nlp.c_lower[eq]
        return dual, primal

    def predict(self, nlp: CollocationNLP, *, tol: float = 1e-8, max_steps: int | None = None,
                hold: bool = True) -> Prediction | None:
        """The predicted solution of ``nlp`` (this predictor's NLP at another offset).

        Steps with the reference factors, from the learnt surface's value where it applies
        (:meth:`learn`; from the reference solution when those steps do not converge) or
        from the reference solution, at most ``max_steps`` times (default :attr:`MAX_STEPS`; 1
        gives the first-order prediction alone). A point is converged within IPOPT's
        tolerances, ``max |c_eq| <= tol / 10`` and ``max |grad f + J^T lambda| <= min(1, tol *
        s_d)``, where ``s_d = max(1, mean |lambda| / 100)`` is IPOPT's dual scaling (IPOPT's
        own test uses the scaled problem, whose values are at most these). The steps aim at a
        tenth of the dual one (at the tolerance itself, 21 of 100 starts from the learnt
        surface met the test and IPOPT still took an iteration from them) and stop short of
        it where the dual residual stops falling (:meth:`_judge`: its rounding level). They
        keep the converged point with the smallest dual residual, or failing one the point
        with the smallest constraint violation. A point that crosses a bound of ``p`` is
        predicted again with the crossed rows held on their bounds (``hold``;
        :attr:`Prediction.active`).

        Returns
        -------
        Prediction or None
            None when the NLP has another structure or the steps give non-finite values
            (start IPOPT from the reference then).
        """
        ref = self.nlp
        if nlp.structure is not ref.structure or nlp.n != ref.n or nlp.m != ref.m:
            return None
        max_steps = self.MAX_STEPS if max_steps is None else int(max_steps)
        if self.surface is not None:
            z = self.surface.start(nlp.transform.c)
            if z is not None:
                lam = np.array(self.solution.mult_g, dtype=float)
                lam[:nlp.layout.equality_rows.stop] = z[nlp.n:]
                best = self._steps(nlp, z[:nlp.n], lam, tol, max_steps)
                if best is not None and best.converged:
                    return self._finish(nlp, replace(best, from_surface=True), tol, hold)
        best = self._steps(nlp, np.array(self.solution.x, dtype=float), np.array(self.solution.mult_g, dtype=float),
                           tol, max_steps)
        if best is None or best.steps == 0:
            return None
        return self._finish(nlp, best, tol, hold)

    def _finish(self, nlp: CollocationNLP, best: Prediction, tol: float, hold: bool = True) -> Prediction:
        best = replace(best, mult_g=self._inequality_multipliers(nlp, best.x, best.mult_g),
                       feasible=self._within_bounds(nlp, best.x))
        if best.feasible or not best.converged or not hold:
            return best
        held = self._on_bounds(nlp, best, tol)
        return best if held is None else held

    #: Rounds of the active set: a held row whose multiplier has the wrong sign is released.
    ACTIVE_ROUNDS = 3

    def _on_bounds(self, nlp: CollocationNLP, best: Prediction, tol: float) -> Prediction | None:
        """The prediction with the inequality rows that ``best`` crosses held on their bounds.

        The solution of the re-offset NLP then has those bounds active: the steps solve the
        KKT conditions with the held rows as equalities, ``[[K, B], [B^T, 0]]`` with ``B`` the
        rows (``K``'s reference factors and their Schur complement, one back-solve per held row
        and per step). A held row whose multiplier comes out with the wrong sign (IPOPT's: <= 0
        on a lower bound, >= 0 on an upper) is released and the rest held again
        (:attr:`ACTIVE_ROUNDS`). None when a variable bound is crossed, the steps do not meet
        the tolerances of :meth:`predict`, or the point still leaves a bound. (RA-66, the
        study's run 1: the 10 of 300 draws whose prediction crosses a bound of ``p`` take 1
        IPOPT iteration from this point against 4-8 from the reference solution,
        ``benchmarks/bench_draw_bounds.py``.)"""
        rows = nlp.layout.linear_rows
        if rows.stop == rows.start or np.any(best.x < nlp.x_lower) or np.any(best.x > nlp.x_upper):
            return None
        A = nlp.structure.A_lin
        lo, hi = nlp.c_lower[rows], nlp.c_upper[rows]
        a = A @ best.x
        held = np.flatnonzero((a < lo) | (a > hi))
        lower = a[held] < lo[held]
        meq = nlp.layout.equality_rows.stop
        dual_tol, primal_tol = self._tolerances(tol)
        for _ in range(self.ACTIVE_ROUNDS):
            if held.size == 0:
                return None
            got = self._held_steps(nlp, best, held, np.where(lower, lo[held], hi[held]), dual_tol, primal_tol)
            if got is None:
                return None
            x, lam, mu, steps = got
            wrong = (lower & (mu > 0)) | (~lower & (mu < 0))
            if not wrong.any():
                mult = np.array(best.mult_g, dtype=float)
                mult[:meq] = lam
                mult[rows.start + held] = mu
                if not self._within_bounds(nlp, x, slack=primal_tol):
                    return None
                r_dual, r_primal = self.residual(nlp, x, mult)
                primal = float(np.max(np.abs(r_primal))) if r_primal.size else 0.0
                return Prediction(x, mult, best.steps + steps, primal, float(np.max(np.abs(r_dual))), True, True,
                                  best.from_surface, tuple(int(i) for i in held))
            held, lower = held[~wrong], lower[~wrong]
        return None

    def _held_steps(self, nlp: CollocationNLP, best: Prediction, held: np.ndarray, target: np.ndarray,
                    dual_tol: float, primal_tol: float):
        """Simplified Newton steps on the KKT conditions with rows ``held`` of ``A_lin`` equal to ``target``:
        ``(x, equality multipliers, held rows' multipliers, steps)`` of the converged point with the smallest
        dual residual (:meth:`_judge`), or None when none converges."""
        n, meq = nlp.n, nlp.layout.equality_rows.stop
        rows = nlp.layout.linear_rows
        Ah = nlp.structure.A_lin[held]
        B = np.zeros((n + meq, held.size))
        B[:n] = Ah.T.toarray()
        W = np.column_stack([self.lu.solve(B[:, j]) for j in range(held.size)])
        # the products in einsum's own loops, not BLAS's (whose summation order may follow its thread count):
        # a draw's start, and so IPOPT's iterate of record, must not depend on the executor
        S = np.einsum("ij,ik->jk", B, W)
        x, lam, mu = np.array(best.x, dtype=float), np.array(best.mult_g[:meq], dtype=float), np.zeros(held.size)
        full = np.array(best.mult_g, dtype=float)
        full[rows] = 0.0
        kept, kept_dual, previous = None, np.inf, None         # the converged point with the smallest dual residual
        with np.errstate(all="ignore"):
            for step in range(2 * self.MAX_STEPS + 1):       # from a point off the held bounds: more steps
                full[:meq] = lam
                full[rows.start + held] = mu
                r_dual, r_primal = self.residual(nlp, x, full)
                r_held = Ah @ x - target
                primal = max(float(np.max(np.abs(r_primal))) if r_primal.size else 0.0, float(np.max(np.abs(r_held))))
                dual = float(np.max(np.abs(r_dual)))
                if not (np.isfinite(primal) and np.isfinite(dual)):
                    return kept
                converged, done = self._judge(primal, dual, previous, dual_tol, primal_tol)
                previous = dual
                if converged and dual < kept_dual:
                    kept, kept_dual = (x, lam, mu, step), dual
                if done or step == 2 * self.MAX_STEPS:
                    return kept
                u = self.lu.solve(-np.concatenate([r_dual, r_primal]))
                try:
                    dmu = np.linalg.solve(S, np.einsum("ij,i->j", B, u) + r_held)
                except np.linalg.LinAlgError:
                    return None
                d = u - np.einsum("ij,j->i", W, dmu)
                if not (np.all(np.isfinite(d)) and np.all(np.isfinite(dmu))):
                    return None
                x, lam, mu = x + d[:n], lam + d[n:], mu + dmu
        return None

    def _tolerances(self, tol: float) -> tuple[float, float]:
        """``(dual, primal)`` aims of the steps (:meth:`predict`): a tenth of IPOPT's tolerances, the dual one
        on IPOPT's dual scaling ``max(1, mean |lambda| / 100)`` at the reference."""
        s_d = max(1.0, float(np.mean(np.abs(self.solution.mult_g))) / 100.0)
        return min(1.0, tol * s_d) / 10.0, tol / 10.0

    #: A step that divides the dual residual by less than ``1 / STALL`` has reached its rounding level.
    STALL = 0.5

    @classmethod
    def _judge(cls, primal: float, dual: float, previous_dual: float | None, dual_tol: float,
               primal_tol: float) -> tuple[bool, bool]:
        """``(converged, done)`` of a step's point against the aims ``dual_tol, primal_tol`` of
        :meth:`_tolerances`: converged within IPOPT's tolerances (the primal aim and ten times
        the dual aim), done when also at the dual aim or where the residual stopped falling.

        The dual aim can lie below what double precision reaches. The residual ``grad f + J^T
        lambda`` sums terms as large as ``|J^T| |lambda|``: RA-66's multipliers reach 1e11, and a
        component's rounding error (from its terms and, through the Hessian, from the last bit
        of ``x``) is 2e-4 to 4e-3 after the steps (a draw's median over its later steps; single
        steps up to 7e-3), against the aim 3.3e-3 (sampling draws of the reference case,
        ``benchmarks/bench_predictor_floor.py``). There the steps, which shrink the residual
        5- to 700-fold each before, stop shrinking it and it jitters from step to step; more
        steps make no better start."""
        converged = primal <= primal_tol and dual <= 10.0 * dual_tol
        done = converged and (dual <= dual_tol or (previous_dual is not None and dual > cls.STALL * previous_dual))
        return converged, done

    def _steps(self, nlp: CollocationNLP, x: np.ndarray, lam: np.ndarray, tol: float,
               max_steps: int) -> Prediction | None:
        """Simplified Newton steps from ``(x, lam)`` with the reference factors; the converged point
        with the smallest dual residual (:meth:`_judge`), or failing one the point with the smallest
        constraint violation (None when the first residual is not finite)."""
        n, meq = nlp.n, nlp.layout.equality_rows.stop
        dual_tol, primal_tol = self._tolerances(tol)
        best, previous = None, None
        with np.errstate(all="ignore"):
            for step in range(max_steps + 1):
                r_dual, r_primal = self.residual(nlp, x, lam)
                primal = float(np.max(np.abs(r_primal))) if r_primal.size else 0.0
                dual = float(np.max(np.abs(r_dual)))
                if not (np.isfinite(primal) and np.isfinite(dual)):
                    break
                converged, done = self._judge(primal, dual, previous, dual_tol, primal_tol)
                previous = dual
                if (best is None or (converged and not (best.converged and best.dual <= dual))
                        or (not best.converged and primal < best.primal)):
                    best = Prediction(x, lam, step, primal, dual, converged)
                if done or step == max_steps:
                    break
                d = self.lu.solve(-np.concatenate([r_dual, r_primal]))
                if not np.all(np.isfinite(d)):
                    break
                x = x + d[:n]
                lam = lam.copy()
                lam[:meq] += d[n:]
        return best

    def learn(self, offsets: np.ndarray, *, degree: int | None = None, tol: float = 1e-8) -> "SolutionPredictor":
        """This predictor with a :class:`SolutionSurface` learnt from solutions at ``offsets``.

        Each offset's solution is found by this predictor's steps (to ``tol``, up to 16
        back-solves); the converged ones and the reference are fitted, component by component,
        by a polynomial in the offset's coordinates within the span of ``offsets - c_ref``
        (least squares). The steps of a later prediction then start from the polynomial's
        value, which leaves them the error of a polynomial fit instead of the whole change of
        the solution: on RA-66's sampling (3 fixed directions, 100 offsets drawn like the
        draws, degree 4) about 2 back-solves per draw instead of 5.8.

        Parameters
        ----------
        offsets : ndarray, shape (k, n_p)
            Sample offsets ``c``, drawn like the offsets to be predicted.
        degree : int, optional
            Of the polynomial; by default the highest, at most 4, whose number of
            coefficients is at most ``k / 2.5``.
        tol : float
            Of the steps that solve at each offset.
        """
        t0 = time.perf_counter()
        offsets = np.atleast_2d(np.asarray(offsets, dtype=float))
        c_ref = np.asarray(self.nlp.transform.c, dtype=float)
        meq = self.nlp.layout.equality_rows.stop
        z_ref = np.concatenate([self.solution.x, self.solution.mult_g[:meq]])
        dc = offsets - c_ref
        _, sv, vt = np.linalg.svd(dc, full_matrices=False) if dc.size else (None, np.zeros(0), None)
        rank = int(np.sum(sv > 1e-10 * max(1.0, sv[0] if sv.size else 0.0)))
        if rank == 0:
            return self
        basis = vt[:rank].T
        points, values = [np.zeros(rank)], [z_ref]
        base = replace(self, surface=None)
        for c, u in zip(offsets, np.einsum("ij,jk->ik", dc, basis)):
            # the smooth solution surface: a point across a bound is kept as the steps find it, not held on
            # the bound (a bound's kink is no polynomial)
            got = base.predict(self.nlp.with_offset(c), tol=tol, max_steps=16, hold=False)
            if got is not None and got.converged:
                points.append(u)
                values.append(np.concatenate([got.x, got.mult_g[:meq]]))
        U, Z = np.array(points), np.array(values)
        if degree is None:
            degree = 0
            while degree < 4 and 2.5 * SolutionSurface.n_terms(rank, degree + 1) <= len(U):
                degree += 1
        if degree < 1 or SolutionSurface.n_terms(rank, degree) > len(U):
            return self
        lo, hi = U.min(axis=0), U.max(axis=0)
        surface = SolutionSurface(c_ref, z_ref, basis, lo, hi, int(degree), np.zeros((0, Z.shape[1])), len(U) - 1, 0.0)
        F = surface.features(U)
        # least squares by the normal equations, with the products in einsum's own loops: a
        # BLAS product's summation order can follow its thread count, and every worker must
        # learn the same surface to the bit (the draws' results do not depend on the executor)
        gram = np.einsum("ij,ik->jk", F, F)
        try:
            coef = np.linalg.solve(gram, np.einsum("ij,ik->jk", F, Z - z_ref))
        except np.linalg.LinAlgError:      # the learnt points do not determine the polynomial
            return self
        if not np.all(np.isfinite(coef)):
            return self
        return replace(self, surface=replace(surface, coef=coef, formed_s=time.perf_counter() - t0))

    @staticmethod
    def _within_bounds(nlp: CollocationNLP, x: np.ndarray, slack: float = 0.0) -> bool:
        """``x`` within the variable bounds and the inequality rows within theirs (or ``slack`` past them:
        a row held on its bound by the steps)."""
        rows = nlp.layout.linear_rows
        a = nlp.structure.A_lin @ x if rows.stop > rows.start else np.empty(0)
        return bool(np.all(x >= nlp.x_lower) and np.all(x <= nlp.x_upper)
                    and np.all(a >= nlp.c_lower[rows] - slack) and np.all(a <= nlp.c_upper[rows] + slack))

    def _inequality_multipliers(self, nlp: CollocationNLP, x: np.ndarray, mult_g: np.ndarray) -> np.ndarray:
        """Multipliers of the inequality rows that keep each row's complementarity (slack times
        multiplier, IPOPT's barrier parameter at the reference) at the new point."""
        rows = nlp.layout.linear_rows
        if rows.stop == rows.start:
            return mult_g
        ref, st = self.nlp, nlp.structure
        lam = mult_g[rows]
        lower = lam < 0  # IPOPT's sign: a negative multiplier pushes away from the lower bound
        a_ref, a_new = st.A_lin @ self.solution.x, st.A_lin @ x
        s_ref = np.where(lower, a_ref - ref.c_lower[rows], ref.c_upper[rows] - a_ref)
        s_new = np.where(lower, a_new - nlp.c_lower[rows], nlp.c_upper[rows] - a_new)
        with np.errstate(all="ignore"):
            ok = (s_ref > 0) & (s_new > 0) & np.isfinite(s_ref) & np.isfinite(s_new)
            scaled = np.where(ok, lam * s_ref / np.where(ok, s_new, 1.0), lam)
        out = mult_g.copy()
        out[rows] = scaled
        return out


@dataclass(frozen=True, eq=False)
class SolutionSurface:
    """The primal-dual solution of a re-offset NLP as a polynomial in its offset
    (:meth:`SolutionPredictor.learn`).

    The offsets ``c`` of the sampling's (7.9) move in a space of the dimension of ``q2``;
    ``u = basis^T (c - c_ref)`` are their coordinates there, ``s = (u - mid) / half`` the
    coordinates scaled to ``[-1, 1]`` over the learnt range, and the solution's change from
    the reference is ``sum_j coef_j m_j(s)`` over the monomials ``m_j`` of total degree 0 to
    ``degree``.

    Attributes
    ----------
    c_ref : ndarray, shape (n_p,)
        The reference offset.
    z_ref : ndarray, shape (n + m_eq,)
        The reference solution ``(x, mult_g[:m_eq])``.
    basis : ndarray, shape (n_p, r)
        Orthonormal basis of the learnt offsets' span.
    lo, hi : ndarray, shape (r,)
        The learnt coordinates' range; :meth:`start` declines offsets more than 5 % of it
        outside (a polynomial extrapolates poorly).
    degree : int
    coef : ndarray, shape (n_terms, n + m_eq)
        Per monomial, the change of ``(x, mult_g[:m_eq])``.
    n_learnt : int
        Offsets whose solutions converged and were fitted (besides the reference).
    formed_s : float
        Wall time of learning.
    """

    c_ref: np.ndarray
    z_ref: np.ndarray
    basis: np.ndarray
    lo: np.ndarray
    hi: np.ndarray
    degree: int
    coef: np.ndarray
    n_learnt: int
    formed_s: float

    @staticmethod
    def n_terms(r: int, degree: int) -> int:
        """Monomials of total degree 0 to ``degree`` in ``r`` variables."""
        from math import comb
        return comb(r + degree, degree)

    def features(self, U: np.ndarray) -> np.ndarray:
        """The monomials at coordinates ``U`` (shape (k, r)), shape (k, n_terms)."""
        from itertools import combinations_with_replacement
        half = np.where(self.hi > self.lo, (self.hi - self.lo) / 2.0, 1.0)
        S = (np.atleast_2d(U) - (self.hi + self.lo) / 2.0) / half
        cols = [np.ones(S.shape[0])]
        for d in range(1, self.degree + 1):
            for idx in combinations_with_replacement(range(S.shape[1]), d):
                cols.append(np.prod(S[:, list(idx)], axis=1))
        return np.stack(cols, axis=1)

    def start(self, c: np.ndarray) -> np.ndarray | None:
        """The polynomial's ``(x, mult_g[:m_eq])`` at offset ``c``, or None where ``c`` is
        outside the learnt span or range."""
        dc = np.asarray(c, dtype=float) - self.c_ref
        u = np.einsum("ij,i->j", self.basis, dc)
        off_span = np.max(np.abs(dc - np.einsum("ij,j->i", self.basis, u)), initial=0.0)
        if off_span > 1e-9 * max(1.0, float(np.max(np.abs(dc), initial=0.0))):
            return None
        margin = 0.05 * (self.hi - self.lo)
        if np.any(u < self.lo - margin) or np.any(u > self.hi + margin):
            return None
        return self.z_ref + np.einsum("j,jk->k", self.features(u[None, :])[0], self.coef)


class _BorderedBanded:
    """``K x = b`` for a sparse ``K`` that is banded but for a few border rows and columns.

    The unknowns other than the border are put in reverse Cuthill-McKee order, where their
    block ``A`` has a small bandwidth; ``A`` gets LAPACK's banded LU (``dgbtrf``, partial
    pivoting) and the border a Schur complement ``C - B^T A^-1 B``. A back-solve costs a
    banded back-solve and a few dense products: about a quarter of SuperLU's on RA-66's
    KKT matrix, whose fill-reducing column order still leaves 0.7 million non-zeros.
    """

    def __init__(self, perm, inv, nb, kl, lub, piv, B, AiB, S_inv):
        self.perm, self.inv, self.nb, self.kl = perm, inv, nb, kl
        self.lub, self.piv, self.B, self.AiB, self.S_inv = lub, piv, B, AiB, S_inv

    @classmethod
    def factor(cls, K: sps.csc_matrix, border: np.ndarray) -> "_BorderedBanded | None":
        """The factors, or None where ``K`` is not banded enough (or a block is singular)."""
        from scipy.linalg import lapack
        from scipy.sparse.csgraph import reverse_cuthill_mckee
        N = K.shape[0]
        rest = np.setdiff1d(np.arange(N), border)
        Kr = K.tocsr()[rest][:, rest]
        order = reverse_cuthill_mckee((abs(Kr) + abs(Kr).T).tocsr(), symmetric_mode=True)
        perm = np.concatenate([rest[order], border])
        inv = np.empty_like(perm)
        inv[perm] = np.arange(N)
        Kp = K[perm][:, perm].tocsc()
        nb = rest.size
        A = Kp[:nb, :nb].tocoo()
        kl = int(np.max(np.abs(A.row - A.col))) if A.nnz else 0
        if kl == 0 or kl > max(8, nb // 10):
            return None
        ab = np.zeros((3 * kl + 1, nb))
        ab[2 * kl + A.row - A.col, A.col] = A.data
        lub, piv, info = lapack.dgbtrf(ab, kl, kl)
        if info != 0:
            return None
        B = Kp[:nb, nb:].toarray()
        AiB = lapack.dgbtrs(lub, kl, kl, B, piv)[0]
        S = Kp[nb:, nb:].toarray() - B.T @ AiB
        try:
            S_inv = np.linalg.inv(S) if S.size else S
        except np.linalg.LinAlgError:
            return None
        if not (np.all(np.isfinite(AiB)) and np.all(np.isfinite(S_inv))):
            return None
        return cls(perm, inv, nb, kl, lub, piv, B, AiB, S_inv)

    def solve(self, b: np.ndarray) -> np.ndarray:
        from scipy.linalg import lapack
        v = b[self.perm]
        nb = self.nb
        y = lapack.dgbtrs(self.lub, self.kl, self.kl, v[:nb], self.piv)[0]
        z = self.S_inv @ (v[nb:] - self.B.T @ y)
        return np.concatenate([y - self.AiB @ z, z])[self.inv]
