"""The declared moving start's time (``start_exit``, ``start_mass_exit``): a vehicle that leaves its rail later.

The truth here is not the effect's expression: it is the vehicle **declared again** as a user would, starting
``d`` seconds later from the same rail-exit state -- the model's start time moved, a mass state started from
what the stated motor leaves at that time -- and simulated. The effect's model, with ``dt_start = d``, must
read the same GPS outputs at the same (motor-clock) times, to within its first-order output shift (measured
with a 20 ms delay: Wren-H's altitude moves 22 m and the shape is 0.010 m off, its speed 1.02 m/s and 0.0097
m/s off; Tern-2's 123 m and 0.054 m, 2.25 m/s and 0.028 m/s -- the second-order term at the motor's
burn-out).
"""

from __future__ import annotations

import sys
from pathlib import Path

import numpy as np
import pytest

HERE = Path(__file__).resolve().parent
for extra in (HERE, HERE / "vehicles"):
    if str(extra) not in sys.path:
        sys.path.insert(0, str(extra))

import tern  # noqa: E402
import wren  # noqa: E402

import rocketid as ri  # noqa: E402
from rocketid.diagnostics import CATALOGUE, with_effects  # noqa: E402
from rocketid.diagnostics.effects import (Vehicle, start_exit_effect, start_mass_exit_effect,  # noqa: E402
                                          START_TIME)
from rocketid.errors import ModelError  # noqa: E402

DELAY = 0.02     # s: a rail exit 20 ms late (a cold motor leaves Wren-H's rail 27 ms late)


def _later_wren(monkeypatch):
    """Wren-H declared with its rail exit ``DELAY`` later: the same state (mass a definition of time)."""
    t_rail, v_rail = wren.rail_exit()
    monkeypatch.setattr(wren, "rail_exit", lambda: (t_rail + DELAY, v_rail))
    return wren.build_model()


def _later_tern(monkeypatch):
    """Tern-2 declared with its rail exit ``DELAY`` later: the same state, the mass state's start what the
    motor has burnt by then."""
    monkeypatch.setattr(tern, "T_RAIL", tern.T_RAIL + DELAY)
    monkeypatch.setattr(tern, "M_START", tern.M_LAUNCH - tern.burnt(tern.T_RAIL))
    return tern.build_model()


@pytest.mark.parametrize("vehicle, later, times", [
    (wren, _later_wren, wren.gps_times()),
    (tern, _later_tern, np.arange(1.0, 60.0, 0.5)),
], ids=["wren-mass-definition", "tern-mass-state"])
def test_a_later_start_is_the_vehicle_declared_later(vehicle, later, times, monkeypatch):
    spec = vehicle.build_model()
    p = dict(vehicle.truth(spec))
    base = ri.simulate(spec, p, times).outputs()
    shifted = ri.simulate(with_effects(spec, [start_exit_effect()]), {**p, "dt_start": DELAY, "dv_start": 0.0},
                          times).outputs()
    declared = ri.simulate(later(monkeypatch), p, times).outputs()
    for name in "xhv":
        moved = np.max(np.abs(declared[name] - base[name]))
        err = np.max(np.abs(shifted[name] - declared[name]))
        assert err < 0.02 * moved and err < 0.15 * vehicle.SIGMA[name], (name, moved, err)


def test_zero_gives_the_base_model_and_the_start_moves_with_dv():
    """At zero the effect is the base model; ``dv_start`` moves the declared start's speed as ``start_speed``."""
    spec = wren.build_model()
    p = dict(wren.truth(spec))
    t = wren.gps_times()
    base = ri.simulate(spec, p, t).outputs()
    mass_exit = with_effects(spec, [start_mass_exit_effect()])
    zero = ri.simulate(mass_exit, {**p, "dm_start": 0.0, "dv_start": 0.0, "dt_start": 0.0}, t).outputs()
    for name in "xhv":
        np.testing.assert_allclose(zero[name], base[name], rtol=0, atol=1e-9)
    fast = ri.simulate(mass_exit, {**p, "dm_start": 0.0, "dv_start": 0.5, "dt_start": 0.0}, t).outputs()
    speed = ri.simulate(with_effects(spec, ["start_speed"]), {**p, "dv_start": 0.5}, t).outputs()
    np.testing.assert_allclose(fast["v"], speed["v"], rtol=0, atol=1e-9)


def _vehicle(start_speed: float) -> Vehicle:
    return Vehicle(thrust=3.6e3, mass=60.0, mass_flow=1.0, speed=400.0, start_speed=start_speed, duration=44.0,
                   altitude=(1200.0, 10200.0), mach=(0.1, 1.35), sigma={"v": 0.25}, sample_interval=0.1,
                   knot_times=tuple(np.linspace(0.6, 44.0, 30)))


def test_offered_for_a_moving_start_only():
    """The shapes are refinements of ``start_mass`` and ``start_speed`` for a declared moving start, with the
    start's realistic sizes; from rest there is no declared start to move and applying them is refused."""
    moving, rest = _vehicle(25.0), _vehicle(0.0)
    assert [e.name for e in CATALOGUE["start_mass"].refinements(moving)] == ["start_mass_exit", "mass_jettison"]
    assert [e.name for e in CATALOGUE["start_mass"].refinements(rest)] == ["mass_jettison"]
    assert [e.name for e in CATALOGUE["start_speed"].refinements(moving)] == ["start_exit"]
    assert CATALOGUE["start_speed"].refinements(rest) == []
    assert start_mass_exit_effect(moving).sizes(moving) == {"dm_start": 0.6, "dv_start": 0.75, "dt_start": START_TIME}
    m = ri.Model("rest", 0.0, 10.0)
    from rocketid.physics.ascent import ascent_dynamics, ascent_states, flight_conditions
    st = ascent_states(m, initial=(0.0, 0.0, 0.0, 1.5))
    fc = flight_conditions(m, st)
    ascent_dynamics(m, st, fc, thrust=m.constant("P", 1e4), mass=m.constant("M", 500.0),
                    area=m.constant("S", 0.1), cd=m.constant("cd0", 0.3), cl=0, alpha=0)
    m.output("v", st.v, sigma=1.0)
    with pytest.raises(ModelError, match="moving start"):
        with_effects(m.freeze(), [start_exit_effect()])
