"""``rocketid diagnose`` on a high-site liquid booster and hidden physics the team never tuned on.

Petrel-V (``tests/vehicles/petrel.py``) is a pressure-fed liquid suborbital booster declared from the
user documentation: a sampled, regressive sea-level thrust table with a cutoff and a coast, the mass
as a state, a rail exit 1420 m above sea level at 30 m/s, CD and the lift slope as Mach tables, a
sampled pitch program with the attack angle ``pitch_cmd - theta``, GNSS data at 10 Hz. Its truth
(``tests/petrel_study/truth.py``) flies Earth-centred Cartesian position and velocity with scipy's
integrator, its own 1976 atmosphere, and every hidden effect in its own shape.

The normal suite checks the instruments (a few seconds): the truth without effects reproduces the
estimation model, the truth's atmosphere is rocketid's us76 where the model uses it, the vehicle fits
clean data to the noise, and every hidden effect changes the flight by a stated amount. The diagnoses
run ``rocketid diagnose`` from the command line, one per case, and are ``slow``:
``pytest -m slow tests/test_petrel_study.py``. The results table and the command that made it are in
docs/effects.md ("Evaluation on a high-site liquid booster (Petrel-V)").
"""

from __future__ import annotations

import math

import numpy as np
import pytest


import petrel as V

import rocketid as ri
from petrel_study import truth
from petrel_study.cases import ALL, BY_NAME, FRESH, JET, MIS, Hidden
from petrel_study.run import STUDY

#: Cases measured not to meet the bar (``STUDY.acceptable``), with the measured reason.
KNOWN_FAILURES: dict[str, str] = {
    "cold-day+ellipsoid-height": "b06d8d2, 511eec0 and e581239: bias_h 24.87 +- 0.23 explained at chi2/dof 1.021; the "
                                 "cold day is absorbed by the coefficients as in cold-day (there: nothing missing), "
                                 "density never needed: right but partly",
    "cold-day+heavy-start": "bd25983 (fresh pair): start_mass, dm_start 41.38 +- 0.41 (40), chi2/dof 1.011, partly "
                            "explained -- fitted on 0-40.9 s it predicts the rest worse than the base model (mean "
                            "squared error 230 against 28.8 sigma^2: the coast's drag knot CD_5, beyond the window, held "
                            "at its guess 0.4 for 0.31 in both window fits, where the base model's wrong lower knots "
                            "happen to compensate); the cold day is not in these data",
    "vacuum-nozzle+cold-day": "bd25983 (fresh pair): back_pressure_fade, A_e 0.0594 +- 0.0002 (0.06), chi2/dof 0.989, "
                              "explained; the cold day is not in these data (test_a_cold_day_beside_a_visible_effect_"
                              "is_beyond_these_data: dT_air -0.2 +- 2.1 K beside the nozzle): right but partly",
    "blowdown+cold-day": "bd25983 (fresh pair): thrust_profile_3 (-4 % and -9 % at the later knots), chi2/dof 0.943, "
                         "explained; the cold day is not in these data (dT_air -0.1 +- 2.0 K beside the profile): "
                         "right but partly",
}
# Mended: "blowdown+jet-wind" (511eec0: time_offset_2 + temperature, partly explained; e581239: wind_pl_13 +
# thrust_profile_3, 0.956, explained -- a warm refit at the noise at an implausible point is also made from the
# model's guesses) and "vacuum-nozzle+doppler-scale" (511eec0: back_pressure + scale_v + time_offset, 1.172;
# e581239: back_pressure_fade + scale_v, 1.033, explained -- the back-pressure's tail-off fade estimated).


@pytest.fixture(scope="module")
def petrel_spec():
    return V.build_model()


@pytest.fixture(scope="module")
def clean_outputs():
    return truth.exact_outputs(Hidden(), V.sample_times())


def test_truth_reproduces_the_vehicle_model(petrel_spec, clean_outputs):
    """Cartesian position and velocity about the Earth's centre (truth) against speed and path angle
    (model), through the cutoff, the tail-off and the coast: < 1 mm (measured 3e-5 m)."""
    model = ri.simulate(petrel_spec, V.truth(petrel_spec), V.sample_times()).outputs()
    for name in ("x", "h", "v"):
        assert np.max(np.abs(clean_outputs[name] - model[name])) < 1e-3, name


def test_the_truth_s_atmosphere_is_the_1976_standard():
    """The truth's own layers and hydrostatic integration against rocketid's us76 over 0-50 km: density,
    pressure and speed of sound agree to 1e-9 (measured 2e-13), far below what moves the flight."""
    from rocketid.physics.atmosphere import density, speed_of_sound, us76_pressure
    hs = np.linspace(0.0, 50_000.0, 201)
    air = truth.air(0.0)
    rho = np.array([air.density(h) for h in hs])
    sound = np.array([air.sound_speed(h) for h in hs])
    pressure = np.array([air.pressure(h) for h in hs])
    assert np.max(np.abs(rho / density(hs, "us76") - 1)) < 1e-9
    assert np.max(np.abs(sound / speed_of_sound(hs) - 1)) < 1e-9
    assert np.max(np.abs(pressure / np.array([float(us76_pressure(h)) for h in hs]) - 1)) < 1e-9


def test_the_cold_day_is_hydrostatic_from_the_standard_sea_level():
    """10 K colder: the sea-level pressure the standard's, density +3.6 % there, +3.1 % at the pad, -15 %
    at 30 km; the speed of sound unchanged (a pure density change)."""
    std, cold = truth.air(0.0), truth.air(-10.0)
    assert cold.pressure(0.0) == pytest.approx(101_325.0, rel=1e-12)
    assert cold.density(1420.0) / std.density(1420.0) - 1 == pytest.approx(0.0307, abs=5e-4)
    assert cold.density(30_000.0) / std.density(30_000.0) - 1 == pytest.approx(-0.146, abs=2e-3)
    assert cold.sound_speed(20_000.0) == std.sound_speed(20_000.0)


def test_the_flight_is_a_booster_s(clean_outputs, petrel_spec):
    """Realistic flight conditions: Mach 3.4 at cutoff, 31 km at 60 s, a coast after the tail-off."""
    from rocketid.physics.atmosphere import speed_of_sound
    states = ri.simulate(petrel_spec, V.truth(petrel_spec), V.sample_times()).states
    mach = states[:, 2] / speed_of_sound(states[:, 1])
    assert 3.2 < mach.max() < 3.6
    assert 28_000.0 < clean_outputs["h"][-1] < 34_000.0
    assert clean_outputs["v"][-1] < clean_outputs["v"][499]            # slowing in the coast
    assert states[-1, 4] == pytest.approx(states[510, 4], abs=1e-6)    # no mass flow after 51 s


def test_vehicle_fits_clean_data_to_the_noise(petrel_spec):
    """The base model at the noise on clean data (seed 7, not a study seed), every coefficient within 3 %."""
    data = truth.measurements(Hidden(), seed=7)
    fit = ri.estimate(petrel_spec, data)
    assert fit.success, fit.message
    dof = fit.n_data - fit.n_estimated
    assert abs(fit.chi2_per_dof - 1) < 4 * math.sqrt(2 / dof)
    for name, true in V.truth(petrel_spec).items():
        assert abs(fit.value(name) / true - 1) < 0.03, name


def test_vehicle_fits_noise_free_truth_exactly(petrel_spec, clean_outputs):
    """The cutoff, the 1 s tail-off and the coast on the default mesh: noise-free truth data fit to
    2J < 0.01 (measured 3e-4), the coefficients to 1e-3."""
    data = ri.Measurements.from_arrays(V.sample_times(), clean_outputs, sigma=dict(V.SIGMA))
    fit = ri.estimate(petrel_spec, data)
    assert fit.success, fit.message
    assert fit.chi2_per_dof * (fit.n_data - fit.n_estimated) < 0.01
    for name, true in V.truth(petrel_spec).items():
        assert abs(fit.value(name) / true - 1) < 1e-3, name


def test_the_blowdown_loses_six_percent_at_cutoff():
    """The thrust factor ``1 - c m_used`` is 0.94 at cutoff, from the flight's own propellant used."""
    flight = truth.Flight(Hidden(blowdown=0.06))
    mass = flight.states(np.array([truth.V.T_CUTOFF]))[0, 4]
    assert 1 - flight.c_blow * (flight.m0 - mass) == pytest.approx(0.94, abs=1e-8)


def test_the_nozzle_adds_its_pressure_term_from_the_pad_up():
    """At the rail exit (1420 m) the 0.06 m^2 exit adds A_e (p_sl - p) = 0.96 kN, and nothing in the coast."""
    y = truth.Flight(Hidden()).initial()
    for t, added in ((0.0, 0.06 * (101_325.0 - truth.air(0.0).pressure(1420.0))), (55.0, 0.0)):
        plain = np.array(truth.Flight(Hidden()).rhs(t, y))
        nozzle = np.array(truth.Flight(Hidden(A_e=0.06)).rhs(t, y))
        force = np.hypot(*(nozzle - plain)[2:4]) * y[4]
        assert force == pytest.approx(added, rel=1e-9, abs=1e-9)
    assert 950.0 < 0.06 * (101_325.0 - truth.air(0.0).pressure(1420.0)) < 960.0


def test_the_wind_profile():
    """4 m/s at the pad, 8 m/s 1 km above it (log law), 25 m/s more at the jet's core."""
    hid = Hidden(jet_wind=JET)
    assert truth.wind(hid, 1400.0) == pytest.approx(4.0 + 25.0 * math.exp(-0.5 * (9.6 / 2.0) ** 2), abs=1e-9)
    assert truth.wind(hid, 2400.0) == pytest.approx(8.0 + 25.0 * math.exp(-0.5 * (8.6 / 2.0) ** 2), abs=1e-9)
    assert truth.wind(hid, 11_000.0) == pytest.approx(33.0, abs=1e-9)


@pytest.mark.parametrize("hidden, channel, low, high", [          # measured: the largest change
    (Hidden(blowdown=0.06), "v", 40.0, 100.0),                     # 65.7 m/s
    (Hidden(A_e=0.06), "v", 80.0, 150.0),                          # 113 m/s
    (Hidden(cold_dT=-10.0), "v", 2.5, 5.0),                        # 3.7 m/s (25 sigma)
    (Hidden(jet_wind=JET), "x", 450.0, 900.0),                     # 672 m
    (Hidden(dm0=40.0), "v", 20.0, 45.0),                           # 32.8 m/s
    (Hidden(delta=MIS), "x", 25.0, 60.0),                          # 42 m (14 sigma)
    (Hidden(bias_h=25.0), "h", 24.99, 25.01),                      # 25 m
    (Hidden(scale_v=0.003), "v", 2.5, 3.5),                        # 0.3 % of 1000 m/s
    (Hidden(v_latency=0.12), "v", 2.5, 5.0),                       # 3.7 m/s in the tail-off (25 sigma)
])
def test_each_hidden_effect_changes_the_flight(clean_outputs, hidden, channel, low, high):
    """Every hidden effect moves the outputs by a realistic amount (largest change in range): at least
    a few sigma somewhere."""
    moved = truth.exact_outputs(hidden, V.sample_times())[channel]
    change = float(np.max(np.abs(moved - clean_outputs[channel])))
    assert low < change < high, change
    assert change > 3 * V.SIGMA[channel]


def test_the_speed_latency_moves_the_speed_channel_only(clean_outputs):
    moved = truth.exact_outputs(Hidden(v_latency=0.12), V.sample_times())
    assert np.array_equal(moved["x"], clean_outputs["x"]) and np.array_equal(moved["h"], clean_outputs["h"])
    late = truth.exact_outputs(Hidden(), V.sample_times()[5:] - 0.12)["v"]        # on-grid shifted samples
    assert np.max(np.abs(moved["v"][5:] - late)) < 1e-9


def test_classification_rules():
    """A wrong family called explained is the worst outcome; the out-of-catalogue case passes only
    without "explained"."""
    case = BY_NAME["vacuum-nozzle"]
    final = {"effects": ["back_pressure"], "verdict": "explained", "parameters": {}}
    assert STUDY.classify(case, {"final": final}) == "right & explained"
    assert STUDY.classify(case, {"final": {**final, "effects": ["thrust_profile_5"]}}) == "WRONG called explained"
    latency = BY_NAME["v-latency"]
    assert not STUDY.acceptable(latency, {"final": {**final, "effects": ["time_offset"]}})
    assert STUDY.acceptable(latency, {"final": {**final, "effects": ["time_offset"], "verdict": "partly explained"}})
    pair = BY_NAME["blowdown+jet-wind"]
    assert STUDY.classify(pair, {"final": {**final, "effects": ["burn_rate"]}}) == "right but partly"
    assert STUDY.classify(pair, {"final": {**final, "effects": ["burn_rate", "wind_pl_6"]}}) == "right & explained"
    clean = BY_NAME["clean-520"]
    assert not STUDY.acceptable(clean, {"final": final})


def test_the_cases_are_consistent():
    """Names and seeds unique, every needed family a right one, a pair with one set per effect; the study's 21
    cases and the eight fresh pairs (seeds 531-538), none out of the catalogue but the speed latency."""
    assert len(BY_NAME) == len(ALL) == 29 and len({c.seed for c in ALL}) == len(ALL)
    for case in ALL:
        assert case.needed <= case.right, case.name
        assert all(group <= case.right for group in case.needed_each), case.name
        assert ("+" in case.name) == bool(case.needed_each), case.name
    assert [c.name for c in ALL if c.out_of_catalogue] == ["v-latency"]
    assert [c.seed for c in FRESH] == list(range(531, 539))
    # a blowdown found with its mass flow is right, not needed
    assert STUDY.classify(BY_NAME["blowdown+heavy-start"], {"final": {
        "effects": ["thrust_profile_3", "mass_flow", "start_mass"], "verdict": "explained", "parameters": {}}}) \
        == "right & explained"


def test_the_hold_out_holds_a_drag_knot_its_window_does_not_determine(petrel_spec):
    """The speed reading 0.3 % high: fitted on 0-40.9 s (Mach <= 2.5) the last drag knot (Mach 3.5) is only
    touched (standard error 1.6-2.2 for a value near 0.4) and its extrapolation decided the prediction of
    the coast -- the right effect was 'not an explanation' (x RMS 70 m against the base model's 26 m). Held at
    the model's own guess in both window fits, the prediction of the coast carries the same guess in both,
    and the model with ``scale_v`` predicts it no worse than the base model."""
    from rocketid.diagnostics.refit import confirm

    case = BY_NAME["doppler-scale"]
    data = truth.measurements(case.hidden, case.seed)
    base = ri.estimate(petrel_spec, data)
    conf = confirm(base, "scale_v")
    assert conf.predicts, conf.prediction_note
    assert abs(conf.effect_estimates["k_v"][0] - 0.003) < 1e-4
    assert any("do not determine CD_5" in n and "held at their guesses in both" in n for n in conf.notes), conf.notes
    assert all(new <= old for old, new in conf.holdout_rms.values()), conf.holdout_rms
    assert conf.holdout_error(1) <= conf.holdout_error(0)


@pytest.mark.parametrize("name, visible", [("vacuum-nozzle+cold-day", "back_pressure_fade"),
                                           ("blowdown+cold-day", "thrust_profile_3")])
def test_a_cold_day_beside_a_visible_effect_is_beyond_these_data(petrel_spec, name, visible):
    """The measured reason of the fresh cold-day pairs' KNOWN_FAILURES: on Petrel-V the 10 K cold day is not in
    these data (alone, the cold-day case reaches the noise with nothing added: the drag table takes it). Beside the
    visible effect the diagnosis finds, the temperature offset refitted from the base fit comes out near zero
    with a standard error of about 2 K -- the true -10 K more than three standard errors away -- and adds nothing
    the noise can show: the visible effect alone explains the data at a BIC lower."""
    from study_harness import SetCheck
    case = BY_NAME[name]
    check = SetCheck(ri.estimate(petrel_spec, truth.measurements(case.hidden, case.seed)))
    shapes = check.shapes("back_pressure", "density", "thrust_level")
    alone, with_cold = check.judge([shapes[visible]]), check.judge([shapes[visible], shapes["temperature"]])
    assert alone.accepted, [c.name for c in alone.checks if not c.passed]
    dT, se = with_cold.refit.estimate("dT_air")
    assert abs(dT - case.hidden.cold_dT) > 3 * se and abs(dT) < 2 * se, (dT, se)
    assert alone.refit.bic[1] < with_cold.refit.bic[1], (alone.refit.bic, with_cold.refit.bic)


def test_beside_the_finer_wind_the_start_mass_explains_what_a_thrust_profile_took(petrel_spec):
    """The premise of the exchange after the finer shape (``rocketid.diagnostics.step._refined_again``), on a fresh
    pair that was a wrong explanation before it (bd25983): 40 kg of ballast and a jet stream ended ``wind_pl_9`` +
    ``thrust_profile_9``, explained -- the thrust error on nine knots chosen beside the coarse wind. From the base
    fit, ``wind_pl_9`` + ``start_mass`` passes every check at a BIC more than ``BIC_TIE`` lower, with the ballast's
    mass; the constant thrust error beside the wind does not reach the noise."""
    from rocketid.diagnostics.step import BIC_TIE
    from study_harness import SetCheck
    case = BY_NAME["heavy-start+jet-wind"]
    check = SetCheck(ri.estimate(petrel_spec, truth.measurements(case.hidden, case.seed)))
    sh = check.shapes("wind", "thrust_level")
    profile, mass, level = (check.judge([sh["wind_pl_9"], sh[n]]) for n in ("thrust_profile_9", "start_mass",
                                                                             "thrust_level"))
    assert profile.accepted and mass.accepted and not level.accepted
    assert mass.refit.bic[1] < profile.refit.bic[1] - BIC_TIE, (mass.refit.bic, profile.refit.bic)
    assert abs(mass.refit.estimate("dm_start")[0] - case.hidden.dm0) < 3.0, mass.refit.estimate("dm_start")


def test_a_refit_at_the_noise_from_a_distorted_start_is_tried_from_the_guesses(petrel_spec):
    """Blowdown and a jet-stream wind at once: the base fit is pushed to its bounds (the drag's first knot at
    2.0, the lift slope at 30), the 13-knot wind alone reaches chi2/dof 2.80 with oversized knots, and the
    wind with a 3-knot thrust profile started from there converged at 1.045 -- inside the noise band, with
    knots of 155-449 m/s and the lift slope at 0: a local optimum the search took as "beyond a plausible
    size". A refit that lands at the noise with an effect beyond five realistic sizes (or a coefficient at a
    bound) is also made from the model's own guesses, and the better optimum is kept: the pair at 0.956,
    the jet's peak within 10 % of the truth's 33 m/s, the thrust profile's last knot 6-12 % low (the truth's
    thrust is 6 % low at cutoff and its mass flow falls with it, which a thrust profile alone carries as a
    larger fall: 9.0 % in the fit)."""
    from rocketid.diagnostics import step as S
    from rocketid.diagnostics.accept import SIZE_FACTOR, noise_band
    from rocketid.diagnostics.effects import CATALOGUE
    from rocketid.diagnostics.refit import run_refit
    from rocketid.diagnostics.screen import vehicle_of

    case = BY_NAME["blowdown+jet-wind"]
    data = truth.measurements(case.hidden, case.seed)
    base = ri.estimate(petrel_spec, data)
    veh = vehicle_of(base)
    band = noise_band(base)
    ctx = S._Search(petrel_spec, band, veh, 0.05, None, 180.0, 1, True, None)
    shapes = {e.name: e for f in ("wind", "thrust_level") for e in CATALOGUE[f].refinements(veh)}
    wind, thrust = shapes["wind_pl_13"], shapes["thrust_profile_3"]
    alone, _ = run_refit(ctx.task(base, [wind], (wind.name,)))
    assert band.upper < alone.chi2_per_dof < 5
    current = S._fit_of(petrel_spec, [wind], alone, data, base.prepared.transcription.mesh, None)
    pair, _ = run_refit(ctx.task(current, [wind, thrust], (thrust.name,)))
    assert any("refitted from the model's guesses" in n and "beyond 5 realistic sizes" in n for n in pair.notes), \
        pair.notes
    assert pair.success and pair.chi2_per_dof < 1.0, pair.chi2_per_dof
    assert max(pair.size_ratio().values()) < SIZE_FACTOR and not pair.at_bound
    peak = max(pair.estimate(f"W_{j}")[0] for j in range(13))
    assert abs(peak - 33.0) < 3.3, peak
    assert -0.12 < pair.estimate("eps_P2")[0] < -0.06


@pytest.mark.slow
@pytest.mark.parametrize("case", ALL, ids=[c.name for c in ALL])
def test_diagnose_on_petrel_case(case, tmp_path, monkeypatch, request):
    """``rocketid diagnose`` (CLI) on the case: clean data add nothing, an effect the base fit does not
    show may go unfound, a visible one is found and explained, the out-of-catalogue speed latency is
    not called explained, and a wrong family is never reported as explained."""
    STUDY.check_case(case, KNOWN_FAILURES, tmp_path, monkeypatch, request)
