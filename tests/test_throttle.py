"""The throttle primitive: thrust and mass flow scaled together, piecewise in time, event times as breakpoints.

Truths not derived from the code under test: the closed-form mass against a numerical
integral of the interpolated setting (``numpy.interp`` + ``scipy.integrate.quad``), and a
throttle-down estimated as an effect (``d(t)``, the reduction) from data simulated with the
schedule declared as a known input (the setting ``tau(t)``, another shape).
"""

from __future__ import annotations

import importlib.util
import math
from pathlib import Path

import numpy as np
import pytest
import sympy as sp
from scipy.integrate import quad

import rocketid as ri
from rocketid.diagnostics import throttle_effect, with_effects
from rocketid.errors import ModelError
from rocketid.estimability import uncertainty
from rocketid.physics.ascent import ascent_dynamics, ascent_states, flight_conditions
from rocketid.physics.propulsion import throttle_schedule, throttled_propulsion

ROOT = Path(__file__).resolve().parents[1]
TIMES = (20.0, 27.0, 39.0, 46.0)
LEVELS = (1.0, 0.72, 0.78, 1.0)


def _stage30():
    spec = importlib.util.spec_from_file_location("stage30_throttle", ROOT / "tests" / "vehicles" / "stage30.py")
    mod = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(mod)
    return mod


def test_closed_form_mass_matches_a_numerical_integral():
    m = ri.Model("thr", 5.0, 80.0)
    y = m.state("y", 0.0)
    m.ode({y: 1.0})
    m.output("y", y, sigma=1.0)
    thr = throttle_schedule(m, TIMES, LEVELS)
    thrust, mass = throttled_propulsion(m, thr, thrust=1000.0, mass0=500.0, mass_flow=3.0)
    spec = m.freeze()
    assert set(TIMES) <= set(spec.events) and set(TIMES) <= set(spec.breakpoints)
    f_mass = sp.lambdify(m.t, spec.expand(mass))
    f_thrust = sp.lambdify(m.t, spec.expand(thrust))
    setting = lambda s: np.interp(s, TIMES, LEVELS)
    for t in (5.0, 15.0, 21.5, 27.0, 33.3, 45.9, 60.0, 80.0):
        pts = [b for b in TIMES if 5.0 < b < t]
        expected = 500.0 - 3.0 * quad(setting, 5.0, t, points=pts or None, limit=200)[0]
        assert float(f_mass(t)) == pytest.approx(expected, rel=1e-12, abs=1e-9)
        assert float(f_thrust(t)) == pytest.approx(1000.0 * setting(t), rel=1e-12)
    # the default mesh puts an element boundary at every event time
    mesh = ri.default_mesh(spec)
    assert all(np.min(np.abs(mesh.boundaries - b)) < 1e-12 for b in TIMES)


def test_bad_schedules_are_refused():
    m = ri.Model("thr", 0.0, 10.0)
    with pytest.raises(ModelError, match="strictly increasing"):
        throttle_schedule(m, [3.0, 2.0], [1.0, 0.5])
    with pytest.raises(ModelError, match="one level per time"):
        throttle_schedule(m, [1.0, 2.0], [1.0])
    with pytest.raises(ModelError, match="not a parameter"):
        throttle_schedule(m, [1.0, 2.0], [1.0, sp.Symbol("zz")])


def _throttled_truth_model(mod):
    """Stage-30 flying a known throttle-down (the schedule as an input, levels tau)."""
    m = ri.Model("Stage-30 throttled", 0.0, mod.TF)
    st = ascent_states(m, initial=(0.0, 0.0, mod.V0, math.radians(mod.THETA0_DEG)))
    fc = flight_conditions(m, st, atmosphere="us76")
    tt, aa = mod.program_table()
    alpha = m.input("alpha", times=tt, values=aa)
    cd = m.table("CD", fc.mach, mod.MACH_KNOTS, 0.35, bounds=(0.01, 2.0), nominal=0.35)
    cla = m.parameter("CL_alpha", 2.0, bounds=(0.0, 10.0), nominal=2.5)
    thr = throttle_schedule(m, TIMES, LEVELS)
    thrust, mass = throttled_propulsion(m, thr, thrust=m.constant("P_sl", mod.THRUST_SL), mass0=mod.M0,
                                        mass_flow=mod.MDOT)
    ascent_dynamics(m, st, fc, thrust=thrust, mass=mass, area=m.constant("S_ref", mod.AREA), cd=cd,
                    cl=cla * alpha, alpha=alpha)
    for s in (st.x, st.h, st.v):
        m.output(str(s), s, sigma=1.0)
    return m.freeze()


def test_a_throttle_down_is_estimated_as_an_effect():
    mod = _stage30()
    truth_spec = _throttled_truth_model(mod)
    data = ri.simulate_measurements(truth_spec, mod.truth(truth_spec), mod.sample_times(), seed=4)
    base = mod.build_model().freeze()
    fit0 = ri.estimate(base, data)
    assert fit0.chi2_per_dof > 5          # without the throttle the model cannot fit
    effect = throttle_effect(TIMES)
    spec = with_effects(base, [effect])
    assert spec.parameter_names[-2:] == ("d_throttle_1", "d_throttle_2")
    fit = ri.estimate(spec, data)
    assert fit.success
    assert 0.9 < fit.chi2_per_dof < 1.1
    se = uncertainty(fit).standard_errors
    names = spec.parameter_names
    for j, level in ((1, LEVELS[1]), (2, LEVELS[2])):
        i = names.index(f"d_throttle_{j}")
        assert abs(fit.p[i] - (1 - level)) < 4 * se[i] + 1e-4
    for j, cd in enumerate(mod.CD_TRUTH):
        i = names.index(f"CD_{j}")
        assert abs(fit.p[i] - cd) < 4 * se[i] + 1e-3
