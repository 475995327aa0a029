"""``rocketid diagnose`` on a liquid core with two strap-on solid boosters jettisoned in flight.

Auk-B (``tests/vehicles/auk.py``) is declared from the user documentation: lift-off from a sea-level
pad at rest, a throttled liquid core (a commanded max-q bucket, ``throttle_schedule`` and
``throttled_propulsion``), two solid boosters' static-firing table with their grain a state, the
boosters' casings and cross-sections leaving at 40 s (a known ``Piecewise`` input of time at a model
event), a sampled pitch program, CD as a Mach table, a lift slope, 10 Hz GNSS data. Its truth
(``tests/auk_study/truth.py``) flies radius, central angle and velocity components about the Earth's
centre with vector forces, its own 1976 atmosphere and the jettison as a discontinuity, every hidden
effect in its own shape.

The normal suite checks the instruments: the truth without effects reproduces the estimation model,
its atmosphere is the 1976 standard, the vehicle fits clean data to the noise, the noise is as stated,
and every hidden effect changes the flight by a stated amount. The diagnoses run ``rocketid diagnose``
from the command line, one per case, and are ``slow``: ``pytest -m slow tests/test_auk_study.py``; the
whole study with its table is ``python tests/auk_study/run.py --json auk.json``.
"""

from __future__ import annotations

import math
from dataclasses import replace

import numpy as np
import pytest

import auk as A

import rocketid as ri
from auk_study import truth
from auk_study.cases import (ALL, BIAS_H, BY_NAME, COLD, COLD_DAY, JET, LATE, LATENCY, MIS, WEAK, BUCKET_LEVEL,
                             Hidden)
from auk_study.run import STUDY

#: Cases measured not to meet the bar (``STUDY.acceptable``), with the measured reason.
KNOWN_FAILURES: dict[str, str] = {
    "core-misalignment": "5ae42bd (after the motors' shapes): a three-way tie the hold-out cannot decide -- "
                         "misalignment_other_than_booster_thrust (the core's thrust turned, 0.00418 for 0.00436), "
                         "misalignment_fade (0.00464, s_fade 0.78) and wind_pl_6 (a surface headwind of 8.5 m/s) "
                         "reach the noise within BIC 10, the window's data do not reach CD_6: nothing added, the "
                         "rivals named, partly explained (2a62fcc: the same tie without the core's shape)",
    "core-misalignment+cold-day": "5ae42bd: misalignment_other_than_booster_thrust (0.004259 +- 4.4e-05 for "
                                  "0.004363) explained at chi2/dof 1.004 -- right, but the cold day is not found: "
                                  "it is not in these data (cold-day alone: nothing missing, the drag table takes "
                                  "it up), and the pair needs a density family",
    "deep-bucket+latency": "2a62fcc (first run): time_offset (0.156 s for 0.15) + thrust_profile_5 + "
                           "back_pressure_vacuum (A_e_vac 0.48) at chi2/dof 1.106 above the band 1.078, v not white: "
                           "partly explained with a wrong family, not called explained. The free shape, a thrust error "
                           "on 32 knots beside time_offset, reaches 1.026 (residuals not white) and reads -11 to "
                           "-5.4 % over 35.3-43 s: the bucket delivered 6.7 % low",
    "late-separation": "5ae42bd (as on 2a62fcc): drag_mach_6 + bias_x at chi2/dof 1.097 above the band, partly "
                       "explained with wrong families, not called explained. The wide scan makes the throttle "
                       "window a contender, and its refit reaches 0.985, white, but as a full cut over 40.59-40.81 s "
                       "(d_window 1, at its bound: the lost impulse of the casings carried 1.5 s longer, on the "
                       "ridge where a window's depth and width trade off): implausible, not taken. The free shape, a "
                       "thrust error on 32 knots alone, reaches the noise (1.003) and reads -21 % at 39 s",
    "late-separation+jet-stream": "6cca436 (a wind knot beyond 120 m/s implausible on every effect of the model): "
                                  "wind (-47 m/s at 13 km) + bias_x_drift + time_offset at chi2/dof 1.203, partly "
                                  "explained -- the right wind with a wrong pair, not called explained. On 5ae42bd "
                                  "it was wind_pl_10 + drag_mach_18 called explained with a knot at -147 m/s "
                                  "carrying the late separation (right but partly)",
    "deep-bucket": "2a62fcc and 5ae42bd: thrust_profile_5 (its knot in the bucket at -5.6 %: the bucket 6.7 % low) + "
                   "drag_mach_18 at chi2/dof 0.994, partly explained -- a drag correction beside the right family, "
                   "not called explained",
}


@pytest.fixture(scope="module")
def auk_spec():
    return A.build_model()


@pytest.fixture(scope="module")
def clean_outputs():
    return truth.exact_outputs(Hidden(), A.sample_times())


def test_truth_reproduces_the_vehicle_model(auk_spec, clean_outputs):
    """Polar position and velocity components with vector forces and the jettison as a split integration
    (truth) against speed and path angle with the jettison as a Piecewise input (rocketid's ``simulate``):
    < 1 mm, < 1 mm/s (measured 0.28 mm in h at 110 s)."""
    model = ri.simulate(auk_spec, A.truth(auk_spec), A.sample_times()).outputs()
    for name in ("x", "h", "v"):
        assert np.max(np.abs(clean_outputs[name] - model[name])) < 1e-3, name


def test_the_flight_drops_its_boosters(auk_spec):
    """Lift-off at rest, the casings (3.2 t) leave at 40 s in the model's mass, the area shrinks with them;
    supersonic at separation, Mach 3-4 and 35-50 km at the end."""
    t = np.array([0.0, 39.9, 40.0, 40.1, A.TF])
    tr = ri.simulate(auk_spec, A.truth(auk_spec), t)
    mass, mach = tr.value("mass"), tr.value("mach")
    assert mass[0] == pytest.approx(A.M_LIFTOFF)
    drop = mass[2] - mass[3]
    assert 3200.0 < drop < 3200.0 + 0.1 * 600.0, drop            # the casings + 0.1 s of the core's flow
    assert 1.2 < mach[2] < 1.5 and 3.0 < mach[-1] < 4.0
    assert 35_000 < tr.states[-1, 1] < 50_000
    assert tr.states[0, 2] == 0.0


#: US Standard Atmosphere 1976 (NOAA-S/T 76-1562): pressure (Pa) and density (kg/m^3) at geometric altitude.
GEOMETRIC = ((0.0, 101_325.0, 1.2250), (10_000.0, 26_499.9, 0.41351), (20_000.0, 5_529.3, 0.088910),
             (30_000.0, 1_197.0, 0.018410), (40_000.0, 287.14, 0.0039957))


def test_atmosphere_is_the_1976_standard():
    """The truth's own hydrostatic layers against the standard's published values; the speed of sound."""
    for z, p, rho in GEOMETRIC:
        _, p_truth, rho_truth, _ = truth.STANDARD_DAY.at(z)
        assert abs(p_truth / p - 1) < 5e-5 and abs(rho_truth / rho - 1) < 5e-5, z
    assert abs(truth.STANDARD_DAY.at(10_000.0)[3] - 299.53) < 0.01
    assert abs(truth.STANDARD_DAY.at(0.0)[3] - 340.29) < 0.01
    cold = truth.Air(COLD_DAY)
    assert cold.at(0.0)[1] == pytest.approx(101_325.0)              # the same sea-level pressure
    assert cold.at(0.0)[2] / truth.STANDARD_DAY.at(0.0)[2] == pytest.approx(288.15 / 276.15)


def test_vehicle_fits_clean_data_to_the_noise(auk_spec):
    """The base model on the truth's clean data, from the declared guesses: chi2/dof at the noise (measured
    0.985 on seed 7), every coefficient within 4 standard errors of the truth."""
    from rocketid.estimability import uncertainty
    data = truth.measurements(Hidden(), seed=7)
    fit = ri.estimate(auk_spec, data)
    assert fit.success, fit.message
    assert 0.9 < fit.chi2_per_dof < 1.15, fit.chi2_per_dof
    se = uncertainty(fit).standard_errors
    p_true = auk_spec.parameter_vector(A.truth(auk_spec))
    z = (fit.p - p_true) / se
    assert np.max(np.abs(z)) < 4, dict(zip(auk_spec.parameter_names, np.round(z, 2)))


def test_the_noise_is_as_stated(clean_outputs):
    """The data are the exact outputs plus N(0, sigma) noise with the vehicle's sigmas (5 m, 8 m, 0.3 m/s),
    declared on the measurements; the same seed gives the same data, another seed other data."""
    t = A.sample_times()
    data = truth.measurements(Hidden(), seed=520)
    again = truth.measurements(Hidden(), seed=520)
    other = truth.measurements(Hidden(), seed=521)
    for name in ("x", "h", "v"):
        sigma = A.SIGMA[name]
        assert np.array_equal(data[name].times, t)
        noise = data[name].values - clean_outputs[name]
        n = noise.size
        assert abs(noise.std() / sigma - 1) < 4 / math.sqrt(2 * n), (name, noise.std())
        assert abs(noise.mean()) < 4 * sigma / math.sqrt(n), (name, noise.mean())
        assert np.array_equal(again[name].values, data[name].values)
        assert not np.array_equal(other[name].values, data[name].values)
        assert np.allclose(data[name].sigma, sigma)


@pytest.mark.parametrize("hidden, channel, low, high", [          # measured: the largest change
    (Hidden(sep_delay=LATE), "h", 100.0, 160.0),                    # 126 m (15.8 sigma)
    (Hidden(cold_boosters=COLD), "v", 12.0, 18.0),                  # 14.7 m/s
    (Hidden(core_misalign=MIS), "x", 140.0, 230.0),                 # 182 m
    (Hidden(jet=JET), "x", 700.0, 1050.0),                          # 870 m
    (Hidden(dT=COLD_DAY), "x", 45.0, 75.0),                         # 59 m
    (Hidden(bucket_level=BUCKET_LEVEL), "h", 650.0, 950.0),         # 790 m
    (Hidden(latency=LATENCY), "x", 120.0, 170.0),                   # 144 m
    (Hidden(weak_booster=WEAK), "h", 1700.0, 2500.0),               # 2085 m
])
def test_each_hidden_effect_changes_the_flight(clean_outputs, hidden, channel, low, high):
    """Every hidden effect moves the outputs by a realistic amount, many sigma (largest change in range)."""
    base = clean_outputs[channel]
    moved = truth.exact_outputs(hidden, A.sample_times())[channel]
    change = float(np.max(np.abs(moved - base)))
    assert low < change < high, change
    assert change > 5 * A.SIGMA[channel]


def test_the_altitude_bias_shows_through_its_samples(clean_outputs):
    """The 20 m altitude bias is 2.5 sigma on each sample (sigma 8 m), not 5: it shows through its 1100 samples
    (its mean over them is 83 standard errors), and nowhere else."""
    moved = truth.exact_outputs(Hidden(bias_h=BIAS_H), A.sample_times())
    shift = moved["h"] - clean_outputs["h"]
    assert np.allclose(shift, BIAS_H, atol=1e-9)
    assert BIAS_H / (A.SIGMA["h"] / math.sqrt(shift.size)) > 5 * 10
    for name in ("x", "v"):
        assert np.array_equal(moved[name], clean_outputs[name])


def test_the_boosters_are_a_motor_of_their_own(auk_spec):
    """The thrust reads the boosters' table beside the throttled core: one motor among others, offered its own
    level and burn-rate errors as refined shapes of ``thrust_level``, and its thrust or every other turned as
    refined shapes of ``misalignment``, each beside its family's ladder; a one-table vehicle has none."""
    from rocketid.diagnostics.effects import Vehicle, thrust_motors, CATALOGUE
    assert thrust_motors(auk_spec) == ("booster_thrust",)
    import wren
    assert thrust_motors(wren.build_model()) == ()
    vehicle = Vehicle(thrust=1.25e6, mass=6e4, mass_flow=300.0, speed=1100.0, start_speed=0.0, duration=A.TF,
                      altitude=(0.0, 4e4), mach=(0.0, 3.5), sigma=A.SIGMA, sample_interval=0.1,
                      knot_times=tuple(np.linspace(0.0, A.TF, 23)), motors=("booster_thrust",))
    names = [e.name for e in CATALOGUE["thrust_level"].refinements(vehicle)]
    assert names[-2:] == ["thrust_level_booster_thrust", "burn_rate_booster_thrust"]
    no_motor = [e.name for e in CATALOGUE["thrust_level"].refinements(replace(vehicle, motors=()))]
    assert not any(n.endswith("booster_thrust") for n in no_motor)
    turned = [e.name for e in CATALOGUE["misalignment"].refinements(vehicle)]
    assert turned[-2:] == ["misalignment_booster_thrust", "misalignment_other_than_booster_thrust"]
    assert all(not e.rung for e in CATALOGUE["misalignment"].refinements(vehicle)[-2:])


@pytest.mark.parametrize("effect, value, hidden, channel, within", [
    # one booster 12 % weak with its grain flow (the pair 6 % low, Isp kept): the same physics, measured 1.7e-6 m/s
    ("thrust_level_booster_thrust", -WEAK / 2, Hidden(weak_booster=WEAK), "v", 1e-3),
    # the truth's 0.96 P(t / 1.04) against k P(k t) at k = 1 / 1.04: the truth's impulse 0.16 % short of the
    # table's, which the burn-rate shape keeps -- measured 0.53 m/s of the effect's 14.7 m/s
    ("burn_rate_booster_thrust", 1 / COLD[1] - 1, Hidden(cold_boosters=COLD), "v", 0.05),
    # the core's thrust turned 0.25 deg, the boosters' along the body: the truth turns the core's force vector
    # from lift-off, the shape the resultant by the core's share, phased in by the lift-off fade -- measured
    # 5.7 m of the effect's 182 m in x (the whole thrust turned: 45.7 m)
    ("misalignment_other_than_booster_thrust", MIS, Hidden(core_misalign=MIS), "x", 0.05),
])
def test_a_motors_shape_flies_the_truths_booster(auk_spec, clean_outputs, effect, value, hidden, channel, within):
    """The motor's shapes on Auk-B against the truth's boosters (``auk_study/truth.py``: the pair's thrust and
    grain flow as a share of boosters on a stretched clock, in polar coordinates, not through the model's
    input): at the truth's value the shape moves the flight as the hidden effect does, to ``within`` of the
    effect's largest change."""
    from rocketid.diagnostics.effects import (motor_burn_effect, motor_level_effect, motor_misalignment_effect,
                                              with_effects)
    e = {"thrust_level": motor_level_effect, "burn_rate": motor_burn_effect,
         "misalignment": lambda mo: motor_misalignment_effect(mo, other=True)}[effect.split("_booster")[0].split(
             "_other")[0]]("booster_thrust")
    assert e.name == effect
    augmented = with_effects(auk_spec, [e])
    values = {**A.truth(auk_spec), e.parameter_names[0]: value}
    shaped = ri.simulate(augmented, values, A.sample_times()).outputs()[channel]
    moved = truth.exact_outputs(hidden, A.sample_times())[channel]
    change = float(np.max(np.abs(moved - clean_outputs[channel])))
    assert float(np.max(np.abs(shaped - moved))) < within * change
    # at zero the shape is the stated motor: the base model's flight
    values[e.parameter_names[0]] = 0.0
    at_zero = ri.simulate(augmented, values, A.sample_times()).outputs()[channel]
    assert float(np.max(np.abs(at_zero - clean_outputs[channel]))) < 1e-3


def test_a_motor_must_be_one_of_the_thrusts(auk_spec):
    """A motor shape on an input the thrust does not read (the pitch program) is refused with the motors named."""
    from rocketid.diagnostics.effects import motor_level_effect, with_effects
    with pytest.raises(ri.ModelError, match="booster_thrust"):
        with_effects(auk_spec, [motor_level_effect("phi")])


def test_the_cases_are_consistent():
    """Every hidden effect has its case, every pair two; seeds of their own from 500; right holds needed."""
    assert len({c.seed for c in ALL}) == len(ALL) and len(BY_NAME) == len(ALL)
    assert min(c.seed for c in ALL) >= 500
    fields = list(Hidden.__dataclass_fields__)
    singles = [c for c in ALL if len(c.needed_each) == 0 and c.right]
    pairs = [c for c in ALL if c.needed_each]
    cleans = [c for c in ALL if not c.right]
    assert len(singles) == len(fields) == 9 and len(pairs) == 4 and len(cleans) == 4
    moved_by = {}
    for case in ALL:
        moved = [f for f in fields if getattr(case.hidden, f) != getattr(Hidden(), f)]
        moved_by[case.name] = moved
        assert case.needed <= case.right, case.name
        if case in pairs:
            assert len(moved) == 2 and all(group <= case.right for group in case.needed_each), case.name
            assert case.needed == case.needed_each[0] | case.needed_each[1], case.name
        elif case in singles:
            assert len(moved) == 1 and case.needed, case.name
        else:
            assert moved == [], case.name
    assert sorted(f for c in singles for f in moved_by[c.name]) == sorted(fields)


def test_classification_rules():
    """The outcome classes on this study's sets: equivalent families right, a wrong one never explained."""
    final = {"effects": ["mass_jettison"], "verdict": "explained", "parameters": {}}
    late = BY_NAME["late-separation"]
    assert STUDY.classify(late, {"final": final}) == "right & explained"
    assert STUDY.classify(late, {"final": {**final, "effects": ["throttle_window"]}}) == "right & explained"
    assert STUDY.classify(late, {"final": {**final, "effects": ["drag_bump"]}}) == "right but partly"
    assert STUDY.classify(late, {"final": {**final, "effects": ["wind_pl_4"]}}) == "WRONG called explained"
    weak = BY_NAME["weak-booster"]
    assert STUDY.classify(weak, {"final": {**final, "effects": ["burn_rate"]}}) == "right & explained"
    assert STUDY.classify(weak, {"final": {**final, "effects": ["thrust_profile_5", "start_mass"]}}) \
        == "right & explained"
    assert STUDY.classify(weak, {"final": final}) == "right but partly"          # the mass alone
    assert STUDY.classify(BY_NAME["cold-day"], {"final": {**final, "effects": ["temperature"]}}) \
        == "right & explained"
    bucket = BY_NAME["deep-bucket+latency"]
    assert STUDY.classify(bucket, {"final": {**final, "effects": ["throttle_window"]}}) == "right but partly"
    assert STUDY.classify(bucket, {"final": {**final, "effects": ["throttle_window", "time_offset"]}}) \
        == "right & explained"
    assert STUDY.classify(BY_NAME["deep-bucket"], {"final": {**final, "effects": ["burn_rate"]}}) \
        == "WRONG called explained"
    clean = BY_NAME["clean-520"]
    assert not STUDY.acceptable(clean, {"final": {**final}})
    assert STUDY.acceptable(clean, {"final": {**final, "effects": []}})


@pytest.mark.slow
@pytest.mark.parametrize("case", ALL, ids=[c.name for c in ALL])
def test_diagnose_on_auk_case(case, tmp_path, monkeypatch, request):
    """``rocketid diagnose`` (CLI) on the case: clean data add nothing, an effect the base fit does not show may
    go unfound, a visible one is found and explained, and a wrong family is never reported as explained."""
    STUDY.check_case(case, KNOWN_FAILURES, tmp_path, monkeypatch, request)


def test_a_late_separation_is_scanned_when_the_constant_shapes_fall_short(auk_spec):
    """A change over 1.5 s is invisible to its family's constant shape: on the late separation the constant
    thrust error is not significant (measured statistic 0.06). When the significant candidates cannot account
    for the misfit (the leader's predicted fall under half the fall to the noise band) the located shapes of
    such families are scanned, and the throttle window's scan makes ``thrust_level`` a contender, placed over
    the separation (measured: a predicted fall of J of 259 at 39.5-43.0 s, six times the leader's); without
    the excess (a fit at the noise) it is not scanned and not a contender."""
    from rocketid.diagnostics.effects import CATALOGUE
    from rocketid.diagnostics.screen import screen
    case = BY_NAME["late-separation"]
    fit = ri.estimate(auk_spec, truth.measurements(case.hidden, case.seed))
    assert fit.chi2_per_dof > 1.1
    candidates = list(CATALOGUE.values())
    below = screen(fit, candidates)
    assert "thrust_level" not in below.names
    # the fall of J to the band's upper edge: the leader's predicted fall (41) is less than half of it
    band_upper = 1.078
    dof = sum(len(c.times) for c in fit.prepared.measurements.channels) - len(fit.p)
    excess = 0.5 * (fit.chi2_per_dof - band_upper) * dof
    assert max(c.predicted_drop for c in below.ranking.candidates if c.significant) < 0.5 * excess
    above = screen(fit, candidates, excess=excess, ranking=below.ranking)
    thrust = next(c for c in above.contenders if c.effect.name == "thrust_level")
    assert thrust.located == "throttle_window"
    where = [float(x) for x in thrust.why.split(" at ")[1].split(" ")[0].split("-")]
    assert where[0] < A.T_SEP + LATE < where[1] and where[0] > A.T_SEP - 5, thrust.why
