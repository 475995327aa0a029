"""Exact NLP derivatives against central finite differences (STYLE.md: unit tier).

Checked for RA-66 and for a small unrelated model (a damped pendulum with an implicit
equation, an input, a piecewise-linear damping with a tie, a free initial angle, and
nonlinear outputs ``(1 + k) th`` and ``om + b dth/dt``, so that the nonlinear
objective-Hessian path of ``rocketid.nlp`` runs), each plain (7.5) and with a random
parameter transform ``p = P r + c`` (7.9):

* the objective gradient against differences of the objective;
* the constraint Jacobian against differences of the constraints;
* the lower triangle of the Lagrangian Hessian ``obj_factor * d2J + sum_k lam_k d2c_k``
  (random ``lam`` and ``obj_factor``) against differences of the *analytic* Lagrangian
  gradient ``obj_factor * grad J + J_c^T lam``.

Differences are central, with step ``h_j = STEP * max(1, |x_j|)`` (relative to the
variable's magnitude: RA-66 mixes altitudes of 1e4 m with CL = 0.1). An entry passes when

    |analytic - fd| <= RTOL * max(|analytic|, FLOOR * sqrt(r_i c_j)) + ATOL * max|analytic|

with ``r_i``, ``c_j`` the largest analytic magnitudes in its row and column: relative to
the entry itself, or, for entries much smaller than their neighbours (and structural
zeros), relative to the row/column scale (invariant under row and column scaling). The
last term is the round-off of differencing functions that do not depend on ``x_j`` at
all. Measured worst ratios (error / tolerance) are about 0.05 for RA-66 and 0.003 for
the pendulum; changing one non-zero by a relative 1e-5 fails the check for about 80 % of
the entries picked at random (the rest are below the row/column floor).
"""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp

import rocketid as ri
from rocketid.nlp import ParameterTransform

RTOL = 1e-6
FLOOR = 1e-2
ATOL = 1e-10
STEP = 1e-5          # Jacobian and Hessian (differences of analytic first derivatives)
STEP_OBJECTIVE = 1e-4  # objective gradient: J sums ~2e4 squares, its round-off needs a longer step

# Geometric altitudes (m) of the kinks of Yang's density fit (docs/design.md, 'Yang's atmosphere'): a
# difference stencil straddling one would compare against a one-sided slope.
_DENSITY_KINKS_M = (11019.1, 20063.1, 32161.9)


# ---------------------------------------------------------------------------
# models and points
# ---------------------------------------------------------------------------


def pendulum_spec() -> ri.ModelSpec:
    """A damped pendulum, unrelated to RA-66, using every modelling feature the NLP expands."""
    m = ri.Model("pendulum", 0.0, 4.0)
    th = m.state("th", 0.5, free=True, bounds=(-2.0, 2.0))
    om = m.state("om", 0.0)
    u = m.input("u", 0.3 * sp.sin(2 * m.t))
    w2 = m.parameter("w2", 9.0, bounds=(1.0, 20.0))
    c = m.piecewise_linear("c", [0.0, 1.0, 2.0, 4.0], [0.2, 0.3, 0.3, 0.1], bounds=(0.0, 2.0), ties=[(1, 2)])
    k = m.parameter("k", 0.05, bounds=(-0.5, 0.5))
    b = m.parameter("b", 0.1, bounds=(-1.0, 1.0))
    inertia = m.define("inertia", 1 + sp.Rational(1, 5) * sp.cos(th) ** 2)
    m.ode({th: om})
    m.implicit({om: inertia * m.der(om) + c * om + w2 * sp.sin(th) - u})
    m.output("angle", (1 + k) * th, sigma=0.01)          # nonlinear: scale factor times a state
    m.output("rate", om + b * m.der(th), sigma=0.05)     # nonlinear: parameter times a derivative
    m.output("omega", om, sigma=0.1)                     # linear
    return m.freeze()


@pytest.fixture(scope="module")
def pendulum_prepared():
    spec = pendulum_spec()
    data = ri.simulate_measurements(spec, spec.guess, np.arange(1, 401) * 0.01, seed=1)
    return ri.prepare(spec, data)


def _random_point(pr, nlp, p_center, rng, *, rel_p, rel_s, abs_s):
    """A point near the trajectory through ``p_center``: parameters and node states perturbed."""
    S, _ = pr.initial_states(p_center)
    p = p_center * (1 + rel_p * rng.uniform(-1, 1, p_center.size))
    S = S * (1 + rel_s * rng.standard_normal(S.shape)) + abs_s * rng.standard_normal(S.shape)
    if "h" in map(str, pr.spec.state_symbols):
        j = pr.spec.state_symbols.index(pr.spec.symbol("h"))
        for kink in _DENSITY_KINKS_M:
            near = np.abs(S[:, j] - kink) < 1.0
            S[near, j] = kink + 2.0
    p = np.clip(p, pr.spec.lower, pr.spec.upper)
    return nlp.initial_x(S, p)


def _transformed(nlp, n_reduced, rng):
    n_p = nlp.transform.P.shape[0]
    P = rng.standard_normal((n_p, n_reduced))
    c = 0.1 * rng.standard_normal(n_p)
    return nlp.with_transform(ParameterTransform(P, c, tuple(f"r{i}" for i in range(n_reduced))))


def _case(request, name):
    """(nlp, x, rng) for a named case: model, plain or transformed, and a seed."""
    model, kind, seed = name.split("-")
    rng = np.random.default_rng(int(seed))
    if model == "ra66":
        pr = request.getfixturevalue("ra66_noisy_prepared")
        p_center = ri.ra66_truth(pr.spec)
        scale = dict(rel_p=0.2, rel_s=1e-3, abs_s=1e-3)
    else:
        pr = request.getfixturevalue("pendulum_prepared")
        p_center = pr.spec.guess
        scale = dict(rel_p=0.1, rel_s=0.05, abs_s=0.02)
    nlp = pr.nlp
    if kind == "transformed":
        nlp = _transformed(nlp, nlp.n - nlp.n_states_vars - 3, rng)
        assert not nlp.transform.is_identity and nlp.m_lin > 0
    x = _random_point(pr, nlp, p_center, rng, **scale)
    return nlp, x, rng


CASES = ["ra66-plain-0", "ra66-plain-1", "ra66-transformed-2",
         "pendulum-plain-0", "pendulum-plain-1", "pendulum-plain-2", "pendulum-transformed-3"]


# ---------------------------------------------------------------------------
# finite differences and the comparison
# ---------------------------------------------------------------------------


def _central_differences(f, x, rel_step):
    """Columns d f / d x_j by central differences, shape (len(f(x)), len(x))."""
    steps = rel_step * np.maximum(1.0, np.abs(x))
    cols = []
    for j in range(x.size):
        e = np.zeros_like(x)
        e[j] = steps[j]
        cols.append((np.atleast_1d(f(x + e)) - np.atleast_1d(f(x - e))) / (2 * steps[j]))
    return np.array(cols).T


def _dense(rows, cols, values, shape):
    A = np.zeros(shape)
    np.add.at(A, (np.asarray(rows), np.asarray(cols)), values)
    return A


def _assert_close(analytic, fd, what, *, row_scale=None, col_scale=None):
    """The comparison of the module docstring; fails naming the worst entry."""
    absA = np.abs(analytic)
    r = absA.max(axis=1) if row_scale is None else row_scale
    c = absA.max(axis=0) if col_scale is None else col_scale
    tol = RTOL * np.maximum(absA, FLOOR * np.sqrt(np.outer(r, c))) + ATOL * absA.max()
    ratio = np.abs(analytic - fd) / tol
    worst = np.unravel_index(np.argmax(ratio), ratio.shape)
    assert ratio[worst] <= 1.0, (
        f"{what}: entry {tuple(int(i) for i in worst)} is {analytic[worst]!r} analytically but "
        f"{fd[worst]!r} by finite differences (error {ratio[worst]:.3g} x tolerance)")
    return float(ratio.max())


# ---------------------------------------------------------------------------
# tests
# ---------------------------------------------------------------------------


def test_pendulum_uses_the_nonlinear_objective_path(pendulum_prepared):
    """The second model really exercises the nonlinear-output Hessian (not only the constant one)."""
    g = pendulum_prepared.nlp.generated
    assert tuple(g.OUTPUT_NAMES) == ("angle", "rate", "omega")
    assert tuple(g.OUTPUT_LINEAR) == (False, False, True)
    assert all(len(rows) > 0 for rows in g.OUTPUT_HESS_ROWS[:2])  # d2/(dk dth), d2/(db d dth_dt)
    names = pendulum_prepared.spec.parameter_names
    assert names == ("th_0", "w2", "c0", "c1", "c3", "k", "b")


@pytest.mark.parametrize("case", CASES)
def test_structures_are_valid(request, case):
    nlp, x, _ = _case(request, case)
    jr, jc = nlp.jacobianstructure()
    hr, hc = nlp.hessianstructure()
    assert len(jr) == len(jc) == nlp.jacobian(x).size
    assert len(hr) == len(hc) == nlp.hessian(x, np.ones(nlp.m), 1.0).size
    assert np.all((0 <= jr) & (jr < nlp.m)) and np.all((0 <= jc) & (jc < nlp.n))
    assert np.all(hr >= hc), "the Hessian structure must be the lower triangle (cyipopt's contract)"
    assert np.all(hc >= 0) and np.all(hr < nlp.n)
    assert len(set(zip(jr.tolist(), jc.tolist()))) == len(jr), "duplicate Jacobian entries"
    assert len(set(zip(hr.tolist(), hc.tolist()))) == len(hr), "duplicate Hessian entries"
    assert nlp.constraints(x).shape == (nlp.m,)
    assert nlp.gradient(x).shape == (nlp.n,)


@pytest.mark.parametrize("case", CASES)
def test_objective_gradient_matches_differences(request, case):
    nlp, x, _ = _case(request, case)
    grad = nlp.gradient(x)
    fd = _central_differences(lambda z: nlp.objective(z), x, STEP_OBJECTIVE)[0]
    # a vector: its scale is its largest entry
    scale = np.array([np.abs(grad).max()])
    _assert_close(grad[None, :], fd[None, :], f"{case}: objective gradient",
                  row_scale=scale, col_scale=scale)


@pytest.mark.parametrize("case", CASES)
def test_constraint_jacobian_matches_differences(request, case):
    nlp, x, _ = _case(request, case)
    rows, cols = nlp.jacobianstructure()
    J = _dense(rows, cols, nlp.jacobian(x), (nlp.m, nlp.n))
    fd = _central_differences(nlp.constraints, x, STEP)
    _assert_close(J, fd, f"{case}: constraint Jacobian")
    # the sparse-matrix view agrees with the callback
    np.testing.assert_array_equal(nlp.jacobian_matrix(x).toarray(), J)


@pytest.mark.parametrize("case", CASES)
def test_lagrangian_hessian_matches_differences(request, case):
    nlp, x, rng = _case(request, case)
    lam = rng.standard_normal(nlp.m)
    obj_factor = float(rng.uniform(0.5, 2.0))
    rows, cols = nlp.hessianstructure()
    H = _dense(rows, cols, nlp.hessian(x, lam, obj_factor), (nlp.n, nlp.n))
    assert not np.any(np.triu(H, 1)), "values outside the lower triangle"

    def lagrangian_gradient(z):
        return obj_factor * nlp.gradient(z) + nlp.jacobian_matrix(z).T @ lam

    fd = _central_differences(lagrangian_gradient, x, STEP)
    full = H + np.tril(H, -1).T
    scale = np.abs(full).max(axis=1)  # symmetric: row and column scales are the same
    _assert_close(H, np.tril(0.5 * (fd + fd.T)), f"{case}: Lagrangian Hessian",
                  row_scale=scale, col_scale=scale)


@pytest.mark.parametrize("case", ["pendulum-plain-0", "pendulum-transformed-3"])
def test_objective_hessian_alone_matches_differences(request, case):
    """obj_factor = 1, no multipliers: the objective's own Hessian, with the curvature
    of the nonlinear outputs times the residuals (not only Gauss-Newton)."""
    nlp, x, _ = _case(request, case)
    rows, cols = nlp.hessianstructure()
    H = _dense(rows, cols, nlp.hessian(x, np.zeros(nlp.m), 1.0), (nlp.n, nlp.n))
    fd = _central_differences(nlp.gradient, x, STEP)
    full = H + np.tril(H, -1).T
    scale = np.abs(full).max(axis=1)
    _assert_close(H, np.tril(0.5 * (fd + fd.T)), f"{case}: objective Hessian", row_scale=scale, col_scale=scale)
    # and the Gauss-Newton part alone would not pass: the residual-curvature term matters here
    gn = nlp.output_jacobian(x)
    W = gn.T @ (gn.multiply(1.0 / nlp.sigma_vector()[:, None] ** 2))
    W = np.tril(np.asarray(W.todense()))
    assert np.abs(W - H).max() > 1e-3 * np.abs(H).max()
