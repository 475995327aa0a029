"""Wren-H: a university team's hybrid-motor sounding rocket, declared as the team would from its static firing.

Written from the user documentation only (README.md, docs/own-vehicle.md, docs/telemetry.md, docs/cli.md
"Model files", ``rocketid.Model`` and ``rocketid.physics.ascent``), for the hybrid sounding-rocket study
(``tests/wren_study``). Unlike the other test vehicles its motor is a **hybrid** (nitrous oxide / paraffin):
its thrust decays through the burn as the oxidiser tank blows down and the fuel port opens, bends down at a
knee when the tank runs out of liquid and trails a long vapour tail-off; the team knows it only as the
**static firing's table** (thrust and propellant consumed, every 0.1 s). Its data are a **GPS log** at
10 Hz, the altitude three times noisier than the downrange, the noise not stated.

==============  ===============================================================
time            seconds from the run valve's opening (T+0, ignition), as on
                the static-firing stand; the model starts at rail exit
                (``T_RAIL``, 0.59 s), the GPS log at ``T_GPS`` = 2 s (the
                receiver re-acquires its fix after the launch's shock)
site            a desert launch site 1200 m above sea level (the altitude h is
                above sea level, as the GPS gives it and the atmosphere needs)
launcher        a 6.1 m rail at 85 deg elevation; the rail-exit speed (25.1
                m/s) from a 1-D integration of the static table along it
                (``rail_exit``)
mass            60.0 kg at ignition, weighed on the pad with 16.0 kg of N2O
                (the fill scale); less the propellant the static firing
                consumed by each time (a table every 0.1 s: the tank's load
                cell plus the paraffin weighed before and after), 41.1 kg
                when the tank is empty
thrust          the static firing's load cell (sea level, 20 C tank), every
                0.1 s (0.01 s through the ignition transient): 3.67 kN after
                the valve opens (0.2 s), decaying to 2.94 kN at
                9 s, a knee as the liquid runs out (9.2-10.5 s), a vapour
                tail-off to zero at 15.5 s (34.9 kN s)
area            the body's cross-section, 0.157 m (6.2 inch) diameter
drag            CD(M) piecewise linear on 8 knots from Mach 0.2 (the coast
                falls below it only in the last 3.6 s, to 0.156, at under
                0.75 kPa; the table holds its first value there) to 1.3 (just
                under the peak, 1.35 at 10.3 s), on the cross-section (one
                curve power-on and power-off: the team's design tool's)
attitude        fin-stabilized: zero attack angle (an input of zeros, no lift)
horizon         T_RAIL .. TF = 44 s: the coast to apogee (10.18 km above sea
                level at 44.2 s; the drogue fires there)
atmosphere      US Standard Atmosphere 1976 (density and speed of sound)
measurements    GPS at 10 Hz from 2 s to 44 s: downrange (great-circle
                distance from the pad), altitude above sea level, speed; 2 % of the fixes
                lost; noise not stated (the truth: 2.5 m, 7.5 m, 0.25 m/s)
==============  ===============================================================

Use it from the command line as ``--model tests/vehicles/wren.py`` with ``--sigma estimate``.

Declaration notes:

- the thrust and the consumed propellant are sampled inputs (``m.input``) read from the static firing's CSV
  (``wren_static_fire.csv``, next to this file); the mass is the launch mass less the consumed table. A
  hybrid's specific impulse changes through the burn (its O/F ratio shifts), so a mass burnt at ``thrust /
  (Isp g0)`` with one Isp would be wrong: the consumed mass is declared as measured;
- the model starts at rail exit, whose states the team computes from the table (``rail_exit``); the GPS log
  starts later, at 2 s, and the fit runs on the whole horizon (no window: the states at rail exit are known);
- every 0.5 s of the table inside the burn is declared an event (element boundaries: ``m.event``), as
  docs/own-vehicle.md advises for a fit that must reach the noise of precise data;
- the channels carry no sigma: the output sigmas declared are placeholders (the study estimates them).
"""

from __future__ import annotations

import functools
import math
from pathlib import Path

import numpy as np

from rocketid import Model
from rocketid.physics.ascent import ascent_dynamics, ascent_states, flight_conditions

HERE = Path(__file__).resolve().parent
STATIC_FIRE = HERE / "wren_static_fire.csv"
#: Standard gravity and the Earth's radius the building blocks use.
G0 = 9.80665
EARTH_RADIUS = 6_371_000.0
#: Launch site altitude above sea level (m), the rail (m, deg).
PAD_ALTITUDE = 1200.0
RAIL_LENGTH = 6.1
ELEVATION_DEG = 85.0
#: Launch mass (kg, weighed on the pad) and the N2O load (kg, the fill scale).
M_LAUNCH = 60.0
OX_LOAD = 16.0
#: Reference area: the body's cross-section, m^2.
DIAMETER = 0.157
S_REF = math.pi * DIAMETER ** 2 / 4
#: The GPS log: first fix after the launch, the horizon (apogee), the rate, the resolution of the log.
T_GPS = 2.0
TF = 44.0
GPS_DT = 0.1
RESOLUTION = {"x": 0.01, "h": 0.1, "v": 0.01}
#: The truth's GPS noise (never given to the diagnosis): downrange m, altitude m, speed m/s.
SIGMA = {"x": 2.5, "h": 7.5, "v": 0.25}
#: Drag table knots in Mach and the truth, on the cross-section; the team's design-tool guess.
CD_KNOTS = (0.2, 0.5, 0.8, 0.9, 1.0, 1.1, 1.2, 1.3)
CD_TRUTH = (0.45, 0.43, 0.46, 0.52, 0.64, 0.66, 0.63, 0.60)
CD_GUESS = 0.5
#: Events: every 0.5 s of the burn (the table's corners on element boundaries).
EVENT_STEP = 0.5


@functools.lru_cache(maxsize=1)
def static_fire():
    """The static firing's table: times (s), thrust (N), propellant consumed (kg)."""
    data = np.loadtxt(STATIC_FIRE, delimiter=",", skiprows=1)
    return data[:, 0], data[:, 1], data[:, 2]


def _air_at(h: float):
    """Density and speed of sound of the 1976 standard's lowest layer (the rail is at 1.2 km)."""
    H = 6_356_766.0 * h / (6_356_766.0 + h)
    T = 288.15 - 0.0065 * H
    p = 101_325.0 * (T / 288.15) ** 5.25588
    return p / (287.053 * T), math.sqrt(1.4 * 287.053 * T)


@functools.lru_cache(maxsize=1)
def rail_exit():
    """(time, speed, ...) at rail exit from the static table: ``dv/dt = (F - D)/m - g sin(E)`` along the rail
    once the thrust exceeds the weight's component, drag with the design tool's low-speed CD."""
    from scipy.integrate import solve_ivp
    t_tab, f_tab, c_tab = static_fire()
    sin_e = math.sin(math.radians(ELEVATION_DEG))

    def along(t, y):
        s, v = y
        h = PAD_ALTITUDE + s * sin_e
        rho, _ = _air_at(h)
        mass = M_LAUNCH - float(np.interp(t, t_tab, c_tab))
        g = G0 * (EARTH_RADIUS / (EARTH_RADIUS + h)) ** 2
        acc = (float(np.interp(t, t_tab, f_tab)) - 0.5 * rho * v * v * S_REF * CD_TRUTH[0]) / mass - g * sin_e
        return [v, acc] if (v > 0.0 or acc > 0.0) else [0.0, 0.0]

    out = lambda t, y: y[0] - RAIL_LENGTH  # noqa: E731
    out.terminal, out.direction = True, 1
    sol = solve_ivp(along, (0.0, 3.0), [0.0, 0.0], method="DOP853", rtol=1e-12, atol=1e-12, events=out,
                    max_step=0.01)
    return float(sol.t_events[0][0]), float(sol.y_events[0][0][1])


def build_model():
    """Wren-H: the drag table CD(Mach) to estimate."""
    t_tab, f_tab, c_tab = static_fire()
    t_rail, v_rail = rail_exit()
    elevation = math.radians(ELEVATION_DEG)
    m = Model("Wren-H", t_rail, TF, description="hybrid sounding rocket, static-firing table, GPS log")
    st = ascent_states(m, initial=(RAIL_LENGTH * math.cos(elevation), PAD_ALTITUDE + RAIL_LENGTH * math.sin(elevation),
                                   v_rail, elevation))
    fc = flight_conditions(m, st, atmosphere="us76")
    thrust = m.input("thrust_table", times=tuple(t_tab) + (TF,), values=tuple(f_tab) + (0.0,))
    consumed = m.input("consumed", times=tuple(t_tab) + (TF,), values=tuple(c_tab) + (float(c_tab[-1]),))
    burn_end = float(t_tab[np.flatnonzero(f_tab > 0)[-1]]) + EVENT_STEP
    for t_event in np.arange(EVENT_STEP, burn_end + 1e-9, EVENT_STEP):
        if t_rail < t_event < TF:
            m.event(float(t_event))
    alpha = m.input("alpha", times=(0.0, TF), values=(0.0, 0.0))        # fin-stabilized: no attack angle
    cd = m.table("CD", fc.mach, CD_KNOTS, CD_GUESS, bounds=(0.05, 3.0), nominal=CD_GUESS)
    ascent_dynamics(m, st, fc, thrust=thrust, mass=M_LAUNCH - consumed, area=m.constant("S_ref", S_REF), cd=cd,
                    cl=0 * alpha, alpha=alpha)
    for s in (st.x, st.h, st.v):
        m.output(str(s), s, sigma=SIGMA[str(s)])             # placeholders: the study estimates them
    return m.freeze()


def truth(spec):
    """The true coefficients."""
    return {f"CD_{j}": v for j, v in enumerate(CD_TRUTH)}


def gps_times():
    """The GPS's 10 Hz tags from ``T_GPS`` to ``TF``."""
    return np.round(T_GPS + GPS_DT * np.arange(int(round((TF - T_GPS) / GPS_DT)) + 1), 6)


def sample_times():
    """The GPS tags (``rocketid simulate`` writes every channel at these)."""
    return gps_times()
