"""Gaussian priors on parameters: the penalty, its derivatives, the covariance and the estimability.

The truth is a model whose maximum a posteriori estimate has a closed form: ``dy/dt = a``,
``y(0) = 0`` (so ``y = a t``), measured with noise sigma, and the prior ``a ~ N(mu, s^2)``::

    a_MAP = (sum t y / sigma^2 + mu / s^2) / (sum t^2 / sigma^2 + 1 / s^2),   sd = (...)^-1/2

and the data's share of the information on ``a`` is ``(sum t^2/sigma^2) / (sum t^2/sigma^2 + 1/s^2)``.
"""

from __future__ import annotations

import numpy as np
import pytest

import rocketid as ri
from rocketid.errors import ModelError
from rocketid.estimability import analyze, uncertainty
from rocketid.sensitivity import sensitivity_of

SIGMA = 0.5
T = np.linspace(0.05, 2.0, 40)


def _ramp(prior=None):
    m = ri.Model("ramp", 0.0, 2.0)
    y = m.state("y", 0.0)
    a = m.parameter("a", 1.0, bounds=(-10.0, 10.0))
    b = m.parameter("b", 0.0, bounds=(-10.0, 10.0))   # a sensor bias, no prior
    m.ode({y: a})
    m.output("y", y + b, sigma=SIGMA)
    if prior is not None:
        m.prior(a, *prior, source="bench")
    return m.freeze()


def _closed_form(y, mu, s):
    """MAP of (a, b) for z = a t + b with the prior on a: a 2x2 linear least-squares problem."""
    X = np.column_stack([T, np.ones_like(T)]) / SIGMA
    H = X.T @ X + np.diag([1 / s ** 2, 0.0])
    g = X.T @ (y / SIGMA) + np.array([mu / s ** 2, 0.0])
    return np.linalg.solve(H, g), np.linalg.inv(H), (X.T @ X)


@pytest.mark.parametrize("mu, s", [(1.5, 0.05), (0.5, 0.3)])
def test_prior_estimate_and_covariance_match_the_closed_form(mu, s):
    rng = np.random.default_rng(3)
    y = 1.2 * T + 0.3 + SIGMA * rng.standard_normal(T.size)
    data = ri.Measurements.from_arrays(T, {"y": y})
    spec = _ramp((mu, s))
    fit = ri.estimate(spec, data)
    assert fit.success
    p_map, cov, H_data = _closed_form(y, mu, s)
    assert np.allclose(fit.p, p_map, atol=1e-6)
    unc = uncertainty(fit)
    assert np.allclose(unc.parameter_covariance, cov, rtol=1e-5)
    # the prior's share of J is reported apart from the data's
    assert fit.prior_objective == pytest.approx(0.5 * ((fit.value("a") - mu) / s) ** 2, rel=1e-9)
    resid = fit.residuals["y"]
    assert fit.data_objective == pytest.approx(0.5 * np.sum((resid / SIGMA) ** 2), rel=1e-9)
    assert fit.to_dict()["priors"]["a"] == {"mean": mu, "sd": s, "source": "bench"}
    assert "priors" in fit.summary().text()
    # the estimability analysis honours the prior: H_r = H_data + diag(1/s^2)
    sens = sensitivity_of(fit)
    assert np.allclose(sens.H_data, H_data, rtol=1e-6)
    assert np.allclose(sens.H_r, H_data + np.diag([1 / s ** 2, 0]), rtol=1e-6)
    est = analyze(fit.prepared, fit.p, sensitivity=sens)
    lam = np.linalg.eigvalsh(H_data + np.diag([1 / s ** 2, 0]))[::-1]
    assert np.allclose(est.eigenvalues, lam, rtol=1e-6)
    share = est.data_share()
    assert np.all((share > 0) & (share <= 1 + 1e-12))
    assert "data share" in est.summary().text()


def test_prior_makes_an_unidentifiable_parameter_estimable():
    """Two parameters that enter only as a sum: singular without a prior, determined with one."""
    m = ri.Model("sum", 0.0, 2.0)
    y = m.state("y", 0.0)
    a = m.parameter("a", 1.0, bounds=(-10.0, 10.0))
    c = m.parameter("c", 0.0, bounds=(-10.0, 10.0))
    m.ode({y: a + c})
    m.output("y", y, sigma=SIGMA)
    rng = np.random.default_rng(0)
    data = ri.Measurements.from_arrays(T, {"y": 1.5 * T + SIGMA * rng.standard_normal(T.size)})
    base = m.freeze()
    est0 = analyze(ri.prepare(base, data), [1.0, 0.5])
    assert est0.eigenvalues[-1] < 1e-9 * est0.eigenvalues[0]
    spec = base.with_priors({"c": (0.4, 0.01, "static firing")})
    fit = ri.estimate(spec, data)
    assert fit.success
    assert fit.value("c") == pytest.approx(0.4, abs=0.03)
    est = analyze(fit.prepared, fit.p)
    D = np.sum(T ** 2) / SIGMA ** 2           # the data's information on a + c
    H = np.array([[D, D], [D, D + 1e4]])      # ... plus 1/sd^2 = 1e4 on c
    assert np.allclose(est.eigenvalues, np.linalg.eigvalsh(H)[::-1], rtol=1e-6)
    assert est.eigenvalues[-1] > 0.9 * D       # no longer singular
    c_dir = int(np.argmax(np.abs(est.V[1])))   # the direction made mostly of c is the prior's
    assert est.data_share()[c_dir] < 0.1
    assert est.data_share()[1 - c_dir] > 0.9


def test_prior_gradient_and_hessian_are_exact():
    spec = _ramp((1.5, 0.2))
    rng = np.random.default_rng(1)
    data = ri.Measurements.from_arrays(T, {"y": T + SIGMA * rng.standard_normal(T.size)})
    nlp = ri.prepare(spec, data).nlp
    x = rng.standard_normal(nlp.n)
    g = nlp.gradient(x)
    eps = 1e-6
    fd = np.array([(nlp.objective(x + eps * e) - nlp.objective(x - eps * e)) / (2 * eps) for e in np.eye(nlp.n)])
    assert np.allclose(g, fd, atol=1e-5)
    r, c = nlp.hessianstructure()
    H = np.zeros((nlp.n, nlp.n))
    H[r, c] = nlp.hessian(x, np.zeros(nlp.m), 1.0)
    H = H + np.tril(H, -1).T
    fdH = np.array([(nlp.gradient(x + eps * e) - nlp.gradient(x - eps * e)) / (2 * eps) for e in np.eye(nlp.n)])
    assert np.allclose(H, fdH, atol=1e-4)


def test_bad_priors_are_refused():
    m = ri.Model("ramp", 0.0, 2.0)
    y = m.state("y", 0.0)
    a = m.parameter("a", 1.0)
    m.ode({y: a})
    m.output("y", y, sigma=SIGMA)
    with pytest.raises(ModelError, match="not an estimated parameter"):
        m.prior("y", 1.0, 0.1)
    with pytest.raises(ModelError, match="sd positive"):
        m.prior(a, 1.0, 0.0)
