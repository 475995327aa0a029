"""Several flights of one vehicle fitted jointly (rocketid.joint).

Truth: two RA-66M flights with different pitch programs, simulated by the high-accuracy
integrator at the true aerodynamics (independent of the collocation under test). Each is
fitted alone, then both jointly: the joint standard errors must be smaller than either
flight's alone and the joint estimates within 4 standard errors of the truth. Per-flight
nuisance parameters (a sensor bias each flight has, of different sizes) keep their flight's
label, and a misfit present in one flight only is reported as such.
"""

from __future__ import annotations

import json

import numpy as np
import pytest
import sympy as sp
from click.testing import CliRunner

import rocketid as ri
from rocketid.cases.ra66 import ra66_times, ra66_vehicle_model
from rocketid.cases.ra66m import RA66M_MACH_KNOTS, ra66m, ra66m_truth
from rocketid.cli import main
from rocketid.diagnostics import with_effects
from rocketid.errors import SettingsError
from rocketid.estimability import uncertainty
from rocketid.joint import Flight, joint_estimate, joint_prepare


def _alpha_b(t):
    """A second pitch program: a -5 deg kick over 3-19 s, then a 2.5 deg excitation of period 9 s."""
    kick = -5 * sp.pi / 180 * sp.sin(sp.pi * (t - 3) / 16) ** 2
    exc = 2.5 * sp.pi / 180 * sp.sin(2 * sp.pi * (t - 19) / 9)
    return sp.Piecewise((0, t < 3), (kick, t <= 19), (exc, True))


def _aero(m, fc, alpha):
    cd = m.table("CD_M", fc.mach, RA66M_MACH_KNOTS, 0.4, bounds=(0.01, 2.0), nominal=0.4)
    cla = m.parameter("CL_alpha", 2.0, bounds=(0.0, 10.0), nominal=2.5)
    return cd, cla * alpha


@pytest.fixture(scope="module")
def two_flights():
    spec_a = ra66m()
    spec_b = ra66_vehicle_model("RA-66M-b", "RA-66M with a second pitch program", _alpha_b, _aero).freeze()
    truth = ra66m_truth(spec_a)
    assert spec_a.parameter_names == spec_b.parameter_names
    data_a = ri.simulate_measurements(spec_a, truth, ra66_times(), seed=11)
    data_b = ri.simulate_measurements(spec_b, truth, ra66_times(), seed=12)
    return spec_a, spec_b, data_a, data_b, truth


def test_joint_fit_beats_either_flight_alone_and_agrees_with_the_truth(two_flights):
    spec_a, spec_b, data_a, data_b, truth = two_flights
    fit_a, fit_b = ri.estimate(spec_a, data_a), ri.estimate(spec_b, data_b)
    assert fit_a.success and fit_b.success
    se_a, se_b = uncertainty(fit_a).standard_errors, uncertainty(fit_b).standard_errors
    joint = joint_estimate([Flight("A", spec_a, data_a), Flight("B", spec_b, data_b)])
    assert joint.success, joint.message
    assert joint.names == spec_a.parameter_names            # all shared, names kept
    se = joint.standard_errors
    assert np.all(se < se_a) and np.all(se < se_b)
    assert np.all(np.abs(joint.theta - truth) < 4 * se)
    assert 0.95 < joint.chi2_per_dof < 1.05
    for r in joint.flights:
        assert 0.95 < r.chi2_per_dof < 1.05
    # J of the joint problem is the flights' J at the joint estimate; it cannot be below the separate
    # minima, and exceeds them by about a chi-square of 8 degrees of freedom when the flights agree
    assert joint.objective == pytest.approx(sum(r.objective for r in joint.flights), rel=1e-10)
    excess = joint.objective - (fit_a.objective + fit_b.objective)
    assert -1e-6 < excess < 30.0
    est = joint.estimability()
    assert est.condition_number < min(est.flight_condition_numbers().values())
    for k in range(est.eigenvalues.size):            # each joint direction's eigenvalue is the flights' sum
        assert est.shares["A"][k] + est.shares["B"][k] == pytest.approx(1.0, abs=1e-8)
    assert "from A" in est.summary().text()


def test_per_flight_biases_carry_the_flight_label(two_flights):
    spec_a, spec_b, data_a, data_b, truth = two_flights
    # each flight's altimeter reads high by its own bias: +15 m on A, -25 m on B
    shifted_a = ri.Measurements.from_arrays(data_a["x"].times, {
        "x": data_a["x"].values, "h": data_a["h"].values + 15.0, "v": data_a["v"].values})
    shifted_b = ri.Measurements.from_arrays(data_b["x"].times, {
        "x": data_b["x"].values, "h": data_b["h"].values - 25.0, "v": data_b["v"].values})
    sa, sb = with_effects(spec_a, ["bias_h"]), with_effects(spec_b, ["bias_h"])
    joint = joint_estimate([Flight("A", sa, shifted_a), Flight("B", sb, shifted_b)], per_flight=["b_h"])
    assert joint.success
    assert "b_h[A]" in joint.names and "b_h[B]" in joint.names and "b_h" not in joint.names
    se = joint.standard_errors
    for name, value in (("b_h[A]", 15.0), ("b_h[B]", -25.0)):
        i = joint.names.index(name)
        assert abs(joint.theta[i] - value) < 4 * se[i]
    d = joint.to_dict()
    assert set(d["shared"]) == set(spec_a.parameter_names)
    assert {"b_h[A]", "b_h[B]"} <= set(d["parameters"]) and set(d["per_flight"]) == {"A", "B"}


def test_a_misfit_in_one_flight_only_is_reported_as_such(two_flights):
    spec_a, spec_b, data_a, data_b, truth = two_flights
    biased_b = ri.Measurements.from_arrays(data_b["x"].times, {
        "x": data_b["x"].values, "h": data_b["h"].values + 4.0, "v": data_b["v"].values})
    joint = joint_estimate([Flight("A", spec_a, data_a), Flight("B", spec_b, biased_b)])
    assert joint.flight("B").chi2_per_dof > joint.flight("A").chi2_per_dof
    alone = {label: r.chi2_per_dof for label, r in zip(joint.labels, joint.alone)}
    assert alone["A"] < 1.1 and alone["B"] > 1.5            # the bias is B's own
    report = joint.consistency()
    assert len(report.notes) == 1 and "flight(s) B do not fit" in report.notes[0]
    # without the bias, both fit alone and together: no note
    clean = joint_estimate([Flight("A", spec_a, data_a), Flight("B", spec_b, data_b)])
    assert clean.consistency().notes == ()


def test_bad_joint_inputs_are_refused(two_flights):
    spec_a, spec_b, data_a, data_b, truth = two_flights
    with pytest.raises(SettingsError, match="labels must differ"):
        joint_prepare([Flight("A", spec_a, data_a), Flight("A", spec_b, data_b)])
    with pytest.raises(SettingsError, match="not a parameter"):
        joint_prepare([Flight("A", spec_a, data_a), Flight("B", spec_b, data_b)], per_flight=["b_zz"])
    with pytest.raises(SettingsError, match="label"):
        Flight("A[1]", spec_a, data_a)


def test_cli_estimates_several_files_jointly(two_flights, tmp_path):
    spec_a, spec_b, data_a, data_b, truth = two_flights
    f1, f2 = data_a.to_csv(tmp_path / "f1.csv"), data_a.to_csv(tmp_path / "f2.csv")
    ri.simulate_measurements(spec_a, truth, ra66_times(), seed=13).to_csv(f2)
    out = tmp_path / "fit.json"
    res = CliRunner().invoke(main, ["estimate", str(f1), str(f2), "--model", "ra66m", "--out", str(out)])
    assert res.exit_code == 0, res.output
    assert "rocketid joint estimation: 2 flights" in res.output
    fit = json.loads(out.read_text())
    assert fit["flights"] == ["f1", "f2"] and set(fit["parameters"]) == set(spec_a.parameter_names)
    assert all(abs(fit["parameters"][n] - v) < 4 * fit["standard_errors"][n]
               for n, v in zip(spec_a.parameter_names, truth))
    col = CliRunner().invoke(main, ["estimate", str(f1), str(f2), "--model", "ra66m", "--errors", "coloured",
                                    "--out", str(out)])
    assert col.exit_code == 0, col.output
    assert "corrected for coloured residuals" in col.output
    fit = json.loads(out.read_text())
    assert fit["std_err_residuals"] == "coloured"
    assert set(fit["standard_errors_coloured"]) == set(spec_a.parameter_names)
    assert all(0.7 < fit["standard_errors_coloured"][n] / fit["standard_errors"][n] < 1.4 for n in spec_a.parameter_names)
    bad = CliRunner().invoke(main, ["estimate", str(f1), "--per-flight", "CL_alpha"])
    assert bad.exit_code == 2 and "several data files" in bad.output


def _ar1_flight(spec, truth, seed, rho):
    """Exact outputs of ``spec`` plus AR(1) errors of lag-1 correlation ``rho`` and each output's sigma as
    their marginal standard deviation (a filtered sensor, a readout whose errors last ~1/(1 - rho) samples)."""
    clean = ri.simulate_measurements(spec, truth, ra66_times(), noise=False)
    rng = np.random.default_rng(seed)
    values = {}
    for ch in clean.channels:
        sigma = float(ch.sigma_array()[0])
        e = np.empty(ch.values.size)
        e[0] = rng.normal(0.0, sigma)
        drive = rng.normal(0.0, sigma * np.sqrt(1 - rho ** 2), ch.values.size)
        for i in range(1, e.size):
            e[i] = rho * e[i - 1] + drive[i]
        values[ch.name] = ch.values + e
    return ri.Measurements.from_arrays(clean.channels[0].times, values, sigma={c.name: float(c.sigma_array()[0])
                                                                               for c in clean.channels})


def test_joint_coloured_errors_follow_the_residuals_correlation(two_flights):
    """The joint sandwich: with white noise it gives the white standard errors (to sampling error); with
    AR(1) errors of lag-1 correlation 0.9 in both flights, the standard errors of parameters whose
    sensitivities vary slowly grow by about sqrt((1 + rho) / (1 - rho)) = 4.4 (the long-run variance of an
    AR(1) mean), and the truth lies within their intervals where the white ones would miss it."""
    spec_a, spec_b, data_a, data_b, truth = two_flights
    white = joint_estimate([Flight("A", spec_a, data_a), Flight("B", spec_b, data_b)])
    ratio = white.coloured_standard_errors / white.standard_errors
    assert np.all((0.75 < ratio) & (ratio < 1.3)), ratio
    rho = 0.9
    red = joint_estimate([Flight("A", spec_a, _ar1_flight(spec_a, truth, 21, rho)),
                          Flight("B", spec_b, _ar1_flight(spec_b, truth, 22, rho))])
    assert red.success, red.message
    ratio = red.coloured_standard_errors / red.standard_errors
    assert np.all((2.5 < ratio) & (ratio < 6.0)), (ratio, np.sqrt((1 + rho) / (1 - rho)))
    assert np.all(np.abs(red.theta - truth) < 4 * red.coloured_standard_errors)


def test_cli_estimability_of_several_files(two_flights, tmp_path):
    spec_a, spec_b, data_a, data_b, truth = two_flights
    f1 = data_a.to_csv(tmp_path / "f1.csv")
    f2 = ri.simulate_measurements(spec_a, truth, ra66_times(), seed=14).to_csv(tmp_path / "f2.csv")
    out = tmp_path / "est.json"
    res = CliRunner().invoke(main, ["estimability", str(f1), str(f2), "--model", "ra66m", "--at", "fit",
                                    "--scaling", "nominal", "--out", str(out)])
    assert res.exit_code == 0, res.output
    est = json.loads(out.read_text())
    assert set(est["flight_eigenvalues"]) == {"f1", "f2"} and est["shared"] == list(spec_a.parameter_names)
    # two flights of the same program and size bring about half of each direction each
    for k in range(len(est["eigenvalues"])):
        assert est["shares"]["f1"][k] + est["shares"]["f2"][k] == pytest.approx(1.0, abs=1e-8)
        assert 0.3 < est["shares"]["f1"][k] < 0.7
    # Weyl: adding a flight's information never lowers any eigenvalue
    for lam_f in est["flight_eigenvalues"].values():
        assert all(j >= f * (1 - 1e-9) for j, f in zip(est["eigenvalues"], lam_f))


def test_eliminating_a_flights_own_parameters_is_the_marginal_information():
    """The information on the shared parameters with the others eliminated is the inverse of the
    shared block of the covariance (an identity of Gaussian marginals), also when the eliminated
    block is singular in some direction."""
    from rocketid.joint import _schur
    rng = np.random.default_rng(0)
    A = rng.standard_normal((6, 6))
    H = A @ A.T
    keep, drop = np.array([0, 1, 2]), np.array([3, 4, 5])
    assert np.allclose(_schur(H, keep, drop), np.linalg.inv(np.linalg.inv(H)[np.ix_(keep, keep)]))
    B = np.zeros((5, 5))
    B[:3, :3] = H[:3, :3]                                   # parameters 3 and 4 have no information
    assert np.allclose(_schur(B, keep, np.array([3, 4])), H[:3, :3])


SIGMA_A = {"x": 2.0, "h": 0.5, "v": 1.5}
SIGMA_B = {"x": 0.8, "h": 1.2, "v": 0.4}


def _no_sigma(data):
    """The channels without the sigma they were simulated with (the fit starts from the model's)."""
    return ri.Measurements(tuple(ri.Channel(c.name, c.times, c.values) for c in data.channels))


@pytest.fixture(scope="module")
def two_noisy_flights(two_flights):
    """The two pitch programs with different, unstated noise levels in each flight."""
    spec_a, spec_b, _, _, truth = two_flights
    data_a = _no_sigma(ri.simulate_measurements(spec_a, truth, ra66_times(), seed=21, sigma=SIGMA_A))
    data_b = _no_sigma(ri.simulate_measurements(spec_b, truth, ra66_times(), seed=22, sigma=SIGMA_B))
    return spec_a, spec_b, data_a, data_b, truth


def test_joint_fit_estimates_each_flights_sigma(two_noisy_flights):
    spec_a, spec_b, data_a, data_b, truth = two_noisy_flights
    joint = joint_estimate([Flight("A", spec_a, data_a), Flight("B", spec_b, data_b)], sigma="estimate")
    assert joint.success, joint.message
    assert joint.sigma_estimated == {"A": ("x", "h", "v"), "B": ("x", "h", "v")}
    assert joint.sigma_iterations >= 2
    for label, true in (("A", SIGMA_A), ("B", SIGMA_B)):
        for ch, s in true.items():
            est = joint.sigma[label][ch]
            assert abs(est / s - 1) < 0.03, (label, ch, est)            # within a few percent
            assert abs(est - s) < 4 * joint.sigma_std[label][ch]          # and within its stated error
            # the relaxation's fixed point: each flight's sigma is the RMS of its own residuals
            assert est == pytest.approx(joint.flight(label).rms[ch], rel=1e-5)
    assert np.all(np.abs(joint.theta - truth) < 4 * joint.standard_errors)
    d = joint.to_dict()
    assert d["sigma_estimated"] == {"A": ["x", "h", "v"], "B": ["x", "h", "v"]}
    assert set(d["sigma"]) == {"A", "B"} and d["sigma"]["B"]["v"] == pytest.approx(joint.sigma["B"]["v"])
    text = joint.summary().text()
    assert "each flight's separately" in text and "(estimated)" in text
    # the covariance uses the estimated sigmas: the same as a joint fit with those sigmas given
    given = joint_estimate([Flight("A", spec_a, data_a.with_sigma(joint.sigma["A"])),
                            Flight("B", spec_b, data_b.with_sigma(joint.sigma["B"]))])
    np.testing.assert_allclose(given.theta, joint.theta, rtol=1e-5)
    np.testing.assert_allclose(given.standard_errors, joint.standard_errors, rtol=1e-3)


def test_joint_fit_estimates_one_channel_and_keeps_the_given(two_noisy_flights):
    spec_a, spec_b, data_a, data_b, truth = two_noisy_flights
    joint = joint_estimate([Flight("A", spec_a, data_a), Flight("B", spec_b, data_b)],
                           sigma={"h": "estimate", "x": 1.0, "v": 1.0})
    assert joint.success, joint.message
    assert joint.sigma_estimated == {"A": ("h",), "B": ("h",)}
    assert joint.sigma["A"]["x"] == 1.0 and joint.sigma["B"]["v"] == 1.0
    assert abs(joint.sigma["A"]["h"] / 0.5 - 1) < 0.05 and abs(joint.sigma["B"]["h"] / 1.2 - 1) < 0.05
    with pytest.raises(ri.DataError, match="no flight has a channel 'q'"):
        joint_estimate([Flight("A", spec_a, data_a), Flight("B", spec_b, data_b)], sigma={"q": "estimate"})
    with pytest.raises(ri.DataError, match="give 'estimate'"):
        joint_estimate([Flight("A", spec_a, data_a), Flight("B", spec_b, data_b)], sigma="guess")


def test_cli_several_files_with_sigma_estimate(two_noisy_flights, tmp_path):
    spec_a, spec_b, data_a, data_b, truth = two_noisy_flights
    f1 = data_a.to_csv(tmp_path / "f1.csv")
    f2 = _no_sigma(ri.simulate_measurements(spec_a, truth, ra66_times(), seed=23, sigma=SIGMA_B)).to_csv(
        tmp_path / "f2.csv")
    out = tmp_path / "fit.json"
    res = CliRunner().invoke(main, ["estimate", str(f1), str(f2), "--model", "ra66m", "--sigma", "estimate",
                                    "--out", str(out)])
    assert res.exit_code == 0, res.output
    fit = json.loads(out.read_text())
    assert fit["sigma_estimated"] == {"f1": ["x", "h", "v"], "f2": ["x", "h", "v"]}
    for label, true in (("f1", SIGMA_A), ("f2", SIGMA_B)):
        assert all(abs(fit["sigma"][label][c] / s - 1) < 0.03 for c, s in true.items()), fit["sigma"]
    est_out = tmp_path / "est.json"
    res = CliRunner().invoke(main, ["estimability", str(f1), str(f2), "--model", "ra66m", "--at", "fit",
                                    "--sigma", "h=estimate", "--out", str(est_out)])
    assert res.exit_code == 0, res.output
    est = json.loads(est_out.read_text())
    assert est["fit"]["sigma_estimated"] == {"f1": ["h"], "f2": ["h"]}
    assert abs(est["fit"]["sigma"]["f1"]["h"] / 0.5 - 1) < 0.05 and abs(est["fit"]["sigma"]["f2"]["h"] / 1.2 - 1) < 0.05
    res = CliRunner().invoke(main, ["estimability", str(f1), str(f2), "--model", "ra66m", "--sigma", "estimate",
                                    "--out", str(est_out)])
    assert res.exit_code == 2 and "--at fit" in res.output
