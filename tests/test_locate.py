"""Locate (ISSUE 5, item 3): where a fit fails, in time, flight phase and flight condition,
and the plausibility checks of the coefficients.

Hidden effects are simulated with the effects catalogue (``with_effects``) on
RA-66M and fitted with the Mach-indexed model (``ra66m``), which leaves them
visible; each must be located where its physics acts:

* nozzle back-pressure with the vacuum thrust stated (``back_pressure_vacuum``, thrust
  ``P - A_e p_a(h)``): the deficit is largest near
  the ground, where the dynamic pressure is too low for CD(M) to absorb it, so
  the altitude residual fails from lift-off through the pitch-over, at low
  Mach and low q;
* altitude sensor bias (``z_h = h + b_h``): the fitted trajectory can shift by
  ``b_h`` only once it flies, so the h residual fails at lift-off (h(0) = 0 is
  fixed);
* thrust misalignment (a normal force from lift-off): the downrange residual fails
  first, from the first seconds after lift-off;
* speed scale factor (``z_v = (1 + k_v) v``): a v residual of one sign over the
  whole flight.

The time-knot trap: the same kind of hidden effect on RA-66's vehicle, fitted
with the chapter's ``ra66()`` (CD0..CD6 on time knots, CL), where the
coefficients absorb it; the plausibility checks must flag it (knots at bounds,
CD(t) not a smooth function of Mach) and must pass the correct model.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest
from scipy.stats import chi2

import rocketid as ri
from rocketid.cases import ra66m, ra66m_truth
from rocketid.diagnostics.compare import compare
from rocketid.diagnostics.effects import with_effects
from rocketid.diagnostics.locate import flight_conditions, flight_phases, locate
from rocketid.diagnostics.plausibility import check_plausibility
from rocketid.errors import DataError, SettingsError
from rocketid.estimability import uncertainty


def _data(base, effect=None, values=None, seed=0):
    spec = with_effects(base, effect, values) if effect else base
    truth = ra66m_truth(spec) if base.name == "RA-66M" else ri.ra66_truth(spec)
    for k, v in (values or {}).items():
        truth[spec.parameter_names.index(k)] = v
    return ri.simulate_measurements(spec, truth, ri.ra66_times(), seed=seed)


@pytest.fixture(scope="module")
def m_spec():
    return ra66m()


@pytest.fixture(scope="module")
def clean_fit(m_spec):
    return ri.estimate(m_spec, _data(m_spec))


@pytest.fixture(scope="module")
def bp_fit(m_spec):
    return ri.estimate(m_spec, _data(m_spec, "back_pressure_vacuum", {"A_e_vac": 0.1}))


@pytest.fixture(scope="module")
def hbias_fit(m_spec):
    return ri.estimate(m_spec, _data(m_spec, "bias_h", {"b_h": 5.0}))


@pytest.fixture(scope="module")
def vscale_fit(m_spec):
    return ri.estimate(m_spec, _data(m_spec, "scale_v", {"k_v": 1e-3}))


# ---------------------------------------------------------------------------
# flight conditions and phases
# ---------------------------------------------------------------------------


def test_flight_conditions_come_from_the_model(clean_fit):
    t = np.array([0.5, 20.0, 40.0, 66.0])
    c = flight_conditions(clean_fit, t)
    assert set(c) == {"h", "v", "mach", "qbar", "alpha"}
    S = clean_fit.states_at(t)
    np.testing.assert_allclose(c["h"], S[:, 1])
    np.testing.assert_allclose(c["qbar"], ri.simulate(clean_fit.spec, clean_fit.p, t).value("qbar"), rtol=1e-3)
    assert c["mach"][-1] == pytest.approx(S[-1, 2] / 295.07, rel=0.02)  # a(17 km) = 295.07 m/s
    assert c["alpha"][0] == 0.0 and c["alpha"][1] < 0


def test_ascent_phases(clean_fit):
    loc = locate(clean_fit)
    names = [p.name for p in loc.phases]
    assert names == ["lift-off", "pitch-over", "gravity turn", "max-q", "supersonic climb"]
    ph = {p.name: p for p in loc.phases}
    assert ph["lift-off"].t_start == pytest.approx(0.01)
    assert ph["lift-off"].t_end == pytest.approx(4.0)  # the pitch-over starts before v = 50 m/s
    assert (ph["pitch-over"].t_start, ph["pitch-over"].t_end) == pytest.approx((4.0, 24.0))
    q = loc.conditions["qbar"]
    t_peak = loc.condition_times[np.argmax(q)]
    assert ph["max-q"].t_start < t_peak < ph["max-q"].t_end
    inside = ph["max-q"].contains(loc.condition_times)
    assert np.all(q[inside] >= 0.9 * q.max() - 1e-9)
    # the phases tile the flight
    for a, b in zip(loc.phases[:-1], loc.phases[1:]):
        assert a.t_end == pytest.approx(b.t_start)


def test_phases_need_an_ascent_model():
    t = np.linspace(0, 10, 50)
    assert flight_phases(t, {}) == ()
    assert flight_phases(t, {"h": t}) == ()
    ph = flight_phases(t, {"v": 10 * t})  # no alpha, no q: lift-off, then the climb
    assert [p.name for p in ph] == ["lift-off", "climb"]
    assert ph[0].t_end == pytest.approx(t[np.argmax(10 * t >= 50)])


# ---------------------------------------------------------------------------
# a correct model: nothing to locate
# ---------------------------------------------------------------------------


def test_a_correct_model_fails_nowhere(clean_fit):
    loc = locate(clean_fit)
    assert not loc.fails and loc.findings == ()
    assert loc.earliest is None
    assert loc.z_critical == pytest.approx(3.55, abs=0.05)  # Bonferroni over 3 x 43 windows at 0.05
    assert all(abs(r["z"]) < loc.z_critical for r in loc.phase_table)
    assert all(c.p_value > 1e-3 for c in loc.cusums.values())
    assert "no window fails" in loc.summary()


def test_window_statistics_match_their_definitions(bp_fit):
    comp = compare(bp_fit)
    loc = locate(bp_fit, comp)
    w = loc.windows["h"]
    ch = comp["h"]
    k = int(np.argmax(np.abs(w.z)))
    sel = (ch.times >= w.t_start[k]) & (ch.times <= w.t_end[k])
    e = ch.normalized[sel]
    assert w.n[k] == e.size
    assert w.bias[k] == pytest.approx(e.mean())
    assert w.z[k] == pytest.approx(e.mean() * np.sqrt(e.size))
    assert w.rms_ratio[k] == pytest.approx(e.std(ddof=1))
    assert w.t_end[k] - w.t_start[k] == pytest.approx(loc.window)
    assert w.t_end[-1] == pytest.approx(66.0)
    c = loc.cusums["h"]
    np.testing.assert_allclose(c.values, np.cumsum(ch.normalized) / np.sqrt(ch.n))


# ---------------------------------------------------------------------------
# hidden effects located where their physics acts
# ---------------------------------------------------------------------------


def test_back_pressure_is_located_near_the_ground(bp_fit):
    loc = locate(bp_fit)
    assert loc.fails
    top = loc.findings[0]
    assert top.channel == "h" and top.sign > 0  # less thrust in the data: the model flies high
    assert top.t_start < 5.0 and top.t_end <= 30.0
    assert top.phases[0] == "lift-off" and "pitch-over" in top.phases
    assert top.conditions["mach"][0] < 0.1 and top.conditions["mach"][1] < 1.0
    assert top.conditions["qbar"][0] < 1.0  # kPa: from lift-off, where q is near zero
    assert top.conditions["h"][1] < 4.0  # km
    for words in ("h residual", "lift-off", "Mach 0.0-", "q 0-", "altitude 0.0-"):
        assert words in top.text, top.text
    assert loc.earliest.t_start < 5.0 and loc.earliest.phases[0] == "lift-off"
    # per phase: the h residual fails most in the pitch-over, and far less after max-q
    z = {r["phase"]: abs(r["z"]) for r in loc.phase_table if r["channel"] == "h"}
    assert max(z, key=z.get) == "pitch-over"
    assert z["pitch-over"] > 3 * z["supersonic climb"]
    # the cumulative sum leaves the white-noise band within the first seconds
    assert loc.cusums["h"].departure_time < 5.0


def test_altitude_bias_is_located_at_lift_off(hbias_fit):
    loc = locate(hbias_fit)
    top = loc.findings[0]
    assert top.channel == "h" and top.sign < 0  # the data read 5 m high: the model is below them
    assert top.t_start == pytest.approx(0.01) and top.phases[0] == "lift-off"
    z = {r["phase"]: r["z"] for r in loc.phase_table if r["channel"] == "h"}
    assert min(z, key=z.get) == "lift-off" and z["lift-off"] < -20
    assert abs(z["supersonic climb"]) < loc.z_critical


def test_misalignment_is_located_from_lift_off_in_downrange():
    """A thrust misalignment (0.05 deg, phased in over the first 2 s as the catalogue defines it)
    pushes the vehicle sideways from lift-off: the downrange residual is the first to fail, from
    the first seconds of the pitch-over on, at Mach 0.1 and q near 1 kPa."""
    spec = ra66m()
    fit = ri.estimate(spec, _data(spec, "misalignment", {"delta_thrust": np.radians(0.05)}))
    loc = locate(fit)
    first = loc.earliest
    assert first.channel == "x" and first.sign > 0
    assert first.t_start < 6.0 and first.phases[0] in ("lift-off", "pitch-over")
    assert first.conditions["mach"][0] < 0.2 and first.conditions["qbar"][0] < 2.0
    departures = {k: c.departure_time for k, c in loc.cusums.items()}
    assert departures["x"] < 10.0 and departures["x"] == min(d for d in departures.values() if d is not None)


def test_speed_scale_is_a_whole_flight_offset(vscale_fit):
    loc = locate(vscale_fit)
    f = next(f for f in loc.findings if f.channel == "v")
    assert f.kind == "offset" and f.sign < 0
    assert (f.t_start, f.t_end) == pytest.approx((0.01, 66.0))
    assert "over the whole flight" in f.text
    assert f.phases == ("lift-off", "pitch-over", "gravity turn", "max-q", "supersonic climb")


def test_location_summary_and_dict(bp_fit, tmp_path):
    loc = locate(bp_fit)
    text = loc.summary()
    for section in ("Settings", "Phases", "Per phase", "Findings", "Cumulative sums"):
        assert section in text
    d = loc.to_dict()
    assert d["findings"][0]["channel"] == "h" and len(d["phases"]) == 5
    axes = loc.plot(path=tmp_path / "loc.png")
    assert len(axes) == 4 and (tmp_path / "loc.png").stat().st_size > 10_000


# ---------------------------------------------------------------------------
# short data, other models, bad settings
# ---------------------------------------------------------------------------


def _decay(n: int, offset: float = 0.0):
    m = ri.Model("decay", 0.0, 2.0)
    y = m.state("y", 1.0)
    k = m.parameter("k", 0.5, bounds=(0.0, 10.0))
    m.ode({y: -k * y})
    m.output("y", y, sigma=0.01)
    spec = m.freeze()
    t = np.linspace(0.02, 2.0, n)
    clean = ri.simulate(spec, {"k": 1.3}, t).states[:, 0]
    noise = np.random.default_rng(0).normal(0, 0.01, n)
    data = ri.Measurements.from_arrays(t, {"y": clean + noise + offset * (t > 1.0)})
    return spec, data


def test_data_too_short_for_the_windows_is_a_clear_error():
    spec, data = _decay(30)
    fit = ri.estimate(spec, data)
    with pytest.raises(DataError, match=r"too short for windowed statistics.*window") as err:
        locate(fit)
    assert "30 samples" in str(err.value) and "compare() still works" in str(err.value)
    assert compare(fit).channels[0].n == 30


def test_a_too_long_window_is_a_clear_error(clean_fit):
    with pytest.raises(DataError, match="too short"):
        locate(clean_fit, window=40.0)
    with pytest.raises(SettingsError, match="window"):
        locate(clean_fit, window=-1.0)
    with pytest.raises(SettingsError, match="level"):
        locate(clean_fit, level=0.0)


def test_diagnose_notes_short_data():
    from rocketid.diagnostics.api import diagnose

    spec, data = _decay(30)
    rep = diagnose(data, spec, confirm_top=0)
    assert rep.location is None
    assert any("too short for windowed statistics" in n for n in rep.notes)
    assert "Location: not available" in rep.summary()


def test_a_model_without_flight_conditions_gets_time_windows():
    spec, data = _decay(400, offset=0.05)  # a 5-sigma step in the data after t = 1 s
    fit = ri.estimate(spec, data)
    loc = locate(fit)
    assert loc.phases == () and loc.conditions == {}
    assert any("time windows only" in n for n in loc.notes)
    assert loc.fails
    assert all(f.conditions == {} and f.phases == () and "Mach" not in f.text for f in loc.findings)
    # the model (one decay rate) splits the step: above the data before t = 1 s, below after
    after = [f for f in loc.findings if f.kind in ("bias", "drift", "offset") and f.sign < 0]
    assert after and after[0].t_start >= 0.9 and after[0].t_end == pytest.approx(2.0)
    assert after[0].text.startswith("y residual") and "t = 1.0" in after[0].text


# ---------------------------------------------------------------------------
# plausibility: the time-knot trap
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def trap_fit():
    """RA-66 data with a small nozzle back-pressure (A_e = 0.02 m^2, 0.5 % of the thrust at sea
    level), fitted with the chapter's time-knot model."""
    spec = ri.ra66()
    return ri.estimate(spec, _data(spec, "back_pressure_vacuum", {"A_e_vac": 0.02}))


def test_the_time_knot_model_passes_on_correct_data(ra66_noisy_fit):
    pl = check_plausibility(ra66_noisy_fit)
    assert pl.passed, pl.summary()
    mc = pl.mach_checks[0]
    assert mc.family == "CD" and mc.knots == ("CD0", "CD1", "CD2", "CD3", "CD4", "CD5", "CD6")
    assert mc.p_value > 0.5
    assert mc.mach[0] == 0.0 and 2.5 < mc.mach[-1] < 3.0


def test_the_time_knot_trap_is_flagged(trap_fit):
    comp = compare(trap_fit)
    assert comp.chi2_per_dof < 2.5  # the residuals come close to the noise ...
    pl = check_plausibility(trap_fit)
    assert not pl.passed  # ... the coefficients do not
    codes = {f.code for f in pl.flags if f.severity == "fail"}
    assert {"at-bound", "mach-smooth"} <= codes, pl.summary()
    assert "CD0" in pl.flagged_parameters()
    bound = pl.flagged("at-bound")[0]
    assert bound.parameters == ("CD0",) and "upper bound 1" in bound.message
    mc = pl.mach_checks[0]
    assert mc.p_value < 1e-3
    assert pl.flagged("subsonic-flat")
    assert "IMPLAUSIBLE" in pl.summary() and "FAIL mach-smooth" in pl.summary()


def test_the_mach_check_uses_the_knots_standard_errors(trap_fit):
    u = uncertainty(trap_fit)
    pl = check_plausibility(trap_fit, uncertainty=u)
    mc = pl.mach_checks[0]
    idx = [trap_fit.spec.parameter_names.index(k) for k in mc.knots]
    np.testing.assert_allclose(mc.standard_errors, u.standard_errors[idx])
    # the generalized least-squares misfit, recomputed
    V = u.parameter_covariance[np.ix_(idx, idx)] + mc.tolerance ** 2 * np.eye(len(idx))
    X = np.column_stack([np.vander(mc.mach, 3), np.exp(-((mc.mach - 1.1) / 0.25) ** 2 / 2)])
    W = np.linalg.inv(V)
    b = np.linalg.solve(X.T @ W @ X, X.T @ W @ mc.values)
    r = mc.values - X @ b
    assert mc.statistic == pytest.approx(r @ W @ r, rel=1e-6)
    assert mc.dof == 3 and mc.p_value == pytest.approx(chi2.sf(r @ W @ r, 3), rel=1e-6)
    # against the standard errors alone (tau = 0) even the correct time-knot fit of a real
    # drag curve would fail; the tolerance is what makes the check usable
    strict = check_plausibility(trap_fit, uncertainty=u, mach_tolerance=0.0).mach_checks[0]
    assert strict.statistic > 100 * mc.statistic


def test_negative_drag_is_the_wrong_sign():
    spec = ri.ra66()
    wide = replace(spec, parameters=tuple(replace(p, lower=-1.0) for p in spec.parameters))
    fit = ri.estimate(wide, _data(spec, "thrust_level", {"eps_thrust": 0.02}))
    pl = check_plausibility(fit)
    wrong = pl.flagged("wrong-sign")
    assert wrong and wrong[0].parameters[0].startswith("CD"), pl.summary()
    assert "cannot be" in wrong[0].message


def test_parameters_of_added_effects_are_never_taken_for_coefficients(ra66_noisy_fit):
    """A parameter named in ``realistic`` (an effect's) is an effect parameter whatever roles it
    enters. A wind's surface value W_0 enters the drag coefficient through the airspeed's Mach
    number, and was once flagged as "outside the plausible range of a launch vehicle's drag
    coefficient" (2.8 m/s), downgrading a right wind + speed-sensor answer on a blind test."""
    from rocketid.cases import ra66m
    from rocketid.diagnostics import with_effects
    from rocketid.diagnostics.effects import wind_profile_effect
    from rocketid.diagnostics.plausibility import coefficient_kinds

    kinds, _ = coefficient_kinds(with_effects(ra66m(), [wind_profile_effect([0, 3, 8, 13])]))
    assert kinds["W_0"] == "drag" and kinds["W_1"] == "other"     # by role alone: what misled the check
    plain = check_plausibility(ra66_noisy_fit, drag_range=(0.6, 1.5))
    assert any(f.parameters == ("CD3",) for f in plain.flagged("implausible"))
    marked = check_plausibility(ra66_noisy_fit, drag_range=(0.6, 1.5), realistic={"CD3": 0.0})
    assert dict(zip(marked.names, marked.kinds))["CD3"] == "effect"
    assert not any(f.parameters == ("CD3",) for f in marked.flagged("implausible"))


def test_implausible_sizes_and_undetermined_parameters(ra66_noisy_fit):
    pl = check_plausibility(ra66_noisy_fit, realistic={"CL": 0.001}, drag_range=(0.6, 1.5))
    big = pl.flagged("implausible")
    assert any(f.parameters == ("CL",) and "100 times" in f.message for f in big)
    assert any(f.parameters == ("CD3",) and "outside the plausible range" in f.message for f in big)
    d = pl.to_dict()
    assert d["passed"] is False and len(d["parameters"]) == 8
    with pytest.raises(SettingsError):
        check_plausibility("fit")


# ---------------------------------------------------------------------------
# the supersonic check: a drag coefficient that climbs with Mach above 1.5
# ---------------------------------------------------------------------------


def test_a_declining_supersonic_drag_passes(clean_fit, ra66_noisy_fit):
    """RA-66M's drag falls from 0.52 at Mach 1.3 to 0.36 at 2.8, RA-66's is constant: no flag."""
    for fit in (clean_fit, ra66_noisy_fit):
        assert not check_plausibility(fit).flagged("supersonic-rise"), fit.spec.name


def test_a_supersonic_drag_rise_is_flagged(m_spec):
    """Data flown with a drag table that climbs from 0.42 at Mach 2 to 0.60 at Mach 2.8 (no real vehicle
    does; the data are made so on purpose): the fit recovers the climb and the check flags it, naming the
    table's knots, with a standard error from the covariance."""
    truth = ra66m_truth(m_spec)
    truth[m_spec.parameter_names.index("CD_M_6")] = 0.60
    data = ri.simulate_measurements(m_spec, truth, ri.ra66_times(), seed=3)
    fit = ri.estimate(m_spec, data)
    assert fit.success
    flags = check_plausibility(fit).flagged("supersonic-rise")
    assert len(flags) == 1 and flags[0].severity == "fail"
    assert "CD_M_6" in flags[0].parameters
    assert "rises from 0.4" in flags[0].message and "+-" in flags[0].message
    # a tolerance larger than the climb lets it pass: the check compares the rise with its tolerance
    assert not check_plausibility(fit, supersonic_tolerance=0.5).flagged("supersonic-rise")
