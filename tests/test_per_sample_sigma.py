"""Per-sample sigma: a noise standard deviation for every sample of a channel.

Truth from outside the code under test: RA-66 outputs from the high-accuracy simulator (no
noise), plus seeded Gaussian noise whose standard deviation grows linearly in time from 0.3
to 3 (the sigma each sample was drawn with is the per-sample sigma given to the fit).
"""

from __future__ import annotations

import json

import numpy as np
import pytest
from click.testing import CliRunner

import rocketid as ri
from rocketid.cli import main
from rocketid.data import equivalent_sigma, read_csv
from rocketid.errors import DataError
from rocketid.estimability import uncertainty
from rocketid.sampling.criterion import criterion_of, statistic_criterion


def _growing(times: np.ndarray) -> np.ndarray:
    return 0.3 + 2.7 * (times - times[0]) / (times[-1] - times[0])


@pytest.fixture(scope="module")
def growing_noise(ra66_clean):
    """RA-66 data whose noise grows in time, each channel carrying the sigma of every sample."""
    rng = np.random.default_rng(3)
    return ri.Measurements(tuple(
        ri.Channel(c.name, c.times, c.values + _growing(c.times) * rng.standard_normal(c.times.size),
                   _growing(c.times)) for c in ra66_clean.channels))


@pytest.fixture(scope="module")
def growing_fit(ra66_spec, growing_noise):
    return ri.estimate(ra66_spec, growing_noise)


def test_true_per_sample_sigma_fits_to_the_noise(growing_fit, ra66_p_true):
    fit = growing_fit
    assert fit.success, fit.message
    # 19 800 values: chi2/dof has a standard deviation of sqrt(2 / 19 800) = 0.01
    assert abs(fit.chi2_per_dof - 1) < 0.04, fit.chi2_per_dof
    se = uncertainty(fit).standard_errors
    assert np.all(np.abs(fit.p - ra66_p_true) < 4 * se), (fit.p - ra66_p_true) / se
    # the normalized residuals are N(0, 1) at every sample: early and late alike
    for name, e in fit.normalized_residuals.items():
        n = e.size
        assert 0.9 < np.std(e[: n // 3]) < 1.1 and 0.9 < np.std(e[-n // 3:]) < 1.1, name
    # eta (7.10) divides each sample by its own sigma: kurtosis near 3
    assert abs(criterion_of(fit).k1 - 3) < 0.2


def test_per_sample_sigma_is_reported(growing_fit):
    fit = growing_fit
    per = fit.sigma_per_sample
    assert set(per) == {"x", "h", "v"}
    assert per["h"]["min"] == pytest.approx(0.3) and per["h"]["max"] == pytest.approx(3.0)
    assert per["h"]["median"] == pytest.approx(1.65, rel=1e-3) and per["h"]["n"] == 6600
    assert fit.sigma["h"] == pytest.approx(equivalent_sigma(_growing(fit.prepared.measurements["h"].times)))
    d = fit.to_dict()
    assert d["sigma_per_sample"]["x"]["n"] == 6600 and d["sigma"]["x"] == pytest.approx(per["x"]["equivalent"])
    assert "per sample 0.3 .. 1.65 .. 3" in fit.summary().text()
    json.dumps(d)


def test_a_wrong_constant_sigma_does_not_fit_to_the_noise(ra66_spec, growing_noise):
    """The same data with one sigma (the per-sample ones' equivalent) give a chi2 near 1 in total
    but residuals that are not N(0, 1) in time: the early ones too small, the late ones too large."""
    equivalent = {c.name: equivalent_sigma(c.sigma) for c in growing_noise.channels}
    fit = ri.estimate(ra66_spec, growing_noise.with_sigma(equivalent))
    e = fit.normalized_residuals["h"]
    assert np.std(e[-e.size // 3:]) > 2.0 * np.std(e[: e.size // 3])


def test_equal_per_sample_values_are_the_scalar_sigma(ra66_spec, growing_noise):
    arrays = ri.Measurements(tuple(ri.Channel(c.name, c.times, c.values, np.full(c.times.size, 1.7))
                                   for c in growing_noise.channels))
    scalar = growing_noise.with_sigma({n: 1.7 for n in growing_noise.names})
    a, b = ri.estimate(ra66_spec, arrays), ri.estimate(ra66_spec, scalar)
    assert a.success and b.success
    np.testing.assert_allclose(a.p, b.p, rtol=1e-7)
    assert a.objective == pytest.approx(b.objective, rel=1e-9)
    assert a.sigma == b.sigma == {"x": 1.7, "h": 1.7, "v": 1.7}


def test_per_sample_weights_reach_the_nlp(ra66_spec, growing_noise, growing_fit):
    """Objective, gradient and Hessian use 1/sigma_i^2 at every sample (checked against the
    residuals, and the gradient against finite differences)."""
    nlp = growing_fit.nlp
    x = growing_fit.x
    J = sum(0.5 * np.sum((r / growing_noise[k].sigma) ** 2) for k, r in growing_fit.residuals.items())
    assert nlp.objective(x) == pytest.approx(J, rel=1e-12)
    np.testing.assert_array_equal(nlp.sigma_vector(), np.concatenate([c.sigma for c in growing_noise.channels]))
    rng = np.random.default_rng(0)
    d = rng.standard_normal(nlp.n)
    h = 1e-6
    fd = (nlp.objective(x + h * d) - nlp.objective(x - h * d)) / (2 * h)
    assert nlp.gradient(x) @ d == pytest.approx(fd, rel=1e-5, abs=1e-6)


def test_window_and_criterion_keep_each_samples_sigma(growing_noise):
    w = growing_noise.window(10.0, 20.0)
    h = w["h"]
    np.testing.assert_array_equal(h.sigma, _growing(growing_noise["h"].times)[
        (growing_noise["h"].times >= 10) & (growing_noise["h"].times <= 20)])
    r = {"h": 2 * h.sigma}
    assert statistic_criterion(r, {"h": h.sigma}).k1 == pytest.approx(16.0)


def _write(path, rows, header="t,x,h,v,sig_h"):
    path.write_text(header + "\n" + "".join((r if isinstance(r, str) else ",".join(map(str, r))) + "\n"
                                             for r in rows))
    return path


def test_read_csv_sigma_columns(tmp_path):
    rows = [(0.1 * k, k, 2 * k, 3 * k, 0.1 * k) for k in range(1, 6)]
    m = read_csv(_write(tmp_path / "d.csv", rows), sigma_columns={"h": "sig_h"})
    np.testing.assert_allclose(m["h"].sigma, [0.1, 0.2, 0.3, 0.4, 0.5])
    assert m["h"].per_sample and not m["x"].per_sample and m["x"].sigma is None
    # multi-rate: a sigma cell may be empty where the channel's is
    gappy = _write(tmp_path / "g.csv", ["0.1,1,2,3,0.5", "0.2,1,,3,", "0.3,1,2,3,0.7"])
    m = read_csv(gappy, sigma_columns={"h": "sig_h"})
    np.testing.assert_allclose(m["h"].sigma, [0.5, 0.7])
    np.testing.assert_allclose(m["h"].times, [0.1, 0.3])
    # the sigma column does not count as an unread column (an absent output is left out with missing="auto")
    m = read_csv(_write(tmp_path / "a.csv", ["0.1,1,0.5", "0.2,2,0.5"], "t,h,sig_h"), ("x", "h"),
                 sigma_columns={"h": "sig_h"}, missing="auto")
    assert m.names == ("h",)


@pytest.mark.parametrize("rows, kwargs, fragment", [
    (["0.1,1,2,3,0.5", "0.2,1,2,3,-0.5"], {"sigma_columns": {"h": "sig_h"}}, "line 3, column 'sig_h'"),
    (["0.1,1,2,3,0.5", "0.2,1,2,3,0"], {"sigma_columns": {"h": "sig_h"}}, "not a positive finite number"),
    (["0.1,1,2,3,0.5", "0.2,1,2,3,inf"], {"sigma_columns": {"h": "sig_h"}}, "is inf"),
    (["0.1,1,2,3,0.5", "0.2,1,2,3,"], {"sigma_columns": {"h": "sig_h"}}, "the cell is empty where h is measured"),
    (["0.1,1,2,3,0.5"], {"sigma_columns": {"h": "sig_q"}}, "no column 'sig_q' for the per-sample sigma of h"),
    (["0.1,1,2,3,0.5"], {"sigma_columns": {"q": "sig_h"}}, "'q', which is not a channel"),
    (["0.1,1,2,3,0.5"], {"sigma_columns": {"h": "sig_h"}, "sigma": {"h": 1.0}}, "both as a number and as a column"),
    (["0.1,1,2,3,0.5"], {"sigma_columns": {"h": "x"}}, "is read as data"),
])
def test_bad_sigma_columns_are_refused(tmp_path, rows, kwargs, fragment):
    with pytest.raises(DataError, match=None) as exc:
        read_csv(_write(tmp_path / "d.csv", rows), **kwargs)
    assert fragment in str(exc.value) and "\n" not in str(exc.value), str(exc.value)


@pytest.mark.parametrize("sigma, fragment", [
    ([1.0, -1.0, 1.0], "not positive and finite"),
    ([1.0, 0.0, 1.0], "not positive and finite"),
    ([1.0, np.nan, 1.0], "not positive and finite"),
    ([1.0, np.inf, 1.0], "not positive and finite"),
    ([1.0, 1.0], "2 per-sample sigmas for 3 samples"),
    ([1.0, 1e-200, 1.0], "out of scale"),
])
def test_bad_per_sample_sigma_is_refused(sigma, fragment):
    with pytest.raises(DataError, match="channel 'h'") as exc:
        ri.Channel("h", [0.0, 1.0, 2.0], [1.0, 2.0, 3.0], np.array(sigma))
    assert fragment in str(exc.value)


def test_estimating_a_per_sample_sigma_is_refused(ra66_spec, growing_noise):
    with pytest.raises(DataError, match="per-sample sigmas .* drop the sigma column"):
        ri.estimate(ra66_spec, growing_noise, sigma={"h": "estimate"})


def test_cli_sigma_column(tmp_path, ra66_spec, growing_noise):
    cols = [growing_noise["x"].times] + [growing_noise[n].values for n in ("x", "h", "v")] + [
        growing_noise[n].sigma for n in ("x", "h", "v")]
    path = tmp_path / "grow.csv"
    np.savetxt(path, np.column_stack(cols), delimiter=",", header="t,x,h,v,sx,sh,sv", comments="")
    out = tmp_path / "fit.json"
    r = CliRunner().invoke(main, ["estimate", str(path), "--sigma-column", "x=sx", "--sigma-column", "h=sh",
                                  "--sigma-column", "v=sv", "--out", str(out)])
    assert r.exit_code == 0, r.output
    d = json.loads(out.read_text())
    assert abs(d["chi2_per_dof"] - 1) < 0.04
    assert d["sigma_per_sample"]["h"]["max"] == pytest.approx(3.0) and "per sample" in r.output
    for args, fragment in [(["--sigma-column", "q=sx"], "has no output 'q'"),
                           (["--sigma-column", "h=nope"], "no column 'nope'"),
                           (["--sigma-column", "h=sh", "--sigma", "h=2"], "both as a number and as a column"),
                           (["--sigma-column", "h=sh", "--sigma", "h=estimate"], "per-sample sigmas")]:
        r = CliRunner().invoke(main, ["estimate", str(path), *args])
        lines = [ln for ln in r.output.splitlines() if ln.strip()]
        assert r.exit_code == 2 and len(lines) == 1 and fragment in lines[0], (args, r.output)
    # every command that reads data has the option
    for cmd in ("estimate", "estimability", "diagnose"):
        assert "--sigma-column" in CliRunner().invoke(main, [cmd, "--help"]).output, cmd


def test_read_channels_sigma_columns(tmp_path):
    from rocketid.data import read_channels
    h = _write(tmp_path / "h.csv", ["0.1,2,0.5", "0.2,3,0.6"], "t,h,sig_h")
    x = _write(tmp_path / "x.csv", ["0.1,1", "0.3,2", "0.5,4"], "t,x")
    m = read_channels({"x": x, "h": h}, sigma_columns={"h": "sig_h"})
    np.testing.assert_allclose(m["h"].sigma, [0.5, 0.6])
    assert m["x"].sigma is None
    with pytest.raises(DataError, match="'v', which has no file"):
        read_channels({"x": x, "h": h}, sigma_columns={"v": "sig_v"})


def test_the_diagnosis_reads_each_samples_sigma(growing_fit, growing_noise):
    """compare() normalizes each sample by its own sigma (early and late residuals alike, eta as the sampling
    computes it), the hold-out split keeps the per-sample sigmas, and the score test's model cache compares
    them as arrays."""
    import importlib

    from rocketid.diagnostics.compare import compare
    refit = importlib.import_module("rocketid.diagnostics.refit")
    comp = compare(growing_fit)
    for c in comp.channels:
        n = c.normalized.size
        assert 0.9 < np.std(c.normalized[: n // 3]) < 1.1 and 0.9 < np.std(c.normalized[-n // 3:]) < 1.1, c.name
        assert abs(c.chi2_per_dof - 1) < 0.08, c.name
    assert comp.criterion["eta"] == pytest.approx(criterion_of(growing_fit).eta, rel=1e-9)
    late = refit._after(growing_noise, 40.0)
    for c, full in zip(late.channels, growing_noise.channels):
        np.testing.assert_array_equal(c.sigma, full.sigma[full.times > 40.0])
