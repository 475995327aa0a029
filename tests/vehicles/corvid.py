"""Corvid-L: a guided liquid first stage flown from a stored pitch program, declared as a user would.

Written from the user documentation only (README.md, docs/own-vehicle.md, docs/telemetry.md,
docs/cli.md "Model files", ``rocketid.Model``, ``rocketid.physics.ascent`` and
``rocketid.physics.propulsion``), for the real-telemetry study (``tests/telemetry_study``). Unlike
the other test vehicles its thrust is a *commanded* throttle schedule (a known input: a max-q
bucket and an acceleration limit), its attitude a stored pitch program with lift, and its telemetry
comes as it really does: three channels at their own rates with drop-outs, no stated noise level,
acquired from T+12 s.

==============  ===============================================================
site            Andoya Spaceport, Norway, 69.29 N, launch azimuth 345 deg (a
                polar ascent over the Norwegian Sea); the model (and the
                study's truth) has a non-rotating spherical Earth and
                standard gravity -- what a user gets from the building blocks
time            seconds from lift-off (T+0); the model starts at lift-off from
                rest, vertical; the telemetry is acquired from T+12 s and
                fitted with ``--window 12:`` (the states at 12 s estimated)
mass            62 000 kg at lift-off; 340 kg/s at full throttle (kerosene /
                LOX), the mass in closed form from the throttle schedule
                (``throttled_propulsion``); 30.7 t at T+100 s
thrust          950 kN at full throttle, stated at sea level and held at every
                altitude (no nozzle term: a simple user model); commanded
                throttle 1 -> 0.72 over 42-46 s, held to 62 s, back to 1 at
                66 s (the max-q bucket), then 1 -> 0.8 over 86-90 s (an
                acceleration limit); a known input, not estimated
attitude        a stored pitch program phi(t) (body axis above the local
                horizon) every 1 s: vertical to 5 s, a 1.2 deg kick, a gravity
                turn at zero attack angle through max-q, then +2.5 deg of
                attack angle from 80 s (lofting); alpha = phi - theta
area            the body's cross-section, 2.1 m diameter (3.464 m^2)
drag            CD(M) piecewise linear on 9 knots from Mach 0.21 (the window's
                start) to 3.6 (just under the peak, 3.65): 0.32 subsonic,
                0.55 at Mach 1.2, 0.28 at Mach 3.6
lift            CL = CL_alpha alpha on the cross-section, CL_alpha 2.6 /rad
horizon         0 .. 100 s: Mach 1 at 42 s, max q 35.7 kPa at 45 s (in the
                bucket's ramp-down); at 100 s 28.9 km, 28.4 km downrange, 1098 m/s, Mach
                3.65, flight-path angle 29.2 deg
atmosphere      US Standard Atmosphere 1976 (density and speed of sound)
measurements    telemetry from T+12 s: speed (INS) at 10 Hz, 0.1 m/s steps;
                altitude (GNSS) at 2 Hz, 1 m steps; downrange (ground radar) at
                1 Hz, 1 m steps, absent over 40-48 s (the radar hand-over);
                drop-outs (3 % of the frames, a 2 s loss of signal at 57 s);
                noise not stated (the truth: 0.25 m/s, 6 m, 20 m)
==============  ===============================================================

Use it from the command line as ``--model tests/vehicles/corvid.py`` with ``--sigma estimate
--window 12:``.

Declaration notes:

- the throttle schedule is the flight computer's command, a known input: declared with
  ``throttle_schedule`` (its event times become element boundaries) and ``throttled_propulsion``
  (thrust and mass flow scaled together);
- the model starts at lift-off from rest, where its states are known; the telemetry starts at 12 s,
  so the fit is cut to the window 12:100 (docs/telemetry.md "A flight window that starts in flight":
  the states at 12 s are estimated, the mass at 12 s is the schedule's);
- the drag table starts at the Mach number of the window's start (0.21), not at 0: docs/own-vehicle.md
  says a knot below the start is never flown; below the first knot the table is held at its value;
- the channels carry no sigma: the sigmas declared on the outputs are placeholders (the study
  estimates every channel's with ``--sigma estimate``); ``SIGMA`` is the truth's noise, for the
  truth only.
"""

from __future__ import annotations

import math

import numpy as np

from rocketid import Model
from rocketid.physics.ascent import ascent_dynamics, ascent_states, flight_conditions
from rocketid.physics.propulsion import throttle_schedule, throttled_propulsion

#: Launch site (for the record: the model and the truth ignore the Earth's rotation).
SITE_LATITUDE_DEG = 69.29
SITE_AZIMUTH_DEG = 345.0
#: Horizon, s from lift-off; the telemetry's first time, s.
TF = 100.0
T_ACQUIRE = 12.0
#: Lift-off mass, kg; full-throttle thrust (sea level), N; full-throttle mass flow, kg/s.
M_LIFTOFF = 62_000.0
THRUST_FULL = 950_000.0
MASS_FLOW = 340.0
#: The commanded throttle schedule: event times (s) and settings (linear between, flat outside).
THROTTLE_TIMES = (42.0, 46.0, 62.0, 66.0, 86.0, 90.0)
THROTTLE_LEVELS = (1.0, 0.72, 0.72, 1.0, 1.0, 0.8)
#: The stored pitch program, deg above the local horizon, every 1 s from 0 to 100 s.
PITCH_STEP = 1.0
PITCH_DEG = (
    90.00, 90.00, 90.00, 90.00, 90.00, 90.00, 89.49, 88.77, 87.86, 87.22, 86.53, 86.26, 86.05, 85.91, 85.31,
    84.67, 84.01, 83.31, 82.66, 82.00, 81.32, 80.63, 79.93, 79.22, 78.49, 77.76, 77.02, 76.27, 75.52, 74.76,
    74.00, 73.28, 72.57, 71.86, 71.16, 70.46, 69.76, 69.01, 68.27, 67.53, 66.79, 66.05, 65.32, 64.59, 63.86,
    63.12, 62.39, 61.64, 60.89, 60.13, 59.37, 58.60, 57.83, 57.05, 56.27, 55.49, 54.70, 53.91, 53.12, 52.33,
    51.54, 50.75, 49.95, 49.16, 48.37, 47.59, 46.82, 46.07, 45.32, 44.59, 43.87, 43.16, 42.46, 42.10, 41.76,
    41.45, 41.17, 40.91, 40.68, 40.48, 40.29, 39.81, 39.35, 38.89, 38.44, 37.99, 37.56, 37.13, 36.71, 36.29,
    35.87, 35.46, 35.05, 34.65, 34.25, 33.86, 33.47, 33.09, 32.71, 32.34, 31.98)
PITCH_TIMES = tuple(PITCH_STEP * k for k in range(len(PITCH_DEG)))
#: Reference area, m^2: the body's cross-section.
DIAMETER = 2.1
S_REF = math.pi * DIAMETER ** 2 / 4
#: Drag table knots in Mach and the truth, on the cross-section; the lift slope's truth, 1/rad.
CD_KNOTS = (0.21, 0.6, 0.9, 1.05, 1.2, 1.5, 2.0, 2.8, 3.6)
CD_TRUTH = (0.32, 0.30, 0.36, 0.52, 0.55, 0.48, 0.40, 0.33, 0.28)
CL_ALPHA = 2.6
#: The truth's telemetry noise (never given to the diagnosis): speed m/s, altitude m, downrange m.
SIGMA = {"x": 20.0, "h": 6.0, "v": 0.25}
#: Quantization steps of the telemetry words.
QUANTUM = {"x": 1.0, "h": 1.0, "v": 0.1}
#: Channel rates (sample interval, s) and first sample time.
RATE = {"v": 0.1, "h": 0.5, "x": 1.0}


def pitch_program(t):
    """The stored pitch attitude (rad), interpolated linearly between the 1 s samples."""
    return np.radians(np.interp(t, PITCH_TIMES, PITCH_DEG))


def build_model():
    """Corvid-L: CD(Mach) on 9 knots and CL_alpha to estimate."""
    m = Model("Corvid-L", 0.0, TF, description="guided liquid first stage, throttle bucket, pitch program")
    st = ascent_states(m, initial=(0.0, 0.0, 0.0, math.radians(90.0)))          # lift-off from rest, vertical
    fc = flight_conditions(m, st, atmosphere="us76")
    phi = m.input("phi", times=PITCH_TIMES, values=np.radians(PITCH_DEG))
    alpha = m.define("alpha", phi - st.theta)
    throttle = throttle_schedule(m, THROTTLE_TIMES, THROTTLE_LEVELS)
    thrust, mass = throttled_propulsion(m, throttle, thrust=m.constant("P_full", THRUST_FULL),
                                        mass0=M_LIFTOFF, mass_flow=MASS_FLOW)
    cd = m.table("CD", fc.mach, CD_KNOTS, 0.4, bounds=(0.05, 2.0), nominal=0.4)
    cla = m.parameter("CL_alpha", 2.0, bounds=(0.0, 10.0))
    ascent_dynamics(m, st, fc, thrust=thrust, mass=mass, area=m.constant("S_ref", S_REF), cd=cd,
                    cl=cla * alpha, alpha=alpha)
    for s in (st.x, st.h, st.v):
        m.output(str(s), s, sigma=SIGMA[str(s)])          # placeholders: the study estimates them
    return m.freeze()


def truth(spec):
    """The true coefficients."""
    return {**{f"CD_{j}": v for j, v in enumerate(CD_TRUTH)}, "CL_alpha": CL_ALPHA}


def channel_times():
    """Each channel's nominal sample times before drop-outs: speed 10 Hz from 12.1 s, altitude 2 Hz from
    12.5 s, downrange 1 Hz from 13 s, all to 100 s."""
    return {name: np.round(T_ACQUIRE + dt * np.arange(1, int(round((TF - T_ACQUIRE) / dt)) + 1), 6)
            for name, dt in RATE.items()}


def sample_times():
    """The speed's 10 Hz tags (``rocketid simulate`` writes every channel at these)."""
    return channel_times()["v"]
