"""``rocketid diagnose`` on a fin-stabilized sounding rocket: a short solid burn, then a long coast.

Tern-2 (``tests/vehicles/tern.py``) is declared from the user documentation: rail exit at 0.5 s
after ignition, 37.6 m/s and 84 deg; a solid motor's sea-level static-firing table every 0.25 s,
the mass as a state, zero attack angle (no lift), CD as a Mach table from 0.11 to 3.8; burn-out at
10.25 s near Mach 3.9, then the coast to 45.6 km by 60 s; radar x, h, v at 20 Hz. Its truth
(``tests/sounding_study/truth.py``) flies three-dimensional position and velocity about the Earth's
centre with vector forces and its own 1976 atmosphere, every hidden effect in its own shape (the
wind with the airframe's weathercock response).

The normal suite checks the instruments: the truth without effects reproduces the estimation
model, the flight is the one the vehicle's docstring states, the truth's atmosphere is the 1976
standard, the vehicle fits clean data to the noise, every hidden effect changes the flight by a
stated amount, and the outcome classes score as the cases say. The diagnoses run ``rocketid
diagnose`` from the command line, one per case, and are ``slow``:
``pytest -m slow tests/test_sounding_study.py``; the whole study with its table is
``python tests/sounding_study/run.py --json sounding.json``.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
from scipy.integrate import solve_ivp


import tern as V

import rocketid as ri
from sounding_study import truth
from sounding_study.run import STUDY
from sounding_study.cases import (A_EXIT, ALL, BASE_DRAG, BIAS_H, BY_NAME, DM0, DRAG_STEP, DT_COLD,
                                  K_COLD, K_V, TAU, WALLOPS, WIND, Hidden)

#: Cases measured not to meet the bar (``STUDY.acceptable``), with the measured reason.
KNOWN_FAILURES: dict[str, str] = {
    "headwind": "ab3aede: the wind is found (wind_pl_6, chi2/dof 0.991) but partly explained: CD_0 (the rail-exit Mach "
                "knot) at its lower bound. The catalogue's wind turns a finned rocket's thrust into the airflow at "
                "once; the truth's body swings into it as a pendulum (the fins' restoring moment against the body's "
                "inertia: a period of 11.5 s at rail exit, 1.5 s at 300 m/s) with a normal force while it swings, "
                "so the first seconds differ and the subsonic drag takes it up",
    "heavy-payload+headwind": "b7bba7f (fresh pair): start_angle + start_mass + wind at chi2/dof 1.074 (band 1.075), "
                              "partly explained -- dm_start 19.77 (20) found; the headwind as in 'headwind' (the "
                              "weathercocking body is not the catalogue's wind), a start angle beside it",
}
# Mended: "cold-day+heavy-payload" (b7bba7f: thrust_profile_5, 1.041, explained -- a wrong effect) and
# "back-pressure+cold-day" (b7bba7f: base_drag_mach_2, 1.026, explained -- a wrong effect): the pair of simple effects
# (7a916e9, bd25983) ends start_mass + temperature at 1.032 and back_pressure + temperature at 1.017, right and explained.


@pytest.fixture(scope="module")
def tern_spec():
    return V.build_model()


@pytest.fixture(scope="module")
def clean_outputs():
    return truth.exact_outputs(Hidden(), V.sample_times())


def test_truth_reproduces_the_vehicle_model(tern_spec, clean_outputs):
    """Three-dimensional position and velocity with vector forces (truth) against speed and path angle
    (rocketid's model, ``simulate``): < 1 mm, < 1 mm/s."""
    model = ri.simulate(tern_spec, V.truth(tern_spec), V.sample_times()).outputs()
    for name in ("x", "h", "v"):
        assert np.max(np.abs(clean_outputs[name] - model[name])) < 1e-3, name


def test_burn_rate_is_the_cold_motor(tern_spec):
    """The catalogue's burn_rate at -0.03 flies the truth's cold motor (its thrust ``0.97 P(0.97 t)`` and its
    mass at rail exit from the table's impulse, in the truth's own Cartesian shape): the data start at rail
    exit, 0.5 s after ignition, where the slower clock has burnt 0.56 kg less, which the effect takes to first
    order (h within 0.2 m, 0.07 sigma)."""
    from rocketid.diagnostics import burn_rate_effect, with_effects
    spec = with_effects(tern_spec, [burn_rate_effect()])
    t = V.sample_times()
    cold = ri.simulate(spec, {**V.truth(tern_spec), "eps_burn": -0.03}, t).outputs()
    expected = truth.exact_outputs(Hidden(motor_clock=0.97), t)
    for name, tol in (("x", 0.05), ("h", 0.2), ("v", 0.01)):
        assert np.max(np.abs(cold[name] - expected[name])) < tol, name


def test_the_site_shape_finds_the_launch_site(tern_spec):
    """The catalogue's Earth rotation is at 28.5 N toward the east; Tern-2 flew from 37.84 N toward 120 deg in
    the truth's three-dimensional Earth-fixed frame (Coriolis and centrifugal as vectors, out of the plane
    too). ``earth_rotation`` alone cannot reach the noise there; the shape that estimates the site does,
    with the real Earth's rate and the truth's latitude and azimuth inside three standard errors."""
    from rocketid.diagnostics import earth_rotation_effect, earth_rotation_site_effect, with_effects
    from rocketid.estimability import uncertainty
    data = truth.measurements(Hidden(rotation=WALLOPS), 611)
    fixed = ri.estimate(with_effects(tern_spec, [earth_rotation_effect()]).with_guess({"k_rot": 1.0}), data)
    spec = with_effects(tern_spec, [earth_rotation_site_effect()]).with_guess({"k_rot": 1.0})
    fit = ri.estimate(spec, data)
    se = dict(zip(spec.parameter_names, uncertainty(fit).standard_errors))
    got = dict(zip(spec.parameter_names, fit.p))
    assert fixed.chi2_per_dof > 1.06 and fit.chi2_per_dof < 1.04, (fixed.chi2_per_dof, fit.chi2_per_dof)
    lat, az = WALLOPS
    for name, want in (("k_rot", 1.0), ("dlat_rot", lat - 28.5), ("daz_rot", az - 90.0)):
        assert np.isfinite(se[name]) and abs(got[name] - want) < 3 * se[name], (name, got[name], se[name])
    assert se["k_rot"] < 0.1 and se["daz_rot"] < 5.0 and se["dlat_rot"] < 8.0


def test_a_wind_turns_a_finned_rocket_into_the_airflow(tern_spec):
    """Tern-2 is declared without lift: in a wind its body, and the thrust along it, turn into the airflow. The
    truth does so as a lightly damped pendulum of its static margin; the catalogue's wind, for a model whose
    lift coefficient is zero, turns the thrust with the airflow at once. On the headwind case a 5-knot wind
    profile then reaches the noise from chi2/dof 2e5, and the wind at the jet core (11 km) is the truth's
    within three standard errors."""
    from rocketid.diagnostics import wind_profile_effect, with_effects
    from rocketid.estimability import uncertainty
    data = truth.measurements(Hidden(wind=WIND), 603)
    spec = with_effects(tern_spec, [wind_profile_effect((0.009, 0.5, 5.0, 11.0, 20.0))])
    fit = ri.estimate(spec, data)
    se = dict(zip(spec.parameter_names, uncertainty(fit).standard_errors))
    got = dict(zip(spec.parameter_names, fit.p))
    assert fit.chi2_per_dof < 1.05, fit.chi2_per_dof
    core = truth.wind_speed(11_000.0, WIND)
    assert abs(got["W_3"] - core) < 3 * se["W_3"] and se["W_3"] < 2.0, (got["W_3"], se["W_3"], core)


def test_a_calm_wind_leaves_the_body_on_the_path(clean_outputs):
    """The weathercock branch with a zero wind flies the clean truth (the body stays on the path), to the
    integrator's tolerance (measured 1.3e-6 m)."""
    calm = truth.exact_outputs(Hidden(wind=(0.0, 0.0)), V.sample_times())
    for name in ("x", "h", "v"):
        assert np.max(np.abs(calm[name] - clean_outputs[name])) < 1e-5, name


def test_the_rail_gives_the_declared_start():
    """The start (37.6 m/s at 0.5 s) is what the thrust table gives along a 7 m rail at 84 deg."""
    def along_rail(t, y):
        thrust = float(np.interp(t, V.THRUST_TIMES, V.THRUST_VALUES))
        mass = V.M_LAUNCH - V.burnt(t)
        return [y[1], max(thrust / mass - V.G0 * math.sin(V.ELEVATION), 0.0)]
    sol = solve_ivp(along_rail, (0.0, V.T_RAIL), [0.0, 0.0], rtol=1e-10, atol=1e-10, max_step=0.01)
    run_m, speed = sol.y[:, -1]
    assert abs(speed - V.START[2]) < 0.1 and 6.5 < run_m < 7.5, (speed, run_m)
    assert abs(V.M_START - 795.67) < 0.01 and abs(V.M_LAUNCH - V.burnt(V.TF) - 423.02) < 0.01


def test_the_flight_is_a_short_burn_and_a_long_coast(tern_spec):
    """Burn-out at 10.25 s, peak Mach 3.9 near it, the coast climbing to 45.6 km by 60 s, far from level;
    every Mach knot of the drag table flown."""
    t = np.concatenate([[V.T_RAIL], V.sample_times()])            # rail exit and the radar's tags
    tr = ri.simulate(tern_spec, V.truth(tern_spec), t)
    x, h, v, theta, mass = tr.states.T
    mach, q = tr.value("mach"), tr.value("qbar")
    thrust = np.interp(t, V.THRUST_TIMES, V.THRUST_VALUES, right=0.0)
    assert t[thrust > 0].max() < V.T_BURNOUT <= t[thrust == 0][t[thrust == 0] > 1].min()
    assert np.ptp(mass[t >= V.T_BURNOUT]) < 1e-9 and abs(mass[-1] - 423.02) < 0.01
    assert 3.85 < mach.max() < 3.95 and 9.0 < t[mach.argmax()] < 10.0
    assert mach.max() > V.CD_KNOTS[-1] and abs(mach[0] - V.CD_KNOTS[0]) < 0.005
    assert 1.55 < mach[-1] < 1.7                                   # the coast crosses Mach 2 again
    assert 45_000 < h[-1] < 46_500 and 7_500 < x[-1] < 8_100 and 525 < v[-1] < 540
    assert 5_500 < h[t <= V.T_BURNOUT][-1] < 7_500
    assert np.all(np.diff(h) > 0) and 74.0 < math.degrees(theta[-1]) < 76.5 and np.all(np.diff(theta) < 0)
    assert 540e3 < q.max() < 560e3


#: US Standard Atmosphere 1976 (NOAA-S/T 76-1562): layer base pressures at geopotential altitude,
#: and the tabulated temperature (K), pressure (Pa) and density (kg/m^3) at geometric altitude.
BASE_PRESSURES = ((11_000.0, 22_632.06), (20_000.0, 5_474.889), (32_000.0, 868.0187),
                  (47_000.0, 110.9063), (51_000.0, 66.93887))
GEOMETRIC = ((0.0, 288.150, 101_325.0, 1.2250), (5_000.0, 255.676, 54_048.0, 0.73643),
             (10_000.0, 223.252, 26_499.9, 0.41351), (20_000.0, 216.650, 5_529.3, 0.088910),
             (30_000.0, 226.509, 1_197.0, 0.018410), (45_000.0, 264.164, 149.10, 0.0019663))


def test_the_truth_atmosphere_is_the_1976_standard():
    """The truth's own hydrostatic layers against the standard's published values."""
    std, r0 = truth.air(0.0), truth.GEOPOTENTIAL_RADIUS
    for H, p in BASE_PRESSURES:
        assert abs(std.at(r0 * H / (r0 - H))[1] / p - 1) < 1e-6, H
    for z, T, p, rho in GEOMETRIC:
        Tt, pt, rt, _ = std.at(z)
        assert abs(Tt - T) < 2e-3 and abs(pt / p - 1) < 5e-5 and abs(rt / rho - 1) < 5e-5, z
    assert abs(std.at(0.0)[3] - 340.29) < 0.01 and abs(std.at(10_000.0)[3] - 299.53) < 0.01


def test_the_cold_day_is_hydrostatic():
    """15 K colder over the column at the standard ground pressure: the densities the case states, and the
    pressure falling faster with height (the hydrostatic equation at the colder temperature)."""
    std, cold = truth.air(0.0), truth.air(DT_COLD)
    for z, ratio in ((0.0, 0.055), (4_000.0, 0.031), (10_000.0, -0.015), (20_000.0, -0.121), (35_000.0, -0.258)):
        assert abs(cold.at(z)[2] / std.at(z)[2] - 1 - ratio) < 1e-3, z
    z, dz = 8_000.0, 1.0
    (T0, p0, rho0, a0), (_, p1, _, _) = cold.at(z), cold.at(z + dz)
    g = truth.STD_GRAVITY * (truth.GEOPOTENTIAL_RADIUS / (truth.GEOPOTENTIAL_RADIUS + z)) ** 2
    assert abs((p1 - p0) / dz / (-rho0 * g) - 1) < 1e-3
    assert abs(a0 / std.at(z)[3] - math.sqrt(T0 / std.at(z)[0])) < 1e-12


def test_the_back_pressure_thrust_is_the_stated_one():
    """A 0.30 m nozzle exit: +2.8 kN at 4 km, nothing at the rail, nothing after burn-out."""
    flight = truth.Flight(Hidden(A_e=A_EXIT))
    std = truth.air(0.0)
    t = 7.0
    extra = flight.motor(t, std.at(4_000.0)[1])[0] - truth.table_thrust(t)
    assert 2_790 < extra < 2_820, extra
    assert abs(flight.motor(t, truth.SEA_LEVEL_PRESSURE)[0] - truth.table_thrust(t)) < 1e-9
    assert flight.motor(12.0, 100.0) == (0.0, 0.0)
    assert abs(math.pi * 0.15 ** 2 - A_EXIT) < 1e-4


def test_vehicle_fits_clean_data_to_the_noise(tern_spec):
    """The base model on the truth's clean data, from the declared guesses: chi2/dof at the noise,
    every coefficient within 4 standard errors of the truth."""
    from rocketid.estimability import uncertainty
    data = truth.measurements(Hidden(), seed=7)
    fit = ri.estimate(tern_spec, data)
    assert fit.success, fit.message
    dof = fit.n_data - fit.n_estimated                     # n_data counts every value of every channel
    assert dof == 3 * V.sample_times().size - len(tern_spec.parameter_names)
    assert abs(fit.chi2_per_dof - 1) < 4 * math.sqrt(2 / dof)
    se = uncertainty(fit).standard_errors
    p_true = tern_spec.parameter_vector(V.truth(tern_spec))
    z = (fit.p - p_true) / se
    assert np.max(np.abs(z)) < 4, dict(zip(tern_spec.parameter_names, np.round(z, 2)))


@pytest.mark.parametrize("hidden, absorbed", [
    (Hidden(drag_step=DRAG_STEP), True),          # measured 2J 2.9 on 3559 degrees of freedom
    (Hidden(base_drag=BASE_DRAG), False),         # measured 2J 7.4e4
])
def test_what_the_drag_table_absorbs(tern_spec, hidden, absorbed):
    """Noise-free data of the two drag cases, fitted by the base model: the free Mach table takes a CD error
    above Mach 2 almost exactly (the case's "nothing found" passes), but not a drag that changes with the
    motor's state at the same Mach numbers (boost and coast both fly Mach 1.6-3.9)."""
    t = V.sample_times()
    data = ri.Measurements.from_arrays(t, truth.exact_outputs(hidden, t), sigma=dict(V.SIGMA))
    fit = ri.estimate(tern_spec, data)
    assert fit.success, fit.message
    two_j = 2.0 * fit.data_objective
    assert (two_j < 20.0) if absorbed else (two_j > 1e4), two_j


@pytest.mark.parametrize("hidden, channel, low, high", [          # measured: the largest change
    (Hidden(motor_clock=K_COLD), "v", 35.0, 46.0),                  # 40.3 m/s
    (Hidden(A_e=A_EXIT), "h", 950.0, 1300.0),                       # 1116 m
    (Hidden(wind=WIND), "x", 3500.0, 4700.0),                       # 4065 m
    (Hidden(dT=DT_COLD), "h", 270.0, 370.0),                        # 319 m
    (Hidden(dm0=DM0), "h", 1450.0, 1950.0),                         # 1679 m
    (Hidden(bias_h=BIAS_H), "h", 9.99, 10.01),                      # 10 m
    (Hidden(scale_v=K_V), "v", 2.4, 2.56),                          # 2.48 m/s (0.2 % of 1240 m/s)
    (Hidden(tau=TAU), "v", 2.8, 3.6),                               # 3.20 m/s (20 ms of 160 m/s^2)
    (Hidden(drag_step=DRAG_STEP), "h", 1200.0, 1600.0),             # 1389 m
    (Hidden(base_drag=BASE_DRAG), "h", 1500.0, 2000.0),             # 1742 m
    (Hidden(rotation=WALLOPS), "x", 115.0, 165.0),                  # 139 m
])
def test_each_hidden_effect_changes_the_flight(clean_outputs, hidden, channel, low, high):
    """Every hidden effect moves the outputs by a realistic amount (largest change in range), many sigma
    over the flight (the root sum of squares of the changes in sigma over all samples and channels)."""
    moved = truth.exact_outputs(hidden, V.sample_times())
    change = float(np.max(np.abs(moved[channel] - clean_outputs[channel])))
    assert low < change < high, change
    significance = math.sqrt(sum(float(np.sum(((moved[n] - clean_outputs[n]) / V.SIGMA[n]) ** 2))
                                 for n in ("x", "h", "v")))
    assert significance > 50.0, significance


def test_the_cases_are_consistent():
    """Names and seeds unique, every needed family a right one, pairs with one set per effect, six clean
    seeds, no out-of-catalogue case; the study's 20 cases and the eight fresh pairs."""
    assert len(BY_NAME) == len(ALL) == 28 and len({c.seed for c in ALL}) == len(ALL)
    for case in ALL:
        assert case.needed <= case.right, case.name
        assert all(group <= case.right for group in case.needed_each), case.name
        assert ("+" in case.name) == bool(case.needed_each), case.name
    assert sum(c.name.startswith("clean-") for c in ALL) == 6
    # the base drag was out of the catalogue until the study's runs called it explained by a density profile;
    # base_drag (2026-11-26) is its family since
    assert not [c.name for c in ALL if c.out_of_catalogue] and BY_NAME["base-drag"].right == {"base_drag"}
    assert set(STUDY.coefficients) == {f"CD_{j}" for j in range(len(V.CD_KNOTS))}


@pytest.mark.parametrize("name, flexible, wrong_sign, pair, truth_sizes", [
    ("cold-day+heavy-payload", "thrust_profile_5", False, ("start_mass", "temperature"), {"dm_start": (DM0, 1.5),
                                                                                          "dT_air": (DT_COLD, 1.5)}),
    ("back-pressure+cold-day", "base_drag_mach_2", True, ("back_pressure", "temperature"), {"A_e": (A_EXIT, 0.005),
                                                                                             "dT_air": (DT_COLD, 1.5)}),
])
def test_the_true_pair_explains_at_a_lower_bic_than_the_flexible_shape_of_the_first_step(tern_spec, name, flexible,
                                                                                        wrong_sign, pair, truth_sizes):
    """The premise of the pair of simple effects (``rocketid.diagnostics.step``, module note 11), on two fresh pairs
    that were wrong explanations before it (b7bba7f): from the base fit, the flexible shape the first step takes (a
    5-knot thrust error; a power-off base drag on two Mach knots, -0.28 at the first) reaches the noise, and the
    true pair of simple effects explains the data at the truth's sizes with a BIC more than ``BIC_TIE`` (10) lower
    -- the margin the stage asks before it replaces the flexible shape. The thrust error passes every check of an
    explanation; the base drag, since 2026-11-28, fails one: its average over the Mach range flown is negative, a
    power-off *decrease*, the wrong sign for its physics (``Effect.positive``). The whole diagnosis of each case
    is ``test_diagnose_on_sounding_case`` (slow)."""
    from rocketid.diagnostics.step import BIC_TIE
    from study_harness import SetCheck
    case = BY_NAME[name]
    check = SetCheck(ri.estimate(tern_spec, truth.measurements(case.hidden, case.seed)))
    shapes = check.shapes("thrust_level", "density", "base_drag")
    shape, truth_pair = (check.judge(found) for found in ([shapes[flexible]], [shapes[n] for n in pair]))
    assert truth_pair.accepted, truth_pair.reason()
    if wrong_sign:
        assert shape.failed == ["size"] and "the wrong sign for its physics" in shape.check("size").detail, \
            shape.reason()
    else:
        assert shape.accepted, shape.reason()
    assert truth_pair.refit.bic[1] < shape.refit.bic[1] - BIC_TIE, (truth_pair.refit.bic, shape.refit.bic)
    for n, (value, tol) in truth_sizes.items():
        assert abs(truth_pair.refit.estimate(n)[0] - value) < tol, (n, truth_pair.refit.estimate(n))


def test_classification_rules():
    """The outcome classes: a wrong family called explained is the worst outcome; a pair needs both; a drag
    shape in Mach or a density profile is not a power-off base drag."""
    final = {"effects": ["back_pressure"], "verdict": "explained", "parameters": {}}
    case = BY_NAME["back-pressure"]
    assert STUDY.classify(case, {"final": final}) == "right & explained"
    assert STUDY.classify(case, {"final": {**final, "effects": ["thrust_profile_5"]}}) == "right & explained"
    assert STUDY.classify(case, {"final": {**final, "effects": ["burn_rate"]}}) == "WRONG called explained"
    assert STUDY.classify(case, {"final": {**final, "effects": ["wind"], "verdict": "partly explained"}}) \
        == "wrong, not called explained"
    assert STUDY.classify(case, {"final": {**final, "effects": []}}) == "nothing found"
    assert STUDY.classify(case, {"final": {**final, "verdict": "partly explained"}}) == "right but partly"
    cold = BY_NAME["cold-motor"]
    assert STUDY.classify(cold, {"final": {**final, "effects": ["burn_rate"]}}) == "right & explained"
    assert STUDY.classify(cold, {"final": {**final, "effects": ["start_mass"]}}) == "WRONG called explained"
    assert STUDY.classify(BY_NAME["cold-day"], {"final": {**final, "effects": ["temperature"]}}) \
        == "right & explained"
    winter = BY_NAME["cold-motor+cold-day"]
    assert STUDY.classify(winter, {"final": {**final, "effects": ["burn_rate"]}}) == "right but partly"
    assert STUDY.classify(winter, {"final": {**final, "effects": ["burn_rate", "density_pl_6"]}}) \
        == "right & explained"
    pair = BY_NAME["headwind+h-bias"]
    assert STUDY.classify(pair, {"final": {**final, "effects": ["wind_pl_4"]}}) == "right but partly"
    assert STUDY.classify(pair, {"final": {**final, "effects": ["wind_pl_4", "bias_h"]}}) == "right & explained"
    drag = BY_NAME["supersonic-drag"]
    assert STUDY.classify(drag, {"final": {**final, "effects": ["drag_mach_8"]}}) == "right & explained"
    assert STUDY.classify(drag, {"final": {**final, "effects": ["drag_bump"]}}) == "right & explained"
    assert STUDY.acceptable(drag, {"final": {**final, "effects": []}, "base_chi2": 1.01, "band": 1.05})
    assert not STUDY.acceptable(drag, {"final": {**final, "effects": []}, "base_chi2": 1.3, "band": 1.05})
    base = BY_NAME["base-drag"]
    assert STUDY.classify(base, {"final": {**final, "effects": ["drag_mach_8"]}}) == "WRONG called explained"
    assert STUDY.classify(base, {"final": {**final, "effects": ["density_pl_7"]}}) == "WRONG called explained"
    assert STUDY.classify(base, {"final": {**final, "effects": ["base_drag_mach_2"]}}) == "right & explained"
    assert not STUDY.acceptable(base, {"final": {**final, "effects": ["drag_mach_8"]}})
    clean = BY_NAME["clean-700"]
    assert not STUDY.acceptable(clean, {"final": {**final}})
    assert STUDY.acceptable(clean, {"final": {**final, "effects": []}})


def test_a_case_makes_its_csv(tmp_path, monkeypatch):
    """The harness writes the case's data where ``ROCKETID_SOUNDING_DIR`` says, readable by ``read_csv``: the
    radar's tags, three channels, the hidden bias in the altitude."""
    monkeypatch.setenv("ROCKETID_SOUNDING_DIR", str(tmp_path))
    path = STUDY.make_data(BY_NAME["h-bias"])
    assert path.parent == tmp_path and path.exists()
    data = ri.read_csv(path, ("x", "h", "v"))
    t = V.sample_times()
    assert data.names == ("x", "h", "v") and data.n_samples == 3 * t.size
    clean = truth.exact_outputs(Hidden(), t)
    h = {c.name: c for c in data.channels}["h"]
    assert np.allclose(h.times, t)
    assert abs(float(np.mean(h.values - clean["h"])) - BIAS_H) < 4 * V.SIGMA["h"] / math.sqrt(t.size)


@pytest.mark.slow
@pytest.mark.parametrize("case", ALL, ids=[c.name for c in ALL])
def test_diagnose_on_sounding_case(case, tmp_path, monkeypatch, request):
    """``rocketid diagnose`` (CLI) on the case: clean data add nothing, an effect the base fit does
    not show may go unfound, a visible one is found and explained, an out-of-catalogue one is not
    called explained, and a wrong family is never reported as explained."""
    STUDY.check_case(case, KNOWN_FAILURES, tmp_path, monkeypatch, request)
