"""Noise levels estimated with the parameters (maximum likelihood, the output-error relaxation).

Truths come from outside the code under test: the noise levels the data were simulated with
(SciPy's DOP853 at tolerance 1e-12 plus seeded Gaussian noise), and, for the coverage study,
the true parameters over repeated data sets.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

import rocketid as ri
from rocketid.cli import main
from rocketid.errors import DataError
from rocketid.estimability import uncertainty
from rocketid.sampling.criterion import criterion_of, statistic_criterion

SIGMA = {"x": 2.0, "h": 0.5, "v": 1.5}


@pytest.fixture(scope="module")
def ra66_unequal(ra66_spec, ra66_p_true):
    """RA-66 data whose noise levels differ from the model's sigma = 1 in every channel (the
    channels do not carry the simulated sigma: the fit starts from the model's)."""
    data = ri.simulate_measurements(ra66_spec, ra66_p_true, ri.ra66_times(), seed=7, sigma=SIGMA)
    return ri.Measurements(tuple(ri.Channel(c.name, c.times, c.values) for c in data.channels))


@pytest.fixture(scope="module")
def ra66_sigma_fit(ra66_spec, ra66_unequal):
    return ri.estimate(ra66_spec, ra66_unequal, sigma="estimate")


def test_recovers_known_sigmas_on_ra66(ra66_sigma_fit, ra66_p_true):
    fit = ra66_sigma_fit
    assert fit.success, fit.message
    assert fit.sigma_estimated == ("x", "h", "v")
    for k, s in SIGMA.items():
        assert abs(fit.sigma[k] / s - 1) < 0.02, (k, fit.sigma[k])
        # the stated uncertainty is sigma / sqrt(2 n): 0.87 % of sigma for 6600 samples
        assert fit.sigma_std[k] == pytest.approx(fit.sigma[k] / np.sqrt(2 * 6600), rel=1e-12)
        assert abs(fit.sigma[k] - s) < 4 * fit.sigma_std[k]
    assert np.allclose(fit.p, ra66_p_true, atol=0.02)
    # the fixed point of the relaxation: each sigma is the RMS of its channel's residuals
    for k in SIGMA:
        assert fit.sigma[k] == pytest.approx(fit.rms[k], rel=1e-5)
    # the estimated sigmas are the data's sigmas downstream (covariance, eta, score test)
    assert all(fit.prepared.measurements[k].sigma == fit.sigma[k] for k in SIGMA)
    assert fit.chi2_per_dof == pytest.approx(fit.n_data / (fit.n_data - fit.n_estimated), rel=1e-4)


def test_estimated_sigma_weights_the_covariance(ra66_spec, ra66_unequal, ra66_sigma_fit):
    """The standard errors follow the estimated sigmas: a fit with the true sigmas given gives
    the same errors (within the sigmas' own estimation error), a fit with the model's sigma = 1
    does not."""
    given = ri.estimate(ra66_spec, ra66_unequal, sigma=SIGMA)
    wrong = ri.estimate(ra66_spec, ra66_unequal)
    se_est = uncertainty(ra66_sigma_fit).standard_errors
    se_true = uncertainty(given).standard_errors
    se_wrong = uncertainty(wrong).standard_errors
    assert np.allclose(se_est, se_true, rtol=0.03)
    assert not np.allclose(se_wrong, se_true, rtol=0.2)


def test_eta_loses_its_spread_terms_when_sigma_is_estimated(ra66_spec, ra66_unequal, ra66_sigma_fit):
    """eta (7.10) with the model's wrong sigma = 1 sees the wrong spread (k1 far from 3); with the
    sigma estimated, the normalized residuals have mean square 1 by construction, so eta is at
    its noise level (about sqrt(96 / n)): it no longer tests the spread, only the shape."""
    wrong = ri.estimate(ra66_spec, ra66_unequal)
    assert criterion_of(wrong).eta > 1.0
    c = criterion_of(ra66_sigma_fit)
    assert c.eta < 5 * np.sqrt(96 / c.n)
    assert abs(c.k1 - c.k2) < 0.01
    # still a test of the shape: uniform (not Gaussian) noise of the same spread gives k1 = 1.8
    rng = np.random.default_rng(0)
    u = rng.uniform(-np.sqrt(3), np.sqrt(3), 20000)
    assert statistic_criterion(u / np.sqrt(np.mean(u ** 2))).eta > 1.0


def test_one_channel_estimated_the_others_given(ra66_spec, ra66_unequal):
    fit = ri.estimate(ra66_spec, ra66_unequal, sigma={"x": 2.0, "h": "estimate", "v": 1.5})
    assert fit.success
    assert fit.sigma_estimated == ("h",)
    assert fit.sigma["x"] == 2.0 and fit.sigma["v"] == 1.5
    assert abs(fit.sigma["h"] / SIGMA["h"] - 1) < 0.02
    assert set(fit.sigma_std) == {"h"}


def test_coverage_of_intervals_with_estimated_sigma():
    """Over repeated data sets, the 95 % intervals computed with the estimated sigma hold the
    truth about 95 % of the time (two parameters, 80 data sets: 160 intervals; the binomial
    standard deviation of the coverage is 1.7 %)."""
    m = ri.Model("decay2", t0=0.0, tf=2.0)
    y = m.state("y", initial=1.0, free=True, bounds=(0.0, 10.0))
    k = m.parameter("k", guess=0.5, bounds=(0.0, 10.0))
    m.ode({y: -k * y})
    m.output("y", y, sigma=1.0)               # the model's sigma is 50x the truth
    spec = m.freeze()
    truth = np.array([1.3 if n == "k" else 2.0 for n in spec.parameter_names])
    times = np.linspace(0.02, 2.0, 100)
    mesh = ri.default_mesh(spec, K=4, element_length=0.2)
    hits, sig = [], []
    for seed in range(80):
        data = ri.simulate_measurements(spec, truth, times, seed=seed, sigma={"y": 0.02})
        fit = ri.estimate(spec, data, sigma="estimate", mesh=mesh)
        assert fit.success
        ci = uncertainty(fit).interval(0.95)
        hits.extend((ci[:, 0] <= truth) & (truth <= ci[:, 1]))
        sig.append(fit.sigma["y"])
    coverage = np.mean(hits)
    assert 0.90 <= coverage <= 0.99, coverage
    # the ML sigma is biased low by the fitted parameters: E[sigma^2] = sigma^2 (n - p) / n
    assert np.mean(np.square(sig)) == pytest.approx(0.02 ** 2 * (100 - 2) / 100, rel=0.05)


@pytest.mark.slow
def test_coverage_on_ra66_sizes(ra66_spec, ra66_p_true):
    """The same coverage study on RA-66 (8 parameters, 19 800 values, 40 data sets with
    sigma = 2, 0.5, 1.5 unknown): about 45 s on one core."""
    hits = []
    for seed in range(40):
        data = ri.simulate_measurements(ra66_spec, ra66_p_true, ri.ra66_times(), seed=100 + seed, sigma=SIGMA)
        fit = ri.estimate(ra66_spec, data, sigma="estimate")
        assert fit.success
        ci = uncertainty(fit).interval(0.95)
        hits.extend((ci[:, 0] <= ra66_p_true) & (ra66_p_true <= ci[:, 1]))
    assert 0.90 <= np.mean(hits) <= 0.99, np.mean(hits)


def test_cli_sigma_estimate_writes_fit_json(tmp_path, ra66_unequal):
    data = tmp_path / "d.csv"
    ra66_unequal.to_csv(data)
    out = tmp_path / "fit.json"
    r = CliRunner().invoke(main, ["estimate", str(data), "--sigma", "h=estimate", "--sigma", "x=2",
                                  "--sigma", "v=1.5", "--out", str(out)])
    assert r.exit_code == 0, r.output
    d = json.loads(out.read_text())
    assert d["sigma_estimated"] == ["h"]
    assert d["sigma"]["x"] == 2.0 and abs(d["sigma"]["h"] / 0.5 - 1) < 0.02
    assert set(d["std_err"]) == {f"CD{i}" for i in range(7)} | {"CL"}
    assert "std err" in r.output and "(estimated)" in r.output
    r = CliRunner().invoke(main, ["estimate", str(data), "--sigma", "estimate", "--out", str(out)])
    assert r.exit_code == 0, r.output
    assert json.loads(out.read_text())["sigma_estimated"] == ["x", "h", "v"]


@pytest.mark.parametrize("args, fragment", [
    (["--sigma", "estimate", "--sigma", "h=2"], "cannot be combined"),
    (["--sigma", "q=estimate"], "has no output 'q'"),
    (["--sigma", "h=guess"], "is not a number or 'estimate'"),
    (["--sigma", "estimated"], "is not NAME=VALUE, NAME=estimate or estimate"),
    (["--sigma", "h=estimate", "--sigma", "h=1"], "given twice"),
])
def test_cli_bad_sigma_requests(tmp_path, args, fragment):
    data = tmp_path / "d.csv"
    data.write_text("t,x,h,v\n" + "".join(f"{0.1 * k:.1f},{k},{k},{k}\n" for k in range(1, 20)))
    r = CliRunner().invoke(main, ["estimate", str(data), *args])
    assert r.exit_code == 2
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error:") and fragment in lines[0], r.output


def test_estimability_at_guess_refuses_sigma_estimate(tmp_path):
    data = tmp_path / "d.csv"
    data.write_text("t,x,h,v\n" + "".join(f"{0.1 * k:.1f},{k},{k},{k}\n" for k in range(1, 20)))
    r = CliRunner().invoke(main, ["estimability", str(data), "--sigma", "estimate", "--out", str(tmp_path / "e.json")])
    assert r.exit_code == 2 and "--at fit" in r.output


def test_api_bad_sigma_requests(ra66_spec, ra66_unequal):
    with pytest.raises(DataError, match="no channel 'q'"):
        ri.estimate(ra66_spec, ra66_unequal, sigma={"q": "estimate"})
    with pytest.raises(DataError, match="give 'estimate'"):
        ri.estimate(ra66_spec, ra66_unequal, sigma="estimat")
    with pytest.raises(DataError, match="positive and finite"):
        ri.estimate(ra66_spec, ra66_unequal, sigma={"h": -1.0})


def test_sigma_request_unit():
    from rocketid.data import sigma_request
    assert sigma_request(None, ("x", "h")) == ({}, ())
    assert sigma_request("estimate", ("x", "h")) == ({}, ("x", "h"))
    assert sigma_request({"h": "estimate", "x": 2}, ("x", "h")) == ({"x": 2.0}, ("h",))
    with pytest.raises(DataError, match="positive number or 'estimate'"):
        sigma_request({"x": "two"}, ("x",))


def test_cli_estimability_at_fit_with_sigma_estimate(tmp_path, ra66_unequal):
    data = ra66_unequal.to_csv(tmp_path / "d.csv")
    out = tmp_path / "est.json"
    r = CliRunner().invoke(main, ["estimability", str(data), "--sigma", "estimate", "--at", "fit", "--out", str(out)])
    assert r.exit_code == 0, r.output
    est = json.loads(out.read_text())
    assert est["at"] == "fit" and est["fit"]["success"]
    assert est["fit"]["sigma_estimated"] == ["x", "h", "v"]
    assert all(abs(est["fit"]["sigma"][k] / s - 1) < 0.02 for k, s in SIGMA.items()), est["fit"]["sigma"]
    # H_r is weighted by the estimated sigmas: its eigenvalues are those of a fit with the true sigmas given
    given = tmp_path / "given.json"
    r = CliRunner().invoke(main, ["estimability", str(data), "--at", "fit", "--out", str(given),
                                  *[a for k, s in SIGMA.items() for a in ("--sigma", f"{k}={s}")]])
    assert r.exit_code == 0, r.output
    np.testing.assert_allclose(est["eigenvalues"], json.loads(given.read_text())["eigenvalues"], rtol=0.1)


def test_cli_diagnose_with_sigma_estimate(tmp_path, ra66_unequal):
    """A quick diagnosis (no refits, no hold-out) of RA-66 data with unstated noise: the sigmas are
    estimated from the data alone (fourth differences, not the base fit's residuals), recorded in
    diagnosis.json, and the base fit is judged against them."""
    data = ra66_unequal.to_csv(tmp_path / "d.csv")
    out = tmp_path / "rep"
    r = CliRunner().invoke(main, ["diagnose", str(data), "--out", str(out), "--sigma", "estimate",
                                  "--confirm", "0", "--holdout", "none"])
    assert r.exit_code == 0, r.output
    d = json.loads((out / "diagnosis.json").read_text())
    noise = d["noise_from_data"]
    assert set(noise) == {"x", "h", "v"} and all(noise[k]["differences"] > 6000 for k in noise)
    assert all(abs(noise[k]["sigma"] / s - 1) < 0.05 for k, s in SIGMA.items()), noise
    assert all(d["fit"]["sigma"][k] == pytest.approx(noise[k]["sigma"]) for k in SIGMA)
    assert any("noise estimated from the data alone" in n for n in d["notes"])
    assert (out / "report.html").is_file()


def test_difference_noise_follows_the_sensor_not_the_flight():
    """The noise from the data alone, against the noise that made the data (an independent truth): RA-66M
    at 100 Hz within 3 %; a channel thinned to 2 Hz with drop-outs (steady runs only) within 20 %; a channel
    rounded to a step of 2 sigma: the rounding's q^2/12 adds to sigma^2; a flight that is pure signal
    (no noise) gives centimetres, not the trajectory's size."""
    from rocketid.cases.ra66m import ra66m, ra66m_truth
    from rocketid.data import difference_noise
    spec = ra66m()
    truth = ra66m_truth(spec)
    clean = ri.simulate_measurements(spec, truth, ri.ra66_times(), noise=False)
    rng = np.random.default_rng(4)
    for ch in clean.channels:
        noisy = ri.Channel(ch.name, ch.times, ch.values + 3.0 * rng.standard_normal(ch.values.size))
        sigma, n = difference_noise(noisy)
        assert abs(sigma / 3.0 - 1) < 0.03 and n == ch.values.size - 4, (ch.name, sigma)
        assert difference_noise(ch)[0] < 0.05, ch.name                  # the trajectory itself: no noise
    h = clean["h"]
    keep = np.zeros(h.times.size, bool)
    keep[::50] = True                                                 # 2 Hz
    keep[(h.times > 20) & (h.times < 24)] = False                     # a drop-out
    t2 = h.times[keep]
    thinned = ri.Channel("h", t2, h.values[keep] + 3.0 * rng.standard_normal(t2.size))
    sigma, n = difference_noise(thinned)
    assert abs(sigma / 3.0 - 1) < 0.2 and n == t2.size - 2 * 4, sigma  # two runs, 4 differences lost in each
    v = clean["v"]
    rounded = ri.Channel("v", v.times, np.round((v.values + 0.5 * rng.standard_normal(v.times.size)) / 1.0) * 1.0)
    assert difference_noise(rounded)[0] == pytest.approx(np.sqrt(0.25 + 1.0 / 12), rel=0.05)
    with pytest.raises(DataError, match="give its sigma"):
        difference_noise(ri.Channel("x", np.arange(8.0), np.arange(8.0)))


def test_diagnose_with_sigma_estimate_on_clean_time_knot_data(ra66_spec, ra66_p_true, ra66_unequal):
    """RA-66 (time-knot drag) on clean data with unstated noise: the noise from the data alone is within 3 %
    of the noise that made the data, nothing is missing, and the Mach-indexed variant's discovery uses the
    same noise and a band widened for it."""
    from rocketid.diagnostics import diagnose
    rep = diagnose(ra66_unequal, ra66_spec, sigma="estimate", workers=1, holdout=None)
    assert rep.final is not None and rep.final.verdict == "nothing missing"
    assert all(abs(rep.noise_from_data[k][0] / s - 1) < 0.03 for k, s in SIGMA.items()), rep.noise_from_data
    assert rep.variant is not None and rep.variant.noise_from_data == rep.noise_from_data
    assert "widened for the noise of x, h, v" in rep.discovery.band.note
    assert "widened for the noise of x, h, v" in rep.variant.discovery.band.note
