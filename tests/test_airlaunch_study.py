"""``rocketid diagnose`` on an air-launched winged vehicle started in flight.

Osprey-A (``tests/vehicles/osprey.py``) is declared from the user documentation: dropped from a
carrier aircraft, the data start at first-stage ignition at 11.8 km, 236 m/s and -1.5 deg; a
solid motor's sea-level thrust table, the mass as a state, a wing with a Mach table of the
lift-curve slope, a pull-up attitude program, CD as a Mach table from 0.8 to 9, 20 Hz data. Its
truth (``tests/airlaunch_study/truth.py``) flies Cartesian position and velocity about the
Earth's centre with vector forces and its own 1976 atmosphere, every hidden effect in its own
shape.

The normal suite checks the instruments: the truth without effects reproduces the estimation
model, the pressure table reproduces the 1976 standard, the vehicle fits clean data to the noise,
and every hidden effect changes the flight by a stated amount. The diagnoses run ``rocketid
diagnose`` from the command line, one per case, and are ``slow``:
``pytest -m slow tests/test_airlaunch_study.py``; the whole study with its table is
``python tests/airlaunch_study/run.py --json air.json``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest


import osprey as O

import rocketid as ri
from airlaunch_study import truth
from airlaunch_study.run import STUDY
from airlaunch_study.cases import ALL, BY_NAME, FRESH, JET, MIS, Hidden

#: Cases measured not to meet the bar (``STUDY.acceptable``), with the measured reason.
KNOWN_FAILURES: dict[str, str] = {
    "cold-column+drag-hump": "2c7cc74 (fresh pair): temperature, dT_air -7.5 +- 1.0 K (-8), explained at chi2/dof 1.003; "
                             "the hump at Mach 1.05 sits on the drag table's knot at Mach 1.0 (+0.106 there, +0.018 "
                             "at 1.25), which takes it up: CD_1 1.11 for 0.98 + 0.106 -- the model's own table draws "
                             "it, nothing of the drag family is missing: right but partly",
    "westward-rotation+v-scale": "d9b20fa (fresh pair): scale_v (k_v -0.003987 for -0.004) at step 1 (chi2/dof 4.31), "
                                 "then earth_rotation with k_rot -0.935 (the catalogue's 28.5 N eastward site: the "
                                 "Coriolis term reversed, the launch westward) and a misalignment from 21 s reach the "
                                 "noise within BIC 10: the tie named, partly explained; with the site stated "
                                 "(earth_rotation_effect(35, 270)) k_rot is 1.004 +- 0.009 at chi2/dof 1.042",
}
# (2026-11-26: "hot-motor" and "hot-motor+misalignment" failed on ffc28ec -- the 3 % faster burn reaches its
# tail-off 2 s early and no catalogue shape followed it; burn_rate, the motor on a faster clock, explains both.)


@pytest.fixture(scope="module")
def osprey_spec():
    return O.build_model()


@pytest.fixture(scope="module")
def clean_outputs():
    return truth.exact_outputs(Hidden(), O.sample_times())


def test_truth_reproduces_the_vehicle_model(osprey_spec, clean_outputs):
    """Cartesian position and velocity with vector forces (truth) against speed and path angle
    (rocketid's model, ``simulate``): < 1 mm, < 1 mm/s."""
    model = ri.simulate(osprey_spec, O.truth(osprey_spec), O.sample_times()).outputs()
    for name in ("x", "h", "v"):
        assert np.max(np.abs(clean_outputs[name] - model[name])) < 1e-3, name


def test_the_flight_is_an_air_launch(osprey_spec):
    """Ignition in flight at Mach 0.8, a pull-up to a climb, burn-out high and hypersonic."""
    tr = ri.simulate(osprey_spec, O.truth(osprey_spec), np.arange(0.0, O.TF + 1e-9, 1.0))
    mach, theta = tr.value("mach"), np.degrees(tr.states[:, 3])
    assert 0.78 < mach[0] < 0.82 and 8.0 < mach[-1] < 9.0
    assert theta.min() < -1.0 and 30.0 < theta.max() < 40.0
    assert 45_000 < tr.states[-1, 1] < 60_000
    assert np.degrees(np.abs(tr.value("alpha"))).max() < 17.0


#: US Standard Atmosphere 1976 (NOAA-S/T 76-1562): layer base pressures at geopotential altitude,
#: and the tabulated pressure (Pa) and density (kg/m^3) at geometric altitude.
BASE_PRESSURES = ((11_000.0, 22_632.06), (20_000.0, 5_474.889), (32_000.0, 868.0187),
                  (47_000.0, 110.9063), (51_000.0, 66.93887))
GEOMETRIC = ((10_000.0, 26_499.9, 0.41351), (20_000.0, 5_529.3, 0.088910), (30_000.0, 1_197.0, 0.018410),
             (40_000.0, 287.14, 0.0039957), (50_000.0, 79.779, 0.0010269))


def test_pressure_table_is_the_1976_standard():
    """The truth's own hydrostatic layers against the standard's published values."""
    r0 = truth.R0_GEOPOT
    for H, p in BASE_PRESSURES:
        _, p_truth, _ = truth.STANDARD.state(r0 * H / (r0 - H))
        assert abs(p_truth / p - 1) < 1e-6, H
    hs, p_truth, rho_truth = truth.pressure_table([z for z, _, _ in GEOMETRIC])
    for (z, p, rho), pt, rt in zip(GEOMETRIC, p_truth, rho_truth):
        assert abs(pt / p - 1) < 5e-5 and abs(rt / rho - 1) < 5e-5, z
    T10, _, _ = truth.STANDARD.state(10_000.0)
    assert abs(truth.STANDARD.sound(T10) - 299.53) < 0.01


def test_vehicle_fits_clean_data_to_the_noise(osprey_spec):
    """The base model on the truth's clean data, from the declared guesses: chi2/dof at the noise,
    every coefficient within 4 standard errors of the truth."""
    from rocketid.estimability import uncertainty
    data = truth.measurements(Hidden(), seed=7)
    fit = ri.estimate(osprey_spec, data)
    assert fit.success, fit.message
    dof = fit.n_data - fit.n_estimated             # n_samples counts every value of every channel
    assert abs(fit.chi2_per_dof - 1) < 4 * math.sqrt(2 / dof)
    se = uncertainty(fit).standard_errors
    p_true = osprey_spec.parameter_vector(O.truth(osprey_spec))
    z = (fit.p - p_true) / se
    assert np.max(np.abs(z)) < 4, dict(zip(osprey_spec.parameter_names, np.round(z, 2)))


def test_burn_rate_is_the_hot_motor(osprey_spec):
    """The catalogue's burn_rate at 0.03 flies the truth's hot motor (thrust curve and mass flow 3 % higher and
    3 % faster, written in the truth's own Cartesian shape) to 0.1 mm."""
    from rocketid.diagnostics import burn_rate_effect, with_effects
    spec = with_effects(osprey_spec, [burn_rate_effect()])
    t = O.sample_times()
    hot = ri.simulate(spec, {**O.truth(osprey_spec), "eps_burn": 0.03}, t).outputs()
    expected = truth.exact_outputs(Hidden(hot_motor=1.03), t)
    for name in ("x", "h", "v"):
        assert np.max(np.abs(hot[name] - expected[name])) < 1e-4, name


@pytest.mark.parametrize("hidden, channel, low, high", [          # measured: the largest change
    (Hidden(hot_motor=1.03), "x", 2000.0, 3500.0),                  # 2785 m
    (Hidden(A_e=0.9), "x", 8000.0, 14000.0),                        # 11.1 km
    (Hidden(jet=JET), "h", 350.0, 650.0),                           # 493 m
    (Hidden(dT=-10.0), "x", 350.0, 650.0),                          # 480 m
    (Hidden(delta=MIS), "h", 100.0, 200.0),                         # 142 m
    (Hidden(bias_h=(15.0, 0.0)), "h", 14.99, 15.01),                # 15 m
    (Hidden(scale_v=0.003), "v", 8.0, 9.5),                         # 8.69 m/s (0.3 % of 2.9 km/s)
    (Hidden(rotation=(28.5, 90.0)), "h", 100.0, 200.0),             # 151 m
    (Hidden(tau=0.03), "x", 60.0, 95.0),                            # 76.7 m
    (Hidden(dm0=292.5), "x", 1100.0, 1900.0),                       # 1486 m
    (Hidden(drag_bump=(0.15, 1.1, 0.15)), "x", 20.0, 40.0),        # 28.6 m
])
def test_each_hidden_effect_changes_the_flight(clean_outputs, hidden, channel, low, high):
    """Every hidden effect moves the outputs by a realistic amount, many sigma (largest change in range)."""
    base = clean_outputs[channel]
    moved = truth.exact_outputs(hidden, O.sample_times())[channel]
    change = float(np.max(np.abs(moved - base)))
    assert low < change < high, change
    assert change > 5 * O.SIGMA[channel]


def test_classification_rules():
    """The outcome classes: a wrong family called explained is the worst outcome; a pair needs both."""
    case = BY_NAME["back-pressure"]
    final = {"effects": ["back_pressure"], "verdict": "explained", "parameters": {}}
    assert STUDY.classify(case, {"final": final}) == "right & explained"
    assert STUDY.classify(case, {"final": {**final, "effects": ["thrust_level"]}}) == "right & explained"
    assert STUDY.classify(case, {"final": {**final, "effects": ["wind"]}}) == "WRONG called explained"
    assert STUDY.classify(case, {"final": {**final, "effects": ["wind"], "verdict": "partly explained"}}) \
        == "wrong, not called explained"
    assert STUDY.classify(case, {"final": {**final, "effects": []}}) == "nothing found"
    assert STUDY.classify(case, {"final": {**final, "verdict": "partly explained"}}) == "right but partly"
    pair = BY_NAME["jet-stream+h-bias"]
    assert STUDY.classify(pair, {"final": {**final, "effects": ["wind_pl_4"]}}) == "right but partly"
    assert STUDY.classify(pair, {"final": {**final, "effects": ["wind_pl_4", "bias_h"]}}) == "right & explained"
    assert STUDY.classify(BY_NAME["drag-hump"], {"final": {**final, "effects": ["drag_bump"]}}) == "right & explained"
    assert STUDY.classify(BY_NAME["cold-column"], {"final": {**final, "effects": ["temperature"]}}) \
        == "right & explained"
    clean = BY_NAME["clean-500"]
    assert not STUDY.acceptable(clean, {"final": {**final}})
    assert STUDY.acceptable(clean, {"final": {**final, "effects": []}})


def test_the_fresh_pairs_are_consistent():
    """The fresh pairs: seeds of their own, two hidden effects each, both families needed and right."""
    assert [c.seed for c in FRESH] == list(range(415, 423))
    assert len({c.seed for c in ALL}) == len(ALL) and len(BY_NAME) == len(ALL)
    for case in FRESH:
        assert len(case.needed_each) == 2 and all(group <= case.right for group in case.needed_each), case.name
        assert case.needed == case.needed_each[0] | case.needed_each[1], case.name
        moved = [f for f in Hidden.__dataclass_fields__ if getattr(case.hidden, f) != getattr(Hidden(), f)]
        assert len(moved) == 2, (case.name, moved)


def test_a_model_at_the_noise_takes_only_an_explanation(osprey_spec, tmp_path, monkeypatch):
    """Clean data (seed 501) that fit to the noise (chi2/dof 0.993) with one channel's Ljung-Box p at 0.011:
    the score test still names a time offset (corrected p 0.04), whose refit moves CD_0 by 24 % for 0.002 in
    chi2/dof -- not an explanation, so nothing is added (it once was, "partly explained")."""
    from rocketid.diagnostics import diagnose
    monkeypatch.setenv("ROCKETID_AIR_DIR", str(tmp_path))
    report = diagnose(STUDY.make_data(BY_NAME["clean-501"]), osprey_spec, workers=1)
    assert report.final.effects == () and report.final.verdict == "nothing missing", report.final
    assert any("does not explain more" in (s.why or "") for s in report.discovery.steps)


@pytest.mark.slow
def test_a_hot_motor_before_its_tail_off_is_not_a_lighter_vehicle(osprey_spec, tmp_path, monkeypatch):
    """The hot motor seen over 0-60 s only (a window that ends before the tail-off, where the faster clock
    shows): the thrust 3 % high and the vehicle 2 % light fit these x, h, v much alike, and before the burn
    rate was a shape, ``start_mass`` (-408 kg) was called explained. The burn rate is the answer, at its size."""
    from rocketid.diagnostics import diagnose
    monkeypatch.setenv("ROCKETID_AIR_DIR", str(tmp_path))
    data = STUDY.make_data(BY_NAME["hot-motor"])
    report = diagnose(ri.read_csv(data).window(0.0, 60.0), osprey_spec.windowed(0.0, 60.0), workers=2)
    assert report.final.effects == ("burn_rate",) and report.final.verdict == "explained", report.final
    value, std = report.final.parameters["eps_burn"]
    assert abs(value - 0.03) < 3 * std + 1e-3, (value, std)


@pytest.mark.slow
def test_a_westward_launch_stated_as_such_is_earth_rotation(osprey_spec):
    """The fresh pair westward-rotation+v-scale (KNOWN_FAILURES): the truth rotates its Cartesian frame at 35 N
    with the launch due west. The catalogue's rotation (28.5 N, east) refits to k_rot -0.935 -- the Coriolis term
    reversed -- and ties with a late misalignment; stated as the site it is, the rotation is Earth's own."""
    from rocketid.diagnostics import earth_rotation_effect
    from rocketid.diagnostics.refit import confirm
    case = BY_NAME["westward-rotation+v-scale"]
    base = ri.estimate(osprey_spec, truth.measurements(case.hidden, case.seed))
    stated = confirm(base, ["scale_v", earth_rotation_effect(35.0, 270.0)])
    k, sk = stated.effect_estimates["k_rot"][:2]
    assert stated.confirmed and abs(k - 1.0) < 3 * sk + 0.01, (k, sk)
    assert abs(stated.effect_estimates["k_v"][0] + 0.004) < 1e-4
    default = confirm(base, ["scale_v", "earth_rotation"])
    assert default.effect_estimates["k_rot"][0] < -0.8           # the stated site's rotation, reversed
    # the reading names the azimuths at 28.5 N whose Coriolis term (cos(lat) sin(az)) is the truth's, 35 N west
    from rocketid.diagnostics import CATALOGUE
    sine = math.cos(math.radians(35.0)) * math.sin(math.radians(270.0)) / math.cos(math.radians(28.5))
    west = sorted(((math.degrees(math.asin(sine)) % 360.0), (180.0 - math.degrees(math.asin(sine))) % 360.0))
    said = CATALOGUE["earth_rotation"].reading({"k_rot": default.effect_estimates["k_rot"][:2]})
    assert said.startswith("the Coriolis term reversed") and "state the launch site" in said, said
    lo, hi = (float(a) for a in said.split("flight toward ")[1].split(" deg")[0].split(" or "))
    assert abs(lo - west[0]) < 3.0 and abs(hi - west[1]) < 3.0, (said, west)


@pytest.mark.slow
@pytest.mark.parametrize("case", ALL, ids=[c.name for c in ALL])
def test_diagnose_on_air_launch_case(case, tmp_path, monkeypatch, request):
    """``rocketid diagnose`` (CLI) on the case: clean data add nothing, an effect the base fit does
    not show may go unfound, a visible one is found and explained, and a wrong family is never
    reported as explained."""
    STUDY.check_case(case, KNOWN_FAILURES, tmp_path, monkeypatch, request)
