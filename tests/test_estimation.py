"""Estimation (7.5) end to end: RA-66 against the truth in units of its standard deviations,
exactly solvable models against their closed forms, warm starts, and the result object.

The standard deviations of the RA-66 estimates (noise sigma = 1 in x, h, v) are
``sqrt(diag((S^T S)^-1))`` with ``S = dy/dp`` the output sensitivities, here computed by
central differences of the high-accuracy *simulator* (not of the collocation NLP), so
that they are independent of the code under test. Measured: CD0..CD6 = 5.56e-3, 1.15e-3,
4.72e-4, 2.78e-4, 2.42e-4, 3.53e-4, 1.40e-3, CL = 7.1e-6 (the standard errors of the seed-0 fit in
docs/reference-cases.md: 0.0056, 0.0011, 0.0005, 0.0003, 0.0002, 0.0004, 0.0014).
"""

from __future__ import annotations

import json
import math

import numpy as np
import pytest
import sympy as sp

import rocketid as ri
from rocketid.errors import ModelError

# Rounded reference standard deviations (docs/reference-cases.md, RA-66 seed 0), for a sanity check of the
# computed ones
METHOD_SIGMA = {"CD0": 5.6e-3, "CD1": 1.2e-3, "CD6": 1.4e-3, "CL": 1e-5}
METHOD_SIGMA_CD2_CD5 = (2.4e-4, 4.7e-4)


@pytest.fixture(scope="module")
def ra66_sigma(ra66_spec, ra66_p_true):
    """Standard deviations of the RA-66 estimates from simulator sensitivities."""
    times = ri.ra66_times()

    def outputs(p):
        traj = ri.simulate(ra66_spec, p, times)
        assert traj.success, traj.message
        y = traj.outputs()
        return np.concatenate([y["x"], y["h"], y["v"]])

    step = 1e-3  # outputs are smooth in p; 1e-3 to 1e-5 agree to 1e-4 relative
    S = np.empty((3 * times.size, ra66_p_true.size))
    for j in range(ra66_p_true.size):
        e = np.zeros(ra66_p_true.size)
        e[j] = step
        S[:, j] = (outputs(ra66_p_true + e) - outputs(ra66_p_true - e)) / (2 * step)
    return np.sqrt(np.diag(np.linalg.inv(S.T @ S)))


@pytest.fixture(scope="module")
def ra66_clean_fit(ra66_spec, ra66_clean):
    return ri.estimate(ra66_spec, ra66_clean)


def _in_sigmas(fit, p_true, sigma):
    return (fit.p - p_true) / sigma


# ---------------------------------------------------------------------------
# RA-66
# ---------------------------------------------------------------------------


def test_standard_deviations_agree_with_method(ra66_spec, ra66_sigma):
    names = ra66_spec.parameter_names
    assert names == ("CD0", "CD1", "CD2", "CD3", "CD4", "CD5", "CD6", "CL")
    sig = dict(zip(names, ra66_sigma))
    for name, ref in METHOD_SIGMA.items():
        assert ref / 1.5 <= sig[name] <= ref * 1.5, (name, sig[name], ref)
    lo, hi = METHOD_SIGMA_CD2_CD5
    for name in ("CD2", "CD3", "CD4", "CD5"):
        assert lo / 1.1 <= sig[name] <= hi * 1.1, (name, sig[name])


def test_noise_free_fit_recovers_the_truth(ra66_spec, ra66_clean_fit, ra66_p_true, ra66_sigma):
    fit = ra66_clean_fit
    assert fit.success, fit.summary()
    assert fit.prepared.transcription.mesh.K == 4 and fit.prepared.transcription.mesh.n_elements == 66
    np.testing.assert_array_equal(ra66_spec.guess, ri.RA66_P0)  # started from p0
    z = _in_sigmas(fit, ra66_p_true, ra66_sigma)
    # measured: at most 0.006 sigma (K = 3 would give 0.10 for CD0 and CL, docs/accuracy.md)
    assert np.all(np.abs(z) <= 0.1), dict(zip(ra66_spec.parameter_names, np.round(z, 4)))
    assert fit.chi2_per_dof < 1e-4  # the fit is at the collocation error, far below the noise


def test_noisy_fit_is_consistent_with_the_noise(ra66_spec, ra66_noisy_fit, ra66_p_true, ra66_sigma):
    fit = ra66_noisy_fit
    assert fit.success, fit.summary()
    assert fit.n_data == 19800
    assert 0.95 <= 2 * fit.objective / 19800 <= 1.05   # measured 0.9913
    assert 0.95 <= fit.chi2_per_dof <= 1.05
    z = _in_sigmas(fit, ra66_p_true, ra66_sigma)
    # measured: -0.35, 0.09, 0.22, -0.43, 0.35, -0.39, 1.04, -1.17
    assert np.all(np.abs(z) <= 3.0), dict(zip(ra66_spec.parameter_names, np.round(z, 2)))
    assert all(abs(r - 1.0) < 0.05 for r in fit.rms.values()), fit.rms


def test_warm_start_from_another_fit_reaches_the_same_optimum(ra66_spec, ra66_noisy, ra66_clean_fit,
                                                              ra66_noisy_fit, ra66_sigma):
    """Warm-started from the noise-free solution (primal and dual), on the noisy data."""
    warm = ri.estimate(ra66_spec, ra66_noisy, warm_start=ra66_clean_fit)
    assert warm.success, warm.summary()
    assert np.all(np.abs(warm.p - ra66_noisy_fit.p) <= 1e-3 * ra66_sigma)
    assert warm.objective == pytest.approx(ra66_noisy_fit.objective, rel=1e-8)


def test_warm_start_from_its_own_solution_with_a_new_guess(ra66_spec, ra66_noisy, ra66_noisy_fit, ra66_sigma):
    guess = dict(ra66_noisy_fit.parameters)
    guess[ra66_spec.symbol("CL")] = 0.2
    warm = ri.estimate(ra66_spec, ra66_noisy, warm_start=ra66_noisy_fit, guess=guess,
                       prepared=ra66_noisy_fit.prepared)
    assert warm.success, warm.summary()
    assert np.all(np.abs(warm.p - ra66_noisy_fit.p) <= 1e-3 * ra66_sigma)


def test_result_accessors(ra66_spec, ra66_noisy_fit):
    fit = ra66_noisy_fit
    CL, CD3, x = ra66_spec.symbol("CL"), ra66_spec.symbol("CD3"), ra66_spec.symbol("x")
    assert fit.value(CL) == fit.p[7] and isinstance(fit.value(CL), float)
    assert fit.value("CD3") == fit.value(CD3) == fit.p[3]
    assert fit.parameters[CL] == fit.p[7]
    assert all(isinstance(k, sp.Symbol) for k in fit.parameters)
    xs = fit.value(x)
    assert xs.shape == (66 * 4 + 1,) and xs[0] == pytest.approx(0.0, abs=1e-9)
    assert xs[-1] == pytest.approx(12.5e3, rel=0.05)  # x = 12.5 km at 66 s (docs/reference-cases.md)
    with pytest.raises(ModelError, match="Cl"):
        fit.value("Cl")
    # the states at sample times follow the collocation polynomial through the data
    assert np.abs(fit.states_at([66.0])[0, 1] - ra66_noisy_fit.prepared.measurements["h"].values[-1]) < 5


def test_result_dictionary_and_summary(ra66_noisy_fit):
    d = ra66_noisy_fit.to_dict()
    assert {"success", "parameters", "objective", "iterations", "timings"} <= set(d)
    assert d["success"] is True
    assert list(d["parameters"]) == ["CD0", "CD1", "CD2", "CD3", "CD4", "CD5", "CD6", "CL"]
    assert d["parameters"]["CL"] == ra66_noisy_fit.value("CL")
    assert d["objective"] == ra66_noisy_fit.objective and isinstance(d["iterations"], int)
    assert d["iterations"] == ra66_noisy_fit.iterations > 0
    assert set(d["timings"]) >= {"setup_s", "solve_s"}
    assert all(isinstance(v, float) and v >= 0 for v in d["timings"].values())
    json.dumps(d)  # JSON-ready
    text = ra66_noisy_fit.summary().text()
    for section in ("Problem", "Solver", "Parameters", "Fit"):
        assert f"\n{section}\n" in text
    assert "converged" in text and "CL" in text


# ---------------------------------------------------------------------------
# Exactly solvable models
# ---------------------------------------------------------------------------


def _decay_spec():
    m = ri.Model("decay", 0.0, 2.0)
    y = m.state("y", 1.0, free=True, bounds=(0.1, 10.0))
    k = m.parameter("k", 0.3, bounds=(0.0, 5.0))
    m.ode({y: -k * y})
    m.output("y", y, sigma=0.01)
    return m.freeze()


def test_exponential_decay_fit_is_exact():
    """Noise-free samples of y0 exp(-k t) (the analytic solution, no simulator) give back
    k and y0 to 1e-6 relative."""
    spec = _decay_spec()
    k_true, y0_true = 0.7, 1.3
    t = np.arange(1, 201) * 0.01
    data = ri.Measurements.from_arrays(t, {"y": y0_true * np.exp(-k_true * t)})
    fit = ri.estimate(spec, data)  # measured: 5e-13 and 2e-12 relative
    assert fit.success, fit.summary()
    assert spec.parameter_names == ("y_0", "k")
    assert fit.value("k") == pytest.approx(k_true, rel=1e-6)
    assert fit.value("y_0") == pytest.approx(y0_true, rel=1e-6)
    assert fit.objective < 1e-6


def test_a_fit_held_at_a_bound_gives_its_estimates_back_as_a_guess():
    """Data decaying at k = 0.7 fitted with k <= 0.5: k ends on its bound, where IPOPT's bound relaxation may
    leave it a hair past (1e-8 relative); those estimates given back as the next fit's guess are taken (the
    guess moved onto the bound) and reach the same optimum, while a guess clearly outside is still refused."""
    m = ri.Model("decay-bounded", 0.0, 2.0)
    y = m.state("y", 1.0, free=True, bounds=(0.1, 10.0))
    k = m.parameter("k", 0.3, bounds=(0.0, 0.5))
    m.ode({y: -k * y})
    m.output("y", y, sigma=0.01)
    spec = m.freeze()
    t = np.arange(1, 201) * 0.01
    data = ri.Measurements.from_arrays(t, {"y": 1.3 * np.exp(-0.7 * t)})
    fit = ri.estimate(spec, data)
    assert fit.success and [str(s) for s, _ in fit.active_bounds()] == ["k"]
    past = {"y_0": fit.value("y_0"), "k": 0.5 * (1 + 5e-8)}
    again = ri.estimate(spec, data, guess=past)
    assert again.success and again.value("k") <= 0.5 + 2e-8       # IPOPT: the bound relaxed by 1e-8 max(1, |b|)
    assert again.objective == pytest.approx(fit.objective, rel=1e-6)
    with pytest.raises(ri.ModelError, match="the guess 0.51 of parameter k lies outside its bounds"):
        ri.estimate(spec, data, guess={"k": 0.51})


@pytest.mark.parametrize("free_start", [False, True])
def test_linear_in_parameter_fit_equals_least_squares(free_start):
    """y' = c u with u = 1: y = y0 + c t. The maximum-likelihood c (and y0) from noisy
    samples are the linear least-squares solution: sum(t y) / sum(t^2) with y0 = 0 fixed."""
    m = ri.Model("ramp", 0.0, 5.0)
    y = m.state("y", 0.0, free=free_start)
    u = m.input("u", sp.Integer(1))
    c = m.parameter("c", 1.0)
    m.ode({y: c * u})
    m.output("y", y, sigma=0.5)
    spec = m.freeze()
    rng = np.random.default_rng(3)
    t = np.linspace(0.05, 5.0, 100)
    y_meas = 0.5 + 2.5 * t + rng.normal(0.0, 0.5, t.size)
    fit = ri.estimate(spec, ri.Measurements.from_arrays(t, {"y": y_meas}))
    assert fit.success, fit.summary()
    if free_start:
        intercept, slope = np.linalg.lstsq(np.column_stack([np.ones_like(t), t]), y_meas, rcond=None)[0]
        assert fit.value("y_0") == pytest.approx(intercept, rel=1e-8)
    else:
        slope = float(t @ y_meas / (t @ t))
    assert fit.value("c") == pytest.approx(slope, rel=1e-8)
    residual = y_meas - (fit.value("y_0") if free_start else 0.0) - slope * t
    assert fit.objective == pytest.approx(0.5 * float(residual @ residual) / 0.25, rel=1e-8)


def test_output_with_a_state_derivative_round_trip():
    """An output ``x + b dx/dt`` (a lagging sensor): simulated measurements use ds/dt from the
    model, and the fit of noise-free data returns the parameters."""
    m = ri.Model("lag", 0.0, 3.0)
    x = m.state("x", 0.0)
    u = m.input("u", 1 + sp.sin(3 * m.t))
    a = m.parameter("a", 1.0, bounds=(0.1, 10.0))
    b = m.parameter("b", 0.1, bounds=(-1.0, 1.0))
    m.ode({x: -a * x + u})
    m.output("xm", x + b * m.der(x), sigma=0.01)
    spec = m.freeze()
    truth = spec.parameter_vector({a: 2.0, b: 0.3})
    t = np.arange(1, 301) * 0.01
    traj = ri.simulate(spec, truth, t)
    xs = traj.value(x)
    expected = xs + 0.3 * (-2.0 * xs + 1 + np.sin(3 * t))
    data = ri.simulate_measurements(spec, truth, t, noise=False)
    np.testing.assert_allclose(data["xm"].values, expected, rtol=1e-12, atol=1e-12)
    fit = ri.estimate(spec, data)
    assert fit.success, fit.summary()
    np.testing.assert_allclose(fit.p, truth, rtol=1e-5)
    assert math.isfinite(fit.objective) and fit.objective < 1e-4
