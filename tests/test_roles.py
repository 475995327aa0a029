"""Typed physical roles (issue 12, item 3): diagnostics and effects find the physics by role.

A user writes an ascent model by hand with names of their own (``alt``, ``spd``, ``gam``,
``T``, ``CDm``) and declares the roles; the catalogue's effects then apply to it, the
location finds its flight conditions, and a model without a role is told which analysis
needs which role.
"""

from __future__ import annotations

import math

import numpy as np
import pytest
import sympy as sp

import rocketid as ri
from rocketid.diagnostics import with_effects
from rocketid.diagnostics.locate import flight_conditions, locate, missing_conditions
from rocketid.errors import ModelError
from rocketid.model import ROLES, TableSpec
from rocketid.physics.atmosphere import us76_density, us76_speed_of_sound


def user_model(roles: bool = True) -> ri.Model:
    """A 20 s ascent from 20 m/s, written without rocketid.physics.ascent."""
    m = ri.Model("user", 0.0, 20.0)
    xr = m.state("xr", 0.0)
    alt = m.state("alt", 0.0)
    spd = m.state("spd", 20.0)
    gam = m.state("gam", math.radians(85.0))
    aoa = m.input("aoa", sp.Float(0.02) * sp.sin(m.t / 3))
    dens = m.define("dens", us76_density(alt))
    q = m.define("q", dens * spd ** 2 / 2)
    mach_no = m.define("mach_no", spd / us76_speed_of_sound(alt))
    T = m.define("T", sp.Float(300000.0))
    mass_kg = m.define("mass_kg", 15000.0 - 90.0 * m.t)
    cd_table = m.table("CDm", mach_no, (0.0, 0.5, 1.0), 0.3, bounds=(0.01, 2.0))
    CDm = m.define("cd_user", cd_table)
    cla = m.parameter("CLa", 2.0, bounds=(0.0, 10.0))
    CL = m.define("cl_user", cla * aoa)
    tdir = m.define("tdir", aoa)
    S = 1.2
    D = m.define("Dforce", q * S * CDm)
    L = m.define("Lforce", q * S * CL)
    g = 9.80665
    m.ode({xr: spd * sp.cos(gam), alt: spd * sp.sin(gam),
           spd: T * sp.cos(tdir) / mass_kg - D / mass_kg - g * sp.sin(gam),
           gam: (T * sp.sin(tdir) / mass_kg + L / mass_kg - g * sp.cos(gam)) / spd})
    for s in (xr, alt, spd):
        m.output(str(s), s, sigma=1.0)
    if roles:
        for role, sym in (("downrange", xr), ("altitude", alt), ("speed", spd), ("flight_path_angle", gam),
                          ("density", dens), ("dynamic_pressure", q), ("mach", mach_no), ("thrust", T),
                          ("mass", mass_kg), ("drag_coefficient", CDm), ("lift_coefficient", CL),
                          ("thrust_direction", tdir), ("drag", D), ("lift", L), ("attack_angle", aoa)):
            m.declare_role(role, sym)
    return m


def test_roles_are_declared_kept_and_checked():
    m = user_model()
    spec = m.freeze()
    assert spec.role("altitude") == m.alt and spec.role("mach") == m.mach_no
    assert spec.to_model().role("thrust") == m.T                       # freeze -> to_model keeps them
    assert spec.with_guess({"CLa": 2.5}).role("speed") == m.spd
    tb = spec.tables[0]
    assert isinstance(tb, TableSpec) and tb.name == "CDm" and tb.variable_role == "mach"
    assert tb.knots == (0.0, 0.5, 1.0) and [str(p) for p in tb.parameters] == ["CDm_0", "CDm_1", "CDm_2"]
    assert spec.table_of("CDm_1") is tb and spec.table_of("CLa") is None
    with pytest.raises(ModelError, match="unknown role 'height'"):
        m.declare_role("height", m.alt)
    with pytest.raises(ModelError, match="no component named 'nope'"):
        m.declare_role("altitude", "nope")
    assert set(ROLES) >= {"altitude", "speed", "flight_path_angle", "mach", "dynamic_pressure", "attack_angle",
                          "thrust", "mass", "drag_coefficient", "lift_coefficient"}


def test_the_ascent_builders_declare_the_roles():
    spec = ri.ra66()
    assert str(spec.role("altitude")) == "h" and str(spec.role("dynamic_pressure")) == "qbar"
    assert str(spec.role("drag_coefficient")) == "cd" and str(spec.role("attack_angle")) == "alpha"


def test_effects_apply_to_a_model_with_other_names():
    spec = user_model().freeze()
    new = with_effects(spec, ["back_pressure", "thrust_level", "mass_flow", "misalignment", "bias_h", "density",
                              "wind", "earth_rotation", "transonic_drag"])
    for n in ("A_e", "eps_thrust", "eps_mdot", "delta_thrust", "b_h", "drho_1", "wind_1", "k_rot", "dCD_transonic"):
        assert n in new.parameter_names
    # the altitude bias lands on the output that reads the altitude state (named "alt" here)
    out = {o.name: o.expr for o in new.outputs}
    assert new.symbol("b_h") in out["alt"].free_symbols
    # the start speed is 20 m/s: the misalignment acts from t0, with no lift-off fade
    tdir = new.expand(new.role("thrust_direction"))
    assert sp.diff(tdir, new.symbol("delta_thrust")) == 1
    # the wind replaces the attack angle by the air-relative one in the lift coefficient
    cl = new.expand(new.role("lift_coefficient"))
    assert new.symbol("wind_speed") in cl.free_symbols


def test_a_model_without_roles_is_told_which_role_an_analysis_needs():
    spec = user_model(roles=False).freeze()
    with pytest.raises(ModelError, match=r"effect 'back_pressure' needs the thrust \(role 'thrust'\).*"
                                         r"m\.declare_role\('thrust', symbol\)"):
        with_effects(spec, ["back_pressure"])
    with pytest.raises(ModelError, match=r"needs the Mach number \(role 'mach'\)"):
        spec.require_role("mach", "the Mach-indexed variant")
    assert set(missing_conditions(spec)) == {"altitude", "speed", "mach", "dynamic_pressure", "attack_angle"}


def test_location_uses_the_roles_of_a_users_model():
    spec = user_model().freeze()
    truth = spec.parameter_vector({"CDm_0": 0.3, "CDm_1": 0.35, "CDm_2": 0.5, "CLa": 2.5})
    data = ri.simulate_measurements(spec, truth, np.linspace(0.01, 20.0, 2000), seed=0)
    fit = ri.estimate(spec, data)
    assert fit.success
    conds = flight_conditions(fit, np.array([1.0, 10.0, 19.0]))
    assert set(conds) == {"h", "v", "mach", "qbar", "alpha"}
    np.testing.assert_allclose(conds["h"], fit.states_at([1.0, 10.0, 19.0])[:, 1])
    assert conds["mach"][2] > conds["mach"][0] > 0
    loc = locate(fit)
    assert not any("declares no" in n for n in loc.notes)
    # without roles the location still runs, on time windows only, and says why
    bare = user_model(roles=False).freeze()
    fit2 = ri.estimate(bare, data)
    loc2 = locate(fit2)
    assert any("declares none of the roles altitude, mach, dynamic_pressure" in n for n in loc2.notes)


def _named_cd_model() -> ri.Model:
    """A 20 s ascent declared with the ascent builders whose drag table is called ``Cd`` and whose
    lift slope ``Kl``: names the name patterns (CD*, CL*) do not recognize."""
    from rocketid.physics.ascent import ascent_dynamics, ascent_states, flight_conditions

    m = ri.Model("named-Cd", 0.0, 20.0)
    st = ascent_states(m, (0.0, 0.0, 20.0, math.radians(85.0)))
    fc = flight_conditions(m, st)
    alpha = m.input("alpha", sp.Float(0.02) * sp.sin(m.t / 3))
    cd = m.table("Cd", fc.mach, (0.0, 0.5, 1.0), 0.3, bounds=(-1.0, 3.0))
    kl = m.parameter("Kl", 2.0, bounds=(-10.0, 10.0))
    ascent_dynamics(m, st, fc, thrust=sp.Float(300000.0), mass=15000.0 - 90.0 * m.t, area=1.2, cd=cd,
                    cl=kl * alpha, alpha=alpha)
    for s in (st.x, st.h, st.v):
        m.output(str(s), s, sigma=0.5)
    return m


def test_coefficient_checks_find_the_drag_by_its_role_whatever_its_name():
    from rocketid.diagnostics.plausibility import check_plausibility, coefficient_kinds

    spec = _named_cd_model().freeze()
    kinds, notes = coefficient_kinds(spec)
    assert kinds == {"Cd_0": "drag", "Cd_1": "drag", "Cd_2": "drag", "Kl": "lift slope"} and not notes
    # a negative drag coefficient, one beyond any launch vehicle's, one held by its bound
    truth = {"Cd_0": -0.3, "Cd_1": 2.4, "Cd_2": 3.0, "Kl": 2.0}
    data = ri.simulate_measurements(spec, truth, np.linspace(0.0, 20.0, 401), seed=1)
    fit = ri.estimate(spec.with_guess({"Cd_0": 0.3, "Cd_1": 2.0, "Cd_2": 2.9}), data)
    pl = check_plausibility(fit)
    codes = {(f.code, f.parameters[0]) for f in pl.flags if f.severity == "fail"}
    assert ("wrong-sign", "Cd_0") in codes, pl.summary()
    assert ("implausible", "Cd_1") in codes, pl.summary()
    assert ("at-bound", "Cd_2") in codes and "an even larger drag coefficient" in pl.summary(), pl.summary()
    assert pl.kinds[list(pl.names).index("Cd_0")] == "drag"


def test_coefficient_kinds_fall_back_to_names_without_the_roles():
    from rocketid.diagnostics.plausibility import coefficient_kinds

    kinds, notes = coefficient_kinds(ri.ra66())
    assert kinds["CD0"] == "drag" and kinds["CL"] == "lift" and not notes
    spec = user_model(roles=False).freeze()
    kinds, notes = coefficient_kinds(spec)
    # by name: CDm_* match CD*, and CLa matches CL* (a lift, where its role would say lift slope)
    assert kinds == {"CDm_0": "drag", "CDm_1": "drag", "CDm_2": "drag", "CLa": "lift"}
    assert coefficient_kinds(user_model().freeze())[0]["CLa"] == "lift slope"
    assert len(notes) == 1 and "'drag_coefficient' or 'lift_coefficient'" in notes[0] and "by name" in notes[0]
