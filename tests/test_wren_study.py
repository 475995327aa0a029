"""``rocketid diagnose`` on a hybrid-motor sounding rocket, declared from its static firing and tracked by GPS.

Wren-H (``tests/vehicles/wren.py``) is declared from the user documentation as a university team would: an
N2O / paraffin hybrid known only by its static firing's thrust and consumed-propellant tables, the launch
mass weighed on the pad, a 6.1 m rail at 85 deg 1200 m above sea level, zero attack angle and no lift,
CD as a Mach table; flown from rail exit to apogee (10.2 km, 44 s); its GPS log at 10 Hz from T+2 s, the
altitude three times noisier than the downrange, the noise not stated (``--sigma estimate``). The truth
(``tests/wren_study/truth.py``) has its own hybrid motor (a blowing-down N2O tank, a regressing port, the
O/F ratio and the specific impulse shifting), Cartesian equations of motion and 1976 atmosphere.

The normal suite checks the instruments (truth against ``rocketid.simulate``, the static table against the
truth's motor, the rail, the atmosphere, the flight the docstring states, the GPS log's shape, each effect's
size and visibility, the scoring rules). The diagnoses are ``slow``: ``pytest -m slow
tests/test_wren_study.py``; the whole study with its table is ``python tests/wren_study/run.py --json
wren.json``.
"""

from __future__ import annotations

import math
from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).resolve().parent

import wren as V  # noqa: E402

import rocketid as ri  # noqa: E402
from wren_study import truth  # noqa: E402
from wren_study.cases import (ALL, BALLAST, BY_NAME, DT_HOT, GEOID, HEADWIND, HOT_TANK, COLD_TANK,  # noqa: E402
                              FRESH, LATENCY, MEASURED_2J, RAIL_TRUE_DEG, THIN_WEB, VENTED, VISIBLE_2J, Hidden)
from wren_study.run import STUDY  # noqa: E402

#: Cases measured not to meet the bar (``STUDY.acceptable``), with the measured reason. None run yet.
KNOWN_FAILURES: dict[str, str] = {
    "hot-tank": "177ddc5: burn_rate + start_speed + wind_pl_5, chi2/dof 929 -> 12.1, partly explained (237 s; before "
                "every effect of a step was judged by its size, burn_rate + start_mass + base_drag_mach_2 at 1.678 with "
                "eps_burn 0.1307, 6.5 times its realistic size): the hotter tank changes thrust and mass flow together, "
                "in time and by 8 %, and no catalogue shape at a solid motor's sizes does that. Identical on 85acc7a "
                "(the CLI, 897 s beside two studies), where the free shape the verdict names, a thrust error on the "
                "burn's 31 element boundaries, reaches chi2/dof 1.011 alone: +7.5 to +12 % over 2-7.5 s, -80 % at "
                "9.3-10.5 s (the knee a second early)",
    "cold-tank": "177ddc5: burn_rate + start_speed + time_offset, chi2/dof 589 -> 8.01, partly explained (288 s; on "
                 "abfec42 burn_rate + base_drag_mach_5 + start_speed at 1.195; with the rail exit's shapes and only the "
                 "added effect's sizes judged, start_mass_exit third was called explained with eps_burn 5.1 times its "
                 "size): as hot-tank; noise-free, burn_rate + start_exit + thrust_profile_9 reaches the noise with "
                 "eps_burn -0.107 and the profile 11-30 % in the tail-off. Identical on 32ca943 (1789 s at load 4); "
                 "the free shape (benchmarks/free_shape_rows.py) reaches 1.09 alone (band 1.29): -10 to -6.6 % over "
                 "2-9 s, the tail longer",
    "hot-tank+hot-day": "177ddc5: burn_rate + wind_pl_5 + time_offset_2, chi2/dof 837 -> 8.48, partly explained (271 s): "
                        "the hot tank's motor change (as hot-tank) hides the warmer air. Identical on 32ca943 (1713 s "
                        "at load 4); the free shape reaches 1.047 alone, +7.6 to +11 % over 2-7.5 s: the warm air "
                        "inside it",
    "burn-through": "177ddc5: base_drag_mach_5 + drag_mach_7, chi2/dof 6.33 -> 1.71, partly explained (102 s; before, "
                    "+ temperature at 1.556 with dCD_M6 -1.08, ten times its size): a thrust loss from 6.8 s that grows "
                    "(the port at the liner) is taken by drag shapes; thrust_profile on the mesh did not win. On "
                    "32ca943 (745 s) burn_rate + back_pressure_vacuum_fade + base_drag_mach_2 at 1.215, as since "
                    "e940a4a; the free shape reaches 0.989 alone: -81 % at 10.5 s, -100 % from 14.5 s",
    "hot-day": "3a42d0c: base_drag called explained; since 9c92e9e (refined shapes of other families weighed as "
               "rivals) a named tie -- base_drag, temperature (dT_air 15 for 15), mass_jettison, throttle_step "
               "reach the noise within BIC 10 and the hold-out from 2 s predicts them alike: not explained by the "
               "catalogue, nothing added (honest, not the right answer)",
    "pad-hold": "298194c and abfec42: burn_rate + wind_pl_5 + base_drag_mach_3, chi2/dof 74 -> 1.919, partly "
                "explained (1633 s, 872 s with the table functions; "
                "on 296ee06 a throttle window six times its realistic size -- its times crossed, 63 % less thrust "
                "from 8.2 s -- was called explained: the main process's fit had left the point the window's test "
                "judged, and a 13-knot wind swung +-100 m/s between knots): the vented oxidiser changes the "
                "lift-off mass and the thrust's knee "
                "together, which no single catalogue shape does; start_mass alone (dm_start -1.59 for -1.5) is "
                "the step-1 refit with the right size but leaves CD_7 at 2.8. Identical on 32ca943 (3461 s at "
                "load 4). The free shape (e940a4a's report) "
                "reaches 1.178 alone: the knee early, -61 to -69 % at 9-10.5 s",
    # the fresh pairs (2026-11-28, data nobody had fitted; docs/effects.md, "Fresh pairs on Wren-H")
    "cool-tank+ballast": "e940a4a (fresh pair): burn_rate + wind_pl_5 + time_offset, chi2/dof 2.59, partly explained "
                         "(on 83c4694 burn_rate + wind_pl_5 + base_drag_mach_2 at 2.13, the base drag since the wrong "
                         "sign): the cool tank changes thrust and flow in time as the hot and the cold tank do (no "
                         "catalogue shape), and the 2 kg of ballast is not found under it. Identical on 32ca943 "
                         "(2578 s at load 4). The free shape reaches "
                         "1.065 alone: -8.3 to -13 % over 2-8.5 s, the ballast read as thrust",
    "short-web+geoid": "e940a4a (fresh pair): bias_h (-14.3 +- 0.5 m for -15) + base_drag_mach_3 + transonic_drag, "
                       "chi2/dof 1.031, partly explained (on 83c4694 bias_h + base_drag_mach_2 at 1.045, that base drag "
                       "since the wrong sign): the burn-through late in the burn is a thrust loss of 9 % at 12 s and 70 % at "
                       "burn-out, which thrust_profile_5 beside the bias fits at 0.983 (BIC 1291 against 1349) but "
                       "judged 35 times a 2 % thrust error at its burn-out knot; a size of 2 % of the largest thrust "
                       "in force where each knot sits was tried and left: it made thrust_profile_9 tie base_drag_mach_5 "
                       "on the base-drag case (BIC 1342.3 against 1342.2). Identical on 32ca943 (485 s); the free "
                       "shape (the drag's first, then the thrust's) reaches 0.978 beside the three: -12 to -14 % late "
                       "in the burn",
    "vent+tailwind": "29cfd03 (fresh pair): wind_pl_5 + burn_rate + mass_flow, chi2/dof 3.79, partly explained: the "
                     "wind found, the vented oxidiser (lighter lift-off, earlier knee) not, as in pad-hold; on 83c4694 "
                     "the diagnosis did not end within the harness's 3600 s at load 4-5. The free shape: the wind's "
                     "does not converge; the thrust's beside wind_pl_5 reaches 1.018, the knee early",
    "warm-tank+shallow-rail": "e940a4a (fresh pair): start_angle (-0.990 deg for -1.0) + burn_rate + start_mass, chi2/dof "
                              "1.709, partly explained: the warm tank's motor is not a faster clock (the hot and cold "
                              "tanks' physics, no catalogue shape); on c615eb9 start_angle + burn_rate + base_drag_mach_5 "
                              "at 1.059 was called explained -- a WRONG effect, a power-off increment of -0.25 to -0.03 "
                              "(less drag once the jet stops), since e940a4a the wrong sign. Identical on 32ca943 "
                              "(520 s); the free shape beside start_angle reaches 1.025: +2.8 to +5.8 % over 2-7 s",
}


@pytest.fixture(scope="module")
def spec():
    return V.build_model()


@pytest.fixture(scope="module")
def clean_outputs():
    return truth.exact_outputs(Hidden(), V.gps_times())


def test_truth_reproduces_the_vehicle_model(spec, clean_outputs):
    """The truth's own motor (smooth, from the tank and the port) in Cartesian equations against the declared
    model (the static table interpolated, speed and path angle) in ``simulate``: within 0.05 m, 0.2 m and
    0.1 m/s at every GPS tag (measured 0.010 m, 0.084 m at 15.5 s, 0.041 m/s at 9.7 s: the 0.1 s table across
    the knee), far below the GPS's noise (2.5 m, 7.5 m, 0.25 m/s)."""
    model = ri.simulate(spec, V.truth(spec), V.gps_times()).outputs()
    for name, tol in (("x", 0.05), ("h", 0.2), ("v", 0.1)):
        assert np.max(np.abs(clean_outputs[name] - model[name])) < tol, name


def test_the_static_table_is_the_nominal_motor():
    """The team's table (``wren_static_fire.csv``) is the truth's motor at the static firing's conditions,
    sampled (0.01 s through the ignition transient, 0.1 s after) and rounded to 0.1 N and 0.1 g."""
    t, thrust, consumed = V.static_fire()
    motor = truth.motor_of(truth.MotorConfig())
    assert t[0] == 0.0 and t[-1] >= motor.t_empty and np.all(np.diff(t) > 0)
    assert np.max(np.abs(thrust - [motor.thrust(float(u)) for u in t])) < 0.051
    assert np.max(np.abs(consumed - [motor.consumed(float(u)) for u in t])) < 5.1e-5


def test_the_motor_is_a_hybrid():
    """The motor behaves as an N2O / paraffin hybrid: the tank blows down from 50.6 bar (20 C) to 36 bar when
    the liquid runs out; thrust 3.67 kN decaying, the knee from 9.2 s, zero at 15.5 s; the oxidiser and the
    fuel flows both vary and their ratio shifts (O/F 5.3 -> 5.0 over the liquid burn); the delivered specific
    impulse falls from 212 s to under 150 s in the vapour tail-off; 16 kg of N2O and 3.1 kg of paraffin."""
    m = truth.motor_of(truth.MotorConfig())
    assert abs(truth.n2o_vapour_pressure(293.15) / 1e5 - 50.6) < 0.1
    assert abs(truth.n2o_vapour_pressure(HOT_TANK) / 1e5 - 57.9) < 0.1
    assert 9.1 < m.t_ingestion < 9.3 and 15.4 < m.t_zero_thrust < 15.7 and 21.5 < m.t_empty < 22.2
    assert 3.6e3 < m.thrust(0.5) < 3.7e3 and 2.9e3 < m.thrust(9.0) < 3.0e3 and m.thrust(16.0) == 0.0
    of = [m.flows(t)[0] / m.flows(t)[1] for t in (1.0, 5.0, 9.0)]
    assert of[0] > of[1] > of[2] and 0.05 < of[0] / of[2] - 1 < 0.15, of
    isp = [m.thrust(t) / m.mass_flow(t) / truth.STD_GRAVITY for t in (1.0, 9.0, 13.0)]
    assert 205 < isp[0] < 215 and isp[1] < isp[0] and isp[2] < 150, isp
    ox_left, _, _, fuel = m.final
    assert 15.8 < 16.0 - ox_left < 16.0 and 2.9 < fuel < 3.2


def test_the_rail_gives_the_declared_start():
    """The team's rail exit (the static table integrated along the rail) is the truth's (its own motor and
    Cartesian rail phase): 0.5903 s, 25.065 m/s, within 0.2 ms and 1 mm/s."""
    t_team, v_team = V.rail_exit()
    t_true, y = truth.Flight(Hidden()).rail_exit
    assert abs(t_team - 0.5903) < 5e-4 and abs(v_team - 25.065) < 0.005
    assert abs(t_team - t_true) < 2e-4 and abs(v_team - math.hypot(*y[2:])) < 1e-3


def test_the_truth_atmosphere_is_the_models(spec):
    """The truth's own hydrostatic 1976 layers against the model's density and speed of sound along the
    flight (to 1e-6), and the standard's published values."""
    t = np.arange(1.0, V.TF + 1e-9, 1.0)
    tr = ri.simulate(spec, V.truth(spec), t)
    air = truth.Air()
    for h, rho, a in zip(tr.states[:, 1], tr.value("rho"), tr.value("a_sound")):
        _, _, rho_t, a_t = air.at(float(h))
        assert abs(rho_t / rho - 1) < 1e-6 and abs(a_t / a - 1) < 1e-6, h
    for z, T, p, rho in ((0.0, 288.150, 101_325.0, 1.2250), (10_000.0, 223.252, 26_499.9, 0.41351)):
        Tt, pt, rt, _ = air.at(z)
        assert abs(Tt - T) < 2e-3 and abs(pt / p - 1) < 5e-5 and abs(rt / rho - 1) < 5e-5, z


def test_the_flight_is_the_stated_one(spec):
    """Rail exit Mach 0.075; peak Mach 1.35 at 10.3 s (just above the table's last knot, 1.3); apogee 10.18 km
    above sea level at 44.2 s, 2.2 km downrange; the data's lowest Mach number 0.156 at 44 s, below the table's
    first knot 0.2 only over the last 3.6 s (below 0.75 kPa of dynamic pressure, where the table holds its first
    value); 41.1 kg once the tank is empty."""
    t = np.append(np.arange(V.rail_exit()[0], V.TF, 0.05), V.TF)
    tr = ri.simulate(spec, V.truth(spec), t)
    x, h, v, theta = tr.states.T
    mach = tr.value("mach")
    assert abs(mach[0] - 0.075) < 0.002
    assert V.CD_KNOTS[-1] < mach.max() < 1.36 and 10.0 < t[mach.argmax()] < 10.6
    assert 1.0 < math.degrees(theta[-1]) < 4.0                       # the log ends just before apogee (2.4 deg)
    late = np.arange(43.0, 46.0, 0.05)
    h_true = truth.outputs_of(truth.Flight(Hidden()).states(late))
    k = h_true["h"].argmax()
    assert 10_150 < h_true["h"][k] < 10_210 and 44.0 < late[k] < 44.5 and 2_100 < h_true["x"][k] < 2_200
    data = (t >= V.T_GPS) & (t <= V.TF)
    assert 0.15 < mach[data].min() < V.CD_KNOTS[0] and t[data][mach[data] < V.CD_KNOTS[0]][0] > 40.0
    assert abs(tr.value("mass")[-1] - (V.M_LAUNCH - 18.926)) < 0.01


def test_the_gps_log_comes_as_stated(tmp_path, monkeypatch):
    """The harness writes one CSV: 10 Hz from 2 s to 44 s with about 2 % of the fixes lost (whole rows), the
    log's resolution, no sigma; the noise is the truth's, the altitude three times the downrange's."""
    monkeypatch.setenv("ROCKETID_WREN_DIR", str(tmp_path))
    case = BY_NAME["clean-320"]
    path = STUDY.make_data(case)
    assert path.parent == tmp_path and path.read_text().splitlines()[0] == "t,x,h,v"
    data = ri.read_csv(path, ("x", "h", "v"))
    ch = {c.name: c for c in data.channels}
    nominal = V.gps_times()
    for name in ("x", "h", "v"):
        c = ch[name]
        assert c.sigma is None and np.array_equal(c.times, ch["x"].times)
        assert c.times[0] >= V.T_GPS and c.times[-1] <= V.TF
        assert 0.95 * nominal.size < c.times.size < 0.995 * nominal.size
        q = V.RESOLUTION[name]
        assert np.allclose(c.values / q, np.round(c.values / q), atol=1e-6), name
    exact = truth.exact_outputs(Hidden(), ch["x"].times)
    sd = {n: float(np.std(ch[n].values - exact[n])) for n in ch}
    for name in ("x", "h", "v"):
        assert abs(sd[name] / V.SIGMA[name] - 1) < 0.15, (name, sd[name])
    assert sd["h"] > 2.5 * sd["x"]


def test_vehicle_fits_clean_data_with_the_noise_estimated(spec):
    """The user's fit, as the docs describe it: every channel's sigma estimated; the sigmas come out at the
    truth's and every coefficient within 4 standard errors of the truth."""
    from rocketid.estimability import uncertainty
    data = truth.measurements(Hidden(), seed=7)
    fit = ri.estimate(spec, data, sigma="estimate")
    assert fit.success, fit.message
    for name in ("x", "h", "v"):
        assert abs(fit.sigma[name] / V.SIGMA[name] - 1) < 0.15, (name, fit.sigma[name])
    se = uncertainty(fit).standard_errors
    z = {n: (p - t) / s for n, p, s, t in zip(spec.parameter_names, fit.p, se, V.CD_TRUTH)}
    assert max(abs(v) for v in z.values()) < 4, z


def test_the_second_order_time_offset_follows_the_gps_latency(spec):
    """Wren-H's GPS 0.2 s late: the catalogue's second-order time offset at tau = 0.2 is the model's flight 0.2 s
    earlier within 0.02 m, 0.1 m and 0.35 m/s (measured 0.010 m, 0.063 m, 0.29 m/s: the third-order term across
    the tail-off), three times closer in speed than the first-order shape (0.96 m/s, four GPS sigmas). The
    outputs hold the model's dynamics, its layered atmosphere and Mach table included, and evaluate along a
    simulation (the confirmation's hold-out does so)."""
    from rocketid.diagnostics import with_effects
    from rocketid.diagnostics.effects import time_offset_second_effect
    t = V.gps_times()
    truth_p = dict(V.truth(spec))
    late = ri.simulate(spec, truth_p, t - 0.2).outputs()
    second = ri.simulate(with_effects(spec, [time_offset_second_effect()]), {**truth_p, "tau": 0.2}, t).outputs()
    first = ri.simulate(with_effects(spec, ["time_offset"]), {**truth_p, "tau": 0.2}, t).outputs()
    for name, tol in (("x", 0.02), ("h", 0.1), ("v", 0.35)):
        assert np.max(np.abs(second[name] - late[name])) < tol, name
    err1 = np.max(np.abs(first["v"] - late["v"]))
    assert err1 > 0.8 and err1 > 3 * np.max(np.abs(second["v"] - late["v"]))


def test_a_misread_rail_is_the_start_angle(spec):
    """The rail at 83.5 deg, declared 85 (the truth's own rail phase, Cartesian, from its own motor): the
    catalogue's ``start_angle`` refit from the diagnosis's base fit (the noise from the data's differences)
    reaches the noise band and reads the rail 1.50 deg low (measured -1.5001 deg); a start-speed error alone
    does not explain it (chi2/dof 314 measured)."""
    base, judged = _refits_from_the_base_fit(spec, Hidden(elevation_deg=RAIL_TRUE_DEG), "rail-angle")
    assert not judged.band.contains(base.chi2_per_dof)
    angle = judged("start_angle")
    assert angle.accepted, angle.reason()
    value, std = angle.refit.estimate("dgamma_start")
    assert abs(math.degrees(value) - (RAIL_TRUE_DEG - 85.0)) < 0.02 and std < math.radians(0.01)
    speed = judged("start_speed")
    assert not speed.check("noise").passed


def _refits_from_the_base_fit(spec, hidden: Hidden, case: str):
    """The case's base fit as the diagnosis makes it (the noise from the data's differences, its mesh), and
    ``judged(*effects)``: the refit of those effects (catalogue names or :class:`Effect` values) from it,
    judged by the acceptance test (``judged.band`` the noise band, ``judged.vehicle`` the vehicle's scales)."""
    from rocketid.diagnostics import CATALOGUE
    from rocketid.diagnostics.accept import accept, noise_band
    from rocketid.diagnostics.api import base_fit
    from rocketid.diagnostics.refit import run_refit
    from rocketid.diagnostics.screen import vehicle_of
    from rocketid.diagnostics.step import _Search
    data = truth.measurements(hidden, seed=BY_NAME[case].seed)
    fit, _, counts, _, _ = base_fit(spec, data, "estimate")
    band = noise_band(fit)
    ctx = _Search(spec, band, vehicle_of(fit), 0.05, None, 300.0, 1, False, None)

    def judged(*effects):
        effects = [CATALOGUE[e] if isinstance(e, str) else e for e in effects]
        return accept(run_refit(ctx.task(fit, effects, [e.name for e in effects]))[0], band)
    judged.band = band
    judged.vehicle = ctx.vehicle
    return fit, judged


def test_the_ballast_is_a_mass_with_its_rail_exit(spec):
    """1.5 kg of nose ballast: the heavier rocket leaves the 6.1 m rail later and slower than the team's rail
    exit (worked out for 60 kg) says, and only the start mass with the declared start's speed **and time**
    corrected (``start_mass_exit``) is the truth's physics. The truth's rail exit, from its own rail
    integration (``truth.Flight.rail_exit``), is the reference: 7.51 ms later and 0.367 m/s slower.

    From the diagnosis's base fit: ``start_mass_exit`` is accepted with the truth's mass, speed and time (its
    time as the speed change it goes with along the rail, ``dv_exit``, agreeing with ``dv_start``), at a BIC
    far below a 3 % thrust error's, which also reaches the noise -- thrust and mass act through their ratio,
    and what tells them apart here is the rail exit. Without the exit's time, the truth's mass and speed
    (``start_mass`` + ``start_speed``) leave the speed residuals not white (a 7.5 ms later start is 0.37 m/s
    of speed at 50 m/s^2), which is why a thrust error was called explained before the shape existed."""
    from rocketid.diagnostics.effects import _rail_exit_ratio, start_mass_exit_effect
    heavy, nominal = truth.Flight(Hidden(dm_payload=BALLAST)).rail_exit, truth.Flight(Hidden()).rail_exit
    later = heavy[0] - nominal[0]
    slower = float(np.hypot(*heavy[1][2:]) - np.hypot(*nominal[1][2:]))
    assert 0.006 < later < 0.009 and -0.45 < slower < -0.3, (later, slower)
    _, judged = _refits_from_the_base_fit(spec, Hidden(dm_payload=BALLAST), "nose-ballast")
    exit_, thrust, pair = judged(start_mass_exit_effect(judged.vehicle)), judged("thrust_level"), \
        judged("start_mass", "start_speed")
    assert exit_.accepted and thrust.accepted, (exit_.reason(), thrust.reason())
    est = {n: exit_.refit.estimate(n) for n in ("dm_start", "dv_start", "dv_exit")}
    dt = _rail_exit_ratio(spec.to_model(), "start_mass_exit") * np.array(est["dv_exit"])
    assert abs(est["dm_start"][0] - BALLAST) < 3 * est["dm_start"][1] + 0.01, est
    assert abs(est["dv_start"][0] - slower) < 3 * est["dv_start"][1], (est, slower)
    assert abs(dt[0] - later) < 3 * abs(dt[1]), (dt, later)
    assert exit_.refit.bic[1] < thrust.refit.bic[1] - 20
    assert not pair.accepted and not pair.check("white").passed


def test_an_earlier_step_s_effect_is_judged_by_its_size_at_the_next(spec):
    """A step's refit holds the effects of earlier steps, and those keep a plausible size too (Wren-H's cold tank
    was called explained with burn_rate at 5.1 times its realistic size, reached only at step 3). Here a
    thrust error is the first step and a start-speed error the second, from the first step's fit; with the
    thrust error's realistic size stated at 0.1 % its -3 % fails the second step's size check by name."""
    from rocketid.diagnostics import CATALOGUE
    from rocketid.diagnostics.accept import accept, noise_band
    from rocketid.diagnostics.api import base_fit
    from rocketid.diagnostics.effects import state_sizes
    from rocketid.diagnostics.refit import run_refit
    from rocketid.diagnostics.screen import vehicle_of
    from rocketid.diagnostics.step import _Search, _fit_of
    fit, _, _, _, _ = base_fit(spec, truth.measurements(Hidden(dm_payload=BALLAST), seed=BY_NAME["nose-ballast"].seed),
                            "estimate")
    band = noise_band(fit)
    ctx = _Search(spec, band, vehicle_of(fit), 0.05, None, 300.0, 1, False, None)
    thrust, speed = state_sizes([CATALOGUE["thrust_level"], CATALOGUE["start_speed"]], {"eps_thrust": 0.001})
    first = run_refit(ctx.task(fit, [thrust], ("thrust_level",)))[0]
    step1 = _fit_of(spec, [thrust], first, fit.prepared.measurements, fit.prepared.transcription.mesh, None)
    second = accept(run_refit(ctx.task(step1, [thrust, speed], ("start_speed",)))[0], band)
    size = second.check("size")
    assert "eps_thrust" in second.refit.sizes and not size.passed and "eps_thrust" in size.detail, size.detail
    assert "dv_start" not in size.detail


def test_a_confounded_mate_s_fuller_shape_replaces_a_snug_choice(spec):
    """The search's side of the ballast: ``thrust_level`` reaches the noise first (snug), and ``start_mass``,
    which the screen puts in its confounded group, refits just past the near-rival line -- only as a confounded
    mate are its refined shapes tried, and ``start_mass_exit`` replaces the choice by BIC (measured: chi2/dof
    1.275 against a line of 1.267; the shape at 1.006, BIC 45 below the thrust error's)."""
    from rocketid.diagnostics import CATALOGUE, discover
    from rocketid.diagnostics.accept import noise_band
    from rocketid.diagnostics.api import base_fit
    from rocketid.diagnostics.step import NEAR_RIVAL
    fit, _, _, _, _ = base_fit(spec, truth.measurements(Hidden(dm_payload=BALLAST), seed=BY_NAME["nose-ballast"].seed),
                            "estimate")
    band = noise_band(fit)
    found = discover(fit, [CATALOGUE["thrust_level"], CATALOGUE["start_mass"]], workers=1)
    step = found.steps[0]
    by_name = {a.refit.name: a for a in step.acceptances}
    assert step.screen.ranking.group_of("thrust_level") == step.screen.ranking.group_of("start_mass")
    assert by_name["thrust_level"].accepted
    assert by_name["start_mass"].refit.chi2_per_dof > 1 + NEAR_RIVAL * (band.upper - 1)
    assert found.effect_names == ("start_mass_exit",) and found.verdict == "explained", (found.effect_names, found.verdict)
    assert by_name["start_mass_exit"].refit.bic[1] < by_name["thrust_level"].refit.bic[1] - 20


@pytest.mark.parametrize("name", sorted(MEASURED_2J))
def test_visibility(spec, name):
    """Each case's ``visible`` is what the base model's fit to its noise-free GPS log (the truth's sigmas) leaves:
    2J >= 25 visible (measured values in ``cases.MEASURED_2J``, within 20 %; the clean log's 0.19 is the
    table's and the mesh's own error)."""
    case = BY_NAME[name]
    times = truth.gps_times(case.seed)
    exact = truth.exact_outputs(case.hidden, times)
    data = ri.Measurements(tuple(ri.Channel(n, times, exact[n], V.SIGMA[n]) for n in ("x", "h", "v")))
    two_j = 2.0 * ri.estimate(spec, data).data_objective
    if case.right or case.out_of_catalogue:
        assert (two_j >= VISIBLE_2J) == bool(case.visible), (name, two_j)
    assert two_j < 1.0 if MEASURED_2J[name] < 1.0 else abs(two_j / MEASURED_2J[name] - 1) < 0.2, (name, two_j)


@pytest.mark.parametrize("hidden, channel, low, high", [          # measured: the largest change over 2-44 s
    (Hidden(tank_temperature=HOT_TANK), "v", 30.0, 40.0),          # 35.1 m/s
    (Hidden(tank_temperature=COLD_TANK), "v", 33.0, 44.0),         # 38.5 m/s
    (Hidden(grain_radius=THIN_WEB), "h", 850.0, 1100.0),           # 971 m
    (Hidden(vented=VENTED), "h", 1000.0, 1250.0),                  # 1130 m
    (Hidden(wind=HEADWIND), "x", 1700.0, 2200.0),                  # 1935 m
    (Hidden(elevation_deg=RAIL_TRUE_DEG), "x", 550.0, 700.0),      # 628 m
    (Hidden(bias_h=GEOID), "h", 24.99, 25.01),                     # 25 m
    (Hidden(tau=LATENCY), "v", 9.0, 12.0),                         # 10.4 m/s (0.2 s of 52 m/s^2)
    (Hidden(dm_payload=BALLAST), "h", 190.0, 240.0),               # 215 m
    (Hidden(dT=DT_HOT), "h", 100.0, 140.0),                        # 119 m
    (Hidden(base_drag=True), "h", 280.0, 370.0),                   # 323 m
])
def test_each_hidden_effect_changes_the_data(clean_outputs, hidden, channel, low, high):
    """Every hidden effect moves the GPS's readings by a realistic amount (largest change in range) and by many
    sigma over the log (root sum of squares of the changes in sigma)."""
    moved = truth.exact_outputs(hidden, V.gps_times())
    change = float(np.max(np.abs(moved[channel] - clean_outputs[channel])))
    assert low < change < high, change
    significance = math.sqrt(sum(float(np.sum(((moved[n] - clean_outputs[n]) / V.SIGMA[n]) ** 2)) for n in "xhv"))
    assert significance > 50.0, significance


def test_the_truth_is_written_apart_from_rocketid():
    """The truth's physics imports nothing of rocketid (only ``measurements`` uses its data container), and the
    hidden effects at zero are the clean flight exactly."""
    source = (HERE / "wren_study" / "truth.py").read_text()
    imports = [line.strip() for line in source.splitlines() if "rocketid" in line and "import" in line]
    assert imports == ["import rocketid as ri"], imports
    assert source.count("ri.") == 2                       # ri.Channel, ri.Measurements
    zero = Hidden(wind=(0.0, 0.0), elevation_deg=V.ELEVATION_DEG)
    a = truth.exact_outputs(zero, V.gps_times()[::20])
    b = truth.exact_outputs(Hidden(), V.gps_times()[::20])
    for name in ("x", "h", "v"):
        assert np.max(np.abs(a[name] - b[name])) < 1e-6, name


def test_the_cases_are_consistent():
    """Names and seeds unique, every needed family a right one, pairs with one set per effect, four clean seeds,
    every effect visible by its measured 2J."""
    assert len(BY_NAME) == len(ALL) == 25 and len({c.seed for c in ALL}) == len(ALL)
    for case in ALL:
        assert case.needed <= case.right, case.name
        assert all(group <= case.right for group in case.needed_each), case.name
        assert ("+" in case.name) == bool(case.needed_each), case.name
        if case.right or case.out_of_catalogue:
            assert case.visible == (MEASURED_2J[case.name] >= VISIBLE_2J), case.name
    assert sum(c.name.startswith("clean-") for c in ALL) == 4
    # the rail angle was out of the catalogue until start_angle was added for it (cases.py says so)
    assert not any(c.out_of_catalogue for c in ALL) and BY_NAME["rail-angle"].needed == {"start_angle"}
    assert all(not c.right for c in ALL if c.out_of_catalogue)
    assert set(STUDY.coefficients) == {f"CD_{j}" for j in range(len(V.CD_KNOTS))}


def test_the_fresh_pairs_are_consistent():
    """The fresh pairs: seeds of their own, two hidden effects each (the truth's fields moved), both needed sets
    right, every one visible."""
    assert [c.seed for c in FRESH] == list(range(330, 338))
    for case in FRESH:
        assert len(case.needed_each) == 2 and case.needed == case.needed_each[0] | case.needed_each[1], case.name
        moved = [f for f in Hidden.__dataclass_fields__ if getattr(case.hidden, f) != getattr(Hidden(), f)]
        assert len(moved) == 2 and case.visible and MEASURED_2J[case.name] >= VISIBLE_2J, (case.name, moved)


def test_the_harness_runs_the_regime(monkeypatch, tmp_path):
    """The diagnosis command carries ``--sigma estimate`` and no window (the states at rail exit are declared)."""
    import subprocess
    seen = []

    def fake(command, **kwargs):
        seen.append(command)
        return subprocess.CompletedProcess(command, 2, "", "no")
    monkeypatch.setattr(subprocess, "run", fake)
    monkeypatch.setenv("ROCKETID_WREN_DIR", str(tmp_path))
    record = STUDY.diagnose_cli(BY_NAME["clean-320"])
    assert seen[-1][-4:] == ["--workers", "1", "--sigma", "estimate"] and "--window" not in seen[-1]
    assert str(V.__file__).endswith("wren.py") and str(STUDY.model_file) in seen[-1]
    assert record["command"].endswith("--workers 1 --sigma estimate")


def test_classification_rules():
    """The outcome classes as the cases state them: a burn-through is a thrust shape (a constant level alone is
    partly right, a faster clock wrong); the vented oxidiser is either half; the rail angle passes only when
    not called explained; a pair needs both."""
    final = {"effects": ["throttle_step"], "verdict": "explained", "parameters": {}}
    burn = BY_NAME["burn-through"]
    assert STUDY.classify(burn, {"final": final}) == "right & explained"
    assert STUDY.classify(burn, {"final": {**final, "effects": ["thrust_level"]}}) == "right but partly"
    assert STUDY.classify(burn, {"final": {**final, "effects": ["burn_rate"]}}) == "WRONG called explained"
    hold = BY_NAME["pad-hold"]
    for effects in (["start_mass"], ["throttle_step"], ["start_mass", "thrust_profile_5"]):
        assert STUDY.classify(hold, {"final": {**final, "effects": effects}}) == "right & explained", effects
    hot = BY_NAME["hot-tank"]
    assert STUDY.classify(hot, {"final": {**final, "effects": ["burn_rate"]}}) == "right & explained"
    assert STUDY.classify(hot, {"final": {**final, "effects": ["mass_flow"]}}) == "right but partly"
    rail = BY_NAME["rail-angle"]
    assert STUDY.classify(rail, {"final": {**final, "effects": ["start_angle"]}}) == "right & explained"
    assert STUDY.classify(rail, {"final": {**final, "effects": ["wind_pl_4"]}}) == "WRONG called explained"
    nothing = {"final": {**final, "effects": []}, "base_chi2": 1.0, "band": 1.2}
    assert not STUDY.acceptable(rail, nothing) and not STUDY.acceptable(BY_NAME["hot-day"], nothing)
    ballast = BY_NAME["nose-ballast"]
    assert STUDY.classify(ballast, {"final": {**final, "effects": ["start_mass", "start_speed"]}}) == \
        "right & explained"
    assert STUDY.classify(ballast, {"final": {**final, "effects": ["start_speed"]}}) != "right & explained"
    pair = BY_NAME["geoid+gps-latency"]
    assert STUDY.classify(pair, {"final": {**final, "effects": ["bias_h"]}}) == "right but partly"
    assert STUDY.classify(pair, {"final": {**final, "effects": ["bias_h", "time_offset"]}}) == "right & explained"
    summer = BY_NAME["hot-tank+hot-day"]
    assert STUDY.classify(summer, {"final": {**final, "effects": ["burn_rate"]}}) == "right but partly"
    assert STUDY.classify(summer, {"final": {**final, "effects": ["burn_rate", "temperature"]}}) == "right & explained"
    assert STUDY.classify(BY_NAME["base-drag"], {"final": {**final, "effects": ["drag_mach_9"]}}) == \
        "WRONG called explained"
    assert STUDY.acceptable(BY_NAME["clean-321"], nothing)


@pytest.mark.slow
@pytest.mark.parametrize("case", ALL, ids=[c.name for c in ALL])
def test_diagnose_on_wren_case(case, tmp_path, monkeypatch, request):
    """``rocketid diagnose --sigma estimate`` (CLI) on the case: clean data add nothing, every effect (all
    visible) is found and explained with right families only, the out-of-catalogue rail angle is not called
    explained, and a wrong family is never reported as explained."""
    STUDY.check_case(case, KNOWN_FAILURES, tmp_path, monkeypatch, request)


def test_the_shape_tool_puts_its_knots_over_the_burn(spec):
    """``tests/wren_study/shapes.py`` (the tool the motor cases' shapes were measured with): its powered shapes
    have their knots on mesh boundaries over the burn only, and a powered profile of zero is the model."""
    from wren_study import shapes
    from rocketid.diagnostics import with_effects
    from rocketid.diagnostics.effects import Vehicle
    mesh = ri.default_mesh(spec, refine_first=3)
    veh = Vehicle(thrust=3600.0, mass=60.0, mass_flow=1.0, speed=300.0, start_speed=25.0, duration=spec.tf - spec.t0,
                  altitude=(1200.0, 10200.0), mach=None, sigma={}, sample_interval=0.1,
                  knot_times=tuple(float(b) for b in mesh.boundaries))
    knots = shapes._burn_knots(veh, 9)
    assert len(knots) == 9 and knots[0] == spec.t0 and knots[-1] == shapes.BURN_END
    assert set(knots) <= set(veh.knot_times)
    prof = shapes.effect("powered_profile9", veh)
    assert len(prof.parameter_names) == 9
    t = np.array([3.0, 12.0, 30.0])
    truth_p = dict(V.truth(spec))
    base = ri.simulate(spec, truth_p, t).outputs()
    zero = ri.simulate(with_effects(spec, [prof]), {**truth_p, **{n: 0.0 for n in prof.parameter_names}}, t).outputs()
    for name in ("x", "h", "v"):
        np.testing.assert_allclose(zero[name], base[name], rtol=1e-8, atol=1e-5)   # the integrator's tolerance
    assert shapes.effect("powered_throttle5", veh).name == "powered_throttle5"
    with pytest.raises(SystemExit, match="unknown effect"):
        shapes.effect("powered_thing", veh)
