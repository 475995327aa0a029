"""The catalogue of candidate effects: each applies to both reference cases, its zero value gives back
the base model exactly, its parameter enters the model, and bad effects are refused with clear errors."""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp

import rocketid as ri
from rocketid.cases import ra66m
from rocketid.diagnostics import (CATALOGUE, KINDS, Effect, custom_effect, is_present, liftoff_fade, resolve_effects,
                                  with_effects)
from rocketid.errors import ModelError

REQUIRED = {"back_pressure", "thrust_level", "mass_flow", "transonic_drag", "wind", "earth_rotation", "misalignment",
            "density", "bias_x", "bias_h", "bias_v", "scale_v", "scale_h",
            "time_offset"}


@pytest.fixture(scope="module")
def ra66_spec():
    return ri.ra66()


def test_catalogue_holds_the_issue_effects():
    assert REQUIRED <= set(CATALOGUE)
    for name, e in CATALOGUE.items():
        assert e.name == name and e.kind in KINDS and e.title and e.description
        assert e.realistic and all(v != 0 for v in e.realistic.values()), name
    assert len(CATALOGUE["wind"].realistic) >= 3 and len(CATALOGUE["density"].realistic) >= 3
    assert CATALOGUE["earth_rotation"].realistic == {"k_rot": 1.0}
    assert CATALOGUE["back_pressure"].realistic["A_e"] == pytest.approx(0.4)


def _random_point(spec: ri.ModelSpec, rng: np.random.Generator) -> dict:
    """Plausible values of every symbol an expanded equation or output can hold."""
    vals = {spec.t: rng.uniform(5, 60)}
    typical = {"x": (0, 1e4), "h": (100, 2e4), "v": (50, 800), "theta": (0.8, 1.5), "wind_speed": (0, 0)}
    for s in spec.states:
        lo, hi = typical.get(str(s.symbol), (0, 0) if str(s.symbol).endswith("_speed") else (0, 1))
        vals[s.symbol] = rng.uniform(lo, hi)
        vals[s.derivative] = rng.uniform(-1, 1)
    for u in spec.input_symbols:
        vals[u] = rng.uniform(-0.03, 0.03)
    for f in spec.families:
        vals[f.symbol] = rng.uniform(0.2, 0.6)
    for p in spec.parameters:
        vals[p.symbol] = rng.uniform(0.2, 0.6) if p.guess != 0 else 0.0
    return vals


def _values(spec: ri.ModelSpec, exprs, point: dict) -> np.ndarray:
    out = []
    for e in exprs:
        e = spec.expand(e)
        out.append(float(sp.N(e.xreplace({k: sp.Float(v) for k, v in point.items() if k in e.free_symbols}))))
    return np.array(out)


#: Catalogue effects for a motor that stops inside the horizon (RA-66's burns throughout): tested on Tern-2.
NEEDS_BURN_OUT = {"base_drag"}
#: Catalogue effects for a declared moving start (RA-66 lifts off from rest): tested on Wren-H below.
NEEDS_MOVING_START = {"start_angle", "start_speed"}


@pytest.mark.parametrize("name", sorted(set(CATALOGUE) - NEEDS_BURN_OUT - NEEDS_MOVING_START))
@pytest.mark.parametrize("case", ["ra66m", "ra66"])
def test_zero_gives_back_the_base_model(name, case, ra66m_spec, ra66_spec):
    base = ra66m_spec if case == "ra66m" else ra66_spec
    spec = with_effects(base, [name])
    assert set(base.parameter_names) < set(spec.parameter_names)
    new = [n for n in spec.parameter_names if n not in base.parameter_names]
    assert set(new) == set(CATALOGUE[name].realistic)
    assert all(spec.parameter(n).guess == 0.0 for n in new)
    assert spec.state_symbols[:len(base.states)] == base.state_symbols
    rng = np.random.default_rng(3)
    for _ in range(2):
        point = _random_point(spec, rng)
        # residuals and outputs at zero effect parameters equal the base model's
        np.testing.assert_allclose(_values(spec, spec.equations[:len(base.states)], point),
                                   _values(base, base.equations, point), rtol=1e-12, atol=1e-9)
        np.testing.assert_allclose(_values(spec, [o.expr for o in spec.outputs], point),
                                   _values(base, [o.expr for o in base.outputs], point), rtol=1e-12, atol=1e-9)
        # and a realistic value changes them (the parameter enters)
        moved = dict(point)
        for n, v in CATALOGUE[name].realistic.items():
            moved[spec.symbol(n)] = v
        a = np.concatenate([_values(spec, spec.equations, point), _values(spec, [o.expr for o in spec.outputs], point)])
        b = np.concatenate([_values(spec, spec.equations, moved), _values(spec, [o.expr for o in spec.outputs], moved)])
        assert np.max(np.abs(a - b)) > 0, name


def test_with_effects_sets_values_and_keeps_the_base_guesses(ra66m_spec):
    spec = with_effects(ra66m_spec, ["back_pressure", "bias_h"], {"A_e": 0.4, "b_h": 5.0})
    assert spec.parameter("A_e").guess == 0.4 and spec.parameter("b_h").guess == 5.0
    for p in ra66m_spec.parameters:
        assert spec.parameter(p.symbol).guess == p.guess
    # a spec with changed guesses keeps them through with_effects
    moved = ra66m_spec.with_guess({"CL_alpha": 2.4})
    assert with_effects(moved, ["bias_x"]).parameter("CL_alpha").guess == 2.4


def test_the_users_model_is_not_changed():
    m = ra66m(build=False)
    before = m.freeze()
    spec = with_effects(m, ["thrust_level", "time_offset"])
    after = m.freeze()
    assert after.parameter_names == before.parameter_names
    assert after.outputs == before.outputs
    assert "tau" in spec.parameter_names


def test_time_offset_uses_state_derivatives(ra66m_spec):
    spec = with_effects(ra66m_spec, ["time_offset"])
    tau = spec.symbol("tau")
    for o in spec.outputs:
        s = spec.symbol(o.name)
        assert sp.simplify(o.expr - (s - tau * spec.states[spec.state_symbols.index(s)].derivative)) == 0


def test_sensor_effects_edit_their_channel_only(ra66m_spec):
    spec = with_effects(ra66m_spec, ["bias_h", "scale_v"])
    out = {o.name: o.expr for o in spec.outputs}
    assert out["x"] == spec.symbol("x")
    assert out["h"] == spec.symbol("h") + spec.symbol("b_h")
    assert sp.expand(out["v"] - (1 + spec.symbol("k_v")) * spec.symbol("v")) == 0


def test_a_sensor_lag_delays_its_channel_only_and_adds_to_a_time_offset(ra66m_spec):
    """``sensor_lag_effect("v")``: ``z_v = v - tau_v dv/dt``, x and h untouched; after ``time_offset`` the two
    delays add on v (``v - (tau + tau_v) dv/dt``, to first order); an unknown channel is refused."""
    from rocketid.diagnostics import sensor_lag_effect
    from rocketid.errors import ModelError
    dv = ra66m_spec.states[ra66m_spec.state_symbols.index(ra66m_spec.symbol("v"))].derivative
    spec = with_effects(ra66m_spec, [sensor_lag_effect("v")])
    out = {o.name: o.expr for o in spec.outputs}
    assert out["x"] == spec.symbol("x") and out["h"] == spec.symbol("h")
    assert sp.expand(out["v"] - (spec.symbol("v") - spec.symbol("tau_v") * dv)) == 0
    both = with_effects(ra66m_spec, ["time_offset", sensor_lag_effect("v")])
    out = {o.name: o.expr for o in both.outputs}
    tau, tau_v = both.symbol("tau"), both.symbol("tau_v")
    assert sp.expand(out["v"] - (both.symbol("v") - (tau + tau_v) * dv)) == 0
    assert tau_v not in out["h"].free_symbols and tau in out["h"].free_symbols
    with pytest.raises(ModelError, match="channel must be one of x, h, v"):
        sensor_lag_effect("q")


def test_liftoff_fade():
    t = sp.Symbol("t")
    f = sp.lambdify(t, liftoff_fade(t))
    assert f(0.0) == 0.0 and f(3.0) == pytest.approx(0.5) and f(30.0) == pytest.approx(1.0, abs=1e-3)
    # vanishes faster than t at lift-off (no free constant C of the singular start is excited)
    assert f(1e-3) / 1e-3 < 1e-6


def test_zero_effect_simulates_like_the_base(ra66m_spec):
    times = np.linspace(0.5, 66, 40)
    spec = with_effects(ra66m_spec, ["wind", "earth_rotation", "misalignment"])
    p_base = ri.cases.ra66m_truth(ra66m_spec)
    a = ri.simulate(ra66m_spec, p_base, times).outputs()
    b = ri.simulate(spec, ri.cases.ra66m_truth(spec), times).outputs()
    for k in a:
        np.testing.assert_allclose(b[k], a[k], atol=1e-4)


# ---------------------------------------------------------------------------
# errors
# ---------------------------------------------------------------------------


def test_an_effect_already_present_is_refused(ra66m_spec):
    spec = with_effects(ra66m_spec, ["bias_h"])
    with pytest.raises(ModelError, match="already present"):
        with_effects(spec, ["bias_h"])
    assert is_present(spec, "bias_h") and not is_present(spec, "bias_x")
    spec = with_effects(ra66m_spec, ["time_offset"])
    with pytest.raises(ModelError, match="already present"):
        with_effects(spec, ["time_offset"])
    with pytest.raises(ModelError, match="given twice"):
        with_effects(ra66m_spec, ["bias_h", "bias_h"])


def test_a_custom_effect_already_present_is_refused(ra66m_spec):
    def gravity(m):
        eps = m.parameter("eps_g", 0.0)
        m.redefine("g", m.definition("g") * (1 + eps))
        return eps
    effect = custom_effect("gravity_scale", gravity)
    spec = with_effects(ra66m_spec, [effect])
    with pytest.raises(ModelError, match="already present"):
        with_effects(spec, [effect])


def test_a_parameter_that_does_not_enter_is_refused(ra66m_spec):
    def idle(m):
        return m.parameter("k_idle", 0.0)
    with pytest.raises(ModelError, match="does not enter the model"):
        with_effects(ra66m_spec, [custom_effect("idle", idle)])


def test_other_bad_effects_are_refused(ra66m_spec):
    with pytest.raises(ModelError, match="did you mean back_pressure"):
        with_effects(ra66m_spec, ["back_presure"])

    def nonzero(m):
        k = m.parameter("k_nz", 1.0)
        m.redefine("thrust", m.definition("thrust") * k)
        return k
    with pytest.raises(ModelError, match="guess 0"):
        with_effects(ra66m_spec, [custom_effect("nonzero", nonzero)])

    def silent(m):
        m.parameter("k_s", 0.0)
    with pytest.raises(ModelError, match="must return the parameters"):
        with_effects(ra66m_spec, [custom_effect("silent", silent)])
    with pytest.raises(ModelError, match="unknown kind"):
        Effect("x", "x", "magic", lambda m: ())


def test_an_effect_needing_what_the_model_lacks_says_what():
    m = ri.Model("decay", 0.0, 1.0)
    y = m.state("y", 1.0)
    k = m.parameter("k", 0.5)
    m.ode({y: -k * y})
    m.output("y", y, sigma=0.1)
    # issue 12: effects find the physics by role, and the message names the role to declare
    with pytest.raises(ModelError, match=r"needs the thrust \(role 'thrust'\).*declare_role\('thrust'"):
        with_effects(m, ["back_pressure"])
    with pytest.raises(ModelError, match="output named 'h'"):
        with_effects(m, ["bias_h"])
    # an output-only effect applies to any model
    assert "tau" in with_effects(m, ["time_offset"]).parameter_names


def test_resolve_effects_accepts_names_and_effects():
    e = CATALOGUE["wind"]
    assert [x.name for x in resolve_effects(["bias_h", e])] == ["bias_h", "wind"]
    assert resolve_effects("bias_v")[0] is CATALOGUE["bias_v"]
    with pytest.raises(ModelError, match="expected an Effect"):
        resolve_effects([3])


def test_effects_are_immutable_values():
    e = CATALOGUE["thrust_level"]
    with pytest.raises(Exception):
        e.name = "other"
    with pytest.raises(TypeError):
        e.realistic["eps_thrust"] = 1.0
    assert hash(e) == hash(CATALOGUE["thrust_level"])
    assert math.isclose(CATALOGUE["misalignment"].realistic["delta_thrust"], math.radians(0.25))


def test_back_pressure_conventions(ra66m_spec):
    """Issue 8: by default the stated thrust holds at sea level and rises as the pressure falls,
    P + A_e (p0 - p_a(h)); the vacuum option is P - A_e p_a(h); on a model whose thrust already
    has a nozzle term the effect is an area correction dA_e of either sign."""
    from rocketid.diagnostics.effects import SEA_LEVEL_PRESSURE
    from rocketid.physics.atmosphere import us76_pressure
    sea = with_effects(ra66m_spec, "back_pressure", {"A_e": 0.4})
    vac = with_effects(ra66m_spec, "back_pressure_vacuum", {"A_e_vac": 0.4})
    h = sea.role("altitude")
    T_sea = sea.expand(sea.role("thrust"))
    T_vac = vac.expand(vac.role("thrust"))
    P = 400000.0
    for alt in (0.0, 10000.0, 30000.0):
        pa = float(us76_pressure(sp.Float(alt)))
        got = float(T_sea.subs({h: alt, sea.symbol("A_e"): 0.4}))
        assert got == pytest.approx(P + 0.4 * (SEA_LEVEL_PRESSURE - pa), rel=1e-9)
        got = float(T_vac.subs({h: alt, vac.symbol("A_e_vac"): 0.4}))
        assert got == pytest.approx(P - 0.4 * pa, rel=1e-9)
    assert sea.parameter("A_e").lower == 0.0 and vac.parameter("A_e_vac").lower == 0.0
    # a model that already has a nozzle term: a correction of either sign, not A_e >= 0
    nozzle = with_effects(ra66m_spec, "back_pressure_vacuum", {"A_e_vac": 0.4})
    again = with_effects(nozzle, "back_pressure")
    assert "dA_e" in again.parameter_names and again.parameter("dA_e").lower == -math.inf


def test_sizes_are_relative_to_the_vehicle():
    from rocketid.diagnostics.effects import SEA_LEVEL_PRESSURE, Vehicle
    veh = Vehicle(thrust=610e3, mass=30e3, mass_flow=240.0, speed=1800.0, start_speed=5.0, duration=66.0,
                  altitude=(0.0, 30e3), mach=(0.0, 3.8), sigma={"x": 2.0, "h": 3.0, "v": 0.5}, sample_interval=0.02)
    assert CATALOGUE["back_pressure"].sizes(veh)["A_e"] == pytest.approx(0.1 * 610e3 / SEA_LEVEL_PRESSURE)
    assert CATALOGUE["bias_h"].sizes(veh)["b_h"] == pytest.approx(15.0)       # 5 sigma of a 3 m channel
    assert CATALOGUE["time_offset"].sizes(veh)["tau"] == pytest.approx(0.02)   # one sample
    assert CATALOGUE["back_pressure"].sizes()["A_e"] == pytest.approx(0.4)     # RA-66's without a vehicle
    assert CATALOGUE["earth_rotation"].least["k_rot"] == pytest.approx(0.2)


def test_piecewise_linear_interpolates_exactly_with_flat_ends():
    """The ramp form against numpy's interpolation (an independent implementation)."""
    from rocketid.diagnostics.effects import piecewise_linear
    x = sp.Symbol("x")
    knots, vals = [0.0, 1.5, 2.0, 4.0], [1.0, -2.0, 0.5, 3.0]
    f = sp.lambdify(x, piecewise_linear(x, knots, vals))
    pts = np.linspace(-1.0, 6.0, 57)
    np.testing.assert_allclose([float(f(p)) for p in pts], np.interp(pts, knots, vals), rtol=0, atol=1e-12)
    with pytest.raises(ModelError, match="strictly increasing"):
        piecewise_linear(x, [0.0, 0.0], [1.0, 2.0])


def _refined(spec, name):
    """Every refined shape of a catalogue family, for a vehicle flying 0-16 km at Mach 0-4.5 with the
    model's drag table knots."""
    from rocketid.diagnostics.effects import Vehicle
    from rocketid.diagnostics.screen import _mach_knots
    veh = Vehicle(thrust=9e5, mass=3e4, mass_flow=300.0, speed=1400.0, start_speed=0.0, duration=66.0,
                  altitude=(0.0, 16000.0), mach=(0.0, 4.5), sigma={"x": 1.0, "h": 1.0, "v": 1.0}, sample_interval=0.01,
                  knot_times=tuple(np.linspace(0, 66, 67)), mach_knots=_mach_knots(spec))
    return CATALOGUE[name].refinements(veh)


@pytest.mark.parametrize("family", ["wind", "density", "transonic_drag"])
def test_refined_profiles_give_back_the_base_model_at_zero(family, ra66m_spec):
    """The piecewise-linear wind (with a surface value), density and drag-in-Mach shapes: zero gives the
    base model exactly; realistic values change it; more knots come later in the list (BIC picks)."""
    shapes = _refined(ra66m_spec, family)
    assert len(shapes) >= 2
    counts = [len(e.realistic) for e in shapes if e.scan is None]     # the knot ladder (a located shape is beside it)
    assert counts == sorted(counts) and counts[0] < counts[-1]
    rng = np.random.default_rng(5)
    for e in shapes:
        spec = with_effects(ra66m_spec, [e])
        base = ra66m_spec
        point = _random_point(spec, rng)
        np.testing.assert_allclose(_values(spec, spec.equations[:len(base.states)], point),
                                   _values(base, base.equations, point), rtol=1e-12, atol=1e-9)
        moved = dict(point)
        for n, v in e.realistic.items():
            moved[spec.symbol(n)] = v
        for n in e.locations:                                  # a located shape placed where the point is
            moved[spec.symbol(n)] = float(_values(spec, [spec.role("mach")], point)[0])
        assert np.max(np.abs(_values(spec, spec.equations, moved) - _values(spec, spec.equations, point))) > 0, e.name


def test_the_site_shape_is_the_catalogues_rotation_at_its_site(ra66m_spec):
    """``earth_rotation_site`` is the catalogue's ``earth_rotation`` refined: zero gives the base model, the
    stated site with ``k_rot`` gives the catalogue's equations, and another site is the fixed-site effect
    declared there (``earth_rotation_effect(lat, az)``)."""
    from rocketid.diagnostics import earth_rotation_effect, earth_rotation_site_effect
    shapes = _refined(ra66m_spec, "earth_rotation")
    assert [e.name for e in shapes] == ["earth_rotation_site"]
    said = shapes[0].reading({"k_rot": (1.02, 0.06), "dlat_rot": (10.04, 5.0), "daz_rot": (30.46, 2.8)})
    assert "latitude 38.5 +- 5 deg N, azimuth 120.5 +- 2.8 deg" in said and "38.5 deg S toward 59.5 deg" in said
    site = with_effects(ra66m_spec, [earth_rotation_site_effect()])
    point = _random_point(site, np.random.default_rng(11))
    n = len(ra66m_spec.states)
    np.testing.assert_allclose(_values(site, site.equations[:n], point), _values(ra66m_spec, ra66m_spec.equations, point),
                               rtol=1e-12, atol=1e-9)
    for (lat, az), k in (((28.5, 90.0), 1.0), ((69.3, 45.0), 0.9), ((-12.0, 200.0), 1.1)):
        fixed = with_effects(ra66m_spec, [earth_rotation_effect(lat, az)])
        at = dict(point)
        at.update({site.symbol("k_rot"): k, site.symbol("dlat_rot"): lat - 28.5, site.symbol("daz_rot"): az - 90.0})
        np.testing.assert_allclose(_values(site, site.equations[:n], at), _values(fixed, fixed.equations[:n], at),
                                   rtol=1e-10, atol=1e-9)


def _coriolis_up(latitude_deg: float, azimuth_deg: float) -> float:
    """The upward part of ``-2 Omega x V`` (Omega = 1) for a unit horizontal velocity toward ``azimuth_deg`` at
    ``latitude_deg``, from the cross product in the site's east-north-up frame."""
    phi, a = np.radians(latitude_deg), np.radians(azimuth_deg)
    omega = np.array([0.0, np.cos(phi), np.sin(phi)])
    velocity = np.array([np.sin(a), np.cos(a), 0.0])
    return float(-2.0 * np.cross(omega, velocity)[2])


@pytest.mark.parametrize("true_site, k_expected", [((28.5, 250.0), None), ((28.5, 120.0), None), ((28.5, 90.0), 1.0)])
def test_the_rotation_reading_names_the_azimuth_flown(true_site, k_expected):
    """``earth_rotation``'s reading of ``k_rot`` at the catalogue's site (28.5 N, east): the rate factor whose
    Coriolis term is a flight toward another azimuth (from the cross product, not the effect's formula) is read as
    that azimuth or its mirror about east-west, reversed when westward, and 1 as the stated site."""
    from rocketid.diagnostics import CATALOGUE
    k = _coriolis_up(*true_site) / _coriolis_up(28.5, 90.0)
    assert k_expected is None or abs(k - k_expected) < 1e-12
    said = CATALOGUE["earth_rotation"].reading({"k_rot": (k, 0.01)})
    if k_expected == 1.0:
        assert said.startswith("Earth's rotation at the stated site (28.5 N, toward 90 deg)"), said
        return
    az = true_site[1]
    pair = sorted((az % 360.0, (180.0 - az) % 360.0))
    assert f"toward {pair[0]:.0f} or {pair[1]:.0f} deg at the stated latitude 28.5 N" in said, said
    assert said.startswith("the Coriolis term reversed") == (k < 0) and "state the launch site" in said, said


def test_a_tie_note_carries_the_rivals_readings():
    """A tie's note names each rival with its sizes and, for an effect with a reading, what they say: the
    rotation's reversed Coriolis term as an azimuth, beside a misalignment with none."""
    from types import SimpleNamespace
    from rocketid.diagnostics import CATALOGUE
    from rocketid.diagnostics.step import _with_sizes
    rot = SimpleNamespace(name="earth_rotation", parameter_names=("CD_0", "k_rot"), p=np.array([0.4, -0.9355]),
                          std=np.array([0.01, 0.0088]), effect_parameters=("k_rot",))
    text = _with_sizes(rot, CATALOGUE["earth_rotation"])
    assert text.startswith("earth_rotation (k_rot -0.935: the Coriolis term reversed: the term of a flight") and "249 or 291" in text, text
    mis = SimpleNamespace(name="misalignment", parameter_names=("delta_thrust",), p=np.array([0.006]),
                          std=np.array([1e-4]), effect_parameters=("delta_thrust",))
    assert _with_sizes(mis, CATALOGUE["misalignment"]) == "misalignment (delta_thrust 0.006)"


def test_a_wind_turns_the_thrust_of_a_vehicle_without_lift(ra66m_spec):
    """A vehicle declared without lift flies at its attack angle to the air: the wind turns its thrust by the
    airflow's angle to the path (``atan2(W sin theta, v - W cos theta)``) and leaves the lift coefficient at
    zero; a lifting vehicle holds its attitude (the thrust as declared, the lift at the air-relative angle)."""
    import tern
    from rocketid.diagnostics import wind_profile_effect
    finned = tern.build_model()
    for spec, turns in ((finned, True), (ra66m_spec, False)):
        windy = with_effects(spec, [wind_profile_effect((0.0, 5.0), name="w")], {"W_0": -8.0, "W_1": -20.0})
        th, v = windy.symbol("theta"), windy.symbol("v")
        point = {p.symbol: p.guess for p in windy.parameters}
        point.update({th: 1.2, v: 300.0, windy.symbol("w_speed"): 0.0, windy.symbol("W_0"): -8.0, windy.symbol("W_1"): -20.0})

        def at(s, expr):
            expr = s.expand(expr)
            return float(expr.xreplace({k: point.get(k, 0.0) for k in expr.free_symbols}))
        base, got = at(spec, spec.role("thrust_direction")), at(windy, windy.role("thrust_direction"))
        lift_moves = at(windy, windy.role("lift_coefficient")) != at(spec, spec.role("lift_coefficient"))
        assert lift_moves is not turns, spec.name
        expected = math.atan2(-8.0 * math.sin(1.2), 300.0 + 8.0 * math.cos(1.2)) if turns else 0.0
        assert got - base == pytest.approx(expected, abs=1e-12), spec.name


def test_wind_profile_has_a_surface_value_and_hat_knots(ra66m_spec):
    from rocketid.diagnostics.effects import wind_profile_effect
    e = wind_profile_effect([0.0, 4.0, 8.0])
    assert e.name == "wind_pl_3" and set(e.realistic) == {"W_0", "W_1", "W_2"}
    assert e.realistic["W_0"] == pytest.approx(10.0)
    spec = with_effects(ra66m_spec, [e], {"W_0": 5.0, "W_1": 20.0, "W_2": 40.0})
    h = spec.symbol("h")
    expr = [d for s, d in spec.definitions if str(s) == "wind_pl_3_airspeed"]
    assert expr, "the airspeed definition is named after the effect"
    # W(h) itself: the wind at the knots and between them, against numpy's interpolation
    from rocketid.diagnostics.effects import piecewise_linear
    W = sp.lambdify(h, piecewise_linear(h, [0.0, 4000.0, 8000.0], [5.0, 20.0, 40.0]))
    np.testing.assert_allclose([W(z) for z in (0.0, 2000.0, 6000.0, 12000.0)], [5.0, 12.5, 30.0, 40.0])
    no_surface = wind_profile_effect([0.0, 4.0, 8.0], surface=False)
    assert set(no_surface.realistic) == {"W_1", "W_2"}


def test_profile_knots_start_where_the_flight_starts():
    """A flight that starts aloft (an air launch at 11.8 km) gets wind and density knots from its start
    altitude up, the first wind value a wind like the others (not a surface wind), and no surface-layer knot;
    a flight from the pad keeps the ground knot and the knot at the top of the surface layer."""
    from rocketid.diagnostics.effects import SURFACE_LAYER_M, Vehicle

    def vehicle(z0, z1):
        lev = tuple(float(z) for z in np.linspace(z0, z1, 101))
        return Vehicle(thrust=5e5, mass=2e4, mass_flow=200.0, speed=2900.0, start_speed=236.0, duration=68.0,
                       altitude=(z0 - 300.0, z1), mach=(0.7, 9.0), sigma={"x": 2.0, "h": 2.0, "v": 0.2},
                       sample_interval=0.05, knot_times=tuple(np.linspace(0, 68, 69)), aero_altitudes=lev)
    aloft, pad = vehicle(11800.0, 30000.0), vehicle(0.0, 30000.0)
    profiles = [e for e in CATALOGUE["wind"].refinements(aloft) + CATALOGUE["density"].refinements(aloft)
                if e.name.startswith(("wind_pl_", "density_pl_"))]
    assert len(profiles) >= 4
    for e in profiles:
        knots = [float(k) for k in e.description.split(" at ")[1].split(" km")[0].split(", ")]
        assert knots[0] == pytest.approx(11.8) and all(k > 11.8 for k in knots[1:]), (e.name, knots)
    wind_aloft = CATALOGUE["wind"].refinements(aloft)[0]
    assert wind_aloft.realistic["W_0"] == pytest.approx(30.0) and "at the start altitude" in wind_aloft.description
    wind_pad = CATALOGUE["wind"].refinements(pad)[0]
    knots = [float(k) for k in wind_pad.description.split(" at ")[1].split(" km")[0].split(", ")]
    assert knots[:2] == [0.0, SURFACE_LAYER_M / 1000.0] and wind_pad.realistic["W_0"] == pytest.approx(10.0)


def test_drag_correction_is_pinned_at_the_tables_knots(ra66m_spec):
    """The CD(M) refinement adds shape between the model's own Mach knots: at those knots it is 0 whatever
    its values, so it cannot trade with the table's values."""
    from rocketid.diagnostics.screen import _mach_knots
    table = _mach_knots(ra66m_spec)
    assert len(table) >= 3
    shapes = _refined(ra66m_spec, "transonic_drag")
    first = shapes[0]
    spec = with_effects(ra66m_spec, [first], {n: 0.3 for n in first.realistic})
    # the drag coefficient's definition as a function of the Mach symbol (not expanded further)
    sym = spec.role("drag_coefficient")
    mach = spec.role("mach")
    cd = dict(spec.definitions)[sym]
    cd_base = dict(ra66m_spec.definitions)[ra66m_spec.role("drag_coefficient")]
    values = {p.symbol: 0.3 + 0.01 * j for j, p in enumerate(ra66m_spec.parameters)}
    values.update({spec.symbol(n): 0.3 for n in first.realistic})
    f = sp.lambdify(mach, cd.xreplace(values))
    g = sp.lambdify(mach, cd_base.xreplace(values))
    for k in table:
        assert float(f(k)) == pytest.approx(float(g(k)), abs=1e-12)
    # between two knots it differs by the correction's hat (0.3 at the midpoint of the first interval)
    mid = 0.5 * (table[0] + table[1])
    assert float(f(mid)) - float(g(mid)) == pytest.approx(0.3, abs=1e-12)


def _zero_is_the_base_model(base: ri.ModelSpec, effect, size: str) -> ri.ModelSpec:
    """``base`` with an event-time effect: with its size parameter at zero the equations are the base
    model's at a random point, whatever the event time. Returns the augmented spec."""
    spec = with_effects(base, [effect])
    point = _random_point(spec, np.random.default_rng(3))
    point[spec.symbol(size)] = 0.0
    np.testing.assert_allclose(_values(spec, spec.equations[:len(base.states)], point),
                               _values(base, base.equations, point), rtol=1e-12, atol=1e-9)
    return spec


def test_misalignment_onset_switches_on_at_its_estimated_time(ra66m_spec):
    """The onset shape: zero delta gives the base model whatever the onset; with delta the thrust direction
    moves by delta (1 + tanh((t - t0 - t_misalign) / width)) / 2, written out here by hand; every vehicle
    with a mesh gets it, and from rest it is also phased in by the lift-off fade."""
    from rocketid.diagnostics.effects import Vehicle, misalignment_onset_effect
    veh = Vehicle(thrust=9e5, mass=3e4, mass_flow=300.0, speed=1400.0, start_speed=5.0, duration=66.0,
                  altitude=(0.0, 16000.0), mach=(0.0, 4.5), sigma={"x": 1.0}, sample_interval=0.01,
                  knot_times=tuple(np.linspace(0.0, 66.0, 34)))
    (onset,) = CATALOGUE["misalignment"].refinements(veh)
    assert onset.name == "misalignment_onset" and set(onset.realistic) == {"delta_thrust", "t_misalign"}
    assert "2 s" in onset.description                       # the width: one element (66 / 33 s), at least 1 s
    rest = Vehicle(**{**veh.__dict__, "start_speed": 0.0})
    assert [e.name for e in CATALOGUE["misalignment"].refinements(rest)] == ["misalignment_fade", "misalignment_onset"]
    spec = _zero_is_the_base_model(ra66m_spec, misalignment_onset_effect(ra66m_spec.t0, ra66m_spec.tf, 2.0),
                                   "delta_thrust")
    at = dict(spec.definitions)[spec.role("thrust_direction")]
    at0 = dict(ra66m_spec.definitions)[ra66m_spec.role("thrust_direction")]
    for t, want in ((30.0, 0.5), (32.0, (1 + math.tanh(1.0)) / 2), (20.0, (1 + math.tanh(-5.0)) / 2)):
        d = (at - at0).xreplace({spec.symbol("delta_thrust"): 0.01, spec.symbol("t_misalign"): 30.0,
                                 spec.t: spec.t0 + t})
        assert float(d) == pytest.approx(0.01 * want, rel=1e-12)
    lo, hi = spec.parameter("t_misalign").lower, spec.parameter("t_misalign").upper
    assert (lo, hi) == (-6.0, pytest.approx(ra66m_spec.tf - ra66m_spec.t0))


def test_mass_jettison_releases_its_mass_at_the_estimated_time(ra66m_spec):
    """start_mass's event shape: zero dm gives the base model; the mass falls by dm around t0 + t_jettison,
    (1 + tanh((t - t0 - t_j) / w)) / 2 of it, written out by hand here; its size is 1 % of the start mass."""
    from rocketid.diagnostics.effects import Vehicle, mass_jettison_effect
    veh = Vehicle(thrust=9e5, mass=3e4, mass_flow=300.0, speed=1400.0, start_speed=5.0, duration=66.0,
                  altitude=(0.0, 16000.0), mach=(0.0, 4.5), sigma={"x": 1.0}, sample_interval=0.01,
                  knot_times=tuple(np.linspace(0.0, 66.0, 67)))
    (jet,) = CATALOGUE["start_mass"].refinements(veh)      # a moving start (5 m/s), not a rail exit
    assert jet.name == "mass_jettison" and jet.sizes(veh) == {"dm_jettison": 300.0, "t_jettison": 66.0}
    assert len(jet.starts) == 4 and "1 s" in jet.description
    spec = _zero_is_the_base_model(ra66m_spec, mass_jettison_effect(ra66m_spec.t0, ra66m_spec.tf, 1.0), "dm_jettison")
    mass = dict(spec.definitions)[spec.role("mass")]
    mass0 = dict(ra66m_spec.definitions)[ra66m_spec.role("mass")]
    for t, share in ((40.0, 0.5), (41.0, (1 + math.tanh(1.0)) / 2), (30.0, (1 + math.tanh(-10.0)) / 2)):
        d = (mass - mass0).xreplace({spec.symbol("dm_jettison"): 150.0, spec.symbol("t_jettison"): 40.0,
                                     spec.t: spec.t0 + t})
        assert float(d) == pytest.approx(-150.0 * share, rel=1e-12)


@pytest.mark.parametrize("shape", ["throttle_step", "throttle_window"])
def test_a_throttle_shape_scales_thrust_and_mass_flow_together(shape, ra66m_spec):
    """thrust_level's event shapes: zero size gives the base model; the thrust is scaled by 1 - d w(t), w the
    step (or the step minus a later one: a window), written out by hand here; the mass starts at the base
    model's and falls at the base mass flow times the same factor -- checked by differentiating the closed
    form numerically, not by its own integral."""
    from rocketid.diagnostics.effects import throttle_step_effect, throttle_window_effect
    make, size, times = {"throttle_step": (throttle_step_effect, "d_step", {"t_step": 20.0}),
                         "throttle_window": (throttle_window_effect, "d_window",
                                             {"t_win_on": 20.0, "t_win_off": 35.0})}[shape]
    effect = make(ra66m_spec.t0, ra66m_spec.tf, 1.5)
    assert effect.event_time == next(iter(times)) and effect.locations == {n: "s" for n in times}
    spec = _zero_is_the_base_model(ra66m_spec, effect, size)
    defs, defs0 = dict(spec.definitions), dict(ra66m_spec.definitions)
    values = {spec.symbol(size): 0.2, **{spec.symbol(n): v for n, v in times.items()}}

    def switch(t):
        on = [(1 + math.tanh((t - v) / 1.5)) / 2 for v in times.values()]
        return on[0] - (on[1] if len(on) > 1 else 0.0)

    def at(expr, t):
        return float(sp.N(expr.xreplace({**values, spec.t: spec.t0 + t}).subs(dict(spec.constants))))

    thrust, thrust0 = defs[spec.role("thrust")], defs0[ra66m_spec.role("thrust")]
    mass, mass0 = defs[spec.role("mass")], defs0[ra66m_spec.role("mass")]
    assert at(mass, 0.0) == pytest.approx(at(mass0, 0.0), rel=1e-12)
    for t in (10.0, 20.0, 21.0, 30.0, 35.0, 50.0):
        assert at(thrust, t) == pytest.approx(at(thrust0, t) * (1 - 0.2 * switch(t)), rel=1e-12)
        h = 1e-3
        rate = (at(mass, t + h) - at(mass, t - h)) / (2 * h)
        rate0 = (at(mass0, t + h) - at(mass0, t - h)) / (2 * h)
        assert rate == pytest.approx(rate0 * (1 - 0.2 * switch(t)), rel=1e-6)


def test_a_drag_bump_is_a_hump_placed_in_mach(ra66m_spec):
    """transonic_drag's located shape: zero height gives the base model; the drag coefficient gains
    dCD exp(-((M - M_bump) / (0.1 e^s))^2), written out by hand here; the height is a hump (>= 0), the scan
    covers the Mach range flown and the verdict's unit for M_bump is Mach, not seconds."""
    from rocketid.diagnostics.effects import drag_bump_effect
    bump = drag_bump_effect(0.3, 4.2)
    assert bump.locations == {"M_bump": "Mach"} and bump.event_time is None
    assert bump.scan.unit == "Mach" and bump.scan.times[0] > 0.3 and bump.scan.times[-1] < 4.2
    spec = _zero_is_the_base_model(ra66m_spec, bump, "dCD_bump")
    assert spec.parameter("dCD_bump").lower == 0.0
    assert (spec.parameter("M_bump").lower, spec.parameter("M_bump").upper) == (0.0, 4.2)
    cd, cd0 = dict(spec.definitions)[spec.role("drag_coefficient")], dict(ra66m_spec.definitions)[ra66m_spec.role("drag_coefficient")]
    mach = spec.role("mach")
    for M, want in ((1.2, 1.0), (1.3, math.exp(-(0.1 / (0.1 * math.exp(0.5))) ** 2)), (2.2, math.exp(-100 / math.e))):
        d = (cd - cd0).xreplace({spec.symbol("dCD_bump"): 0.08, spec.symbol("M_bump"): 1.2,
                                 spec.symbol("s_bump"): 0.5, mach: M})
        assert float(d) == pytest.approx(0.08 * want, rel=1e-12)


def test_misalignment_fade_time_is_estimated_only_from_rest(ra66m_spec):
    """From rest (RA-66M) the misalignment's refined shape estimates its fade time t_r e^s (zero gives
    the base model; s = 0 is the catalogue's 3 s fade); a vehicle released at speed has no such shape."""
    from rocketid.diagnostics.effects import LIFTOFF_FADE_TIME, Vehicle
    veh = Vehicle(thrust=9e5, mass=3e4, mass_flow=300.0, speed=1400.0, start_speed=0.0, duration=66.0,
                  altitude=(0.0, 16000.0), mach=(0.0, 4.5), sigma={"x": 1.0}, sample_interval=0.01)
    (fade,) = CATALOGUE["misalignment"].refinements(veh)
    assert set(fade.realistic) == {"delta_thrust", "s_fade"}
    moving = Vehicle(**{**veh.__dict__, "start_speed": 5.0})
    assert CATALOGUE["misalignment"].refinements(moving) == []
    spec = with_effects(ra66m_spec, [fade])
    rng = np.random.default_rng(7)
    point = _random_point(spec, rng)
    np.testing.assert_allclose(_values(spec, spec.equations[:len(ra66m_spec.states)], point),
                               _values(ra66m_spec, ra66m_spec.equations, point), rtol=1e-12, atol=1e-9)
    # at s = 0 the thrust direction is the catalogue's faded misalignment: half of delta at t0 + 3 s
    at = dict(spec.definitions)[spec.role("thrust_direction")]
    at0 = dict(ra66m_spec.definitions)[ra66m_spec.role("thrust_direction")]
    d = (at - at0).xreplace({spec.symbol("delta_thrust"): 0.01, spec.symbol("s_fade"): 0.0,
                             spec.t: spec.t0 + LIFTOFF_FADE_TIME})
    assert float(d) == pytest.approx(0.005, rel=1e-12)
    d2 = (at - at0).xreplace({spec.symbol("delta_thrust"): 0.01, spec.symbol("s_fade"): math.log(2.0),
                              spec.t: spec.t0 + 2 * LIFTOFF_FADE_TIME})
    assert float(d2) == pytest.approx(0.005, rel=1e-12)


@pytest.mark.parametrize("channel", ["x", "h", "v"])
def test_a_sensor_bias_refines_to_a_drifting_bias(channel, ra66m_spec):
    """z = y + b + db (t - t0): the output moves by b at t0 and by b + 10 db ten seconds later."""
    from rocketid.diagnostics.effects import Vehicle
    veh = Vehicle(thrust=9e5, mass=3e4, mass_flow=300.0, speed=1400.0, start_speed=0.0, duration=66.0,
                  altitude=(0.0, 16000.0), mach=(0.0, 4.5), sigma={channel: 1.0}, sample_interval=0.01)
    (drift,) = CATALOGUE[f"bias_{channel}"].refinements(veh)
    assert drift.name == f"bias_{channel}_drift" and set(drift.realistic) == {f"b_{channel}", f"db_{channel}"}
    spec = with_effects(ra66m_spec, [drift], {f"b_{channel}": 2.0, f"db_{channel}": 0.3})
    out = next(o for o in spec.outputs if o.name == channel).expr
    base = next(o for o in ra66m_spec.outputs if o.name == channel).expr
    for t, want in ((spec.t0, 2.0), (spec.t0 + 10.0, 5.0)):
        diff = (out - base).xreplace({spec.symbol(f"b_{channel}"): 2.0, spec.symbol(f"db_{channel}"): 0.3, spec.t: t})
        assert float(diff) == pytest.approx(want, abs=1e-12)


def test_a_heavier_vehicle_is_found_as_a_start_mass_error(ra66m_spec):
    """The data fly RA-66M's vehicle declared 150 kg heavier (its own Vehicle value: the mass constant, not the
    effect's expression); the model as stated plus ``start_mass`` recovers the extra mass, and the size is
    judged against the vehicle's mass (1 % of it)."""
    from dataclasses import replace as dc_replace

    from rocketid.cases.ra66 import ra66_vehicle_model
    from rocketid.cases.ra66m import RA66M_MACH_KNOTS, ra66m_alpha, ra66m_truth
    from rocketid.cases.vehicle import RA66_VEHICLE
    from rocketid.diagnostics.effects import Vehicle

    def aero(m, fc, alpha):
        cd = m.table("CD_M", fc.mach, RA66M_MACH_KNOTS, 0.4, bounds=(0.01, 2.0), nominal=0.4)
        return cd, m.parameter("CL_alpha", 2.0, bounds=(0.0, 10.0), nominal=2.5) * alpha

    heavy = ra66_vehicle_model("heavy", "RA-66M 150 kg heavier", ra66m_alpha, aero,
                               vehicle=dc_replace(RA66_VEHICLE, mass0=RA66_VEHICLE.mass0 + 150.0)).freeze()
    data = ri.simulate_measurements(heavy, ra66m_truth(heavy), ri.ra66_times(), seed=11)
    spec = with_effects(ra66m_spec, ["start_mass"])
    fit = ri.estimate(spec, data, guess={n: v for n, v in zip(ra66m_spec.parameter_names, ra66m_truth(ra66m_spec))})
    assert fit.success
    from rocketid.estimability import uncertainty
    sd = uncertainty(fit).standard_errors[spec.parameter_names.index("dm_start")]
    assert abs(fit.value("dm_start") - 150.0) < 4 * sd, (fit.value("dm_start"), sd)
    assert abs(fit.chi2_per_dof - 1) < 0.05
    veh = Vehicle(thrust=4e5, mass=20e3, mass_flow=100.0, speed=900.0, start_speed=0.0, duration=66.0,
                  altitude=(0.0, 3e4), mach=(0.0, 2.7), sigma={"x": 1.0}, sample_interval=0.01)
    assert CATALOGUE["start_mass"].sizes(veh)["dm_start"] == pytest.approx(200.0)


def test_temperature_offset_follows_the_hydrostatic_equation():
    """A day 10 K colder than the standard at the standard's sea-level pressure: the effect's density and
    speed of sound against the hydrostatic equation integrated here (the standard's layer temperatures
    written from its table, geopotential altitude, scipy's ODE solver), at 5-40 km."""

    from scipy.integrate import solve_ivp
    import stage30

    from rocketid.diagnostics import temperature_effect
    base = stage30.build_model().freeze()
    spec = with_effects(base, [temperature_effect()])
    h, cold = spec.symbol("h"), {spec.symbol("dT_air"): -10.0}
    rho0, rho1 = (sp.lambdify(h, s.expand(s.symbol("rho")).subs(cold)) for s in (base, spec))
    a0, a1 = (sp.lambdify(h, s.expand(s.symbol("a_sound")).subs(cold)) for s in (base, spec))
    table = [(0.0, 288.15, -6.5e-3), (11e3, 216.65, 0.0), (20e3, 216.65, 1e-3), (32e3, 228.65, 2.8e-3),
             (47e3, 270.65, 0.0)]

    def t_std(H):
        hb, tb, lb = [row for row in table if row[0] <= H][-1]
        return tb + lb * (H - hb)

    gm_r = 9.80665 * 0.0289644 / 8.31432
    # d ln p / dH for the standard and for the cold day; their difference integrated from sea level
    sol = solve_ivp(lambda H, y: [-gm_r / (t_std(H) - 10.0) + gm_r / t_std(H)], (0.0, 40e3), [0.0],
                    dense_output=True, rtol=1e-11, atol=1e-13, max_step=200.0)
    r0 = 6356766.0
    for z in (5e3, 12e3, 25e3, 40e3):
        H = r0 * z / (r0 + z)
        expected = math.exp(sol.sol(H)[0]) * t_std(H) / (t_std(H) - 10.0)
        assert rho1(z) / rho0(z) == pytest.approx(expected, rel=2e-4), z
        assert a1(z) / a0(z) == pytest.approx(math.sqrt((t_std(H) - 10.0) / t_std(H)), rel=1e-9), z
    assert rho1(25e3) / rho0(25e3) < 0.95 < 1.0 < rho1(1e3) / rho0(1e3)     # denser low, thinner aloft


def test_burn_rate_scales_thrust_and_mass_flow_together(monkeypatch):
    """A constant thrust and a mass falling linearly (Stage-30): ``eps_burn`` 0.03 flies as the vehicle
    declared with its thrust and its mass flow both 3 % higher (the specific impulse kept)."""
    import stage30

    from rocketid.diagnostics import burn_rate_effect
    base = stage30.build_model().freeze()
    t = stage30.sample_times()
    p = dict(zip(base.parameter_names, stage30.truth(base)))
    faster = ri.simulate(with_effects(base, [burn_rate_effect()]), {**p, "eps_burn": 0.03}, t).outputs()
    monkeypatch.setattr(stage30, "THRUST_SL", stage30.THRUST_SL * 1.03)
    monkeypatch.setattr(stage30, "MDOT", stage30.MDOT * 1.03)
    by_hand = stage30.build_model().freeze()
    expected = ri.simulate(by_hand, dict(zip(by_hand.parameter_names, stage30.truth(by_hand))), t).outputs()
    for name in ("x", "h", "v"):
        assert np.max(np.abs(faster[name] - expected[name])) < 1e-3, name
    assert np.max(np.abs(faster["x"] - ri.simulate(base, p, t).outputs()["x"])) > 100.0


def test_burn_rate_keeps_the_motors_ignition_in_a_window():
    """A thrust table and a mass state (Kestrel-S), cut to a window from 20 s: the motor's clock still
    starts at the table's first time (ignition), ``P(t) = k P_tab(k t)``, and the mass state's
    equation burns ``k`` times faster on that clock."""
    import kestrel

    from rocketid.diagnostics import burn_rate_effect
    spec = with_effects(kestrel.build_model().windowed(20.0, 35.0), [burn_rate_effect()])
    k = 1.04
    values = {spec.symbol("eps_burn"): k - 1}
    thrust = sp.lambdify(spec.t, spec.expand(spec.symbol("thrust")).subs(values))
    for tt in (20.0, 27.3, 33.0):
        assert thrust(tt) == pytest.approx(k * np.interp(k * tt, kestrel.THRUST_TIMES, kestrel.THRUST_VALUES),
                                           rel=1e-12)
    (i,) = [j for j, s in enumerate(spec.states) if str(s.symbol) == "mass_kg"]
    rate = sp.lambdify(spec.t, spec.expand(spec.states[i].derivative - spec.equations[i]).subs(values))
    assert rate(27.3) == pytest.approx(-thrust(27.3) / (kestrel.ISP * kestrel.G0), rel=1e-12)


def test_burn_rate_needs_an_explicit_mass_equation():
    m = ri.Model("implicit-mass", 0.0, 10.0)
    x = m.state("x", 0.0)
    mass = m.state("mass", 100.0)
    m.ode({x: 1.0})
    m.implicit({mass: 2 * m.der(mass) + 1.0})
    m.define("thrust", sp.Float(10.0))
    m.define("m", mass)
    m.declare_role("thrust", m.thrust)
    m.declare_role("mass", m.m)
    m.output("x", x, sigma=1.0)
    from rocketid.diagnostics import burn_rate_effect
    with pytest.raises(ModelError, match="must be explicit"):
        with_effects(m.freeze(), [burn_rate_effect()])


def test_back_pressure_stops_with_the_motor():
    """A motor that burns out inside the horizon (Tern-2: a 10 s burn, then a coast): the back-pressure
    correction acts while the nozzle flows full, shrinks with the thrust below 40 % of its peak (the
    tail-off) and is zero in the coast -- not ``A_e p0`` of thrust from nothing. A motor that runs
    through the horizon (Osprey-A: its thrust stays above 42 % of its peak) keeps the plain correction."""
    import osprey
    import tern

    from rocketid.physics.atmosphere import us76_pressure
    spec = with_effects(tern.build_model(), ["back_pressure"])
    area, h = 0.07, 5000.0
    table = sp.lambdify((spec.symbol("thrust_table"), spec.symbol("h")),
                        spec.expand(spec.symbol("thrust")).subs({spec.symbol("A_e"): area}))

    def thrust(t, h):
        return table(float(np.interp(t, tern.THRUST_TIMES, tern.THRUST_VALUES)), h)
    p_a = float(us76_pressure(sp.Float(h)))
    peak = max(tern.THRUST_VALUES)
    for t in (2.0, 5.0, 9.6, 10.1, 30.0):
        stated = float(np.interp(t, tern.THRUST_TIMES, tern.THRUST_VALUES))
        share = min(1.0, stated / (0.4 * peak))
        assert thrust(t, h) == pytest.approx(stated + area * (101325.0 - p_a) * share, rel=1e-9, abs=1e-6), t
    assert thrust(30.0, h) == 0.0
    assert 0 < float(np.interp(10.1, tern.THRUST_TIMES, tern.THRUST_VALUES)) < 0.4 * peak    # in the tail-off
    plain = with_effects(osprey.build_model(), ["back_pressure"])
    assert "Max" not in str(plain.definitions[[str(d) for d, _ in plain.definitions].index("thrust")][1])


def test_base_drag_acts_once_the_motor_stops(ra66_spec):
    """Power-off base drag on Tern-2 (burn-out at 10.25 s, then a coast): zero gives back the base model; the
    increment is absent while the nozzle flows full, grows through the tail-off and is whole in the coast. A
    motor that burns through the horizon (RA-66) has no power-off phase: the effect says so."""
    import tern

    base = tern.build_model()
    spec = with_effects(base, ["base_drag"])
    expr = dict(spec.definitions)[spec.symbol("cd")].xreplace(
        {spec.symbol(n): sp.Float(v) for n, v in tern.truth(base).items()})
    cd = sp.lambdify((spec.symbol("thrust_table"), spec.symbol("mach"), spec.symbol("dCD_base")), expr)
    peak = max(tern.THRUST_VALUES)
    running, tail, off = cd(peak * 0.9, 2.0, 0.1), cd(peak * 0.2, 2.0, 0.1), cd(0.0, 2.0, 0.1)
    assert cd(0.0, 2.0, 0.0) == pytest.approx(running) == pytest.approx(cd(peak * 0.9, 2.0, 0.0))
    assert off - cd(0.0, 2.0, 0.0) == pytest.approx(0.1) and tail - running == pytest.approx(0.05)
    with pytest.raises(ModelError, match="stops inside the horizon"):
        with_effects(ra66_spec, ["base_drag"])


def test_a_throttle_on_a_mass_that_is_a_state():
    """A mass flow that is not constant (Tern-2's mass is a state burnt at its thrust table's rate): the
    user's throttle (``throttle_effect``, knots given) scales the mass state's equation. Simulated against the
    same vehicle with the throttle written into its own equations by hand -- thrust and the mass equation's
    right-hand side both times ``1 - d(t)``, the piecewise-linear ``d`` written out here -- the outputs agree
    to the integrator's tolerance. The catalogue's throttle window does the same with its own shape."""
    import tern
    from rocketid.diagnostics import throttle_effect
    from rocketid.diagnostics.effects import throttle_window_effect
    base = tern.build_model()
    spec = with_effects(base, [throttle_effect((2.0, 4.0, 7.0, 9.0))])
    assert len(spec.states) == len(base.states)
    levels = {"d_throttle_1": 0.1, "d_throttle_2": 0.15}
    hand = base.to_model()
    t = hand.t
    d = sp.Piecewise((0.0, t < 2.0), (0.1 * (t - 2.0) / 2.0, t < 4.0), (0.1 + 0.05 * (t - 4.0) / 3.0, t < 7.0),
                     (0.15 * (9.0 - t) / 2.0, t < 9.0), (0.0, True))
    thrust_sym = base.role("thrust")
    hand.redefine(thrust_sym, hand.definition(thrust_sym) * (1 - d))
    hand.ode({hand.mass_kg: -hand.thrust_table * (1 - d) / (tern.ISP * tern.G0)})
    hand = hand.freeze()
    times = tern.sample_times()
    got = ri.simulate(spec, {**tern.truth(base), **levels}, times).outputs()
    want = ri.simulate(hand, tern.truth(base), times).outputs()
    plain = ri.simulate(base, tern.truth(base), times).outputs()
    assert np.max(np.abs(want["h"] - plain["h"])) > 100.0          # the throttle matters
    for name in ("x", "h", "v"):
        np.testing.assert_allclose(got[name], want[name], rtol=0, atol=1e-3 * (1 if name == "v" else 10))
    # the catalogue's window: thrust and the mass equation times 1 - d (s_on - s_off), s = (1 + tanh(u / w)) / 2
    w, on, off, depth = 0.5, 3.0, 6.5, 0.12
    window = with_effects(base, [throttle_window_effect(base.t0, base.tf, w)])
    assert len(window.states) == len(base.states)                 # no new state: the mass state's own equation
    hand = base.to_model()
    t = hand.t

    def switch(at):
        return (1 + sp.tanh((t - base.t0 - at) / w)) / 2

    d = depth * (switch(on) - switch(off))
    hand.redefine(thrust_sym, hand.definition(thrust_sym) * (1 - d))
    hand.ode({hand.mass_kg: -hand.thrust_table * (1 - d) / (tern.ISP * tern.G0)})
    got = ri.simulate(window, {**tern.truth(base), "d_window": depth, "t_win_on": on, "t_win_off": off},
                      times).outputs()
    want = ri.simulate(hand.freeze(), tern.truth(base), times).outputs()
    assert np.max(np.abs(want["h"] - plain["h"])) > 100.0
    for name in ("x", "h", "v"):
        np.testing.assert_allclose(got[name], want[name], rtol=0, atol=1e-3 * (1 if name == "v" else 10))


def test_a_throttle_shape_on_a_commanded_schedule_carries_the_unburnt_propellant():
    """A mass written in time whose flow is not constant (a liquid stage's commanded throttle schedule): the
    throttle window adds the propellant not burnt as a state, ``dq/dt = mdot(t) d s(t)``; against the same
    vehicle with the mass as a state whose flow is scaled by hand, the outputs agree. An onset scan's copies
    keep the closed form (no state each)."""
    from rocketid.diagnostics.effects import throttle_window_effect
    from rocketid.physics.ascent import ascent_dynamics, ascent_states, flight_conditions

    def vehicle(mass_as_state: bool, factor=None):
        m = ri.Model("schedule", 0.0, 60.0)
        st = ascent_states(m, initial=(0.0, 0.0, 0.0, 1.5707963267948966))
        fc = flight_conditions(m, st, atmosphere="us76")
        t = m.t
        setting = 1 - 0.3 * (sp.tanh((t - 25.0) / 2.0) - sp.tanh((t - 40.0) / 2.0)) / 2       # a bucket
        flow = 300.0 * setting
        if mass_as_state:
            mass = m.state("mass_kg", 30000.0)
            m.ode({mass: -flow * (factor if factor is not None else 1)})
        else:                                       # the schedule's closed form: 30 t - int flow dt
            def bucket_integral(u):                # int (tanh((u - 25)/2) - tanh((u - 40)/2)) / 2 du
                return sp.log(sp.cosh((u - 25.0) / 2.0)) - sp.log(sp.cosh((u - 40.0) / 2.0))
            mass = m.define("mass_kg", 30000.0 - 300.0 * (t - 0.3 * (bucket_integral(t) - bucket_integral(sp.S.Zero))))
        thrust = 8.0e5 * setting * (factor if factor is not None else 1)
        ascent_dynamics(m, st, fc, thrust=thrust, mass=mass, area=m.constant("S", 3.0),
                        cd=m.parameter("CD", 0.4), cl=0.0 * m.input("alpha", times=(0.0, 60.0), values=(0.0, 0.0)),
                        alpha=m.alpha)
        for s in (st.x, st.h, st.v):
            m.output(str(s), s, sigma=1.0)
        return m.freeze()

    closed = vehicle(False)
    effect = throttle_window_effect(closed.t0, closed.tf, 1.0)
    spec = with_effects(closed, [effect])
    assert any(str(s.symbol).endswith("_unburnt") for s in spec.states)
    bank = with_effects(closed, [effect.scan.bank])
    assert not any(str(s.symbol).endswith("_unburnt") for s in bank.states)
    d, on, off, w = 0.1, 10.0, 30.0, 1.0
    t = sp.Symbol("t")
    switch = (sp.tanh((t - on) / w) - sp.tanh((t - off) / w)) / 2
    hand = vehicle(True, factor=1 - d * switch)
    times = np.linspace(1.0, 60.0, 60)
    got = ri.simulate(spec, {"CD": 0.4, "d_window": d, "t_win_on": on, "t_win_off": off}, times).outputs()
    want = ri.simulate(hand, {"CD": 0.4}, times).outputs()
    plain = ri.simulate(closed, {"CD": 0.4}, times).outputs()
    assert np.max(np.abs(want["h"] - plain["h"])) > 100.0
    for name in ("x", "h", "v"):
        np.testing.assert_allclose(got[name], want[name], rtol=1e-6, atol=1e-3)


@pytest.mark.parametrize("name", sorted(NEEDS_MOVING_START))
def test_a_start_correction_acts_on_a_moving_start_only(name, ra66m_spec):
    """``start_angle`` / ``start_speed`` correct a declared moving start (Wren-H leaves its rail at 25 m/s): at
    zero they give back the base model (same equations, same start), and their parameter moves only the start
    of its state; from rest (RA-66M) they do not apply, and say why."""
    import math
    import wren
    base = wren.build_model()
    spec = with_effects(base, [name])
    (par,) = [n for n in spec.parameter_names if n not in base.parameter_names]
    assert spec.parameter(par).guess == 0.0 and set(CATALOGUE[name].realistic) == {par}
    assert [spec.expand(e) for e in spec.equations] == [base.expand(e) for e in base.equations]
    truth = dict(wren.truth(base))
    p0 = spec.parameter_vector(truth)
    assert np.array_equal(spec.initial_state(p0), base.initial_state(base.parameter_vector(truth)))
    moved = spec.initial_state(spec.parameter_vector({**truth, par: 0.01}))
    role = {"start_angle": "flight_path_angle", "start_speed": "speed"}[name]
    j = spec.state_symbols.index(spec.role(role))
    assert math.isclose(moved[j] - spec.states[j].initial, 0.01)
    assert np.count_nonzero(moved - spec.initial_state(p0)) == 1
    with pytest.raises(ri.ModelError, match="starts at rest"):
        with_effects(ra66m_spec, [name])


def test_second_order_time_offset_against_an_exact_delay():
    """A body pushed by a sampled force (a static firing's table with a 1.5 s tail-off) on a flight path that
    turns (v dtheta/dt = -g cos theta, the implicit form): the data tagged 0.2 s late. ``time_offset_2``'s
    outputs at t are the model's outputs at t - 0.2 (the same simulation, sampled 0.2 s earlier) to third
    order: across the tail-off at least four times closer than the first-order shape."""
    from rocketid.diagnostics.effects import time_offset_second_effect
    m = ri.Model("pushed", 0.0, 12.0)
    x = m.state("x", 0.0)
    h = m.state("h", 0.0)
    v = m.state("v", 30.0)
    th = m.state("theta", 1.3)
    # a static firing's table every 0.05 s: 600 N falling to 520 N, then a 1.5 s cosine tail-off
    tt = np.round(np.arange(0.0, 12.0 + 1e-9, 0.05), 10)
    ff = np.where(tt < 6.0, 600.0 - 80.0 * tt / 6.0, np.where(tt < 7.5, 260.0 * (1 + np.cos(np.pi * (tt - 6.0) / 1.5)),
                                                                 0.0))
    force = m.input("force", times=tuple(tt), values=tuple(ff))
    g = m.constant("g", 9.81)
    m.ode({x: v * sp.cos(th), h: v * sp.sin(th), v: force / 10.0 - g * sp.sin(th) - 1e-3 * v ** 2})
    m.implicit({th: v * m.der(th) + g * sp.cos(th)})
    for name, s in (("x", x), ("h", h), ("v", v)):
        m.output(name, s, 1.0)
    base = m.freeze()
    tau = 0.2
    t = np.linspace(5.0, 7.5, 26)
    exact = ri.simulate(base, [], t - tau, rtol=1e-11, atol=1e-11).outputs()
    second = ri.simulate(with_effects(base, [time_offset_second_effect()]), {"tau": tau}, t, rtol=1e-11,
                         atol=1e-11).outputs()
    first = ri.simulate(with_effects(base, ["time_offset"]), {"tau": tau}, t, rtol=1e-11, atol=1e-11).outputs()
    for name, tol in (("x", 0.04), ("h", 0.08), ("v", 0.25)):
        err2, err1 = (float(np.max(np.abs(y[name] - exact[name]))) for y in (second, first))
        # measured 0.029 m, 0.057 m, 0.20 m/s (the third-order term across the tail-off) against 0.26 m, 0.69 m,
        # 0.95 m/s to first order
        assert err2 < tol and err2 < err1 / 4, (name, err2, err1)
    # a model whose equations hold a time family (RA-66's drag in time) cannot write it into its outputs, and
    # the diagnosis does not offer it there
    with pytest.raises(ri.ModelError, match="time family"):
        with_effects(ri.ra66(), [time_offset_second_effect()])
    from rocketid.diagnostics import CATALOGUE
    from rocketid.diagnostics.screen import vehicle_of
    ra66_fit = ri.estimate(ri.ra66(), ri.simulate_measurements(ri.ra66(), ri.ra66_truth(ri.ra66()), ri.ra66_times(),
                                                                seed=0))
    assert vehicle_of(ra66_fit).time_families and CATALOGUE["time_offset"].refinements(vehicle_of(ra66_fit)) == []
    assert [e.name for e in CATALOGUE["time_offset"].refinements(None)] == ["time_offset_2"]


def test_a_thrust_level_reads_as_a_mass_error_exactly(ra66m_spec):
    """The diagnosis's reading of a thrust level as a mass error (``api._mass_reading``): RA-66M flown with a
    thrust 3 % low is, to every output, RA-66M with its mass (start and consumption) 1/0.97 times as large and
    every aerodynamic coefficient (its CD(Mach) knots and CL_alpha, all estimated) scaled alike -- written here as
    a user would, by scaling the model's mass definition -- and the words give that scale and the start mass."""
    from rocketid.cases import ra66m_truth
    from rocketid.diagnostics.api import _mass_reading
    from rocketid.diagnostics.effects import Vehicle

    def mass_scale(m):
        s = m.parameter("s_mass", 0.0)
        m.redefine("mass", m.definition("mass") * (1 + s))
        return s

    eps = -0.03
    k = 1.0 / (1.0 + eps)
    truth = dict(zip(ra66m_spec.parameter_names, (float(v) for v in ra66m_truth(ra66m_spec))))
    t = np.linspace(1.0, ra66m_spec.tf, 40)
    thrust = ri.simulate(with_effects(ra66m_spec, ["thrust_level"]), {**truth, "eps_thrust": eps}, t).outputs()
    heavier = {n: (v * k if n.startswith(("CD_M_", "CL_alpha")) else v) for n, v in truth.items()}
    scaled = ri.simulate(with_effects(ra66m_spec, [custom_effect("mass_scale", mass_scale)]),
                         {**heavier, "s_mass": k - 1.0}, t).outputs()
    for name in ("x", "h", "v"):
        np.testing.assert_allclose(scaled[name], thrust[name], rtol=1e-7, atol=1e-6)
    veh = Vehicle(thrust=1.0, mass=60.0, mass_flow=1.0, speed=1.0, start_speed=0.0, duration=1.0,
                  altitude=(0.0, 1.0), mach=None, sigma={}, sample_interval=0.1)
    text = _mass_reading({"eps_thrust": (eps, 1e-4)}, veh)
    assert "the thrust -3 % is the mass +3.1 % throughout (+1.86 kg at the start" in text, text
    assert _mass_reading({"eps_thrust": (eps, 1e-4)}, None) == "" and _mass_reading({}, veh) == ""


def test_a_thrust_error_in_time_has_its_knots_over_the_burn():
    """A vehicle that coasts after its burn (Tern-2: thrust until 10.2 s of a 60 s flight) gets its thrust
    profiles, throttle step and window over the burn -- knots up to the first mesh boundary past the thrust's
    end -- not over the coast, where a thrust error does nothing; a vehicle that burns to the end of its
    horizon keeps knots over the whole of it."""
    from rocketid.diagnostics.effects import Vehicle, _refine_thrust
    bounds = tuple(0.5 + 1.25 * j for j in range(48)) + (60.0,)
    coast = Vehicle(thrust=3e4, mass=800.0, mass_flow=20.0, speed=1200.0, start_speed=30.0, duration=59.5,
                    altitude=(0.0, 3e4), mach=(0.1, 4.0), sigma={"x": 1.0}, sample_interval=0.05, knot_times=bounds,
                    powered=(0.5, 10.2))
    shapes = {e.name: e for e in _refine_thrust(coast)}
    profile = shapes["thrust_profile_9"]
    knots = [float(k) for k in profile.description.split(" on ")[1].split(" s")[0].split(", ")]
    assert knots[0] == 0.5 and knots[-1] == 10.5 and len(knots) == 9        # 10.5: the boundary past 10.2 s
    assert "10.5" in shapes["throttle_step"].description or shapes["throttle_step"].scan is not None
    burning = Vehicle(**{**coast.__dict__, "powered": (0.5, 60.0)})
    whole = {e.name: e for e in _refine_thrust(burning)}["thrust_profile_9"]
    every = [float(k) for k in whole.description.split(" on ")[1].split(" s")[0].split(", ")]
    assert every[0] == 0.5 and every[-1] == 60.0 and len(every) == 9


def test_a_thrust_error_over_a_burn_inside_the_horizon_cannot_reverse_the_thrust():
    """Knots that end before the horizon: eps flat after the last one and held at eps >= -1 (a burn-through
    refitted with knots over the whole flight took -1.6 to -2.0 after burn-out); knots over the whole horizon:
    the time family, as before."""
    from rocketid.diagnostics import thrust_profile_effect, with_effects
    inside = with_effects(ra66m(), [thrust_profile_effect([0.0, 20.0, 40.0])])
    bounds = {str(p.symbol): (p.lower, p.upper) for p in inside.parameters if str(p.symbol).startswith("eps_P")}
    assert bounds == {"eps_P0": (-1.0, math.inf), "eps_P1": (-1.0, math.inf), "eps_P2": (-1.0, math.inf)}
    assert not any(str(f.symbol).startswith("eps_P") for f in inside.families)
    whole = with_effects(ra66m(), [thrust_profile_effect([0.0, 33.0, 66.0])])
    assert any(str(f.symbol).startswith("eps_P") for f in whole.families)
    assert {str(p.symbol): (p.lower, p.upper) for p in whole.parameters}["eps_P1"] == (-math.inf, math.inf)


def test_the_back_pressure_fade_is_estimated_where_the_data_see_the_tail_off():
    """The refined back-pressure shape estimates where the correction fades out in the tail-off. Truth
    written here by hand on Tern-2 (a 10 s solid burn, its tail-off from 98 kN at 7.75 s to 0 at 10.25 s), the
    way an engine team might state it: the pressure term scaled with the chamber from the start of the
    shutdown, ``P + A_e (p0 - p_a(h)) min(1, P / 98 kN)``, ``A_e`` 0.05 m^2. The catalogue's shape (fading below
    40 % of the peak) leaves a misfit; the refined one reaches the noise with ``s`` near 98 / 114 and the area
    near the truth. It is offered only for a motor that stops inside the horizon (not Osprey-A's, which burns
    through its data), and zero parameters give back the base model."""
    import osprey
    import tern

    from rocketid.diagnostics.effects import CATALOGUE, FADE_SHARES, NOZZLE_FULL_SHARE
    from rocketid.diagnostics.screen import vehicle_of
    from rocketid.physics.atmosphere import us76_pressure

    base = tern.build_model()
    hand = base.to_model()
    stated, h = hand.thrust_table, hand.h
    cut = 98e3                                          # the table's value where the shutdown starts (7.75 s)
    hand.redefine(hand.thrust, stated + 0.05 * (101325.0 - us76_pressure(h)) * sp.Min(1, stated / cut))
    hand = hand.freeze()
    t = tern.sample_times()
    exact = ri.simulate(hand, tern.truth(hand), t).outputs()
    rng = np.random.default_rng(41)
    data = ri.Measurements(tuple(ri.Channel(n, t, exact[n] + tern.SIGMA[n] * rng.standard_normal(t.size),
                                            tern.SIGMA[n]) for n in ("x", "h", "v")))
    plain = ri.estimate(with_effects(base, ["back_pressure"]), data)
    veh = vehicle_of(plain)
    shapes = {e.name: e for e in CATALOGUE["back_pressure"].refinements(veh)}
    assert set(shapes) == {"back_pressure_vacuum", "back_pressure_fade"}
    fade = shapes["back_pressure_fade"]
    fit = ri.estimate(with_effects(base, [fade]), data)
    est = dict(zip(fit.spec.parameter_names, fit.p))
    assert fit.success and plain.success
    lr = 2 * (plain.objective - fit.objective)          # one parameter more: the LR statistic, chi2 on 1 dof
    assert lr > 100 and fit.chi2_per_dof < 1.05, (lr, plain.chi2_per_dof, fit.chi2_per_dof)
    assert NOZZLE_FULL_SHARE + est["d_fade"] == pytest.approx(cut / max(tern.THRUST_VALUES), abs=0.05)
    assert est["A_e"] == pytest.approx(0.05, rel=0.05)
    assert fade.sizes(veh)["d_fade"] == FADE_SHARES[1] - FADE_SHARES[0]     # a shape: its range, never oversized
    zero = ri.simulate(with_effects(base, [fade]), {**tern.truth(base), "A_e": 0.0, "d_fade": 0.3}, t).outputs()
    ref = ri.simulate(base, tern.truth(base), t).outputs()
    assert np.max(np.abs(zero["x"] - ref["x"])) < 1e-3          # the integrator's tolerance, far below sigma
    o_spec, o_t = osprey.build_model(), osprey.sample_times()
    o_exact = ri.simulate(o_spec, osprey.truth(o_spec), o_t).outputs()
    o_data = ri.Measurements(tuple(ri.Channel(n, o_t, o_exact[n], osprey.SIGMA[n]) for n in ("x", "h", "v")))
    burns_through = vehicle_of(ri.estimate(o_spec, o_data))
    assert [e.name for e in CATALOGUE["back_pressure"].refinements(burns_through)] == ["back_pressure_vacuum"]


def test_a_thrust_input_beside_another_thrust_is_a_motor():
    """``thrust_motors``: each known input the thrust reads beside another time-varying thrust -- two tables
    of a cluster, a sustainer written in time beside a booster's table -- and none for a thrust that is one
    table times constants and the altitude (one motor with its nozzle term), or a thrust constant in time."""
    from rocketid.diagnostics.effects import thrust_motors

    def model(thrust_of):
        m = ri.Model("motors", 0.0, 20.0)
        h = m.state("h", 0.0)
        a = m.input("a", times=[0.0, 10.0, 20.0], values=[1e4, 2e4, 0.0])
        b = m.input("b", times=[0.0, 5.0, 20.0], values=[5e3, 5e3, 0.0])
        sustainer = m.input("sustainer", sp.Piecewise((3e3, m.t <= 12.0), (0.0, True)), breakpoints=[12.0])
        thrust = m.define("thrust", thrust_of(m, a, b, sustainer, h))
        m.declare_role("thrust", thrust)
        m.ode({h: thrust / 1e3})
        return m

    assert thrust_motors(model(lambda m, a, b, s, h: a + 2 * b)) == ("a", "b")
    assert thrust_motors(model(lambda m, a, b, s, h: b + s)) == ("b", "sustainer")
    assert thrust_motors(model(lambda m, a, b, s, h: a + 1e3 * (1 - m.t / 20))) == ("a",)
    assert thrust_motors(model(lambda m, a, b, s, h: a * (1 + 1e-5 * h) + 0.5 * h)) == ()
    assert thrust_motors(model(lambda m, a, b, s, h: 4e4 + 0 * a)) == ()
    # an input read through a nonlinear function (an attitude in a cosine) is not a motor; the table beside it is
    assert thrust_motors(model(lambda m, a, b, s, h: a * sp.cos(1e-3 * s) + b)) == ("a", "b")
