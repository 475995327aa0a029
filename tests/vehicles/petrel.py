"""Petrel-V: a pressure-fed liquid suborbital booster launched from a high site, declared as a user would.

Written from the user documentation only (docs/own-vehicle.md, docs/getting-started.md "Your own
model", docs/cli.md "Model files", ``rocketid.physics.ascent``) for the high-site study
(``tests/petrel_study``). What is new among the test vehicles: a pressure-fed liquid engine (the thrust
regressive as the tank pressure falls) stated by its sea-level acceptance test, flown from a pad 1400 m
above sea level, with a cutoff, a 1 s tail-off and a short coast, tracked by a GNSS receiver.

==============  ===============================================================
time            seconds from rail exit (t = 0): the engine runs up to full
                thrust held on the pad and is released; the thrust table is
                resampled on that clock
start           rail exit: x = 0, h = 1420 m above sea level (the pad at
                1400 m, a 20 m rail), v = 30 m/s, flight-path angle 86 deg
                (the rail's elevation)
mass            2400 kg at rail exit, a state burnt at thrust / (Isp g0),
                Isp 230 s (the acceptance test's sea-level figure)
thrust          the engine's sea-level acceptance-test thrust, one value per
                second: 60 kN at rail exit, regressive to 50 kN at 50 s as
                the tank pressure falls; cutoff at 50 s, a 1 s tail-off to
                zero at 51 s, zero after (the coast)
area            the body's cross-section, 0.6 m diameter (0.2827 m^2)
drag            CD(M) piecewise linear on 6 knots, Mach 0 .. 3.5, on the
                cross-section, one curve power-on and power-off
lift            CLa(M) alpha, the lift-curve slope a 2-knot Mach table
                (0.8, 3.0), alpha = pitch_cmd - theta
attitude        a sampled pitch program, the commanded pitch every second:
                86 deg held 2 s, a gravity-turn-like pitch-down, a small
                sinusoidal excitation (1 deg, 8 s period) so that the lift
                slope is estimable
horizon         0 .. 60 s: max q 61 kPa at 32 s (10.6 km); cutoff at 50 s, 22.9
                km, 996 m/s, Mach 3.35, 1193 kg (1218 kg of propellant burnt
                by 51 s); peak Mach 3.39 in the tail-off; the coast to 31.4 km
                and 920 m/s at 60 s, 12.2 km downrange
atmosphere      US Standard Atmosphere 1976 (density and speed of sound),
                altitude above sea level
measurements    x, h, v from a GNSS receiver at 10 Hz (t = 0.1 .. 60 s, 600
                samples), sigma 3 m, 4 m, 0.15 m/s
==============  ===============================================================

Use it from the command line as ``--model tests/vehicles/petrel.py``.
"""

from __future__ import annotations

import math

import numpy as np

from rocketid import Model
from rocketid.physics.ascent import ascent_dynamics, ascent_states, flight_conditions

#: Horizon, s: cutoff at T_CUTOFF, the tail-off to zero thrust by T_CUTOFF + 1, then the coast.
T_CUTOFF = 50.0
TF = 60.0
#: Thrust table (sea-level acceptance test), N, at t = 0, 1, ..., 60 s.
THRUST_TIMES = tuple(float(t) for t in range(61))


def _thrust_table() -> tuple[float, ...]:
    t = np.arange(51.0)
    burn = 50.0e3 + 10.0e3 * (1.0 - t / T_CUTOFF) ** 1.25      # 60 kN falling to 50 kN as the tank pressure falls
    return tuple(float(v) for v in np.round(burn, 0)) + (0.0,) * 10


THRUST_VALUES = _thrust_table()
#: Specific impulse (sea level), s, and standard gravity for the mass flow.
ISP = 230.0
G0 = 9.80665
#: Rail-exit state: downrange, altitude above sea level, speed, flight-path angle; mass.
PAD_ALTITUDE = 1400.0
M_START = 2400.0
START = (0.0, 1420.0, 30.0, math.radians(86.0))
DIAMETER = 0.6
#: Drag table knots in Mach and the truth.
CD_KNOTS = (0.0, 0.8, 1.05, 1.5, 2.5, 3.5)
CD_TRUTH = (0.30, 0.33, 0.56, 0.50, 0.38, 0.31)
#: Lift-curve slope knots in Mach and the truth, /rad.
CLA_KNOTS = (0.8, 3.0)
CLA_TRUTH = (10.0, 7.0)
#: Attitude program: commanded pitch angle, deg, every second.
PITCH_TIMES = tuple(float(t) for t in range(61))


def _pitch_program() -> tuple[float, ...]:
    t = np.arange(61.0)
    base = 86.0 - 25.0 * np.clip((t - 2.0) / 48.0, 0.0, 1.0)         # 86 deg held 2 s, then down to 61 at cutoff
    base = base - 0.2 * np.clip(t - T_CUTOFF, 0.0, None)                 # the coast: 0.2 deg/s
    wiggle = 1.0 * np.sin(2 * math.pi * (t - 2.0) / 8.0) * (t >= 2.0)   # excitation for the lift slope
    return tuple(float(v) for v in np.round(base + wiggle, 4))


PITCH_DEG = _pitch_program()
#: Measurement noise standard deviations (GNSS: horizontal, vertical, Doppler speed).
SIGMA = {"x": 3.0, "h": 4.0, "v": 0.15}


def build_model():
    """Petrel-V with CD(M) and CLa(M) alpha to estimate."""
    m = Model("Petrel-V", 0.0, TF)
    st = ascent_states(m, initial=START)
    fc = flight_conditions(m, st, atmosphere="us76")
    thrust = m.input("thrust_table", times=THRUST_TIMES, values=THRUST_VALUES)
    pitch = m.input("pitch_cmd", times=PITCH_TIMES, values=tuple(math.radians(d) for d in PITCH_DEG))
    mass = m.state("mass_kg", M_START)
    m.ode({mass: -thrust / (ISP * G0)})
    alpha = pitch - st.theta
    cd = m.table("CD", fc.mach, CD_KNOTS, 0.4, bounds=(0.05, 2.0), nominal=0.4)
    cla = m.table("CLa", fc.mach, CLA_KNOTS, 8.0, bounds=(0.0, 30.0), nominal=8.0)
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
    """10 Hz over the flight: t = 0.1 k s, k = 1..600."""
    return 0.1 * np.arange(1, 601)
