"""Auk-B: a liquid core stage with two strap-on solid boosters jettisoned in flight, declared as a user would.

Written from the user documentation only (README.md, docs/own-vehicle.md, docs/getting-started.md,
docs/cli.md "Model files", the catalogue table of docs/effects.md for the effect names, and the
docstrings of ``rocketid.Model``, ``rocketid.physics.ascent``, ``rocketid.physics.propulsion`` and
``rocketid.tables``) for the booster study (``tests/auk_study``). What is new among the test vehicles:
two strap-on boosters whose burnt-out casings leave the vehicle at a known time -- a **step** in the
mass and in the reference area -- beside a throttled liquid core.

==============  ===============================================================
time            seconds from lift-off (t = 0): the core engine and both
                boosters are at thrust when the hold-downs release
start           a sea-level pad at rest: x = 0, h = 0, v = 0, flight-path
                angle 90 deg (vertical)
mass            60 000 kg at lift-off: the core stage with everything above
                it 48 207 kg loaded, two boosters 5 896 kg each (4 296 kg of
                grain, a 1 600 kg casing)
core engine     600 kN at full throttle and 210 kg/s (Isp 291 s), stated at
                every altitude; a commanded max-q bucket (a known input):
                100 % -> 75 % over 28-30 s, held to 43 s, back to 100 % at
                45 s; thrust and mass flow together (``throttle_schedule``,
                ``throttled_propulsion``: the core's mass in closed form)
boosters        each a solid motor's thrust table, every 0.5 s (a static
                firing): 330 kN at lift-off, 345 kN at 1.5 s, regressive to
                250 kN at 18 s, progressive to 300 kN at 32 s, tail-off from
                33.5 s to zero at 38 s; the grain burnt at thrust / (Isp g0),
                Isp 245 s (the grain a state); 10.32 MN s each
jettison        both casings (2 x 1 600 kg) and whatever grain is left leave
                the vehicle at T_SEP = 40 s; the reference area shrinks from
                the core's and the boosters' cross-sections (2.2 m + 2 x 1.0 m
                diameters, 5.372 m^2) to the core's (3.801 m^2)
drag            CD(M) piecewise linear on 7 knots, Mach 0 .. 3.4, on the
                current cross-section (one curve with and without boosters)
lift            CL_alpha * alpha on the same area, alpha = phi - theta
attitude        a sampled pitch-attitude program phi(t), every 1 s: vertical
                for 6 s, a 7 deg kick over 6-10 s, a gravity-turn-like
                pitch-down to about 30 deg at 110 s, and a +-0.8 deg
                excitation of period 10 s from 12 s (for the lift slope)
horizon         0 .. 110 s: Mach 1 near 28 s, max q 47 kPa near 34 s (the
                bucket); separation at 40 s at 8.8 km, 402 m/s, Mach 1.32;
                at 110 s 41.7 km, 34.5 km downrange, 1.12 km/s, Mach 3.5,
                25.9 t
atmosphere      US Standard Atmosphere 1976 (density and speed of sound)
measurements    x, h, v from a GNSS receiver at 10 Hz (t = 0.1 .. 110 s,
                1100 samples), sigma 5 m, 8 m, 0.3 m/s
==============  ===============================================================

Use it from the command line as ``--model tests/vehicles/auk.py``.

How the jettison is declared. The user documentation has no block for a mass that drops at a known time:
``own-vehicle.md`` writes masses as expressions of ``m.t`` (``12_000.0 - 110.0 * m.t``) or as a state;
``Model.event`` says "Declare an event time (a throttle change, a staging): the right-hand side may have a
kink there, so the default mesh puts an element boundary and the simulator a stop at it"; and
``Model.input`` takes "``expr`` (a SymPy expression of ``m.t``)" with ``breakpoints``. So the boosters'
presence is a known input written as a SymPy ``Piecewise`` of time, ``attached = 1`` for ``t <= 40`` and 0
after, with ``breakpoints=[40]`` and ``m.event(40)``; the mass is the core's closed form plus
``attached * (grain left + casings)`` and the area ``S_core + attached * 2 S_booster``. Whether a *step*
(not a kink) at an event is allowed, and on which side of the element boundary the step's value is taken
(``t <= 40`` here: the element that ends at 40 s sees the boosters on), the docs do not say; this model
relies on the event's element boundary.
"""

from __future__ import annotations

import math

import numpy as np
import sympy as sp

from rocketid import Model
from rocketid.physics.ascent import ascent_dynamics, ascent_states, flight_conditions
from rocketid.physics.propulsion import throttle_schedule, throttled_propulsion

#: Horizon, s.
TF = 110.0
G0 = 9.80665
#: Lift-off state: downrange, altitude, speed, flight-path angle (at rest on a sea-level pad, vertical).
START = (0.0, 0.0, 0.0, math.radians(90.0))

#: Core engine: full-throttle thrust (N, every altitude) and mass flow (kg/s).
CORE_THRUST = 600.0e3
CORE_MASS_FLOW = 210.0
#: The commanded throttle schedule of the core (max-q bucket): event times (s) and settings.
THROTTLE_TIMES = (28.0, 30.0, 43.0, 45.0)
THROTTLE_LEVELS = (1.0, 0.75, 0.75, 1.0)

#: Strap-on boosters: number, thrust table of ONE booster (static firing, N) every 0.5 s over 0..40 s.
N_BOOSTERS = 2
BOOSTER_ISP = 245.0
_BOOSTER_CORNERS = ((0.0, 330.0e3), (1.5, 345.0e3), (6.0, 320.0e3), (18.0, 250.0e3), (26.0, 275.0e3),
                    (32.0, 300.0e3), (33.5, 290.0e3), (36.0, 120.0e3), (38.0, 0.0))
BOOSTER_TIMES = tuple(float(t) for t in np.arange(0.0, 40.01, 0.5))
BOOSTER_THRUST = tuple(float(v) for v in np.round(np.interp(BOOSTER_TIMES, *zip(*_BOOSTER_CORNERS)), 1))
#: Burn-out of the boosters (thrust zero from here), s.
T_BURNOUT = 38.0
#: Grain of one booster, kg: the table's total impulse / (Isp g0) (4296 kg).
BOOSTER_GRAIN = float(np.trapezoid(BOOSTER_THRUST, BOOSTER_TIMES) / (BOOSTER_ISP * G0))
#: Burnt-out casing of one booster, kg.
BOOSTER_CASING = 1600.0
#: Separation (jettison of both boosters), s.
T_SEP = 40.0

#: Lift-off mass, kg, and the core stage's share (the core, the upper stage and payload, loaded).
M_LIFTOFF = 60_000.0
M_CORE = M_LIFTOFF - N_BOOSTERS * (BOOSTER_GRAIN + BOOSTER_CASING)

#: Cross-sections, m^2: the core's (2.2 m) and one booster's (1.0 m).
D_CORE = 2.2
D_BOOSTER = 1.0
S_CORE = math.pi * D_CORE ** 2 / 4
S_BOOSTER = math.pi * D_BOOSTER ** 2 / 4

#: Drag table knots in Mach and the truth (on the current cross-section).
CD_KNOTS = (0.0, 0.8, 1.05, 1.3, 1.8, 2.5, 3.4)
CD_TRUTH = (0.30, 0.33, 0.55, 0.52, 0.43, 0.35, 0.29)
#: Lift-curve slope, /rad, on the same area.
CLA_TRUTH = 3.0

#: Attitude program, sampled every PITCH_STEP s.
PITCH_STEP = 1.0
#: Measurement noise standard deviations (GNSS: horizontal, vertical, Doppler speed).
SIGMA = {"x": 5.0, "h": 8.0, "v": 0.3}


def pitch_program(t) -> np.ndarray:
    """Commanded pitch attitude phi (rad) at ``t`` (s): vertical 6 s, a 7 deg kick over 6-10 s, a cubic
    pitch-down, a +-0.8 deg excitation of period 10 s from 12 s."""
    t = np.asarray(t, float)
    u = np.clip((t - 10.0) / 100.0, 0.0, None)
    deg = np.where(t < 10.0, 90.0 - 7.0 * np.clip((t - 6.0) / 4.0, 0.0, 1.0),
                   83.0 - 42.0 * u - 30.0 * u ** 2 + 20.0 * u ** 3)
    deg = deg + 0.8 * np.sin(2 * math.pi * (t - 12.0) / 10.0) * (t >= 12.0)
    return np.radians(np.round(deg, 3))


def program_table() -> tuple[np.ndarray, np.ndarray]:
    """The sampled attitude program (times, phi), every PITCH_STEP s over the horizon."""
    tt = np.arange(0.0, TF + 1e-9, PITCH_STEP)
    return tt, pitch_program(tt)


def build_model():
    """Auk-B: CD(Mach) and CL_alpha to estimate."""
    m = Model("Auk-B", 0.0, TF, description="liquid core with two strap-on solid boosters jettisoned at 40 s")
    st = ascent_states(m, initial=START)
    fc = flight_conditions(m, st, atmosphere="us76")
    tt, phi_values = program_table()
    phi = m.input("phi", times=tt, values=phi_values)
    alpha = m.define("alpha", phi - st.theta)

    # the core: a commanded max-q bucket, thrust and mass flow together, the core's mass in closed form
    throttle = throttle_schedule(m, THROTTLE_TIMES, THROTTLE_LEVELS)
    core_thrust, core_mass = throttled_propulsion(m, throttle, thrust=m.constant("P_core", CORE_THRUST),
                                                  mass0=M_CORE, mass_flow=CORE_MASS_FLOW)
    # the boosters: a static-firing table each, the grain a state burnt at thrust / (Isp g0)
    booster = m.input("booster_thrust", times=BOOSTER_TIMES, values=BOOSTER_THRUST)
    grain = m.state("booster_grain", N_BOOSTERS * BOOSTER_GRAIN)
    m.ode({grain: -N_BOOSTERS * booster / (BOOSTER_ISP * G0)})
    # the jettison: the boosters are on the vehicle up to T_SEP, then their casings and any grain left go
    attached = m.input("boosters_attached", sp.Piecewise((1.0, m.t <= T_SEP), (0.0, True)), breakpoints=[T_SEP])
    m.event(T_SEP)
    mass = core_mass + attached * (grain + N_BOOSTERS * BOOSTER_CASING)
    area = m.constant("S_core", S_CORE) + attached * N_BOOSTERS * m.constant("S_booster", S_BOOSTER)

    cd = m.table("CD", fc.mach, CD_KNOTS, 0.4, bounds=(0.05, 2.0), nominal=0.4)
    cla = m.parameter("CL_alpha", 2.0, bounds=(0.0, 10.0), nominal=2.0)
    ascent_dynamics(m, st, fc, thrust=core_thrust + N_BOOSTERS * booster, mass=mass, area=area, cd=cd,
                    cl=cla * alpha, alpha=alpha)
    for s in (st.x, st.h, st.v):
        m.output(str(s), s, sigma=SIGMA[str(s)])
    return m.freeze()


def truth(spec):
    """The true coefficients."""
    values = {f"CD_{j}": v for j, v in enumerate(CD_TRUTH)}
    values["CL_alpha"] = CLA_TRUTH
    return values


def sample_times():
    """10 Hz over the flight: t = 0.1 k s, k = 1..1100."""
    return 0.1 * np.arange(1, 1101)
