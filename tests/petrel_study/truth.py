"""Petrel-V's truth: the flight written apart from rocketid's ascent builders, atmosphere and effect catalogue.

The estimation model (``tests/vehicles/petrel.py``) flies downrange, altitude, speed and flight-path
angle (x, h, v, theta) with rocketid's ascent equations. This truth integrates **Cartesian position
and velocity about the Earth's centre in the trajectory plane** (X, Y, VX, VY) and the mass, with
``scipy.integrate.solve_ivp`` (DOP853, rtol 1e-10), restarted at every second (the knots of the
thrust table and the pitch program):

- the Earth a non-rotating sphere of radius 6 371 km, gravity ``-GM R / |R|^3`` with ``GM = g0 Re^2``;
  the rail exit at ``(0, Re + 1420 m)``, the local vertical ``e_up = R / |R|`` and the local
  horizontal downrange ``e_dn = (Y, -X) / |R|``;
- the thrust along the body axis, at the commanded pitch above the local horizontal; drag against
  the air-relative velocity, lift ``q S CLa(M) alpha`` normal to it (rotated toward ``e_up``),
  ``alpha`` the pitch less the air-relative path angle; Mach and dynamic pressure from the airspeed;
- the engine: the sea-level acceptance-test table ``P_tab(t)`` (linear between its samples), the
  mass flow ``P / (Isp g0)``;
- the atmosphere is this file's own US Standard Atmosphere 1976 (``Air``): the standard's layers of
  base geopotential altitude and temperature lapse rate, the base pressures found by integrating the
  hydrostatic equation layer by layer (closed form) from 101 325 Pa, density from the ideal-gas law,
  the speed of sound from the temperature. ``tests/test_petrel_study.py`` checks it against
  rocketid's us76.

Outputs: ``x`` the arc along the sphere under the vehicle, ``Re atan2(X, Y)``; ``h`` the height above
the sphere (above sea level); ``v`` the speed ``|V|``. Without hidden effects this reproduces the
estimation model at its true coefficients to well under a millimetre (the fast tests).

Hidden effects (``Hidden``), each in its own physical shape, none of them a catalogue expression:

- ``blowdown``: the tank pressure falls faster than in the acceptance test: the thrust is the table
  times ``1 - c m_used`` (``m_used`` the propellant burnt so far, from the mass state), ``c`` set so
  that the factor is ``1 - blowdown`` at cutoff; the mass flow falls with it (same Isp);
- ``A_e``: the engine's nozzle exit area; the table is a sea-level figure, in flight the thrust is
  ``P_tab + A_e (p_sl - p(h))`` with ``p`` this file's pressure (at the rail exit, 1420 m, it already
  adds 0.06 m^2 (101.3 - 85.4) kPa = 0.96 kN); the pressure term follows the chamber down through the
  tail-off (scaled by ``P_tab(t) / P_tab(cutoff)`` over 50-51 s) and is gone in the coast; the mass flow
  unchanged;
- ``cold_dT``: the whole column ``dT`` kelvin off the standard, hydrostatic from the standard's
  sea-level pressure; only the density changes (the speed of sound is kept standard);
- ``jet_wind``: a horizontal wind along ``e_dn`` (a tailwind), ``W(z) = W_s (1 + ln(1 + z/z0) /
  ln(1 + 1 km/z0))`` in the first kilometre above the pad (z0 = 10 m: W_s at the ground, 2 W_s at
  1 km), ``2 W_s`` above, plus a Gaussian jet ``W_j exp(-((h - h_j)/s_j)^2 / 2)``;
- ``dm0``: ballast aboard at lift-off that stays aboard (the start mass ``dm0`` above the declared);
- ``delta``: the thrust axis ``delta`` above the body axis from t = 0;
- sensor effects on the sampled outputs: ``bias_h`` (GNSS height above the ellipsoid against the
  model's sea level, a constant offset), ``scale_v`` (the speed reads ``1 + k`` times the truth) and
  ``v_latency`` (only the speed channel sampled ``tau`` late: the truth's speed at ``t - tau``, the
  flight integrated back before the rail exit for the first samples).
"""

from __future__ import annotations

import bisect
import math
import sys
from dataclasses import dataclass
from functools import lru_cache
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

_TESTS = Path(__file__).resolve().parent.parent
for _extra in (_TESTS, _TESTS / "vehicles"):
    if str(_extra) not in sys.path:
        sys.path.insert(0, str(_extra))

import petrel as V  # noqa: E402
from study_harness import with_noise  # noqa: E402

# ---------------------------------------------------------------- constants
EARTH_RADIUS = 6_371_000.0          # m: the sphere the estimation model flies over
STD_GRAVITY = 9.80665               # m/s^2
MU = STD_GRAVITY * EARTH_RADIUS ** 2

# US Standard Atmosphere 1976 (NOAA-S/T 76-1562): defining constants and the layers below 51 km'
R_STAR = 8.31432                    # J/(mol K)
MOLAR_MASS = 0.0289644              # kg/mol
R_AIR = R_STAR / MOLAR_MASS         # J/(kg K)
HEAT_RATIO = 1.4
GEOPOTENTIAL_RADIUS = 6_356_766.0   # m
P_SL = 101_325.0                    # Pa
T_SL = 288.15                       # K
#: base geopotential altitude (m') and lapse rate dT/dH (K/m') of each layer
LAYERS = ((0.0, -6.5e-3), (11_000.0, 0.0), (20_000.0, 1.0e-3), (32_000.0, 2.8e-3), (47_000.0, 0.0))


class Air:
    """The 1976 standard's temperature profile plus ``offset`` K over the whole column, the sea-level
    pressure the standard's. Pressure from the hydrostatic equation ``dp/p = -g0 dH / (R T)`` integrated
    in closed form through each layer (``T`` linear in geopotential altitude ``H``); density
    ``p / (R T)``; the speed of sound ``sqrt(gamma R T_std)`` of the *standard* temperature (so that an
    offset changes the density only)."""

    def __init__(self, offset: float = 0.0):
        self.offset = offset
        bases_H, lapses, t_std, t_air, p = [], [], [], [], []
        T_std, T, P = T_SL, T_SL + offset, P_SL
        for j, (H_b, lapse) in enumerate(LAYERS):
            if j:
                dH = H_b - LAYERS[j - 1][0]
                P = self._p_through(P, T, LAYERS[j - 1][1], dH)
                T_std += LAYERS[j - 1][1] * dH
                T += LAYERS[j - 1][1] * dH
            bases_H.append(H_b)
            lapses.append(lapse)
            t_std.append(T_std)
            t_air.append(T)
            p.append(P)
        self.bases_H, self.lapses, self.t_std, self.t_air, self.p = bases_H, lapses, t_std, t_air, p

    @staticmethod
    def _p_through(p_b: float, T_b: float, lapse: float, dH: float) -> float:
        """The pressure ``dH`` above a layer's base (hydrostatic, ideal gas)."""
        k = STD_GRAVITY / R_AIR
        if lapse == 0.0:
            return p_b * math.exp(-k * dH / T_b)
        return p_b * ((T_b + lapse * dH) / T_b) ** (-k / lapse)

    def _layer(self, h: float) -> tuple[int, float]:
        H = GEOPOTENTIAL_RADIUS * h / (GEOPOTENTIAL_RADIUS + h)
        j = max(0, bisect.bisect_right(self.bases_H, H) - 1)
        return j, H - self.bases_H[j]

    def temperature(self, h: float) -> float:
        j, dH = self._layer(h)
        return self.t_air[j] + self.lapses[j] * dH

    def pressure(self, h: float) -> float:
        j, dH = self._layer(h)
        return self._p_through(self.p[j], self.t_air[j], self.lapses[j], dH)

    def density(self, h: float) -> float:
        j, dH = self._layer(h)
        T = self.t_air[j] + self.lapses[j] * dH
        return self._p_through(self.p[j], self.t_air[j], self.lapses[j], dH) / (R_AIR * T)

    def sound_speed(self, h: float) -> float:
        j, dH = self._layer(h)
        return math.sqrt(HEAT_RATIO * R_AIR * (self.t_std[j] + self.lapses[j] * dH))


@lru_cache(maxsize=None)
def air(offset: float = 0.0) -> Air:
    return Air(offset)


class Table:
    """Linear interpolation in a table, held at its end values (scalar, fast)."""

    def __init__(self, xs, ys):
        self.xs, self.ys = [float(v) for v in xs], [float(v) for v in ys]

    def __call__(self, x: float) -> float:
        xs, ys = self.xs, self.ys
        if x <= xs[0]:
            return ys[0]
        if x >= xs[-1]:
            return ys[-1]
        j = bisect.bisect_right(xs, x) - 1
        return ys[j] + (ys[j + 1] - ys[j]) * (x - xs[j]) / (xs[j + 1] - xs[j])


THRUST = Table(V.THRUST_TIMES, V.THRUST_VALUES)
PITCH = Table(V.PITCH_TIMES, [math.radians(d) for d in V.PITCH_DEG])
CD = Table(V.CD_KNOTS, V.CD_TRUTH)
CLA = Table(V.CLA_KNOTS, V.CLA_TRUTH)
S_REF = math.pi * V.DIAMETER ** 2 / 4
MDOT_PER_N = 1.0 / (V.ISP * V.G0)
P_CUT = THRUST(V.T_CUTOFF)


def nominal_propellant(t: float) -> float:
    """Propellant the table burns from rail exit to ``t`` (trapezoids, exact for the linear table), kg."""
    knots = [k for k in V.THRUST_TIMES if k < t] + [t]
    return sum(0.5 * (THRUST(a) + THRUST(b)) * (b - a) for a, b in zip(knots[:-1], knots[1:])) * MDOT_PER_N


@dataclass(frozen=True)
class Hidden:
    """The hidden effects of one case (zero: absent)."""

    blowdown: float = 0.0             # thrust and mass-flow loss at cutoff, linear in propellant used
    A_e: float = 0.0                  # m^2, nozzle exit area (the table is a sea-level figure)
    cold_dT: float = 0.0              # K, the column's temperature offset (density only)
    jet_wind: tuple[float, float, float, float] = (0.0, 0.0, 11_000.0, 2_000.0)  # (W_s, W_jet m/s, at m MSL, sigma m)
    dm0: float = 0.0                  # kg above the declared start mass
    delta: float = 0.0                # rad, thrust axis above the body axis
    bias_h: float = 0.0               # m on the altitude channel
    scale_v: float = 0.0              # the speed reads (1 + scale_v) v
    v_latency: float = 0.0            # s, the speed channel alone late


def wind(hidden: Hidden, h: float) -> float:
    """The horizontal wind along the downrange direction (a tailwind > 0), m/s."""
    ws, wj, hj, sj = hidden.jet_wind
    if not (ws or wj):
        return 0.0
    z = max(h - V.PAD_ALTITUDE, 0.0)
    z0 = 10.0
    layer = ws * (1.0 + math.log1p(min(z, 1000.0) / z0) / math.log1p(1000.0 / z0))
    return layer + wj * math.exp(-0.5 * ((h - hj) / sj) ** 2)


class Flight:
    """The truth's equations for one case's hidden (non-sensor) effects."""

    def __init__(self, hidden: Hidden):
        self.hidden = hidden
        self.air = air(hidden.cold_dT)
        self.std = air(0.0)
        self.m0 = V.M_START + hidden.dm0
        # blowdown: factor 1 - c m_used; with the mass flow following the thrust, the factor is
        # exp(-c I(t)) for the nominal propellant I(t), so c sets it to 1 - blowdown at cutoff
        self.c_blow = -math.log(1.0 - hidden.blowdown) / nominal_propellant(V.T_CUTOFF) if hidden.blowdown else 0.0

    def initial(self) -> np.ndarray:
        x0, h0, v0, g0 = V.START
        r0 = EARTH_RADIUS + h0
        return np.array([0.0, r0, v0 * math.cos(g0), v0 * math.sin(g0), self.m0])

    def rhs(self, t: float, y) -> list:
        X, Y, VX, VY, m = y
        hid = self.hidden
        r = math.hypot(X, Y)
        h = r - EARTH_RADIUS
        upx, upy = X / r, Y / r                 # local vertical
        dnx, dny = upy, -upx                    # local horizontal, downrange
        u = VX * dnx + VY * dny                 # ground-relative horizontal and vertical velocity
        w = VX * upx + VY * upy
        ua = u - wind(hid, h)                   # air-relative
        va = math.hypot(ua, w)
        theta_air = math.atan2(w, ua)
        pitch = PITCH(t)
        alpha = pitch - theta_air
        # engine
        p_tab = THRUST(t)
        level = 1.0 - self.c_blow * (self.m0 - m) if self.c_blow else 1.0
        thrust = p_tab * level
        mdot = thrust * MDOT_PER_N
        if hid.A_e:
            flowing = min(1.0, p_tab / P_CUT)   # the pressure term follows the chamber through the tail-off
            thrust += hid.A_e * (P_SL - self.air.pressure(h)) * flowing
        # air
        rho = self.air.density(h)
        mach = va / self.std.sound_speed(h)
        q = 0.5 * rho * va * va
        drag = q * S_REF * CD(mach)
        lift = q * S_REF * CLA(mach) * alpha
        # force components along (downrange, up): thrust on the body axis (+ misalignment), drag against
        # the airflow, lift normal to it
        axis = pitch + hid.delta
        f_dn = thrust * math.cos(axis) - drag * ua / va - lift * w / va
        f_up = thrust * math.sin(axis) - drag * w / va + lift * ua / va
        g = MU / (r * r)
        ax = (f_dn * dnx + f_up * upx) / m - g * upx
        ay = (f_dn * dny + f_up * upy) / m - g * upy
        return [VX, VY, ax, ay, -mdot]

    def states(self, times) -> np.ndarray:
        """The state at ``times`` (any order, may start before the rail exit: integrated back)."""
        times = np.asarray(times, dtype=float)
        out = np.empty((times.size, 5))
        y0 = self.initial()
        ahead = times >= 0.0
        if np.any(ahead):
            out[ahead] = self._march(y0, np.sort(np.unique(times[ahead])), times[ahead])
        if np.any(~ahead):                     # before the rail exit (a late channel's first samples)
            back = times[~ahead]
            sol = solve_ivp(self.rhs, (0.0, float(back.min())), y0, method="DOP853", rtol=1e-10, atol=1e-8,
                            dense_output=True)
            if not sol.success:
                raise RuntimeError(sol.message)
            out[~ahead] = sol.sol(back).T
        return out

    def _march(self, y0, grid, wanted) -> np.ndarray:
        """Forward from the rail exit, restarted at every whole second (the tables' knots)."""
        end = float(grid[-1])
        bounds = sorted({float(k) for k in range(int(math.ceil(end)))} | {end})
        values = np.empty((grid.size, 5))
        y = y0
        for a, b in zip(bounds[:-1], bounds[1:]):
            sol = solve_ivp(self.rhs, (a, b), y, method="DOP853", rtol=1e-10, atol=1e-8, dense_output=True)
            if not sol.success:
                raise RuntimeError(sol.message)
            sel = (grid >= a) & (grid <= b)
            if np.any(sel):
                values[sel] = sol.sol(grid[sel]).T
            y = sol.y[:, -1]
        return values[np.searchsorted(grid, wanted)]


def outputs_from_states(states: np.ndarray) -> dict[str, np.ndarray]:
    X, Y, VX, VY = states[:, 0], states[:, 1], states[:, 2], states[:, 3]
    return {"x": EARTH_RADIUS * np.arctan2(X, Y), "h": np.hypot(X, Y) - EARTH_RADIUS, "v": np.hypot(VX, VY)}


def exact_outputs(hidden: Hidden, times) -> dict[str, np.ndarray]:
    """x, h, v at ``times`` from the truth (sensor effects applied), without noise."""
    times = np.asarray(times, dtype=float)
    flight = Flight(hidden)
    out = outputs_from_states(flight.states(times))
    if hidden.v_latency:
        out["v"] = outputs_from_states(flight.states(times - hidden.v_latency))["v"]
    out["h"] = out["h"] + hidden.bias_h
    out["v"] = out["v"] * (1.0 + hidden.scale_v)
    return out


def measurements(hidden: Hidden, seed: int):
    """Noisy measurements at Petrel-V's GNSS sample times: the exact outputs plus N(0, sigma^2), seeded."""
    times = V.sample_times()
    return with_noise(exact_outputs(hidden, times), times, V.SIGMA, seed)
