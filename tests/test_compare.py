"""Compare (ISSUE 5, item 2): each channel against the model, with its fit statistics.

The statistics are checked against their definitions and against SciPy
(Jarque-Bera; Ljung-Box against a direct sum and ``scipy.stats.chi2``), eta
(7.10) against its definition in docs/design.md (eta = |s1| + |k1 - 3| + |s1 - s2| + |k1 - k2|), and ``compare`` on a correct model (RA-66 on
its own data: white noise) and on data with a hidden effect (RA-66M with nozzle
back-pressure: fails visibly).
"""

from __future__ import annotations

import importlib
import math

import numpy as np
import pytest
import scipy.stats

import rocketid as ri
from rocketid.errors import DataError, SettingsError

# the module (the package rocketid.diagnostics exports the function compare under the same name)
cmp = importlib.import_module("rocketid.diagnostics.compare")


# ---------------------------------------------------------------------------
# the statistics, one series at a time
# ---------------------------------------------------------------------------


def _ljung_box_direct(e, h):
    e = np.asarray(e, float)
    n = e.size
    d = e - e.mean()
    c0 = d @ d
    rho = np.array([d[k:] @ d[:n - k] / c0 for k in range(1, h + 1)])
    q = n * (n + 2) * np.sum(rho ** 2 / (n - np.arange(1, h + 1)))
    return q, scipy.stats.chi2.sf(q, h), rho


@pytest.mark.parametrize("n, h", [(50, 5), (1000, 20), (6600, 20)])
def test_ljung_box_matches_its_definition(n, h):
    e = np.random.default_rng(n).normal(size=n)
    lb = cmp.ljung_box(e, h)
    q, p, rho = _ljung_box_direct(e, h)
    assert lb.statistic == pytest.approx(q, rel=1e-10)
    assert lb.p_value == pytest.approx(p, rel=1e-8)
    assert lb.dof == h
    np.testing.assert_allclose(lb.autocorrelation[1:], rho, atol=1e-12)
    assert lb.autocorrelation[0] == pytest.approx(1.0)


def test_ljung_box_separates_white_from_coloured_noise():
    rng = np.random.default_rng(1)
    white = rng.normal(size=6600)
    # white noise: p-values are uniform; over 200 series about 5 % fall below 0.05
    ps = [cmp.ljung_box(rng.normal(size=2000)).p_value for _ in range(200)]
    assert 0.01 <= np.mean(np.array(ps) < 0.05) <= 0.10
    assert cmp.ljung_box(white).p_value > 1e-3
    ar = np.empty_like(white)
    ar[0] = white[0]
    for i in range(1, ar.size):  # AR(1), rho = 0.3
        ar[i] = 0.3 * ar[i - 1] + white[i]
    lb = cmp.ljung_box(ar)
    assert lb.p_value < 1e-10
    assert lb.lag1 == pytest.approx(0.3, abs=0.05)


def test_ljung_box_default_lags_and_refusals():
    assert cmp.ljung_box(np.arange(40.0)).dof == 8  # n // 5 for short series
    assert cmp.ljung_box(np.random.default_rng(0).normal(size=500)).dof == cmp.DEFAULT_LAGS
    with pytest.raises(DataError, match="at least 10"):
        cmp.ljung_box(np.ones(5))
    with pytest.raises(DataError, match="lags"):
        cmp.ljung_box(np.random.default_rng(0).normal(size=20), 25)


def test_normality_is_scipys_jarque_bera():
    rng = np.random.default_rng(2)
    for e in (rng.normal(size=3000), rng.standard_t(4, size=3000), rng.exponential(size=500)):
        ref = scipy.stats.jarque_bera(e)
        got = cmp.normality(e)
        assert got.statistic == pytest.approx(ref.statistic, rel=1e-12)
        assert got.p_value == pytest.approx(ref.pvalue, rel=1e-9, abs=1e-300)
        assert got.skewness == pytest.approx(scipy.stats.skew(e), rel=1e-10)
        assert got.kurtosis == pytest.approx(scipy.stats.kurtosis(e, fisher=False), rel=1e-10)
    assert cmp.normality(rng.exponential(size=2000)).p_value < 1e-10


def test_theil_coefficient_and_proportions():
    rng = np.random.default_rng(3)
    y = np.linspace(0, 100, 500)
    perfect = cmp.theil(y, y)
    assert perfect.U == 0 and perfect.covariance == 1
    noisy = cmp.theil(y + rng.normal(size=y.size), y)
    assert 0 < noisy.U < 0.01
    assert noisy.bias + noisy.variance + noisy.covariance == pytest.approx(1.0, abs=1e-9)
    assert noisy.covariance > 0.9  # unsystematic
    biased = cmp.theil(y + 5.0, y)
    assert biased.bias == pytest.approx(1.0, abs=1e-9)
    U = math.sqrt(25.0) / (math.sqrt(np.mean((y + 5) ** 2)) + math.sqrt(np.mean(y ** 2)))
    assert biased.U == pytest.approx(U)
    assert cmp.theil(-y, y).U == pytest.approx(1.0)


def test_eta_and_its_terms_follow_method_section_5():
    rng = np.random.default_rng(4)
    res = {"x": rng.normal(0, 2, 800), "h": rng.standard_t(5, 800) * 0.5}
    sig = {"x": 2.0, "h": 0.5}
    crit, source = cmp.criterion_terms(res, sig)
    assert source == "rocketid.sampling.criterion"
    e = np.concatenate([res["x"] / 2.0, res["h"] / 0.5])
    s1, k1 = np.mean(e ** 3), np.mean(e ** 4)
    d = e - e.mean()
    s2 = np.mean(d ** 3) / np.mean(d ** 2) ** 1.5
    k2 = np.mean(d ** 4) / np.mean(d ** 2) ** 2
    terms = [abs(s1), abs(k1 - 3), abs(s1 - s2), abs(k1 - k2)]
    assert [crit[k] for k in ("|s1|", "|k1-3|", "|s1-s2|", "|k1-k2|")] == pytest.approx(terms, rel=1e-10)
    assert crit["eta"] == pytest.approx(sum(terms), rel=1e-10)


def test_eta_has_one_implementation():
    """Issue 12: compare() no longer carries its own copy of eta (7.10); it is the sampling
    stage's statistic_criterion, value for value."""
    from rocketid.sampling.criterion import statistic_criterion
    rng = np.random.default_rng(5)
    res, sig = {"x": rng.normal(size=500), "h": 3 * rng.standard_t(4, 500)}, {"x": 1.0, "h": 3.0}
    got, source = cmp.criterion_terms(res, sig)
    assert source == "rocketid.sampling.criterion"
    assert got == statistic_criterion(res, sig).as_dict()
    # (that its docstring cites no working notes is checked with every file: test_docs)


# ---------------------------------------------------------------------------
# compare() on fits
# ---------------------------------------------------------------------------


def test_compare_a_correct_model_is_white_noise(ra66_noisy_fit):
    c = cmp.compare(ra66_noisy_fit)
    assert c.fits_to_noise
    assert c.names == ("x", "h", "v")
    assert c.chi2_per_dof == pytest.approx(ra66_noisy_fit.chi2_per_dof)
    for ch in c.channels:
        np.testing.assert_array_equal(ch.residual, ra66_noisy_fit.residuals[ch.name])
        np.testing.assert_allclose(ch.residual, ch.predicted - ch.measured, atol=1e-9)
        assert ch.rms == pytest.approx(ra66_noisy_fit.rms[ch.name])
        assert 0.95 < ch.chi2_per_dof < 1.05
        assert abs(ch.bias_z) < 4
        assert 0.035 < ch.outside_2sigma < 0.06
        assert ch.whiteness.p_value > 1e-3
        assert ch.theil.U < 2e-3 and ch.theil.covariance > 0.99
    # chi2/dof of the channels: sum(e^2) over the shared degrees of freedom adds up to the fit's
    total = sum(ch.chi2_per_dof * (ch.n - c.n_estimated * ch.n / c.n_data) for ch in c.channels)
    assert total / (c.n_data - c.n_estimated) == pytest.approx(c.chi2_per_dof, rel=1e-9)
    assert c.eta < 0.3
    assert not c.notes
    text = c.summary()
    for word in ("chi2 / dof", "Ljung-Box", "eta", "Theil U", "JB p"):
        assert word in text or word.replace("Ljung-Box", "LB p") in text


def test_compare_fails_visibly_on_a_hidden_effect(bp_fit):
    c = cmp.compare(bp_fit)
    assert not c.fits_to_noise
    assert c.chi2_per_dof > 5
    assert c["h"].whiteness.p_value < 1e-10
    assert c["h"].whiteness.lag1 > 0.9
    assert any("not white" in n for n in c.notes)
    assert any("99.9 %" in n for n in c.notes)
    assert "Notes" in c.summary() and "[1]" in c.summary()
    d = c.to_dict()
    assert d["fits_to_noise"] is False and len(d["channels"]) == 3


def test_compare_plots(bp_fit, tmp_path):
    c = cmp.compare(bp_fit)
    axes = c.plot(tmp_path / "c.png")
    assert axes.shape == (3, 2) and len(axes[0, 0].figure.axes) == 6
    assert (tmp_path / "c.png").stat().st_size > 10_000
    assert c.plot_autocorrelation() is not None


def test_compare_refuses_bad_input(ra66_noisy_fit):
    with pytest.raises(SettingsError, match="EstimationResult"):
        cmp.compare("fit")
    with pytest.raises(SettingsError, match="level"):
        cmp.compare(ra66_noisy_fit, level=1.5)


# ---------------------------------------------------------------------------
# fixtures
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def bp_fit():
    """RA-66M fitted to data with a hidden nozzle back-pressure (A_e = 0.1 m^2)."""
    from rocketid.cases import ra66m, ra66m_truth
    from rocketid.diagnostics.effects import with_effects

    truth_spec = with_effects(ra66m(), "back_pressure_vacuum", {"A_e_vac": 0.1})
    p = ra66m_truth(truth_spec)  # the effect's parameter keeps the value given to with_effects
    assert p[truth_spec.parameter_names.index("A_e_vac")] == 0.1
    data = ri.simulate_measurements(truth_spec, p, ri.ra66_times(), seed=0)
    return ri.estimate(ra66m(), data)
