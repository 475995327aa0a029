"""The truth of the sounding-rocket study: Tern-2 flown in another state space, hidden effects included.

rocketid's model (``tests/vehicles/tern.py``) integrates downrange, altitude, speed and
flight-path angle over a spherical, non-rotating Earth. This truth integrates **three-dimensional
position and velocity** about the Earth's centre with **vector forces**, in the launch frame:
``e1`` the horizontal along the launch azimuth at the rail, ``e2`` the local vertical there,
``e3 = e1 x e2``; the Earth's centre is the origin and the rail exit ``(0, Re + h0, 0)``.

- gravity ``-GM r / |r|^3`` (``GM = g0 Re^2``, ``Re`` = 6 371 km: rocketid's spherical Earth);
- the vehicle is fin-stabilized: with no wind its body is on the flight path (zero attack
  angle, no lift: the model's assumption), the thrust along the velocity and the drag
  ``q S CD(M)`` against it. In a wind ``W(h)`` (horizontal, positive downrange) the airflow is
  ``V_air = V - W(h) e_h`` (``e_h`` the local horizontal in the launch plane) and the rocket
  **weathercocks**: its body turns toward the airflow as a lightly damped pendulum of its static
  margin (two more states, ``Flight.weathercock``), the thrust along the body, the fins' normal
  force across the airflow, the drag against it; Mach number and dynamic pressure from the
  airspeed;
- the motor: the sea-level static-firing table ``P_tab(t)`` from ignition, the mass flow
  ``P_tab / (Isp g0)``; the mass at the data's start (rail exit, ``T_RAIL``) is the launch mass
  less the propellant the motor burnt on the rail;
- in the rotating case, the Coriolis ``-2 Omega x V`` and centrifugal ``-Omega x (Omega x r)``
  accelerations of the Earth-fixed frame, in three dimensions (the flight leaves the launch
  plane).

The atmosphere is this file's own US Standard Atmosphere 1976 (``Air``): the standard's layer
table of base geopotential altitudes and lapse rates, the base pressures found by integrating the
hydrostatic equation layer by layer from 101 325 Pa, a temperature offset over the whole column
when hidden (the ground pressure kept). The outputs: ``x`` the arc along the Earth's surface of
the position projected on the launch plane, ``h`` the height above the sphere, ``v`` the speed in
the Earth-fixed frame.

Every hidden effect is written in its own physical shape (``Hidden``); none is the catalogue's.
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

_VEHICLES = Path(__file__).resolve().parent.parent / "vehicles"
if str(_VEHICLES) not in sys.path:
    sys.path.insert(0, str(_VEHICLES))

import tern as V  # noqa: E402
from study_harness import with_noise  # noqa: E402

import rocketid as ri  # noqa: E402

# ---------------------------------------------------------------- constants
EARTH_RADIUS = 6_371_000.0        # m, the sphere of the trajectory
STD_GRAVITY = 9.80665             # m/s^2
MU = STD_GRAVITY * EARTH_RADIUS ** 2
EARTH_RATE = 7.2921159e-5         # rad/s, sidereal

# US Standard Atmosphere 1976 (NOAA-S/T 76-1562): defining constants and the lower layers
GAS_CONSTANT = 8.31432            # J/(mol K), the standard's R*
MOLAR_MASS = 0.0289644            # kg/mol
HEAT_RATIO = 1.4
GEOPOTENTIAL_RADIUS = 6_356_766.0  # m
SEA_LEVEL_PRESSURE = 101_325.0    # Pa
SEA_LEVEL_TEMPERATURE = 288.15    # K
#: layer base geopotential altitude (km') and temperature gradient (K/km') up to the mesopause region
LAYER_TABLE = ((0.0, -6.5), (11.0, 0.0), (20.0, 1.0), (32.0, 2.8), (47.0, 0.0), (51.0, -2.8), (71.0, -2.0),
               (84.852, 0.0))
_HYDRO = STD_GRAVITY * MOLAR_MASS / GAS_CONSTANT       # K/m: g0 M / R*


class Air:
    """The 1976 standard's temperature profile plus ``offset`` K everywhere, the ground pressure the
    standard's; pressure from the hydrostatic equation in closed form per layer; density from the
    ideal gas law; speed of sound from the temperature."""

    def __init__(self, offset: float = 0.0):
        self.offset = offset
        self.base_h = np.array([1000.0 * b for b, _ in LAYER_TABLE])
        self.grad = np.array([g / 1000.0 for _, g in LAYER_TABLE])
        temps, press = [SEA_LEVEL_TEMPERATURE + offset], [SEA_LEVEL_PRESSURE]
        for j in range(len(LAYER_TABLE) - 1):
            thickness = self.base_h[j + 1] - self.base_h[j]
            press.append(self._pressure(temps[j], press[j], self.grad[j], thickness))
            temps.append(temps[j] + self.grad[j] * thickness)
        self.base_t, self.base_p = np.array(temps), np.array(press)

    @staticmethod
    def _pressure(t_base: float, p_base: float, grad: float, dh: float) -> float:
        if grad == 0.0:
            return p_base * math.exp(-_HYDRO * dh / t_base)
        return p_base * (1.0 + grad * dh / t_base) ** (-_HYDRO / grad)

    def at(self, z: float) -> tuple[float, float, float, float]:
        """(temperature K, pressure Pa, density kg/m^3, speed of sound m/s) at geometric altitude ``z`` m."""
        h_geo = GEOPOTENTIAL_RADIUS * z / (GEOPOTENTIAL_RADIUS + z)
        j = int(np.searchsorted(self.base_h, h_geo, side="right")) - 1
        j = min(max(j, 0), len(self.base_h) - 1)
        dh = h_geo - self.base_h[j]
        temp = self.base_t[j] + self.grad[j] * dh
        p = self._pressure(self.base_t[j], self.base_p[j], self.grad[j], dh)
        return temp, p, p * MOLAR_MASS / (GAS_CONSTANT * temp), math.sqrt(HEAT_RATIO * GAS_CONSTANT * temp / MOLAR_MASS)


@lru_cache(maxsize=None)
def air(offset: float = 0.0) -> Air:
    return Air(offset)


# ---------------------------------------------------------------- hidden effects
@dataclass(frozen=True)
class Hidden:
    """Effects in the truth that the model does not have (defaults: none)."""

    motor_clock: float = 1.0            # k: thrust k P_tab(k t), the mass flow with it (grain temperature)
    A_e: float = 0.0                    # nozzle exit area m^2: thrust P_tab + A_e (p_sl - p_a(h)) while the jet flows
    wind: tuple | None = None           # (wind at 10 m, at the 11 km jet core) m/s, + downrange: see wind_speed
    dT: float = 0.0                     # temperature offset of the whole column, K
    dm0: float = 0.0                    # launch mass above the declared, kg
    bias_h: float = 0.0                 # the altitude channel reads h + bias_h, m
    scale_v: float = 0.0                # the speed channel reads (1 + scale_v) v
    tau: float = 0.0                    # time tags late by tau s: z(t) = y(t - tau)
    drag_step: tuple | None = None      # (relative rise, Mach centre, Mach half-width): CD (1 + r s(M))
    base_drag: float = 0.0              # c: power-off base drag c / M added once the jet stops filling the base
    rotation: tuple | None = None       # (latitude deg, launch azimuth deg from north)


#: The airframe's weathercock response (used in a wind): normal-force slope of body and fins on the
#: cross-section, /rad; static margin, m (1.45 calibers); pitch radius of gyration, m (a 5.6 m body);
#: damping ratio of the pitch oscillation (aerodynamic and jet damping).
CN_ALPHA = 11.0
STATIC_MARGIN = 0.55
GYRATION_RADIUS = 1.6
ZETA = 0.1

#: Below this sea-level thrust the jet no longer fills the nozzle and the base (the tail-off), N.
P_JET = 50_000.0


def wind_speed(h: float, wind) -> float:
    """Horizontal wind (m/s, + downrange): a neutral surface layer growing as ``(h / 10 m)^(1/7)`` from
    its 10 m value to 1 km, then linear to the jet core at 11 km, and above the core a bell that halves
    5 km higher."""
    w10, core = wind
    if h <= 1000.0:
        return w10 * (max(h, 10.0) / 10.0) ** (1.0 / 7.0)
    w1k = w10 * 100.0 ** (1.0 / 7.0)
    if h <= 11_000.0:
        return w1k + (core - w1k) * (h - 1000.0) / 10_000.0
    return core * 2.0 ** (-((h - 11_000.0) / 5000.0) ** 2)


_TT = np.asarray(V.THRUST_TIMES, float)
_PP = np.asarray(V.THRUST_VALUES, float)
_MACH_KNOTS = np.asarray(V.CD_KNOTS, float)


def table_thrust(t: float) -> float:
    """The static-firing table at ``t`` s after ignition, linear between samples, zero after it."""
    if t >= _TT[-1]:
        return 0.0
    return float(np.interp(t, _TT, _PP))


class Flight:
    """Tern-2's truth at given drag coefficients and hidden effects."""

    def __init__(self, hidden: Hidden = Hidden(), cd=V.CD_TRUTH):
        self.hd = hidden
        self.cd = np.asarray(cd, float)
        self.air = air(float(hidden.dT))
        self.k = float(hidden.motor_clock)
        if hidden.rotation is not None:
            lat, az = (math.radians(a) for a in hidden.rotation)
            # Omega = |Omega| (cos(lat) north + sin(lat) up); downrange e1 = sin(az) east + cos(az) north,
            # e2 = up, e3 = e1 x e2 = cos(az) east - sin(az) north
            self.omega = EARTH_RATE * np.array([math.cos(lat) * math.cos(az), math.sin(lat),
                                                -math.cos(lat) * math.sin(az)])
        else:
            self.omega = None

    # ---- the motor (the clock from ignition)
    def motor(self, t: float, p_amb: float) -> tuple[float, float]:
        """(thrust N, mass flow kg/s) at ``t``."""
        p_tab = self.k * table_thrust(self.k * t)
        mdot = p_tab / (V.ISP * V.G0)
        thrust = p_tab
        if self.hd.A_e and p_tab > 0.0:
            thrust += self.hd.A_e * (SEA_LEVEL_PRESSURE - p_amb) * min(1.0, p_tab / P_JET)
        return thrust, mdot

    def drag_coefficient(self, mach: float, t: float) -> float:
        cd = float(np.interp(mach, _MACH_KNOTS, self.cd))
        if self.hd.drag_step is not None:
            rise, centre, width = self.hd.drag_step
            cd *= 1.0 + rise * 0.5 * (1.0 + math.tanh((mach - centre) / width))
        if self.hd.base_drag:
            jet = min(1.0, self.k * table_thrust(self.k * t) / P_JET)
            cd += (1.0 - jet) * self.hd.base_drag / max(mach, 1.0)
        return cd

    # ---- the equations of motion: y = (r1, r2, r3, V1, V2, V3, m, delta, delta')
    def rhs(self, t, y):
        r = y[0:3]
        vel = y[3:6]
        m = y[6]
        rn = math.sqrt(r @ r)
        h = rn - EARTH_RADIUS
        _, p_amb, rho, sound = self.air.at(h)
        thrust, mdot = self.motor(t, p_amb)
        if self.hd.wind is None:                            # the body on the flight path, as in the model
            speed = math.sqrt(vel @ vel)
            axis = flow = vel / speed
            normal = np.zeros(3)
            turn = (0.0, 0.0)
        else:
            speed, axis, flow, normal, turn = self.weathercock(r, vel, m, h, y[7], y[8], rho)
        mach = speed / sound
        q = 0.5 * rho * speed * speed
        drag = q * V.S_REF * self.drag_coefficient(mach, t)
        acc = (thrust * axis - drag * flow + q * V.S_REF * normal) / m - MU / rn ** 3 * r
        if self.omega is not None:
            om = self.omega
            acc = acc - 2.0 * np.cross(om, vel) - np.cross(om, np.cross(om, r))
        return np.concatenate([vel, acc, [-mdot], turn])

    def weathercock(self, r, vel, m, h, delta, delta_rate, rho):
        """In a wind: the airspeed, the body axis, the airflow's direction, the normal-force coefficient
        times its direction, and (d delta/dt, d^2 delta/dt^2).

        The body axis is the ground path turned by ``delta`` in the launch plane. The wind tilts the
        airflow by ``beta`` (air-relative against ground-relative path angle); the fins' restoring moment
        ``q S CN_alpha l_sm (delta - beta)`` and a pitch damping turn the body toward it, the inertia
        ``m k_y^2``: ``I delta'' = -q S CN_alpha l_sm (delta - beta) - c delta'``, ``c`` for the damping
        ratio ``ZETA``. (The body's small trim to follow the gravity turn is left out, as the model
        leaves it out: with no wind ``delta`` stays 0.) The normal force ``q S CN_alpha (delta - beta)``
        acts across the airflow toward the body's side; the thrust along the body; the drag against the
        airflow."""
        up = r / math.sqrt(r @ r)
        horiz = np.array([up[1], -up[0], 0.0])
        horiz /= math.sqrt(horiz @ horiz)
        v_air = vel - wind_speed(h, self.hd.wind) * horiz
        speed = math.sqrt(v_air @ v_air)
        gamma = math.atan2(vel[1], vel[0])                  # path angles in the launch plane's axes
        gamma_air = math.atan2(v_air[1], v_air[0])
        beta = gamma_air - gamma
        psi = gamma + delta
        axis = np.array([math.cos(psi), math.sin(psi), 0.0])
        flow = v_air / speed
        across = np.array([-math.sin(gamma_air), math.cos(gamma_air), 0.0])
        incidence = delta - beta
        q = 0.5 * rho * speed * speed
        stiffness = q * V.S_REF * CN_ALPHA * STATIC_MARGIN
        inertia = m * GYRATION_RADIUS ** 2
        damping = 2.0 * ZETA * math.sqrt(stiffness * inertia)
        accel = (-stiffness * incidence - damping * delta_rate) / inertia
        return speed, axis, flow, CN_ALPHA * incidence * across, (delta_rate, accel)

    def breakpoints(self) -> np.ndarray:
        """Times where a known input has a kink (the thrust table's samples on the motor's clock)."""
        pts = np.concatenate([_TT / self.k, [V.T_RAIL, V.TF]])
        return np.unique(pts[(pts >= V.T_RAIL) & (pts <= V.TF)])

    def start(self) -> np.ndarray:
        x0, h0, v0, th0 = V.START
        assert x0 == 0.0
        mass = V.M_LAUNCH + self.hd.dm0 - V.burnt(V.T_RAIL, self.k)
        return np.array([0.0, EARTH_RADIUS + h0, 0.0, v0 * math.cos(th0), v0 * math.sin(th0), 0.0, mass, 0.0, 0.0])

    def states_at(self, times) -> np.ndarray:
        """The state vectors (r, V, m, delta, delta') at ``times`` (sorted, within [T_RAIL, TF])."""
        times = np.asarray(times, float)
        if times.size and (times[0] < V.T_RAIL - 1e-12 or times[-1] > V.TF + 1e-12 or np.any(np.diff(times) < 0)):
            raise ValueError("times must be sorted within the horizon")
        bps = self.breakpoints()
        out = np.empty((times.size, 9))
        y = self.start()
        for a, b in zip(bps[:-1], bps[1:]):
            last = b == bps[-1]
            sel = np.nonzero((times >= a) & ((times < b) | (last & (times <= b))))[0]
            t_eval = np.append(times[sel], b) if not (sel.size and times[sel[-1]] == b) else times[sel]
            sol = solve_ivp(self.rhs, (a, b), y, method="DOP853", rtol=1e-12, atol=1e-9, t_eval=t_eval)
            if not sol.success:
                raise RuntimeError(sol.message)
            out[sel] = sol.y[:, :sel.size].T
            y = sol.y[:, -1]
        return out

    @staticmethod
    def outputs_from_states(Y: np.ndarray) -> dict:
        r = Y[:, 0:3]
        return {"x": EARTH_RADIUS * np.arctan2(r[:, 0], r[:, 1]),
                "h": np.linalg.norm(r, axis=1) - EARTH_RADIUS,
                "v": np.linalg.norm(Y[:, 3:6], axis=1)}


def exact_outputs(hidden: Hidden, times) -> dict:
    """Noise-free x, h, v at the sample tags ``times``, every hidden effect (sensors included) applied."""
    times = np.asarray(times, float)
    flight = Flight(hidden)
    out = flight.outputs_from_states(flight.states_at(times - hidden.tau))   # tag t holds the value at t - tau
    out["h"] = out["h"] + hidden.bias_h
    out["v"] = out["v"] * (1.0 + hidden.scale_v)
    return out


def measurements(hidden: Hidden, seed: int, times=None) -> "ri.Measurements":
    """The case's data: exact outputs plus N(0, sigma) noise (seeded), the radar's sigmas."""
    times = V.sample_times() if times is None else np.asarray(times, float)
    return with_noise(exact_outputs(hidden, times), times, V.SIGMA, seed)
