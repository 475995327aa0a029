"""Tern-2: a fin-stabilized single-stage sounding rocket, declared as a user would.

Written from the user documentation only (docs/own-vehicle.md, docs/getting-started.md "Your own
model", docs/cli.md "Model files", ``rocketid.Model`` and ``rocketid.physics.ascent``), for the
sounding-rocket study (``tests/sounding_study``). Unlike the other test vehicles it burns for a
few seconds and then coasts unpowered for most of the data: the drag is seen first under thrust
at low altitude, then alone through the long coast.

==============  ===============================================================
time            seconds from ignition (T+0); the data start at rail exit,
                T+0.5 s, and run to T+60 s
start           rail exit: x = 0, h = 9 m, v = 37.6 m/s (Mach 0.11),
                flight-path angle 84 deg (the launcher's elevation; a 7 m
                rail, the exit speed from a 1-D integration along it)
mass            810 kg at ignition, a state burnt at thrust / (Isp g0),
                Isp 242 s (the sea-level figure of the static firing);
                795.7 kg at rail exit (14.3 kg burnt on the rail), 423 kg
                after burn-out (387 kg of propellant)
thrust          a sea-level static-firing table every 0.25 s over 0..10.5 s:
                ignition transient 0 -> 88 kN in 0.25 s, progressive to
                114 kN at 4 s, regressive to 98 kN at 7.75 s, tail-off to 0
                at 10.25 s (burn-out; 0.918 MN s); zero after that
area            the body's cross-section, 0.38 m diameter (0.1134 m^2)
drag            CD(M) piecewise linear on 11 knots from 0.11 (the rail-exit
                Mach number) to 3.8 (just under the peak), on the
                cross-section: 0.40 subsonic, 0.74 at Mach 1.1, 0.31 at Mach
                3.8; one curve power-on and power-off
attitude        fin-stabilized: it flies at zero attack angle (a known input
                alpha = 0, no lift); the path is a gravity turn from the rail
horizon         0.5 .. 60 s: max q 549 kPa at 8.7 s; peak Mach 3.90 (1.24
                km/s) at 9.45 s and 5.9 km; burn-out at 10.25 s, 6.9 km, Mach
                3.86; the coast to 45.6 km, 531 m/s, Mach 1.62 and a path
                angle of 75 deg at 60 s, still climbing (7.8 km downrange)
atmosphere      US Standard Atmosphere 1976 (density and speed of sound)
measurements    x, h, v from a tracking radar at 20 Hz (t = 0.55 .. 60 s,
                1190 samples), sigma 3 m, 3 m, 0.3 m/s
==============  ===============================================================

Use it from the command line as ``--model tests/vehicles/tern.py``.

Declaration notes (what checking it against its truth taught):

- the time axis is the motor's, from ignition, and the model starts at rail exit (``Model(...,
  T_RAIL, TF)``, the thrust table from 0): a static firing and a radar both count from ignition, and
  the mass at rail exit is the launch mass less what burnt on the rail;
- on the default mesh (about 1 s elements) the base model fitted to *noise-free* truth data left a
  misfit of 2J = 54 with ``CD_10`` 3.4 standard errors off: the thrust table has a kink at every
  0.25 s sample and the mesh puts element boundaries only at family breakpoints and events, not at a
  sampled input's sample times. Declaring every sample in the burn an event (``m.event``) puts the
  boundaries there (0.25 s elements in the burn, 1 s in the coast): 2J = 0.001 on noise-free data (the default
  mesh has since put a sampled input's sharp corners on boundaries: 2J = 4.3 without the events);
- the attack angle is an input held at 0 and the lift coefficient ``0 * alpha``: with no lift and no
  excitation there is nothing to estimate but CD(M), which the boost (under thrust, low and dense)
  and the coast (alone, high and thin) both see over Mach 1.6-3.9; the subsonic knots are seen only
  in the first two seconds at low dynamic pressure and are loosely determined (standard errors
  0.04-0.12);
- the Mach table ends at 3.8, not at 4 or more: the table is held constant beyond its last knot, and
  a knot above the peak Mach number (3.90) would never be flown.
"""

from __future__ import annotations

import math

import numpy as np

from rocketid import Model
from rocketid.physics.ascent import ascent_dynamics, ascent_states, flight_conditions

#: Standard gravity, m/s^2; sea-level specific impulse of the static firing, s.
G0 = 9.80665
ISP = 242.0
#: Thrust table (sea-level static firing), N, every 0.25 s from ignition; zero after burn-out.
THRUST_STEP = 0.25
_THRUST_SHAPE = ((0.0, 0.0), (0.1, 55.0), (0.25, 88.0), (0.5, 96.0), (1.0, 100.0), (2.0, 106.0),
                 (3.0, 111.0), (4.0, 114.0), (5.0, 113.0), (6.0, 109.0), (7.0, 103.0), (7.75, 98.0),
                 (8.25, 85.0), (8.75, 52.0), (9.25, 20.0), (9.75, 5.0), (10.25, 0.0))     # (s, kN)
THRUST_TIMES = tuple(float(t) for t in np.arange(0.0, 10.5 + 1e-9, THRUST_STEP))
THRUST_VALUES = tuple(float(v) for v in np.round(
    1e3 * np.interp(THRUST_TIMES, [a for a, _ in _THRUST_SHAPE], [b for _, b in _THRUST_SHAPE]), 0))
#: Burn-out (the tail-off reaches zero), s.
T_BURNOUT = 10.25
#: Rail exit (the data's start), s after ignition, and the horizon.
T_RAIL = 0.5
TF = 60.0
#: Mass at ignition, kg (at rail exit, M_START, the propellant burnt on the rail is taken off).
M_LAUNCH = 810.0


def burnt(t: float, k: float = 1.0) -> float:
    """Propellant burnt from ignition to ``t`` (kg) by the thrust table on a clock ``k`` times faster
    (``k P(k t)``: the burnt mass is the table's impulse up to ``k t``), trapezoids on the table."""
    tt = np.asarray(THRUST_TIMES)
    pp = np.asarray(THRUST_VALUES)
    u = k * t
    grid = np.append(tt[tt < u], u)
    return float(np.trapezoid(np.interp(grid, tt, pp), grid)) / (ISP * G0)


M_START = M_LAUNCH - burnt(T_RAIL)
#: Rail-exit state: downrange, altitude, speed, flight-path angle (the launcher's elevation).
ELEVATION = math.radians(84.0)
START = (0.0, 9.0, 37.6, ELEVATION)
#: Reference area, m^2: the body's cross-section.
DIAMETER = 0.38
S_REF = math.pi * DIAMETER ** 2 / 4
#: Drag table knots in Mach (from the rail-exit Mach number) and the truth, on the cross-section.
CD_KNOTS = (0.11, 0.6, 0.9, 1.1, 1.3, 1.6, 2.0, 2.5, 3.0, 3.4, 3.8)
CD_TRUTH = (0.40, 0.38, 0.47, 0.74, 0.70, 0.61, 0.52, 0.44, 0.38, 0.34, 0.31)
#: Measurement noise standard deviations of the tracking radar.
SIGMA = {"x": 3.0, "h": 3.0, "v": 0.3}
#: Sample interval, s (20 Hz).
DT = 0.05


def build_model():
    """Tern-2: the drag table CD(Mach) to estimate."""
    m = Model("Tern-2", T_RAIL, TF, description="fin-stabilized sounding rocket, 10 s solid burn, coast to 60 s")
    st = ascent_states(m, initial=START)
    fc = flight_conditions(m, st, atmosphere="us76")
    thrust = m.input("thrust_table", times=THRUST_TIMES + (TF,), values=THRUST_VALUES + (0.0,))
    for t_kink in THRUST_TIMES:                  # the table has a kink at every sample: element boundaries there
        if T_RAIL < t_kink < TF:
            m.event(t_kink)
    alpha = m.input("alpha", times=(0.0, TF), values=(0.0, 0.0))          # fin-stabilized: no attack angle
    mass = m.state("mass_kg", M_START)
    m.ode({mass: -thrust / (ISP * G0)})
    cd = m.table("CD", fc.mach, CD_KNOTS, 0.45, bounds=(0.05, 3.0), nominal=0.45)
    ascent_dynamics(m, st, fc, thrust=thrust, mass=mass, area=m.constant("S_ref", S_REF), cd=cd,
                    cl=0 * alpha, alpha=alpha)
    for s in (st.x, st.h, st.v):
        m.output(str(s), s, sigma=SIGMA[str(s)])
    return m.freeze()


def truth(spec):
    """The true coefficients."""
    return {f"CD_{j}": v for j, v in enumerate(CD_TRUTH)}


def sample_times():
    """20 Hz from the first tag after rail exit: t = 0.05 k s, k = 11..1200."""
    return DT * np.arange(11, 1201)
