"""Model declaration: symbols as keys, attribute access, families and ties, free initial
states, editing a frozen model, error messages with hints, fingerprints."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import sympy as sp

import rocketid as ri
from rocketid.errors import ModelError


def pendulum_builder() -> ri.Model:
    m = ri.Model("pendulum", 0.0, 4.0)
    th = m.state("th", 0.5, free=True, bounds=(-2.0, 2.0))
    om = m.state("om", 0.0)
    u = m.input("u", 0.3 * sp.sin(2 * m.t))
    w2 = m.parameter("w2", 9.0, bounds=(1.0, 20.0))
    c = m.piecewise_linear("c", [0.0, 1.0, 2.0, 4.0], [0.2, 0.3, 0.3, 0.1], bounds=(0.0, 2.0), ties=[(1, 2)])
    k = m.parameter("k", 0.05)
    inertia = m.define("inertia", 1 + sp.cos(th) ** 2 / 5)
    m.ode({th: om})
    m.implicit({om: inertia * m.der(om) + c * om + w2 * sp.sin(th) - u})
    m.output("angle", (1 + k) * th, sigma=0.01)
    return m


# ---------------------------------------------------------------------------
# components and symbols
# ---------------------------------------------------------------------------


def test_components_are_symbols_reachable_as_attributes():
    m = ri.Model("m", 0.0, 1.0)
    v = m.state("v", 0.0)
    cd = m.parameter("cd", 0.5)
    assert isinstance(v, sp.Symbol) and str(v) == "v"
    assert m.v is v and m.cd is cd and m.t is m.t and str(m.t) == "t"
    assert m.dv_dt is m.der(v) and m.der("v") is m.der(v)
    with pytest.raises(AttributeError, match="'vv'"):
        m.vv  # noqa: B018
    assert not hasattr(m, "vv")


def test_spec_is_keyed_by_symbols(ra66_spec):
    CL = ra66_spec.symbol("CL")
    CD3 = ra66_spec.symbol("CD3")
    p = ra66_spec.parameter_vector({CL: 0.2, CD3: 0.3})
    assert p[7] == 0.2 and p[3] == 0.3 and p[0] == ri.RA66_P0[0]
    assert ra66_spec.parameter(CL).upper == 1.0 and ra66_spec.parameter(CL).lower == 1e-4
    assert ra66_spec.parameter_dict(p)[CL] == 0.2
    # a symbol is not its name: one with other assumptions is a different key
    with pytest.raises(ModelError, match="CL"):
        ra66_spec.parameter_vector({sp.Symbol("CL", positive=True): 0.2})
    with pytest.raises(ModelError, match="zz"):
        ra66_spec.parameter_vector({sp.Symbol("zz"): 1.0})
    # a state is a component but not a parameter
    with pytest.raises(ModelError, match="not an estimated parameter"):
        ra66_spec.parameter_vector({ra66_spec.symbol("h"): 1.0})


def test_unknown_names_get_close_match_hints(ra66_spec):
    with pytest.raises(ModelError, match=r"no component named 'thetaa'; did you mean theta"):
        ra66_spec.symbol("thetaa")
    with pytest.raises(ModelError, match=r"'CD9'.*did you mean .*CD\d"):
        ra66_spec.parameter("CD9")
    with pytest.raises(ModelError, match="'qqqq'") as info:
        ra66_spec.symbol("qqqq")
    assert "did you mean" not in str(info.value)  # no hint when nothing is close
    m = pendulum_builder()
    with pytest.raises(ModelError, match="omega is not a state .* th, om"):
        m.der("omega")


def test_names_must_be_unique_identifiers():
    m = ri.Model("m", 0.0, 1.0)
    m.state("x", 0.0)
    with pytest.raises(ModelError, match="already has a component named 'x'"):
        m.parameter("x", 1.0)
    with pytest.raises(ModelError, match="already has a component named 'dx_dt'"):
        m.constant("dx_dt", 1.0)
    with pytest.raises(ModelError, match="identifiers.*'C D'"):
        m.parameter("C D", 1.0)


# ---------------------------------------------------------------------------
# families, ties, free initial states
# ---------------------------------------------------------------------------


def test_ties_make_cl_one_parameter(ra66_spec):
    assert ra66_spec.parameter_names == ("CD0", "CD1", "CD2", "CD3", "CD4", "CD5", "CD6", "CL")
    CL = ra66_spec.symbol("CL")
    assert ra66_spec.parameter(CL).family is None  # all knots tied: a plain scalar
    assert [str(f.symbol) for f in ra66_spec.families] == ["CD"]
    cd = ra66_spec.family("CD")
    np.testing.assert_array_equal(cd.breakpoints, np.linspace(0.0, 66.0, 7))
    assert [str(k) for k in cd.knots] == [f"CD{i}" for i in range(7)]


def test_partial_tie_shares_one_knot():
    spec = pendulum_builder().freeze()
    assert spec.parameter_names == ("th_0", "w2", "c0", "c1", "c3", "k")
    fam = spec.family("c")
    assert [str(k) for k in fam.knots] == ["c0", "c1", "c1", "c3"]
    assert all(spec.parameter(k).family == fam.symbol for k in fam.knots)
    values = spec.parameter_dict(spec.guess)
    np.testing.assert_allclose(fam.evaluate(np.array([0.0, 0.5, 1.0, 1.5, 2.0, 3.0, 4.0]), values),
                               [0.2, 0.25, 0.3, 0.3, 0.3, 0.2, 0.1])
    # the family's local value is used in the equations, its knots are the parameters
    assert fam.symbol in spec.local_symbols and not set(fam.knots) & set(spec.local_symbols)


def test_fully_tied_family_with_different_guesses_is_an_error():
    m = ri.Model("m", 0.0, 2.0)
    with pytest.raises(ModelError, match="family a: all knots are tied"):
        m.piecewise_linear("a", [0.0, 1.0, 2.0], [0.1, 0.2, 0.3], ties=[(0, 1, 2)])


def test_family_breakpoints_must_span_the_horizon():
    m = ri.Model("m", 0.0, 2.0)
    with pytest.raises(ModelError, match="family a: breakpoints must start at t0=0 and end at tf=2"):
        m.piecewise_linear("a", [0.0, 1.0], 0.1)
    with pytest.raises(ModelError, match="family b: tie"):
        m.piecewise_linear("b", [0.0, 1.0, 2.0], 0.1, ties=[(1, 3)])


def test_free_initial_state_creates_a_parameter():
    spec = pendulum_builder().freeze()
    th0 = spec.symbol("th_0")
    assert spec.parameter(th0).guess == 0.5 and spec.parameter(th0).lower == -2.0
    assert spec.states[0].free and spec.states[0].initial_parameter is th0
    assert not spec.states[1].free
    p = spec.parameter_vector({th0: 0.8})
    np.testing.assert_array_equal(spec.initial_state(p), [0.8, 0.0])
    assert th0 not in spec.local_symbols  # it enters the initial condition only
    traj = ri.simulate(spec, p, [0.0, 0.1])
    assert traj.states[0, 0] == 0.8


# ---------------------------------------------------------------------------
# editing: freeze, to_model, add_term, substitute
# ---------------------------------------------------------------------------


def test_freeze_is_immutable_and_independent_of_the_builder():
    m = pendulum_builder()
    spec = m.freeze()
    with pytest.raises(dataclasses.FrozenInstanceError):
        spec.name = "other"  # type: ignore[misc]
    before = spec.fingerprint()
    m.add_term("om", -m.k * m.om)  # editing the builder afterwards...
    assert spec.fingerprint() == before  # ...does not touch the frozen spec
    assert m.freeze().fingerprint() != before


def test_to_model_round_trip():
    spec = pendulum_builder().freeze()
    again = spec.to_model().freeze()
    assert again.fingerprint() == spec.fingerprint()
    assert again.parameter_names == spec.parameter_names
    np.testing.assert_array_equal(again.guess, spec.guess)
    assert again.equations == spec.equations and again.outputs == spec.outputs
    # the editable copy is independent: adding to it leaves the spec alone
    edited = spec.to_model()
    drag = edited.parameter("drag", 0.01)
    edited.add_term("om", -drag * edited.om * abs(edited.om))
    new = edited.freeze()
    assert "drag" in new.parameter_names and "drag" not in spec.parameter_names
    assert new.fingerprint() != spec.fingerprint()
    assert spec.to_model().freeze().fingerprint() == spec.fingerprint()


def _rhs(spec, state_name):
    """``d state/dt`` solved from its (possibly implicit) equation, definitions expanded."""
    i = spec.state_symbols.index(spec.symbol(state_name))
    eq = spec.expand(spec.equations[i])
    return sp.solve(eq, spec.derivative_symbols[i])[0]


def test_add_term_adds_to_the_derivative_explicit_and_implicit():
    spec = pendulum_builder().freeze()
    m = spec.to_model()
    g = m.parameter("g_extra", 0.0)
    m.add_term("th", g * m.t)        # explicit equation
    m.add_term(m.om, g * sp.cos(m.th))  # implicit: scaled by the coefficient of dom_dt
    new = m.freeze()
    for name, term in (("th", g * spec.t), ("om", g * sp.cos(spec.symbol("th")))):
        assert sp.simplify(_rhs(new, name) - _rhs(spec, name) - term) == 0, name


def test_add_term_needs_an_equation():
    m = ri.Model("m", 0.0, 1.0)
    y = m.state("y", 1.0)
    with pytest.raises(ModelError, match="state y has no equation yet"):
        m.add_term(y, 1.0)


def test_substitute_replaces_everywhere():
    spec = pendulum_builder().freeze()
    m = spec.to_model()
    w = m.parameter("w", 3.0)
    m.substitute({m.w2: w ** 2, m.k: 2 * w})
    m.substitute({})  # no-op
    new = m.freeze()
    eq_om = new.equations[1]
    assert new.symbol("w2") not in eq_om.free_symbols and w in eq_om.free_symbols
    assert sp.simplify(new.outputs[0].expr - (1 + 2 * w) * new.symbol("th")) == 0
    assert new.fingerprint() != spec.fingerprint()


def test_implicit_equation_forms():
    m = ri.Model("m", 0.0, 1.0)
    y = m.state("y", 1.0)
    m.implicit({y: sp.Eq(m.der(y), -y)})
    m.output("y", y, sigma=1.0)
    spec_eq = m.freeze()
    m2 = ri.Model("m", 0.0, 1.0)
    y2 = m2.state("y", 1.0)
    m2.ode({y2: -y2})
    m2.output("y", y2, sigma=1.0)
    assert spec_eq.fingerprint() == m2.freeze().fingerprint()
    m3 = ri.Model("m", 0.0, 1.0)
    y3 = m3.state("y", 1.0)
    m3.implicit({y3: m3.der(y3) ** 2 - y3})
    m3.output("y", y3, sigma=1.0)
    with pytest.raises(ModelError, match="not linear in dy_dt"):
        m3.freeze()


# ---------------------------------------------------------------------------
# fingerprints
# ---------------------------------------------------------------------------


def test_fingerprint_is_stable_and_tracks_what_code_depends_on():
    base = pendulum_builder().freeze()
    assert pendulum_builder().freeze().fingerprint() == base.fingerprint()  # fresh, equal
    assert len(base.fingerprint()) == 64

    # an equation changes
    m = pendulum_builder()
    m.implicit({m.om: m.inertia * m.der(m.om) + m.c * m.om + m.w2 * sp.sin(m.th) - 2 * m.u})
    assert m.freeze().fingerprint() != base.fingerprint()
    # a definition used by an equation changes
    m = pendulum_builder()
    m.redefine("inertia", 1 + sp.cos(m.th) ** 2 / 4)
    assert m.freeze().fingerprint() != base.fingerprint()
    # an output changes
    m = pendulum_builder()
    m.redefine_output("angle", m.th + m.k)
    assert m.freeze().fingerprint() != base.fingerprint()

    # guesses, bounds and sigma do not enter generated code
    assert base.with_guess({"k": 0.2}).fingerprint() == base.fingerprint()
    m = pendulum_builder()
    m.set_sigma("angle", 0.5)
    assert m.freeze().fingerprint() == base.fingerprint()


def test_spec_summary_lists_components():
    text = pendulum_builder().freeze().summary().text()
    assert "states     : th, om" in text
    assert "parameters : th_0, w2, c0, c1, c3, k" in text
    assert "family c: breakpoints [0.0, 1.0, 2.0, 4.0] -> knots c0, c1, c1, c3" in text


def _falling_body(v0=10.0):
    """A body thrown upward at ``v0``: h' = v, v' = -g, h measured."""
    m = ri.Model("throw", 0.0, 1.5)
    h = m.state("h", 0.0)
    v = m.state("v", v0)
    g = m.parameter("g", 9.0, bounds=(1.0, 20.0))
    m.ode({h: v, v: -g})
    m.output("h", h, 0.01)
    return m


def test_a_start_offset_corrects_the_declared_start():
    """``start_offset`` estimates a correction to a declared initial value: the start is ``initial + p``
    (guess 0, the declared start), and a fit recovers a throw 0.8 m/s faster than declared (the truth
    written by hand: h = (v0 + dv) t - g t^2 / 2)."""
    m = _falling_body()
    dv = m.start_offset("v", "dv", nominal=1.0)
    with pytest.raises(ModelError, match="already estimated"):
        m.start_offset("v", "dv2")
    spec = m.freeze()
    assert spec.states[1].offset and spec.states[1].initial_parameter == dv and not spec.states[0].free
    assert np.allclose(spec.initial_state(), [0.0, 10.0])
    p = spec.parameter_vector({"g": 9.81, "dv": 0.8})
    assert np.allclose(spec.initial_state(p), [0.0, 10.8])
    t = np.linspace(0.05, 1.5, 60)
    data = ri.Measurements((ri.Channel("h", t, 10.8 * t - 9.81 * t ** 2 / 2, sigma=0.01),))
    fit = ri.estimate(spec, data)
    est = dict(zip(spec.parameter_names, fit.p))
    assert fit.success and abs(est["dv"] - 0.8) < 1e-6 and abs(est["g"] - 9.81) < 1e-6
    # a window keeps the offset: the correction now applies to the window's declared start
    w = spec.windowed(0.5, 1.5, initial={"v": 10.8 - 9.81 * 0.5})
    assert w.states[1].offset and np.isclose(w.initial_state(w.parameter_vector({"dv": 0.1}))[1], 10.8 - 4.905 + 0.1)
