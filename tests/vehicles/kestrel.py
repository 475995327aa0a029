"""Kestrel-S: a guided solid-propellant sounding rocket, declared as a user would.

A vehicle unlike RA-66, RA-66M and Stage-30, written from the user documentation only
(docs/getting-started.md "Your own model", docs/cli.md "Model files",
``rocketid.physics.ascent``):

- a 1.5 t single-stage solid motor, 0.5 m diameter, released from a launch rail at
  35 m/s and 84 deg elevation, 12 m above the pad (start speed > 0, no vertical start);
- a **tabulated, regressive thrust curve** (static-firing figures at sea level, one value
  per second, 55 kN falling to 29 kN over the 40 s burn) as a sampled input;
- the **mass as a state** burnt at the thrust over `Isp g0` (Isp 245 s), not a linear law;
- drag a table in Mach on its own knots (0 .. 3.0), lift `CLa(M) alpha` with the lift-curve
  slope a two-knot Mach table (finned body: 9 /rad subsonic, falling supersonic);
- an **attitude program** (commanded pitch angle sampled every second, a gravity-turn-like
  pitch-down with a small excitation), the attack angle the expression `theta_cmd - theta`;
- the 1976 standard atmosphere (`atmosphere="us76"`), measurements at 25 Hz for 40 s with
  channel noise x, h 2 m and v 0.25 m/s (a radar track with a Doppler speed).

Use it from the command line as ``--model tests/vehicles/kestrel.py``.
"""

from __future__ import annotations

import math

import numpy as np

from rocketid import Model
from rocketid.physics.ascent import ascent_dynamics, ascent_states, flight_conditions

#: Horizon: the burn, s.
T_BURN = 40.0
#: Thrust table (sea-level static firing), N, at t = 0, 1, ..., 40 s.
THRUST_TIMES = tuple(float(t) for t in range(41))
THRUST_VALUES = tuple(float(v) for v in np.round(
    np.interp(np.arange(41.0),
              [0.0, 1.0, 3.0, 10.0, 20.0, 30.0, 36.0, 40.0],
              [50.0e3, 55.0e3, 54.0e3, 48.5e3, 42.0e3, 36.0e3, 32.0e3, 29.0e3]), 1))
#: Specific impulse, s, and standard gravity for the mass flow.
ISP = 245.0
G0 = 9.80665
#: Lift-off (rail exit) state: downrange, altitude, speed, flight-path angle.
M_START = 1500.0
START = (0.0, 12.0, 35.0, math.radians(84.0))
DIAMETER = 0.5
#: Drag table knots in Mach and the truth.
CD_KNOTS = (0.0, 0.8, 1.05, 1.3, 2.0, 3.0)
CD_TRUTH = (0.42, 0.44, 0.68, 0.66, 0.52, 0.40)
#: Lift-curve slope knots in Mach and the truth, /rad.
CLA_KNOTS = (0.8, 3.0)
CLA_TRUTH = (9.0, 6.5)
#: Attitude program: commanded pitch angle, deg, every second.
PITCH_TIMES = tuple(float(t) for t in range(41))


def _pitch_program() -> tuple[float, ...]:
    t = np.arange(41.0)
    base = 84.0 - 30.0 * np.clip((t - 3.0) / 37.0, 0.0, 1.0) ** 1.3   # 84 deg held 3 s, then down to 54
    wiggle = 1.5 * np.sin(2 * math.pi * (t - 3.0) / 9.0) * (t >= 3.0)   # excitation for the lift slope
    return tuple(float(v) for v in np.round(base + wiggle, 4))


PITCH_DEG = _pitch_program()
#: Measurement noise standard deviations.
SIGMA = {"x": 2.0, "h": 2.0, "v": 0.25}


def build_model():
    """Kestrel-S with CD(M) and CLa(M) alpha to estimate."""
    m = Model("Kestrel-S", 0.0, T_BURN)
    st = ascent_states(m, initial=START)
    fc = flight_conditions(m, st, atmosphere="us76")
    thrust = m.input("thrust_table", times=THRUST_TIMES, values=THRUST_VALUES)
    pitch = m.input("pitch_cmd", times=PITCH_TIMES, values=tuple(math.radians(d) for d in PITCH_DEG))
    mass = m.state("mass_kg", M_START)
    m.ode({mass: -thrust / (ISP * G0)})
    alpha = pitch - st.theta
    cd = m.table("CD", fc.mach, CD_KNOTS, 0.5, bounds=(0.05, 2.0), nominal=0.5)
    cla = m.table("CLa", fc.mach, CLA_KNOTS, 7.0, bounds=(0.0, 30.0), nominal=8.0)
    ascent_dynamics(m, st, fc, thrust=thrust, mass=mass, area=m.constant("S_ref", math.pi * DIAMETER ** 2 / 4),
                    cd=cd, cl=cla * alpha, alpha=alpha)
    for s in (st.x, st.h, st.v):
        m.output(str(s), s, sigma=SIGMA[str(s)])
    return m.freeze()


def truth(spec):
    """The true coefficients."""
    values = {f"CD_{j}": v for j, v in enumerate(CD_TRUTH)}
    values.update({f"CLa_{j}": v for j, v in enumerate(CLA_TRUTH)})
    return values


def sample_times():
    """25 Hz over the burn: t = 0.04 k s, k = 1..1000."""
    return 0.04 * np.arange(1, 1001)
