"""The free shape the verdict names, fitted (``rocketid.diagnostics.freeshape``).

When the search ends above the noise, the verdict says what to try: a term of free shape of the kind the screen
ranked first. The check fits it. The truth here is none of rocketid's: Wren-H's nitrous-oxide hybrid with its tank
6 K warmer than at the static firing (``tests/wren_study/truth.py``: a blowing-down saturated tank, a regressing
port, the O/F ratio and c* shifting), whose thrust and mass flow change through the burn in no catalogue shape.
The catalogue's search ends "partly explained" on it (docs/effects.md, the Wren-H table); the thrust error on the
burn's element boundaries reaches the noise and reads as the physics does: more thrust through the liquid phase
(the tank's higher vapour pressure), and the liquid out a second early (the thrust's knee earlier).
"""

from __future__ import annotations

import math
from types import SimpleNamespace

import numpy as np
import pytest

from rocketid.diagnostics.effects import Vehicle
from rocketid.diagnostics.freeshape import FreeShape, _spread, free_shape_for, read_shape


def _vehicle(**kw):
    base = dict(thrust=3600.0, mass=60.0, mass_flow=1.0, speed=300.0, start_speed=25.0, duration=43.4,
                altitude=(1200.0, 10200.0), mach=(0.1, 1.35), sigma={"x": 2.5, "h": 7.5, "v": 0.25},
                sample_interval=0.1, knot_times=(0.59, 0.6, 0.62, 1.0, 1.5, 2.0, 2.5, 3.0, 4.0, 6.0, 10.0, 20.0, 44.0),
                mach_knots=(0.2, 0.5, 0.8, 1.1, 1.3), aero_altitudes=tuple(np.linspace(1200.0, 10200.0, 50)),
                powered=(0.59, 2.7))
    base.update(kw)
    return Vehicle(**base)


def test_the_free_shape_of_each_kind():
    """A propulsion or mass candidate: a thrust error on the mesh's boundaries over the burn, the short elements a
    mesh puts at the start merged (a knot 10 ms after the first is not placed by the data); the environment: a
    wind or density profile; the aero: a drag correction in Mach on the table's quarters; a sensor: none; a model
    with a time family (RA-66's CD(t)): none (its Mach-indexed variant answers)."""
    veh = _vehicle()
    shape, knots, unit = free_shape_for("propulsion", "thrust_level", veh)
    assert unit == "s" and knots == (0.59, 1.0, 1.5, 2.0, 2.5, 3.0)      # 0.6, 0.62 merged; to the boundary after 2.7 s
    assert shape.parameter_names == tuple(f"eps_P{j}" for j in range(6))
    assert free_shape_for("mass", "start_mass", veh)[1] == knots
    wind, wk, wu = free_shape_for("environment", "wind", veh)
    dens, dk, _ = free_shape_for("environment", "density", veh)
    assert wu == "km" and wind.name.startswith("wind_pl_") and dens.name.startswith("density_pl_")
    assert len(wind.parameter_names) == len(wk) and len(dens.parameter_names) == len(dk)
    drag, mk, mu = free_shape_for("aero", "transonic_drag", veh)
    assert mu == "Mach" and len(mk) == 4 * 3 and all(0.2 < m < 1.3 for m in mk)
    assert free_shape_for("sensor", "bias_h", veh) is None
    assert free_shape_for("propulsion", "thrust_level", _vehicle(time_families=True)) is None
    assert _spread((0.0, 0.01, 1.0, 2.0, 3.0, 3.02)) == (0.0, 1.0, 2.0, 3.02)
    # a 66 s burn on 1 s elements: MAX_TIME_KNOTS boundaries spread over it, the ends kept
    from rocketid.diagnostics.freeshape import MAX_TIME_KNOTS
    long = free_shape_for("propulsion", "thrust_level", _vehicle(knot_times=tuple(np.arange(0.0, 67.0)),
                                                                  powered=(0.0, 66.0)))[1]
    assert len(long) == MAX_TIME_KNOTS and long[0] == 0.0 and long[-1] == 66.0 and set(long) <= set(np.arange(67.0))


def test_a_shape_reads_as_runs_of_like_values():
    """The reading names each run of three or more like values and the largest departure elsewhere."""
    t = (0.6, 1.5, 2.5, 3.5, 4.5, 5.5, 6.5, 7.5, 8.5)
    v = (0.30, 0.09, 0.08, 0.10, 0.085, -0.75, -0.78, -0.80, 0.0)
    text = read_shape(t, v, "s", 0.05)
    assert "+8.0 % to +10 % over 1.5-4.5 s" in text and "-80 % to -75 % over 5.5-7.5 s" in text, text
    assert "elsewhere up to +30 % (at 0.6 s)" in text
    assert read_shape((0.0, 1.0, 2.0), (0.0, 0.0, 0.0), "s", 0.05) == "+0.0 % over 0-2 s"
    # the knots read apart are those whose whole interval lies before the first sample (Wren-H: GPS from 2 s);
    # a lift-off knot 0.1 s before the first sample reaches into the data and is placed (Auk-B)
    from rocketid.diagnostics.freeshape import _before_first_sample
    assert _before_first_sample(2.0, (0.6, 1.0, 1.5, 2.0, 2.5, 3.0, 3.5)) == 3
    assert _before_first_sample(0.1, (0.0, 3.5, 7.0, 10.5)) == 0
    assert _before_first_sample(2.0, (0.6, 1.0, 2.0, 3.0)) == 0          # fewer than three would remain


def test_the_words_say_a_trace_not_an_explanation():
    """The text says the kind and the shape when the noise is reached, and is never worded as an explanation; when
    it is not reached, what is missing is not of that kind alone."""
    reached = FreeShape("propulsion", "thrust_profile_31", "thrust error in time (31 knots)", (), 1.011, 929.2, True,
                        "", (0.6, 1.0), (0.1, -0.5), "s", "the thrust +10 %", 3.7)
    text = reached.text()
    assert "reaches the noise" in text and "a change of the thrust in time" in text and "not its name" in text
    assert "explained" not in text and "confirmed" not in text
    short = FreeShape("environment", "wind_pl_13", "wind piecewise linear in altitude (13 knots)", ("start_angle",),
                      5.1, 929.2, False, "chi2/dof 5.1 above the noise band", (0.0, 1.0), (1.0, 2.0), "km", "", 3.0,
                      tried=(reached,))
    assert "does not reach the noise" in short.text() and "beside start_angle" in short.text()
    assert short.to_dict()["tried"][0]["chi2_per_dof"] == 1.011
    assert FreeShape("aero", "drag_mach_21", "d", (), math.nan, 9.0, False, "", (), (), "Mach", "", 1.0,
                     "IPOPT did not converge").to_dict()["chi2_per_dof"] is None


@pytest.fixture(scope="module")
def hot_tank():
    """Wren-H's hot-tank data (the study's seed), the base fit with the noise from the data, and a search's
    outline ending with nothing added (the check needs the base fit, the band, the vehicle and the effects)."""
    import wren as V
    from wren_study import truth
    from wren_study.cases import BY_NAME
    from rocketid.diagnostics.accept import noise_band
    from rocketid.diagnostics.api import base_fit
    from rocketid.diagnostics.screen import vehicle_of
    case = BY_NAME["hot-tank"]
    data = truth.measurements(case.hidden, seed=case.seed)
    fit, _, counts, _, _ = base_fit(V.build_model(), data, "estimate")
    band = noise_band(fit, estimated=counts)
    return SimpleNamespace(base_fit=fit, fit=fit, band=band, vehicle=vehicle_of(fit), effects=(), data=data,
                           spec=V.build_model())


def test_the_hot_tank_s_motor_is_a_thrust_change_in_time(hot_tank):
    """Wren-H with its tank at 26 C for the firing's 20 C: the base model is hundreds of times the noise; the
    thrust error on the burn's element boundaries reaches the noise band with white residuals, and reads +6 to +13 %
    through the liquid phase (the truth's vapour pressure 58 bar for 50.6: +8 % thrust) and the thrust's knee early
    (the truth's liquid runs out a second before the static firing's: at 9.5-10.5 s the fitted error is below -50 %)."""
    from rocketid.diagnostics import CATALOGUE
    from rocketid.diagnostics.effects import burn_rate_effect
    from rocketid.diagnostics.freeshape import free_shape_check
    # the search's outline as the study's ended: the burn rate and a start speed (a wrong effect of another kind)
    searched = SimpleNamespace(**{**vars(hot_tank), "effects": (burn_rate_effect(), CATALOGUE["start_speed"])})
    fs = free_shape_check(searched, "propulsion", "thrust_level")
    assert hot_tank.base_fit.chi2_per_dof > 100
    assert fs.reaches_noise, fs.text()
    assert fs.chi2_per_dof <= hot_tank.band.upper and not fs.kept and not fs.tried
    # alone at the noise: the start speed is not needed, the burn rate's place taken -- and said so
    assert fs.not_needed == ("start_speed",) and fs.replaces == ("burn_rate",), fs
    assert "the search's start_speed is not needed to reach the noise" in fs.text(), fs.text()
    assert "unconfirmed either way" in fs.text() and "takes the place of the search's burn_rate" in fs.text()
    assert fs.to_dict()["not_needed"] == ["start_speed"] and fs.parameters["eps_P0"] == fs.values[0]
    t, e = np.asarray(fs.knots), np.asarray(fs.values)
    liquid = (t >= 2.0) & (t <= 7.5)
    assert np.all((e[liquid] > 0.06) & (e[liquid] < 0.13)), dict(zip(t[liquid], e[liquid]))
    knee = (t >= 9.5) & (t <= 10.5)
    assert knee.any() and np.all(e[knee] < -0.5), dict(zip(t[knee], e[knee]))
    assert "the thrust" in fs.reading and "over 2-7.5 s" in fs.reading, fs.reading
    # the knots of the first second after the rail (the GPS from 2 s) are read apart: not placed one by one
    assert "before the first sample at 2 s" in fs.reading and "not placed one by one" in fs.reading, fs.reading
    assert fs.first_sample == 2.0 and fs.to_dict()["first_sample"] == 2.0
    # the curve drawn: the static firing's thrust along the base fit, and times 1 + eps(t) at the knots
    t, stated, fitted = (np.asarray(c) for c in fs.curve)
    assert t.size == stated.size == fitted.size and 3000 < stated.max() < 4000          # Wren-H: 3.67 kN at its peak
    at = np.searchsorted(t, 5.0)
    assert fitted[at] / stated[at] - 1 == pytest.approx(np.interp(t[at], fs.knots, fs.values), abs=1e-9)


def test_a_density_profile_is_not_the_hot_tank(hot_tank):
    """The same data with the environment's free shape: a density profile on the catalogue's finest knots stays
    far above the noise -- the check says what is missing is not of that kind."""
    from rocketid.diagnostics.freeshape import free_shape_check
    # with the thrust's kind next, the check goes on to it and says what it tried first
    both = free_shape_check(hot_tank, "environment", "density", then=[("propulsion", "thrust_level")])
    assert both.kind == "propulsion" and both.reaches_noise and len(both.tried) == 1
    fs = both.tried[0]
    assert fs.kind == "environment" and fs.effect.startswith("density_pl_") and not fs.kept
    assert not fs.reaches_noise and fs.chi2_per_dof > 2 * hot_tank.band.upper, fs.text()
    assert "is not a change of the air with altitude alone" in fs.text()
    assert f"{fs.description} alone stays at chi2/dof" in both.text()


def test_a_drag_shape_draws_the_drag_it_changes():
    """The aerodynamics' free shape (a drag correction in Mach on the table's quarters, pinned at the table's
    knots), RA-66M flown with a transonic drag rise: the report draws what it changes -- the model's drag
    coefficient against Mach along the base fit and along the fit with the correction (the table refitted beside
    it). (On Wren-H's hot tank and power-off base drag the 21-knot correction runs to IPOPT's 500 iterations: the
    check then says it could not be fitted.)"""
    import rocketid as ri
    from rocketid.cases import ra66m, ra66m_truth
    from rocketid.diagnostics.accept import noise_band
    from rocketid.diagnostics.api import base_fit
    from rocketid.diagnostics.effects import with_effects
    from rocketid.diagnostics.freeshape import free_shape_check
    from rocketid.diagnostics.report import _free_shape_plot
    from rocketid.diagnostics.screen import vehicle_of
    spec = with_effects(ra66m(), "transonic_drag")
    p = ra66m_truth(spec)
    p[list(spec.parameter_names).index("dCD_transonic")] = 0.08
    fit, _, _, _, _ = base_fit(ra66m(), ri.simulate_measurements(spec, p, ri.ra66_times(), seed=0), None)
    disc = SimpleNamespace(base_fit=fit, fit=fit, band=noise_band(fit), vehicle=vehicle_of(fit), effects=())
    fs = free_shape_check(disc, "aero", "transonic_drag")
    assert fs.kind == "aero" and fs.values and not fs.message, fs.text()
    mach, cd, mach_fit, cd_fit = (np.asarray(c) for c in fs.drag)
    assert mach.size == cd.size == fit.node_times.size and mach_fit.size == cd_fit.size
    lo, hi = disc.vehicle.mach
    assert mach.max() == pytest.approx(hi, rel=0.05) and 0.05 < np.median(cd) < 2.0
    # the fitted curve is the fit's own drag coefficient: the correction plus the table refitted beside it
    assert not np.allclose(cd, np.interp(mach, mach_fit[np.argsort(mach_fit)], cd_fit[np.argsort(mach_fit)]))
    assert not fs.curve and fs.to_dict()["drag"]["fitted"]["cd"] == list(cd_fit)
    # held at zero on the table's knots, the free knots between them
    table = disc.vehicle.mach_knots
    assert fs.pins and set(fs.pins) <= set(table) and not set(fs.pins) & set(fs.knots)
    assert fs.to_dict()["pins"] == list(fs.pins)
    fig = _free_shape_plot(fs)
    assert fig.axes[0].get_xlabel() == "Mach" and len(fig.axes[0].lines) == 2


def test_beside_the_search_s_effects_the_shape_keeps_only_those_it_needs():
    """Wren-H with its tank at 23 C (about +4 % thrust, the liquid out early) on a rail at 84 deg declared 85: the
    thrust's free shape alone stays above the noise (the start angle is no thrust); beside the search's start angle
    and a transonic drag rise (a wrong effect, of the kind the study's searches took beside the motor) it reaches
    the noise; dropped one at a time, the drag rise goes and the start angle stays. The kept effect is the truth's
    (the angle near -1 deg), the drag rise is named not needed, the burn rate's place taken."""
    import wren as V
    from wren_study import truth
    from wren_study.cases import BY_NAME
    from rocketid.diagnostics import CATALOGUE
    from rocketid.diagnostics.accept import noise_band
    from rocketid.diagnostics.api import base_fit
    from rocketid.diagnostics.effects import burn_rate_effect
    from rocketid.diagnostics.freeshape import free_shape_check
    from rocketid.diagnostics.screen import vehicle_of
    case = BY_NAME["warm-tank+shallow-rail"]
    fit, _, counts, _, _ = base_fit(V.build_model(), truth.measurements(case.hidden, seed=case.seed), "estimate")
    disc = SimpleNamespace(base_fit=fit, fit=fit, band=noise_band(fit, estimated=counts), vehicle=vehicle_of(fit),
                           effects=(CATALOGUE["start_angle"], burn_rate_effect(), CATALOGUE["transonic_drag"]))
    fs = free_shape_check(disc, "propulsion", "thrust_level")
    assert fs.reaches_noise and fs.kept == ("start_angle",), fs.text()
    assert fs.not_needed == ("transonic_drag",) and fs.replaces == ("burn_rate",)
    assert [(t.kept, t.reaches_noise) for t in fs.tried] == [((), False)], [t.text() for t in fs.tried]
    assert math.degrees(fs.parameters["dgamma_start"]) == pytest.approx(-1.0, abs=0.3), fs.parameters
    assert "beside start_angle fits at chi2/dof" in fs.text() and "transonic_drag is not needed" in fs.text()


def test_diagnose_fits_the_free_shape_when_it_ends_above_the_noise(hot_tank, tmp_path):
    """Through ``diagnose``, the catalogue cut to a thrust level for speed: the search ends above the noise, the
    screen's first candidate is a propulsion effect, and the report carries the free shape -- in the verdict's
    words, in diagnosis.json and as a figure -- while the verdict stays the search's."""
    import json
    from rocketid.diagnostics import diagnose
    rep = diagnose(hot_tank.data, hot_tank.spec, candidates=["thrust_level"], sigma="estimate", max_effects=1,
                   refine=False, holdout=None, workers=1, out=tmp_path / "r")
    assert rep.final.verdict in ("partly explained", "not explained by the catalogue") and not rep.final.fits_to_noise
    fs = rep.free_shape
    assert fs is not None and fs.kind == "propulsion" and fs.reaches_noise, fs
    assert any(line == fs.text() for line in rep.verdict())
    assert "Try a thrust error in time" in rep.final.explanation, rep.final.explanation
    saved = json.loads((tmp_path / "r" / "diagnosis.json").read_text())
    assert saved["free_shape"]["effect"] == fs.effect and saved["free_shape"]["reaches_noise"] is True
    assert saved["final"]["verdict"] == rep.final.verdict and "free_shape_s" in saved["timings"]
    assert (tmp_path / "r" / "figures" / "free_shape.png").is_file()
    assert "The free shape the verdict names reaches the noise" in (tmp_path / "r" / "report.html").read_text()


def test_the_kind_is_the_search_s_first_effect_before_the_screen_s_first_candidate():
    """Wren-H's cold tank: the screen ranked a density profile first (leading a confounded group with the start mass
    and the thrust level); the search's refits took the burn rate. The verdict's suggestion and the free shape follow
    the search; the screen's first candidate only when nothing was added."""
    from rocketid.diagnostics import CATALOGUE
    from rocketid.diagnostics.api import _lead, _suggest
    from rocketid.diagnostics.effects import burn_rate_effect
    ranking = SimpleNamespace(candidates=[SimpleNamespace(name="density", kind="environment")])
    searched = SimpleNamespace(effects=(burn_rate_effect(), CATALOGUE["start_speed"]))
    assert _lead(searched, ranking) == ("propulsion", "thrust_level")
    assert _lead(SimpleNamespace(effects=()), ranking) == ("environment", "density")
    assert _lead(None, None) is None
    # a first effect of a kind without a free shape (the start angle of a shallow rail) may be complete: the first
    # effect of a kind with one leads; a search of sensor effects only keeps the sensor's suggestion
    assert _lead(SimpleNamespace(effects=(CATALOGUE["start_angle"], burn_rate_effect())), ranking) == ("propulsion",
                                                                                                   "thrust_level")
    assert _lead(SimpleNamespace(effects=(CATALOGUE["bias_v"],)), ranking) == ("sensor", "bias_v")
    # the kinds tried in turn: the effects' (with a free shape), the screen's first, the thrust's last whatever was
    # found (Wren-H's short web with the geoid: an altitude bias and drag shapes found, sensors ranked first)
    from rocketid.diagnostics.api import _leads
    sensors = SimpleNamespace(candidates=[SimpleNamespace(name="bias_h", kind="sensor")])
    found = SimpleNamespace(effects=(CATALOGUE["bias_h"], CATALOGUE["transonic_drag"], CATALOGUE["base_drag"]))
    assert _leads(found, sensors) == [("aero", "transonic_drag"), ("propulsion", "thrust_level")]
    # the verdict's "Try ..." follows the free shape that reached the noise (there: the thrust's, not the drag's)
    from rocketid.diagnostics.api import _tried_lead
    assert _tried_lead(found, sensors, SimpleNamespace(reaches_noise=True, kind="propulsion")) == ("propulsion", "")
    assert _tried_lead(found, sensors, SimpleNamespace(reaches_noise=False, kind="propulsion")) == _lead(found, sensors)
    assert _tried_lead(found, sensors) == ("aero", "transonic_drag")
    assert _leads(searched, ranking) == [("propulsion", "thrust_level"), ("environment", "density")]
    assert "thrust error in time" in _suggest(_lead(searched, ranking))
    assert "density deviation" in _suggest(_lead(None, ranking))


def test_which_searches_fit_a_free_shape(monkeypatch):
    """Above the noise, not a tie, not cut short: the first kind with a free shape, the others next; a search of
    sensor effects only keeps its sensor-model suggestion and fits none; one of a start angle only tries the
    thrust's."""
    from rocketid.diagnostics import CATALOGUE
    from rocketid.diagnostics import api, freeshape
    from rocketid.diagnostics.effects import burn_rate_effect
    asked = []
    monkeypatch.setattr(freeshape, "free_shape_check",
                        lambda disc, kind, family, **kw: asked.append((kind, family, kw["then"])) or "fitted")
    ranking = SimpleNamespace(candidates=[SimpleNamespace(name="bias_h", kind="sensor")])
    settings = dict(timeout=60.0, options=None)

    def run(effects, **kw):
        disc = SimpleNamespace(effects=tuple(effects), fits_to_noise=False, stopped="", ambiguous="",
                               verdict="partly explained", **kw)
        return api._free_shape(disc, ranking, settings, None, 0.0, [])
    assert run([CATALOGUE["start_angle"], burn_rate_effect(), CATALOGUE["wind"]]) == "fitted"
    assert asked[-1] == ("propulsion", "thrust_level", [("environment", "wind")])
    assert run([CATALOGUE["start_angle"]]) == "fitted" and asked[-1] == ("propulsion", "thrust_level", [])
    n = len(asked)
    assert run([CATALOGUE["bias_v"], CATALOGUE["time_offset"]]) is None and len(asked) == n
    disc = SimpleNamespace(effects=(burn_rate_effect(),), fits_to_noise=True, stopped="", ambiguous="",
                           verdict="partly explained")
    assert api._free_shape(disc, ranking, settings, None, 0.0, []) is None and len(asked) == n
