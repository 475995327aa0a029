"""Starting points that follow the data, and the sanity checks of a start and of a result.

The case is the one a flight-test analyst met: an attack-angle program estimated as a time
family from t = 0, whose guess (0.5 rad everywhere) turns the flight path through 180 degrees
at nearly zero speed in the simulation at the guess. The truth comes from the independent
integrator (DOP853, tolerance 1e-12) at a gentle pitch-over.
"""

from __future__ import annotations

import re

import numpy as np
import pytest
from click.testing import CliRunner

import rocketid as ri
from rocketid.cases.vehicle import RA66_VEHICLE
from rocketid.cli import main
from rocketid.errors import DataError
from rocketid.physics.ascent import ascent_dynamics, ascent_states, flight_conditions
from rocketid.start import local_fit, result_checks, start_checks, states_from_data

TRUTH = {"alpha0": 0.0, "alpha1": 0.0, "alpha2": -0.1, "alpha3": 0.0, "alpha4": 0.0, "CD": 0.5, "CL": 0.1}


def pitch_model(alpha_guess: float) -> ri.ModelSpec:
    """RA-66's vehicle with the attack angle a piecewise-linear family estimated with CD and CL,
    declared the way a user would, from the ascent building blocks."""
    m = ri.Model("pitch-program", 0.0, 66.0)
    st = ascent_states(m)
    fc = flight_conditions(m, st)
    alpha = m.piecewise_linear("alpha", [0, 5, 15, 25, 66], guess=alpha_guess, bounds=(-0.6, 0.6))
    terms = RA66_VEHICLE.declare(m)
    cd = m.parameter("CD", guess=0.3, bounds=(0.01, 2.0))
    cl = m.parameter("CL", guess=0.05, bounds=(-1.0, 1.0))
    ascent_dynamics(m, st, fc, thrust=terms.thrust, mass=terms.mass, area=terms.area, cd=cd, cl=cl, alpha=alpha)
    for s in (st.x, st.h, st.v):
        m.output(str(s), s, sigma=1.0)
    return m.freeze()


@pytest.fixture(scope="module")
def pitch():
    spec = pitch_model(0.5)
    p = spec.parameter_vector(TRUTH)
    return spec, p, ri.simulate_measurements(spec, p, ri.ra66_times(), seed=2)


def test_flipping_guess_starts_from_the_data_and_recovers_the_truth(pitch):
    spec, p, data = pitch
    fit = ri.estimate(spec, data)
    assert fit.success
    notes = " ".join(fit.notes)
    assert "the flight path turns through" in notes and "start from the data" in notes
    assert "theta kinematics" in notes
    assert not fit.sanity
    assert 0.9 < fit.chi2_per_dof < 1.1
    assert np.allclose(fit.p, p, atol=2e-3), fit.p - p


def test_the_old_start_would_have_converged_to_nonsense_and_is_called_so(pitch):
    """The simulation at the guess, held where it fails (the start before issue 11): IPOPT
    'converges' with chi2/dof in the millions; the result checks call it not credible."""
    from rocketid.solve import fit_nlp, prepare
    spec, p, data = pitch
    prep = prepare(spec, data)
    S, _ = prep.initial_states(spec.guess)
    fit = fit_nlp(prep, prep.nlp, prep.nlp.initial_x(S, spec.guess), options={"max_iter": 300})
    assert fit.chi2_per_dof > 1e4
    checks = result_checks(fit)
    assert any("nowhere near the data" in c for c in checks)
    if fit.success:
        text = fit.summary().text()
        assert "NOT CREDIBLE" in text and "status        : converged" not in text


def test_start_checks_name_what_is_wrong(pitch):
    spec, p, data = pitch
    times = np.linspace(0, 66, 133)
    bad = ri.simulate(spec, spec.guess, times)
    notes = start_checks(spec, data, times, bad.states)
    assert any("turns through" in n and "more than 90" in n for n in notes)
    good = ri.simulate(spec, p, times)
    assert start_checks(spec, data, times, good.states) == []
    falling = good.states.copy()
    falling[:, 1] = -falling[:, 1]                 # altitude falling below the pad where the data climb
    notes = start_checks(spec, data, times, falling)
    assert any("descends where the data climb" in n for n in notes)
    assert any("into the ground" in n for n in notes)


def test_states_from_data_match_the_truth(pitch):
    spec, p, data = pitch
    times = np.linspace(2, 66, 65)
    S, source = states_from_data(spec, data, times)
    true = ri.simulate(spec, p, times, rtol=1e-12, atol=1e-12).states
    assert source["theta"] == "kinematics"
    assert np.max(np.abs(S[:, :3] - true[:, :3])) < 1.0
    assert np.max(np.abs(S[:, 3] - true[:, 3])) < 0.02        # sin(theta) = (dh/dt) / v


def test_local_fit_is_exact_on_a_parabola():
    t = np.linspace(0, 10, 101)
    y = 3 - 2 * t + 0.5 * t ** 2
    v, d = local_fit(t, y, np.array([0.0, 4.03, 10.0]), 0.3)
    np.testing.assert_allclose(v, 3 - 2 * np.array([0, 4.03, 10]) + 0.5 * np.array([0, 4.03, 10]) ** 2, rtol=1e-10)
    np.testing.assert_allclose(d, -2 + np.array([0, 4.03, 10]), rtol=1e-9, atol=1e-9)


@pytest.mark.parametrize("channel, factor, fragment", [
    ("h", 1e-3, "looks in km (multiply by 1000)"),
    ("x", 1e-3, "looks in km (multiply by 1000)"),
    ("v", 3.6, "looks in km/h (divide by 3.6)"),
    ("h", 1 / 0.3048, "looks in feet"),
])
def test_units_check_names_the_likely_mistake(tmp_path, ra66_spec, ra66_noisy, channel, factor, fragment):
    chans = tuple(ri.Channel(c.name, c.times, c.values * (factor if c.name == channel else 1.0))
                  for c in ra66_noisy.channels)
    wrong = ri.Measurements(chans)
    with pytest.raises(DataError, match=f"channel .{channel}.*{re.escape(fragment)}"):
        ri.estimate(ra66_spec, wrong)
    r = CliRunner().invoke(main, ["estimate", str(wrong.to_csv(tmp_path / "w.csv"))])
    assert r.exit_code == 2 and fragment in r.output


def test_a_downrange_that_looks_in_feet_is_reported_not_refused(ra66_spec, ra66_noisy):
    """A steep flight's downrange moves by a few times with the wind and the launch angle (a 4 m/s surface
    wind made Wren-H's 2.6 times the model's at its guess), so a downrange channel that differs from the
    model by about the foot's factor is reported, not refused; the altitude and the speed are refused (see
    above), and so is a downrange off by a thousand (km)."""
    chans = tuple(ri.Channel(c.name, c.times, c.values * (1 / 0.3048 if c.name == "x" else 1.0))
                  for c in ra66_noisy.channels)
    fit = ri.estimate(ra66_spec, ri.Measurements(chans))
    notes = " ".join(fit.notes)
    assert "channel 'x' (downrange) looks in feet" in notes and "not refused" in notes, fit.notes


def test_right_units_pass_the_check(ra66_spec, ra66_noisy, ra66_noisy_fit):
    assert ra66_noisy_fit.success and not ra66_noisy_fit.sanity
    assert not any("start from the data" in n for n in ra66_noisy_fit.notes)


def _decay(k_bounds, free_start: bool = False) -> ri.ModelSpec:
    """y' = -k y from y(0) = 1 (free when asked), with the rate's bounds as given."""
    m = ri.Model("bounded-decay", t0=0.0, tf=2.0)
    y = m.state("y", initial=1.0, free=free_start, bounds=(0.0, 10.0))
    k = m.parameter("k", guess=0.3, bounds=k_bounds)
    m.ode({y: -k * y})
    m.output("y", y, sigma=0.01)
    return m.freeze()


def test_every_parameter_at_a_bound_is_not_credible():
    """The data decay at k = 1.3 but the bounds allow 0.1 <= k <= 0.5: IPOPT stops at k = 0.5, an
    optimum of the bounded problem that is no estimate; the result says so."""
    times = np.linspace(0.02, 2.0, 100)
    spec = _decay((0.1, 0.5))
    data = ri.simulate_measurements(spec.with_guess({"k": 0.3}), np.array([1.3]), times, seed=0)
    fit = ri.estimate(spec, data)
    assert fit.success, fit.message
    assert fit.active_bounds() == [(spec.parameter_symbols[0], "upper")]
    notes = result_checks(fit)
    assert any(n.startswith("every parameter is at a bound: this is not an estimate") for n in notes), notes
    assert any("every parameter is at a bound" in n for n in fit.sanity)
    text = fit.summary().text()
    assert "NOT CREDIBLE: every parameter is at a bound" in text and "status        : converged" not in text
    assert fit.to_dict()["sanity"] == list(fit.sanity)
    # one parameter at its bound and another free is a bound note, not this one
    spec2 = _decay((0.1, 0.5), free_start=True)
    fit2 = ri.estimate(spec2, ri.simulate_measurements(spec2, spec2.parameter_vector({"k": 1.3, "y_0": 1.0}),
                                                       times, seed=0))
    assert len(fit2.active_bounds()) == 1
    assert not any("every parameter is at a bound" in n for n in result_checks(fit2))
