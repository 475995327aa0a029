"""Telemetry as it comes: multi-rate channels, drop-outs, per-channel files, flight windows,
unmeasured outputs, quantized and per-sample noise, units checks.

The truths are RA-66 simulations (SciPy DOP853 at tolerance 1e-12, not the collocation that
estimates) at CD = 0.5, CL = 0.1, sampled the way telemetry arrives.
"""

from __future__ import annotations

import numpy as np
import pytest
from click.testing import CliRunner

import rocketid as ri
from rocketid.cli import main
from rocketid.errors import DataError


def _multirate(spec, truth, seed=11):
    """x at 100 Hz, h at 25 Hz with a 2 s drop-out at 30-32 s, v at 10 Hz with a gap at 50-51 s."""
    t100 = ri.ra66_times()
    full = ri.simulate_measurements(spec, truth, t100, seed=seed)
    keep = {"x": np.ones(t100.size, bool),
            "h": (np.arange(t100.size) % 4 == 3) & ~((t100 > 30) & (t100 < 32)),
            "v": (np.arange(t100.size) % 10 == 9) & ~((t100 > 50) & (t100 < 51))}
    return ri.Measurements(tuple(ri.Channel(c.name, c.times[keep[c.name]], c.values[keep[c.name]])
                                 for c in full.channels))


@pytest.fixture(scope="module")
def multirate(ra66_spec, ra66_p_true):
    return _multirate(ra66_spec, ra66_p_true)


def _same(a: ri.Measurements, b: ri.Measurements):
    assert a.names == b.names
    for n in a.names:
        np.testing.assert_array_equal(a[n].times, b[n].times)
        np.testing.assert_array_equal(a[n].values, b[n].values)


def test_multirate_csv_and_per_channel_files_read_the_same(tmp_path, multirate):
    path = multirate.to_csv(tmp_path / "multi.csv")
    text = path.read_text().splitlines()
    assert text[0] == "t,x,h,v" and text[1].endswith(",,")      # t = 0.01: only x measured
    _same(ri.read_csv(path), multirate)
    files = {}
    for c in multirate.channels:
        files[c.name] = ri.Measurements((c,)).to_csv(tmp_path / f"{c.name}.csv")
    _same(ri.read_channels(files), multirate)
    assert multirate["h"].times.size == 1601 and multirate["v"].times.size == 651


def test_multirate_fit_matches_per_channel_data_and_truth(tmp_path, ra66_spec, ra66_p_true, multirate):
    from rocketid.estimability import uncertainty

    direct = ri.estimate(ra66_spec, multirate)
    from_csv = ri.estimate(ra66_spec, ri.read_csv(multirate.to_csv(tmp_path / "m.csv")))
    assert direct.success and from_csv.success
    np.testing.assert_allclose(from_csv.p, direct.p, rtol=1e-10, atol=1e-12)
    assert direct.n_data == 6600 + 1601 + 651
    se = uncertainty(direct).standard_errors
    assert np.all(np.abs(direct.p - ra66_p_true) < 4 * se), (direct.p - ra66_p_true) / se
    assert 0.9 < direct.chi2_per_dof < 1.1


def test_cli_reads_multirate_csv(tmp_path, multirate):
    path = multirate.to_csv(tmp_path / "m.csv")
    r = CliRunner().invoke(main, ["estimate", str(path), "--out", str(tmp_path / "f.json")])
    assert r.exit_code == 0, r.output
    assert "8852 values in 3 channels" in r.output


def test_cli_reads_one_file_per_channel_as_one_flight(tmp_path, multirate):
    """NAME=FILE[,NAME=FILE...] is one flight measured in one file per channel: the same fit as
    the multi-rate CSV; two such arguments are two flights; a bad one is named."""
    import json

    files = {c.name: ri.Measurements((c,)).to_csv(tmp_path / f"{c.name}_ch.csv") for c in multirate.channels}
    arg = ",".join(f"{k}={v}" for k, v in files.items())
    one, many = tmp_path / "one.json", tmp_path / "many.json"
    r = CliRunner().invoke(main, ["estimate", arg, "--out", str(one)])
    assert r.exit_code == 0, r.output
    assert "8852 values in 3 channels" in r.output
    r = CliRunner().invoke(main, ["estimate", str(multirate.to_csv(tmp_path / "m.csv")), "--out", str(many)])
    assert r.exit_code == 0, r.output
    a, b = json.loads(one.read_text()), json.loads(many.read_text())
    for name, value in b["parameters"].items():
        assert a["parameters"][name] == pytest.approx(value, rel=1e-10, abs=1e-12), name
    # an output without a file is predicted, not fitted
    r = CliRunner().invoke(main, ["estimate", f"x={files['x']},h={files['h']}"])
    assert r.exit_code == 0, r.output
    assert "8201 values in 2 channels" in r.output
    for bad, fragment in ((f"q={files['x']}", "no output 'q'; its outputs are x, h, v"),
                          (f"x={files['x']},x={files['h']}", "output 'x' is given two files"),
                          (f"x={files['x']},h", "'h' is not NAME=FILE"),
                          (f"x={tmp_path / 'nope.csv'}", "does not exist")):
        r = CliRunner().invoke(main, ["estimate", bad])
        assert r.exit_code == 2 and fragment in r.output, (bad, r.output)


def test_read_channels_bad_input(tmp_path):
    with pytest.raises(DataError, match="non-empty mapping"):
        ri.read_channels({})
    with pytest.raises(DataError, match="does not exist"):
        ri.read_channels({"h": tmp_path / "nope.csv"})


# ---------------------------------------------------------------------------
# Flight windows
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def ra66_seed5(ra66_spec, ra66_p_true):
    return ri.simulate_measurements(ra66_spec, ra66_p_true, ri.ra66_times(), seed=5)


def test_window_from_20s_with_free_initial_states_recovers_the_truth(ra66_spec, ra66_p_true, ra66_seed5):
    from rocketid.estimability import uncertainty

    fit = ri.estimate(ra66_spec, ra66_seed5, window=(20.0, 66.0))
    assert fit.success, fit.message
    assert fit.spec.t0 == 20.0 and fit.spec.tf == 66.0
    # CD0's hat function lives on [0, 11] s: no longer a parameter; the states at 20 s are
    names = fit.spec.parameter_names
    assert "CD0" not in names and names[-4:] == ("x_0", "h_0", "v_0", "theta_0")
    assert any("CD0 acts only outside the window" in n for n in fit.notes)
    # the truth at 20 s from the independent integrator (DOP853, tolerance 1e-12)
    s20 = ri.simulate(ra66_spec, ra66_p_true, [0.0, 20.0], rtol=1e-12, atol=1e-12).states[-1]
    truth = dict(zip(ra66_spec.parameter_names, ra66_p_true))
    truth.update(zip(("x_0", "h_0", "v_0", "theta_0"), s20))
    unc = uncertainty(fit)
    z = {n: (v - truth[n]) / s for n, v, s in zip(names, fit.p, unc.standard_errors)}
    assert all(abs(v) < 4 for v in z.values()), z
    assert abs(fit.value("theta_0") - s20[3]) < 1e-4 and abs(fit.value("h_0") - s20[1]) < 0.5
    assert 0.9 < fit.chi2_per_dof < 1.1
    assert fit.n_data == 3 * 4601


def test_window_guesses_come_from_the_data(ra66_spec, ra66_p_true, ra66_seed5):
    from rocketid.start import initial_from_data

    values, source = initial_from_data(ra66_spec, ra66_seed5, 20.0)
    s20 = ri.simulate(ra66_spec, ra66_p_true, [0.0, 20.0], rtol=1e-12, atol=1e-12).states[-1]
    assert source == {"x": "measured", "h": "measured", "v": "measured", "theta": "kinematics"}
    got = np.array([values[s] for s in ra66_spec.state_symbols])
    # sigma = 1 m noise, 100 Hz: the local fits are within a metre; sin(theta) = (dh/dt) / v within 0.01 rad
    assert np.all(np.abs(got[:3] - s20[:3]) < 1.0) and abs(got[3] - s20[3]) < 0.01


def test_window_ending_early_keeps_the_launch_state(ra66_spec, ra66_seed5):
    fit = ri.estimate(ra66_spec, ra66_seed5, window=(0.0, 30.0))
    assert fit.success and fit.spec.tf == 30.0
    assert not any(n.endswith("_0") for n in fit.spec.parameter_names)
    assert {"CD4", "CD5", "CD6"}.isdisjoint(fit.spec.parameter_names)   # knots 44, 55, 66 s act after 30 s
    assert 0.9 < fit.chi2_per_dof < 1.1



def test_diagnose_in_a_flight_window_fits_the_cut_model(ra66_spec, ra66_seed5):
    """``diagnose(flight_window=)`` cuts the model and the data before the base fit (the initial states at
    the window's start estimated); a mesh given with a window is refused before any work."""
    from rocketid.diagnostics import diagnose
    from rocketid.errors import SettingsError

    rep = diagnose(ra66_seed5, ra66_spec, flight_window=(20.0, 66.0), confirm_top=0, holdout=None)
    assert rep.fit.spec.t0 == 20.0 and rep.fit.spec.tf == 66.0
    assert rep.fit.spec.parameter_names[-4:] == ("x_0", "h_0", "v_0", "theta_0")
    assert rep.fit.n_data == 3 * 4601 and 0.9 < rep.fit.chi2_per_dof < 1.1
    assert any("CD0 acts only outside the window" in n for n in rep.notes)
    assert rep.ranking is not None and rep.discovery is None       # confirm_top=0: the screen's ranking alone
    with pytest.raises(SettingsError, match="flight_window cuts the model: give no mesh"):
        diagnose(ra66_seed5, ra66_spec, flight_window=(20.0, 66.0), mesh=ri.default_mesh(ra66_spec), confirm_top=0)

def test_cli_window(tmp_path, ra66_seed5):
    path = ra66_seed5.to_csv(tmp_path / "d.csv")
    out = tmp_path / "w.json"
    r = CliRunner().invoke(main, ["estimate", str(path), "--window", "20:", "--out", str(out)])
    assert r.exit_code == 0, r.output
    import json
    d = json.loads(out.read_text())
    assert {"x_0", "h_0", "v_0", "theta_0"} <= set(d["parameters"]) and "CD0" not in d["parameters"]
    assert abs(d["parameters"]["theta_0"] - 1.2625) < 1e-3


@pytest.mark.parametrize("args, fragment", [
    (["--window", "20"], "--window must be T0:T1"),
    (["--window", "30:20"], "the end must be after the start"),
    (["--window", "50:90"], "not inside model 'RA-66''s horizon [0, 66]"),
    (["--window", "a:b"], "--window must be T0:T1"),
    (["--unmeasured", "q"], "--unmeasured q: model 'RA-66' has no output 'q'"),
    (["--unmeasured", "x", "--unmeasured", "h", "--unmeasured", "v"], "nothing is left to fit"),
])
def test_cli_bad_window_and_unmeasured(tmp_path, args, fragment):
    data = tmp_path / "d.csv"
    data.write_text("t,x,h,v\n" + "".join(f"{0.1 * k:.1f},{k},{k},{k}\n" for k in range(1, 20)))
    r = CliRunner().invoke(main, ["estimate", str(data), *args])
    assert r.exit_code == 2
    lines = [ln for ln in r.output.splitlines() if ln.strip()]
    assert len(lines) == 1 and lines[0].startswith("Error:") and fragment in lines[0], r.output


def test_window_without_data_in_it(ra66_spec, ra66_seed5):
    short = ra66_seed5.window(0.0, 10.0)
    with pytest.raises(DataError, match="no samples of x, h, v in the window"):
        ri.estimate(ra66_spec, short, window=(20.0, 66.0))


# ---------------------------------------------------------------------------
# Outputs the data do not measure
# ---------------------------------------------------------------------------


def test_unmeasured_output_is_predicted_not_fitted(tmp_path, ra66_spec, ra66_p_true, ra66_seed5):
    """Without x (no downrange, like broadcast telemetry), h and v still fit; x is predicted and
    the prediction agrees with the independent simulation of x."""
    hv = ra66_seed5.subset(["h", "v"])
    fit = ri.estimate(ra66_spec, hv)
    assert fit.success and fit.unmeasured_outputs == ("x",)
    assert fit.nlp.channel_names == ("h", "v") and fit.n_data == 2 * 6600
    assert any("x are not in the data: predicted" in n for n in fit.summary().notes)
    t = np.linspace(1, 66, 14)
    x_true = ri.simulate(ra66_spec, ra66_p_true, t, rtol=1e-12, atol=1e-12).states[:, 0]
    assert np.max(np.abs(fit.predict("x", t) - x_true)) < 5.0
    # the CLI reads a file without an x column (every column of the file is read) ...
    path = hv.to_csv(tmp_path / "hv.csv")
    out = tmp_path / "f.json"
    r = CliRunner().invoke(main, ["estimate", str(path), "--out", str(out)])
    assert r.exit_code == 0, r.output
    import json
    assert json.loads(out.read_text())["unmeasured_outputs"] == ["x"]
    # ... but a file with an unread column may have misnamed x: an error that says both fixes
    (tmp_path / "alt.csv").write_text("t,h,v,downrange_km\n" + "".join(
        f"{0.1 * k:.1f},{k},{k},{k}\n" for k in range(1, 30)))
    r = CliRunner().invoke(main, ["estimate", str(tmp_path / "alt.csv")])
    assert r.exit_code == 2 and "missing column(s) x" in r.output and "--unmeasured x" in r.output
    r = CliRunner().invoke(main, ["estimate", str(tmp_path / "alt.csv"), "--unmeasured", "x"])
    assert "missing column" not in r.output


def test_predict_bad_output(ra66_spec, ra66_seed5):
    fit = ri.estimate(ra66_spec, ra66_seed5.window(0, 20), window=(0, 20))
    with pytest.raises(ri.ModelError, match="has no output 'q'"):
        fit.predict("q")


# ---------------------------------------------------------------------------
# Sampled inputs: restarts only at kinks
# ---------------------------------------------------------------------------


def test_sampled_kinks_finds_the_kinks_not_the_samples():
    from rocketid.simulate import sampled_kinks

    t = np.linspace(0, 10, 1001)
    assert sampled_kinks(t, np.sin(t)).size == 0                         # smooth: no restart
    tri = np.interp(t, [0, 3, 7, 10], [0, 1, -1, 0.5])                  # kinks at 3 and 7 s
    np.testing.assert_allclose(sampled_kinks(t, tri), [3.0, 7.0])
    bent = np.sin(t) + np.where(t > 5, 0.3 * (t - 5), 0.0)              # a smooth signal with one kink
    np.testing.assert_allclose(sampled_kinks(t, bent), [5.0])


def test_sampled_input_simulates_like_restarting_at_every_sample(monkeypatch):
    """A 10 ms sampled input, integrated across its samples, agrees with the integration that
    restarts at every sample (the previous behaviour) to well within the data's noise."""
    import importlib

    rsim = importlib.import_module("rocketid.simulate")

    m = ri.Model("forced", 0.0, 20.0)
    y = m.state("y", 0.0)
    tt = np.linspace(0, 20, 2001)
    u = m.input("u", times=tt, values=np.sin(0.7 * tt) + np.where(tt > 12, 0.5 * (tt - 12), 0.0))
    k = m.parameter("k", guess=0.8, bounds=(0, 5))
    m.ode({y: -k * y + u})
    m.output("y", y, sigma=0.01)
    spec = m.freeze()
    times = np.linspace(0.05, 20, 400)
    fast = ri.simulate(spec, [0.8], times, rtol=1e-10, atol=1e-10)
    monkeypatch.setattr(rsim, "KINK_FACTOR", 0.0)
    every = ri.simulate(spec, [0.8], times, rtol=1e-10, atol=1e-10)
    assert fast.success and every.success
    assert np.max(np.abs(fast.states - every.states)) < 1e-6


# ---------------------------------------------------------------------------
# Quantized channels
# ---------------------------------------------------------------------------


def test_quantized_sigma_from_the_step(tmp_path, ra66_spec, ra66_p_true):
    """Speed shown in whole km/h (steps of 1/3.6 m/s) and altitude in 0.1 m steps: the step is
    found in the data and sigma = step / sqrt(12); the fit then reaches that noise level."""
    from rocketid.data import quantization_step, resolve_quantized

    clean = ri.simulate_measurements(ra66_spec, ra66_p_true, ri.ra66_times(), noise=False)
    q = {"x": 0.5, "h": 0.1, "v": 1 / 3.6}
    rounded = ri.Measurements(tuple(ri.Channel(c.name, c.times, np.round(c.values / q[c.name]) * q[c.name])
                                    for c in clean.channels))
    assert quantization_step(rounded["v"].values) == pytest.approx(1 / 3.6, rel=1e-9)
    assert quantization_step(clean["v"].values) is None
    sig = resolve_quantized({"x": "quantized", "h": "quantized:0.1", "v": "quantized"}, rounded)
    assert sig == pytest.approx({k: v / np.sqrt(12) for k, v in q.items()}, rel=1e-9)
    fit = ri.estimate(ra66_spec, rounded, sigma={"x": "quantized", "h": "quantized", "v": "quantized"})
    assert fit.success and fit.sigma["v"] == pytest.approx(1 / 3.6 / np.sqrt(12), rel=1e-9)
    assert 0.8 < fit.chi2_per_dof < 1.2        # rounding errors of a smooth signal are nearly uniform, white
    assert np.allclose(fit.p, ra66_p_true, atol=0.01)
    with pytest.raises(DataError, match="not on a common step"):
        ri.estimate(ra66_spec, clean, sigma={"v": "quantized"})
    with pytest.raises(DataError, match="quantized:STEP with a positive step"):
        ri.estimate(ra66_spec, rounded, sigma={"v": "quantized:-1"})
    path = rounded.to_csv(tmp_path / "q.csv")
    r = CliRunner().invoke(main, ["estimate", str(path), "--sigma", "v=quantized", "--sigma", "h=quantized:0.1",
                                  "--sigma", "x=quantized", "--out", str(tmp_path / "q.json")])
    assert r.exit_code == 0, r.output
    assert "v 0.08019" in r.output


def test_unmeasured_output_is_plotted_in_the_comparison(tmp_path, ra66_spec, ra66_seed5):
    from rocketid.diagnostics.compare import compare

    fit = ri.estimate(ra66_spec, ra66_seed5.subset(["h", "v"]))
    comp = compare(fit)
    assert comp.names == ("h", "v")
    (name, t, y), = comp.predicted_only
    assert name == "x" and t.shape == y.shape and y[-1] > 1000       # downrange grows to km
    assert comp.to_dict()["predicted_only"] == ["x"]
    assert any("x are not in the data" in n for n in comp.notes)
    axes = comp.plot(path=tmp_path / "c.png")
    assert axes.shape == (3, 2) and (tmp_path / "c.png").stat().st_size > 1000
