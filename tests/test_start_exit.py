"""A rail exit's speed with its time (``start_exit``, ``start_mass_exit``): a vehicle that leaves its rail later.

The truths here are not the effect's expressions: the vehicle **declared again** as a user would, starting
``d`` seconds later from the rail's end at another speed -- the model's start time moved, a mass state started
from what the stated motor leaves at that time -- and simulated; and the hybrid study's truth simulator's own
rail (``wren_study.truth``), whose exit time and speed for a heavier rocket give the ratio the effect ties.
The effect's model must read the same GPS outputs at the same (motor-clock) times, to within its first-order
output shift (measured with a 20 ms delay: Wren-H's altitude moves 22 m and the shape is 0.010 m off, its
speed 1.02 m/s and 0.0097 m/s off; Tern-2's 123 m and 0.054 m, 2.25 m/s and 0.028 m/s -- the second-order
term at the motor's burn-out; measured with the time free, before it was tied).
"""

from __future__ import annotations


import numpy as np
import pytest


import tern
import wren

import rocketid as ri
from rocketid.diagnostics import CATALOGUE, with_effects
from rocketid.diagnostics.effects import (Vehicle, _rail_exit_ratio, start_exit_effect,
                                          start_mass_exit_effect)
from rocketid.errors import ModelError

DELAY = 0.02     # s: a rail exit 20 ms late (a cold motor leaves Wren-H's rail 27 ms late)


def _ratio(spec) -> float:
    return _rail_exit_ratio(spec.to_model(), "start_exit")


def _later_wren(monkeypatch, dv):
    """Wren-H declared with its rail exit ``DELAY`` later and ``dv`` faster (mass a definition of time)."""
    t_rail, v_rail = wren.rail_exit()
    monkeypatch.setattr(wren, "rail_exit", lambda: (t_rail + DELAY, v_rail + dv))
    return wren.build_model()


def _later_tern(monkeypatch, dv):
    """Tern-2 declared with its rail exit ``DELAY`` later and ``dv`` faster, the mass state's start what the
    motor has burnt by then."""
    monkeypatch.setattr(tern, "T_RAIL", tern.T_RAIL + DELAY)
    monkeypatch.setattr(tern, "M_START", tern.M_LAUNCH - tern.burnt(tern.T_RAIL))
    monkeypatch.setattr(tern, "START", tern.START[:2] + (tern.START[2] + dv,) + tern.START[3:])
    return tern.build_model()


@pytest.mark.parametrize("vehicle, later, times", [
    (wren, _later_wren, wren.gps_times()),
    (tern, _later_tern, np.arange(1.0, 60.0, 0.5)),
], ids=["wren-mass-definition", "tern-mass-state"])
def test_a_later_exit_is_the_vehicle_declared_later(vehicle, later, times, monkeypatch):
    spec = vehicle.build_model()
    dv = DELAY / _ratio(spec)                     # the speed change that goes with a 20 ms later exit
    assert -2.0 < dv < -0.5, dv
    p = dict(vehicle.truth(spec))
    base = ri.simulate(spec, p, times).outputs()
    shifted = ri.simulate(with_effects(spec, [start_exit_effect()]), {**p, "dv_start": dv, "dv_exit": dv}, times).outputs()
    declared = ri.simulate(later(monkeypatch, dv), p, times).outputs()
    for name in "xhv":
        moved = np.max(np.abs(declared[name] - base[name]))
        err = np.max(np.abs(shifted[name] - declared[name]))
        assert err < 0.02 * moved and err < 0.15 * vehicle.SIGMA[name], (name, moved, err)


def test_the_tie_is_the_truth_simulator_s_rail():
    """The exit's ``dt/dv`` from Wren-H's stated motor (rocketid's rail: no drag, the thrust table, the launch
    mass less the consumed table) against the hybrid study's truth simulator, which integrates its own motor,
    drag and rail: 1.5 kg of ballast leaves 7.51 ms later and 0.367 m/s slower (measured -0.02028 against
    -0.02047 s per m/s)."""
    from wren_study import truth
    heavy, nominal = truth.Flight(truth.Hidden(dm_payload=1.5)).rail_exit, truth.Flight(truth.Hidden()).rail_exit
    dt = heavy[0] - nominal[0]
    dv = float(np.hypot(*heavy[1][2:]) - np.hypot(*nominal[1][2:]))
    assert _ratio(wren.build_model()) == pytest.approx(dt / dv, rel=0.02)


def test_zero_gives_the_base_model_and_the_start_moves_with_dv():
    """At zero the effect is the base model; ``dv_start`` moves the declared start's speed as ``start_speed``
    does, and the exit's time with it."""
    spec = wren.build_model()
    p = dict(wren.truth(spec))
    t = wren.gps_times()
    base = ri.simulate(spec, p, t).outputs()
    mass_exit = with_effects(spec, [start_mass_exit_effect()])
    zero = ri.simulate(mass_exit, {**p, "dm_start": 0.0, "dv_start": 0.0, "dv_exit": 0.0}, t).outputs()
    for name in "xhv":
        np.testing.assert_allclose(zero[name], base[name], rtol=0, atol=1e-9)
    fast = ri.simulate(mass_exit, {**p, "dm_start": 0.0, "dv_start": 0.5, "dv_exit": 0.5}, t).outputs()
    speed = ri.simulate(with_effects(spec, ["start_speed"]), {**p, "dv_start": 0.5}, t).outputs()
    assert fast["v"][0] - speed["v"][0] == pytest.approx(-0.5 * _ratio(spec) * 50.0, rel=0.2)


def _vehicle(start_speed: float, rail_exit: bool = False) -> Vehicle:
    return Vehicle(thrust=3.6e3, mass=60.0, mass_flow=1.0, speed=400.0, start_speed=start_speed, duration=44.0,
                   altitude=(1200.0, 10200.0), mach=(0.1, 1.35), sigma={"v": 0.25}, sample_interval=0.1,
                   knot_times=tuple(np.linspace(0.6, 44.0, 30)), rail_exit=rail_exit)


def _tiny(start_speed: float, thrust=None) -> ri.ModelSpec:
    """A small vehicle declared from ``t0 = 1 s`` at ``start_speed``, its thrust ``thrust`` (default a constant)."""
    from rocketid.physics.ascent import ascent_dynamics, ascent_states, flight_conditions
    m = ri.Model("tiny", 1.0, 10.0)
    st = ascent_states(m, initial=(0.0, 0.0, start_speed, 1.5))
    fc = flight_conditions(m, st)
    ascent_dynamics(m, st, fc, thrust=m.constant("P", 1e4) if thrust is None else thrust(m),
                    mass=m.constant("M", 500.0), area=m.constant("S", 0.1), cd=m.constant("cd0", 0.3), cl=0,
                    alpha=0)
    m.output("v", st.v, sigma=1.0)
    return m.freeze()


def test_offered_for_a_rail_exit_only():
    """The shapes are refinements of ``start_mass`` and ``start_speed`` for a rail exit (``Vehicle.rail_exit``,
    read off the fit: Wren-H's is, a start at rest or a moving start from t = 0 such as Kestrel-S's is not),
    with the start's realistic sizes; applying them is refused, with the reason, from rest, without a thrust
    curve from ignition, or when the stated thrust does not reach the declared speed along a rail."""
    from rocketid.diagnostics.screen import _rail_exit
    import kestrel
    assert _rail_exit(wren.build_model()) and _rail_exit(tern.build_model()) and not _rail_exit(kestrel.build_model())
    moving, rest = _vehicle(25.0, rail_exit=True), _vehicle(0.0)
    assert [e.name for e in CATALOGUE["start_mass"].refinements(moving)] == ["start_mass_exit", "mass_jettison"]
    assert [e.name for e in CATALOGUE["start_mass"].refinements(rest)] == ["mass_jettison"]
    assert [e.name for e in CATALOGUE["start_mass"].refinements(_vehicle(25.0))] == ["mass_jettison"]
    assert [e.name for e in CATALOGUE["start_speed"].refinements(moving)] == ["start_exit"]
    assert CATALOGUE["start_speed"].refinements(rest) == [] == CATALOGUE["start_speed"].refinements(_vehicle(25.0))
    exit_ = start_mass_exit_effect(moving)
    assert exit_.sizes(moving) == {"dm_start": 0.6, "dv_start": 0.75, "dv_exit": 0.75}
    assert dict(exit_.changes) == {("dv_start", "dv_exit"): pytest.approx(0.075)}
    with pytest.raises(ModelError, match="moving start"):
        with_effects(_tiny(0.0), [start_exit_effect()])
    with pytest.raises(ModelError, match="no sampled thrust curve that starts before"):
        with_effects(_tiny(15.0), [start_exit_effect()])
    table = lambda m: m.input("P_tab", times=(0.0, 10.0), values=(1e4, 1e4))  # noqa: E731
    # 1 s at a constant 20 - 9.8 sin(1.5) m/s^2 from rest: 10.2 m/s at the start; a rail of L = a t^2 / 2 is
    # left at t = sqrt(2 L / a), v = sqrt(2 a L): dt/dv = -t/v whatever changed the acceleration
    assert _rail_exit_ratio(_tiny(10.2, table).to_model(), "start_exit") == pytest.approx(-1.0 / 10.2, rel=0.01)
    with pytest.raises(ModelError, match="not a rail exit"):
        with_effects(_tiny(30.0, table), [start_mass_exit_effect()])
