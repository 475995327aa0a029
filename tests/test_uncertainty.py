"""Uncertainty of estimates from the reduced Hessian (beyond the chapter).

* Coverage: over 100 noisy data sets of a small identifiable model (a decay with a gain,
  50 samples), the 95 % intervals cover the truth about 95 % of the time, both for the full
  estimation (7.5) and for (7.9) with one direction fixed at its true value.
  Tolerance from the binomial distribution: if the intervals are right, the count of covers
  in n = 100 is Binomial(100, 0.95); P(count <= 86) = 4.6e-4, so the test accepts 87..100
  (a false alarm at most once in about 2000 runs per parameter; the seeds are fixed, so in
  practice the test is deterministic). A count of 100 is not rejected (probability 0.6 %),
  so the scale of the standard errors is also checked from both sides: the mean of
  ((estimate - truth) / standard error)^2 over the data sets is chi-square(100)/100 when the
  errors are right, inside [0.55, 1.6] with probability 1 - 2e-4.
* Grid: the covariance of RA-66's estimates does not depend on the collocation grid
  (N = 66 and N = 132 elements, K = 4, agree to 1e-5 relative in every standard error).
* Notes: active bounds, ill-conditioning, a noise sigma that does not match the residuals;
  refusal when the estimated directions are not identifiable.
"""

from __future__ import annotations

import numpy as np
import pytest
import sympy as sp
from scipy.stats import binom, chi2

import rocketid as ri
from rocketid.errors import SensitivityError
from rocketid.estimability import Uncertainty, analyze, estimate_q1, uncertainty

N_DATASETS = 100
LEVEL = 0.95
COVER_MIN = 87                 # binom.ppf(5e-4, 100, 0.95): P(count < 87) = 4.6e-4
SCALE_RANGE = (0.55, 1.6)      # mean of chi-square(1) over 100 data sets: P(outside) = 2e-4

TRUTH = {"k": 0.8, "g": 2.0}
TIMES = np.linspace(0.1, 5.0, 50)
MESH = ri.uniform_mesh(0.0, 5.0, 10, 4)


def decay_with_gain(*, k_upper: float = 10.0, unused: bool = False) -> ri.ModelSpec:
    """``dx/dt = -k x + g u(t)``, ``u = 1 + sin 2t``, x measured with sigma 0.05."""
    m = ri.Model("decay_gain", 0.0, 5.0)
    x = m.state("x", 0.0)
    u = m.input("u", 1 + sp.sin(2 * m.t))
    k = m.parameter("k", 0.5, bounds=(0.01, k_upper))
    g = m.parameter("g", 1.0, bounds=(0.01, 10.0))
    if unused:
        m.parameter("c", 1.0, bounds=(0.0, 2.0))
    m.ode({x: -k * x + g * u})
    m.output("x", x, sigma=0.05)
    return m.freeze()


def test_the_stated_tolerances_follow_from_the_binomial_and_chi_square_laws():
    assert binom.ppf(5e-4, N_DATASETS, LEVEL) == COVER_MIN
    assert binom.cdf(COVER_MIN - 1, N_DATASETS, LEVEL) < 1e-3
    lo, hi = SCALE_RANGE
    assert chi2.cdf(lo * N_DATASETS, N_DATASETS) + chi2.sf(hi * N_DATASETS, N_DATASETS) < 3e-4


@pytest.fixture(scope="module")
def repeated_fits():
    """Full and (7.9) fits of the decay model on N_DATASETS noisy data sets."""
    spec = decay_with_gain()
    truth = spec.parameter_vector(TRUTH)
    first = ri.prepare(spec, ri.simulate_measurements(spec, truth, TIMES, seed=0), mesh=MESH)
    # one fixed direction (the weaker one), kept at its true value: q1 is the stronger one
    est = analyze(first, n_estimated=1)
    q2_true = est.q2_of(truth)
    full, reduced = [], []
    for seed in range(N_DATASETS):
        data = ri.simulate_measurements(spec, truth, TIMES, seed=seed)
        prepared = ri.prepare(spec, data, mesh=MESH)
        fit = ri.estimate(spec, data, prepared=prepared)
        assert fit.success, (seed, fit.message)
        full.append(uncertainty(fit))
        fit1 = estimate_q1(prepared, est, q2_true)
        assert fit1.success, (seed, fit1.message)
        reduced.append(uncertainty(fit1))
    return truth, est, full, reduced


def coverage(results: list[Uncertainty], truth: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Number of intervals covering the truth, and mean squared standardized error, per parameter."""
    covers = np.zeros(truth.size, int)
    z2 = np.zeros(truth.size)
    for u in results:
        iv = u.interval(LEVEL)
        covers += (iv[:, 0] <= truth) & (truth <= iv[:, 1])
        z2 += ((u.estimates - truth) / u.standard_errors) ** 2
    return covers, z2 / len(results)


def test_95_percent_intervals_cover_the_truth_95_percent_of_the_time(repeated_fits):
    truth, _, full, _ = repeated_fits
    covers, scale = coverage(full, truth)
    print(f"\nfull estimation, {N_DATASETS} data sets: 95 % intervals cover k {covers[0]}, g {covers[1]} times; "
          f"mean z^2 k {scale[0]:.2f}, g {scale[1]:.2f}")
    assert np.all(covers >= COVER_MIN), covers
    assert np.all((SCALE_RANGE[0] <= scale) & (scale <= SCALE_RANGE[1])), scale
    # with 48 degrees of freedom chi2/dof falls outside [0.67, 1.5] in about 4 % of data sets
    # (a note then says so); nothing else is noted
    notes = [n for u in full for n in u.notes]
    assert all(n.startswith("chi2/dof = ") for n in notes), notes
    assert len(notes) <= 12


def test_coverage_of_the_estimated_direction_with_q2_fixed(repeated_fits):
    """With q2 at its true value, p = P q1 + c is right exactly when q1 is: each physical
    interval is the q1 interval scaled, and covers the truth as often."""
    truth, est, _, reduced = repeated_fits
    covers, scale = coverage(reduced, truth)
    print(f"\n(7.9), q2 at its true value: 95 % intervals cover k {covers[0]}, g {covers[1]} times; "
          f"mean z^2 {scale[0]:.2f}")
    assert covers[0] == covers[1]                      # one direction: both or neither
    assert covers[0] >= COVER_MIN
    assert SCALE_RANGE[0] <= scale[0] <= SCALE_RANGE[1]
    u = reduced[0]
    assert u.names == ("q1",) and u.covariance.shape == (1, 1)
    assert np.linalg.matrix_rank(u.parameter_covariance) == 1
    # the fixed direction carries no variance
    P2 = est.V2
    assert abs((P2.T @ u.parameter_covariance @ P2).item()) < 1e-12 * np.trace(u.parameter_covariance)


# ---------------------------------------------------------------------------
# RA-66: grid independence and the covariance formulas
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def ra66_fine_fit(ra66_spec, ra66_noisy):
    return ri.estimate(ra66_spec, ra66_noisy, mesh=ri.ra66_mesh(132, K=4))


def test_covariance_does_not_depend_on_the_grid(ra66_noisy_fit, ra66_fine_fit):
    assert ra66_noisy_fit.prepared.transcription.mesh.n_elements == 66
    assert ra66_fine_fit.prepared.transcription.mesh.n_elements == 132
    assert ra66_fine_fit.success
    u66, u132 = uncertainty(ra66_noisy_fit), uncertainty(ra66_fine_fit)
    rel = np.abs(u132.standard_errors / u66.standard_errors - 1)
    dcorr = np.abs(u132.correlations - u66.correlations).max()
    print("\nRA-66 standard errors, N = 66: " + ", ".join(f"{n} {s:.3g}" for n, s in
                                                          zip(u66.parameter_names, u66.standard_errors))
          + f"\n  N = 132 vs 66: max relative difference {rel.max():.1e}, correlations {dcorr:.1e}")
    assert rel.max() < 1e-3                            # "a few percent" asked; 1e-5 measured
    assert dcorr < 1e-3


def test_index0_covariance_does_not_depend_on_the_grid(ra66_spec, ra66_noisy, ra66_noisy_fit):
    prepared66 = ra66_noisy_fit.prepared
    est = analyze(prepared66, scaling="nominal")
    q2 = est.q2_of(ra66_spec.guess)
    u66 = uncertainty(estimate_q1(prepared66, est, q2))
    u132 = uncertainty(estimate_q1(ri.prepare(ra66_spec, ra66_noisy, mesh=ri.ra66_mesh(132, K=4)), est, q2))
    rel = np.abs(np.sqrt(np.diag(u132.covariance) / np.diag(u66.covariance)) - 1)
    print(f"\nindex 0: standard errors of q1..q5, N = 132 vs 66: max relative difference {rel.max():.1e}")
    assert rel.max() < 1e-3


def test_full_covariance_is_the_inverse_reduced_hessian(ra66_noisy_fit):
    from rocketid.sensitivity import sensitivity_of
    sens = sensitivity_of(ra66_noisy_fit)
    u = uncertainty(ra66_noisy_fit, sensitivity=sens)
    assert u.names == ra66_noisy_fit.spec.parameter_names
    assert np.allclose(u.parameter_covariance @ sens.H_r, np.eye(8), atol=1e-6)
    assert np.allclose(np.diag(u.correlations), 1.0)
    assert np.all(np.abs(u.correlations) <= 1 + 1e-12)
    assert 1e6 < u.condition_number < 1e9
    # 0.9 < chi2/dof < 1.1 for this fit, no bound active: nothing to note
    assert u.notes == ()
    text = u.summary().text()
    assert "95% interval" in text and "CD0" in text and "condition number" in text


def test_index0_notes_that_sigma_does_not_match(ra66_noisy_fit, ra66_spec):
    prepared = ra66_noisy_fit.prepared
    est = analyze(prepared, scaling="nominal")
    fit = estimate_q1(prepared, est, est.q2_of(ra66_spec.guess))
    u = uncertainty(fit)
    print("\n" + u.summary().text())
    assert u.names == ("q1", "q2", "q3", "q4", "q5")
    assert np.linalg.matrix_rank(u.parameter_covariance, tol=1e-12 * u.parameter_covariance.max()) == 5
    assert any(n.startswith("chi2/dof = 37") for n in u.notes)


# ---------------------------------------------------------------------------
# Notes and refusals on the small model
# ---------------------------------------------------------------------------


def small_fit(spec, *, seed=0, sigma=None):
    data = ri.simulate_measurements(spec, TRUTH, TIMES, seed=seed)
    if sigma is not None:
        data = ri.Measurements(tuple(ri.Channel(c.name, c.times, c.values, sigma) for c in data.channels))
    return ri.estimate(spec, data, mesh=MESH)


def test_active_bound_is_noted():
    fit = small_fit(decay_with_gain(k_upper=0.6))      # true k = 0.8
    u = uncertainty(fit)
    assert fit.p[0] == pytest.approx(0.6)
    assert "k is at its upper bound: its interval is not valid on that side" in u.notes


def test_active_bound_row_of_q2_fixed_problem_is_noted():
    spec = decay_with_gain(k_upper=0.6)
    fit0 = small_fit(spec)
    est = analyze(fit0.prepared, n_estimated=1)
    fit = estimate_q1(fit0.prepared, est, est.q2_of(spec.parameter_vector({"k": 0.5, "g": 2.0})))
    u = uncertainty(fit)
    assert "k is at a bound in (7.9): its linear bound constraint is active" in u.notes


def test_ill_conditioning_is_noted():
    u = uncertainty(small_fit(decay_with_gain()), ill_conditioned=10.0)
    assert u.condition_number > 10
    assert any("ill-conditioned" in n for n in u.notes)


def test_wrong_sigma_is_noted():
    u = uncertainty(small_fit(decay_with_gain(), sigma=0.01))    # true noise 0.05: chi2/dof about 25
    assert any(n.startswith("chi2/dof = ") and "off by about" in n for n in u.notes)


def test_unidentifiable_parameters_are_refused():
    fit = small_fit(decay_with_gain(unused=True))
    with pytest.raises(SensitivityError, match="not identifiable"):
        uncertainty(fit)


def _ar1(rng: np.random.Generator, n: int, rho: float) -> np.ndarray:
    """Unit-variance AR(1) noise: e_i = rho e_{i-1} + sqrt(1 - rho^2) w_i (written here, not rocketid's)."""
    w = rng.normal(size=n)
    e = np.empty(n)
    e[0] = w[0]
    for i in range(1, n):
        e[i] = rho * e[i - 1] + np.sqrt(1 - rho ** 2) * w[i]
    return e


def _ra66_with_noise(rho: float, seed: int):
    from rocketid.cases.ra66 import ra66, ra66_times, ra66_truth
    from rocketid.simulate import simulate
    spec = ra66()
    truth = ra66_truth(spec)
    t = ra66_times()
    clean = simulate(spec, truth, times=t).outputs()
    rng = np.random.default_rng(seed)
    data = ri.Measurements(tuple(ri.Channel(c, t, np.asarray(clean[c]) + _ar1(rng, t.size, rho), 1.0)
                                 for c in ("x", "h", "v")))
    return ri.estimate(spec, data), truth


def test_coloured_errors_cover_the_truth_where_white_ones_do_not():
    """RA-66 with AR(1) noise of correlation 0.9 between samples (unit variance, so the stated sigma is right
    and chi2/dof is near 1): the white-noise intervals are too short by about sqrt((1 + rho) / (1 - rho)) =
    4.4, the coloured ones cover the truth about 95 % of the time (8 data sets, 64 intervals; 30 sets,
    ``benchmarks/coloured_coverage.py``, gave 91.7 % against 34.6 %)."""
    hit_white = hit_col = total = 0
    for seed in range(8):
        fit, truth = _ra66_with_noise(0.9, seed)
        white, col = uncertainty(fit), uncertainty(fit, coloured=True)
        err = np.abs(fit.p - truth)
        hit_white += int(np.sum(err <= 1.96 * white.standard_errors))
        hit_col += int(np.sum(err <= 1.96 * col.standard_errors))
        total += err.size
        assert 3.0 < np.median(col.standard_errors / white.standard_errors) < 6.0
        assert "coloured residuals" in col.notes[-1]
    assert hit_white / total < 0.7
    assert hit_col / total >= 0.85


def test_coloured_errors_equal_white_ones_on_white_residuals():
    """On white residuals at the stated sigma the sandwich estimates the information itself: the same
    standard errors to sampling error, with few or no lags."""
    fit, _ = _ra66_with_noise(0.0, 3)
    ratio = uncertainty(fit, coloured=True).standard_errors / uncertainty(fit).standard_errors
    assert np.all(np.abs(ratio - 1) < 0.15), ratio
