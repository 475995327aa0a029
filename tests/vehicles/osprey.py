"""Osprey-A: an air-launched winged first stage (Pegasus-like), declared as a user would.

Written from the user documentation only (docs/own-vehicle.md, docs/getting-started.md "Your own
model", docs/cli.md "Model files", ``rocketid.Model`` and ``rocketid.physics.ascent``), for the
air-launch study (``tests/airlaunch_study``). Unlike every other test vehicle it does not start on
the ground: the carrier aircraft drops it, and the simulation starts at first-stage ignition, in
flight, slightly descending.

==============  ===============================================================
start           ignition after the drop: x = 0, h = 11 800 m, v = 236 m/s
                (Mach 0.80), flight-path angle -1.5 deg
mass            19 500 kg at ignition, a state burnt at thrust / (Isp g0),
                Isp 268 s (the sea-level figure that goes with the table)
thrust          a solid motor's sea-level static-firing table, one value per
                second over 0..72 s: 540 kN at ignition, 585 kN at 2 s, falling
                to 470 kN at 60 s, tail-off from 63 s (13.5 t burnt by 68 s)
areas           reference area the body's cross-section (1.27 m diameter,
                1.267 m^2); the wing's planform 12 m^2
drag            CD(M) piecewise linear on knots 0.8 (the ignition Mach number)
                .. 9, on the body's cross-section: 0.62 at Mach 0.8, 1.05 at
                1.25, falling to 0.42 at Mach 9
wing            lift CL_wing = CLa(M) alpha on the wing's area, CLa a three-knot
                Mach table (3.5 /rad subsonic, 2.4 at Mach 2, 1.1 at Mach 5);
                declared on the body's reference area as
                CL = (S_wing / S_ref) CLa(M) alpha
attitude        a pitch-attitude program phi(t) sampled every 0.5 s: a pull-up
                from 5 deg to 37 deg over 1..21 s (smooth), held, then pitched
                down at 0.3 deg/s from 31 s, with a +-1 deg excitation of
                period 9 s; the attack angle alpha = phi - theta is a definition
                (up to 15 deg in the pull-up; the path angle dips to -2.6 deg,
                then climbs to 33 deg)
horizon         0 .. 68 s (the first-stage burn into its tail-off): burn-out at
                54.5 km, 2.9 km/s, Mach 8.9, 6.0 t; max q 79 kPa at 22 s
atmosphere      US Standard Atmosphere 1976 (density and speed of sound)
measurements    x, h, v at 20 Hz, sigma 2 m, 2 m, 0.2 m/s
==============  ===============================================================

Use it from the command line as ``--model tests/vehicles/osprey.py``.

Declaration notes (what the first diagnoses taught): drag was first written on the wing's area
(CD 0.04-0.11), and ``rocketid diagnose`` then called the true drag at Mach 6.5 and 9 (0.048,
0.044) implausible ("outside the plausible range 0.05-1.5 of a launch vehicle's drag
coefficient"), so no found effect could be "explained"; the reference area is now the body's
cross-section, the usual one for a launch vehicle, and the wing's area enters the lift only. The
drag table first had a knot at Mach 0.7, below the ignition Mach number 0.8, never flown (its
standard error was as large as its value); the table now starts at 0.8.
"""

from __future__ import annotations

import math

import numpy as np

from rocketid import Model
from rocketid.physics.ascent import ascent_dynamics, ascent_states, flight_conditions

#: Horizon, s.
TF = 68.0
#: Ignition state after the drop: downrange, altitude, speed, flight-path angle.
START = (0.0, 11_800.0, 236.0, math.radians(-1.5))
#: Mass at ignition, kg; sea-level specific impulse, s; standard gravity.
M_START = 19_500.0
ISP = 268.0
G0 = 9.80665
#: Thrust table (sea-level static firing), N, at t = 0, 1, ..., 72 s.
THRUST_TIMES = tuple(float(t) for t in range(73))
THRUST_VALUES = tuple(float(v) for v in np.round(
    np.interp(np.arange(73.0),
              [0.0, 2.0, 8.0, 20.0, 35.0, 50.0, 60.0, 63.0, 66.0, 69.0, 72.0],
              [540.0e3, 585.0e3, 580.0e3, 560.0e3, 530.0e3, 500.0e3, 470.0e3, 455.0e3, 380.0e3, 180.0e3, 30.0e3]), 1))
#: Reference area, m^2: the body's cross-section (1.27 m diameter); the wing's planform area.
DIAMETER = 1.27
S_REF = math.pi * DIAMETER ** 2 / 4
S_WING = 12.0
#: Drag table knots in Mach (from the ignition Mach number) and the truth, on the body's cross-section.
CD_KNOTS = (0.8, 1.0, 1.25, 1.6, 2.2, 3.0, 4.5, 6.5, 9.0)
CD_TRUTH = (0.62, 0.98, 1.05, 0.93, 0.78, 0.64, 0.53, 0.45, 0.42)
#: Lift-curve slope knots in Mach and the truth, /rad, on the wing's area.
CLA_KNOTS = (0.8, 2.0, 5.0)
CLA_TRUTH = (3.5, 2.4, 1.1)
#: Attitude program sample interval, s.
PROGRAM_STEP = 0.5
#: Measurement noise standard deviations.
SIGMA = {"x": 2.0, "h": 2.0, "v": 0.2}


def pitch_program(t) -> np.ndarray:
    """Commanded pitch attitude phi (rad) at ``t`` (s)."""
    t = np.asarray(t, float)
    u = np.clip((t - 1.0) / 20.0, 0.0, 1.0)
    pull_up = 32.0 * (3 * u ** 2 - 2 * u ** 3)                   # 5 -> 37 deg over 1..21 s, smooth
    down = 0.3 * np.clip(t - 31.0, 0.0, None)                    # then 0.3 deg/s down from 31 s
    wiggle = 1.0 * np.sin(2 * math.pi * t / 9.0)                 # excitation for the lift slope
    return np.radians(5.0 + pull_up - down + wiggle)


def program_table() -> tuple[np.ndarray, np.ndarray]:
    """The sampled attitude program (times, phi) every PROGRAM_STEP s."""
    tt = np.arange(0.0, TF + 1e-9, PROGRAM_STEP)
    return tt, pitch_program(tt)


def build_model():
    """Osprey-A: CD(Mach) and CL_alpha(Mach) tables to estimate."""
    m = Model("Osprey-A", 0.0, TF, description="air-launched winged solid stage, ignition at 11.8 km, Mach 0.8")
    st = ascent_states(m, initial=START)
    fc = flight_conditions(m, st, atmosphere="us76")
    thrust = m.input("thrust_table", times=THRUST_TIMES, values=THRUST_VALUES)
    tt, phi_values = program_table()
    phi = m.input("phi", times=tt, values=phi_values)
    mass = m.state("mass_kg", M_START)
    m.ode({mass: -thrust / (ISP * G0)})
    alpha = m.define("alpha", phi - st.theta)
    cd = m.table("CD", fc.mach, CD_KNOTS, 0.7, bounds=(0.05, 3.0), nominal=0.7)
    cla = m.table("CLa", fc.mach, CLA_KNOTS, 3.0, bounds=(0.0, 10.0), nominal=3.0)
    # lift on the wing's area, written on the body's reference area: CL_ref = (S_wing / S_ref) CLa alpha
    s_ref = m.constant("S_ref", S_REF)
    cl = m.constant("S_wing", S_WING) / s_ref * cla * alpha
    ascent_dynamics(m, st, fc, thrust=thrust, mass=mass, area=s_ref, cd=cd, cl=cl, alpha=alpha)
    for s in (st.x, st.h, st.v):
        m.output(str(s), s, sigma=SIGMA[str(s)])
    return m.freeze()


def truth(spec):
    """The true coefficients."""
    values = {f"CD_{j}": v for j, v in enumerate(CD_TRUTH)}
    values.update({f"CLa_{j}": v for j, v in enumerate(CLA_TRUTH)})
    return values


def sample_times():
    """20 Hz over the burn: t = 0.05 k s, k = 1..1360."""
    return 0.05 * np.arange(1, 1361)
