"""The truth of the air-launch study: Osprey-A flown in another state space, hidden effects included.

rocketid's model (``tests/vehicles/osprey.py``) integrates speed and flight-path angle over a
spherical, non-rotating Earth. This truth integrates **Cartesian position and velocity** in the
plane of flight, about the Earth's centre, with **vector forces**:

- gravity ``-GM/r^2`` toward the centre (``GM = g0 Re^2``, ``Re`` = 6 371 km);
- thrust along the body axis, at the commanded attitude ``phi`` above the local horizon (plus a
  misalignment when hidden);
- drag against the **air-relative** velocity ``V - W(h) e_horizontal``, lift normal to it (turned
  toward the local vertical): drag ``q S_ref CD(M)`` on the body's cross-section, lift
  ``q S_wing CLa(M) (phi - gamma_air)`` on the wing's area, with ``gamma_air`` the air-relative
  path angle; Mach number and dynamic pressure from the airspeed;
- in the rotating case, the Coriolis and centrifugal accelerations of the Earth-fixed frame,
  taken from the 3-D vectors and projected on the plane of flight.

The atmosphere is this file's own US Standard Atmosphere 1976 from its layer table (base
geopotential altitudes and temperature lapse rates, the hydrostatic equation integrated in closed
form layer by layer from 101 325 Pa), with an optional temperature offset over the whole column.
Downrange ``x`` is the arc along the Earth's surface, ``h`` the height above the sphere, ``v``
the speed in the Earth-fixed frame.

Every hidden effect is written in its own physical shape (``Hidden``); none is the catalogue's.
"""

from __future__ import annotations

import math
import sys
from bisect import bisect_right
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

_VEHICLES = Path(__file__).resolve().parent.parent / "vehicles"
if str(_VEHICLES) not in sys.path:
    sys.path.insert(0, str(_VEHICLES))

import osprey as O  # noqa: E402
from study_harness import with_noise  # noqa: E402

import rocketid as ri  # noqa: E402

# ---------------------------------------------------------------- constants
RE = 6_371_000.0                 # Earth radius of the trajectory, m
G0 = 9.80665                     # standard gravity, m/s^2
GM = G0 * RE ** 2                # so that g(0) = g0
OMEGA_EARTH = 7.2921159e-5       # Earth's sidereal rotation rate, rad/s

# US Standard Atmosphere 1976 (NOAA-S/T 76-1562), the defining constants and layer table
R_STAR = 8.31432                 # universal gas constant, J/(mol K)
M_AIR = 0.0289644                # mean molar mass of sea-level air, kg/mol
GAMMA = 1.4
R0_GEOPOT = 6_356_766.0          # Earth radius for the geopotential altitude, m
P_SEA = 101_325.0                # Pa
T_SEA = 288.15                   # K
#: (base geopotential altitude m, lapse rate K/m) of the layers up to 84.852 km
LAYERS = ((0.0, -0.0065), (11_000.0, 0.0), (20_000.0, 0.0010), (32_000.0, 0.0028),
          (47_000.0, 0.0), (51_000.0, -0.0028), (71_000.0, -0.0020))


class Atmosphere:
    """The 1976 standard's temperature profile shifted by ``dT`` (K) over the column; pressure from
    the hydrostatic equation (closed form per layer), density from the gas law."""

    def __init__(self, dT: float = 0.0):
        self.dT = dT
        self.hb = [lay[0] for lay in LAYERS]
        self.lapse = [lay[1] for lay in LAYERS]
        self.tb = [T_SEA + dT]
        self.pb = [P_SEA]
        for j in range(1, len(LAYERS)):
            dh = self.hb[j] - self.hb[j - 1]
            t_top = self.tb[j - 1] + self.lapse[j - 1] * dh
            self.pb.append(self._p_in_layer(j - 1, dh))
            self.tb.append(t_top)

    def _p_in_layer(self, j: int, dh: float) -> float:
        L, tb, pb = self.lapse[j], self.tb[j], self.pb[j]
        k = G0 * M_AIR / R_STAR
        if L == 0.0:
            return pb * math.exp(-k * dh / tb)
        return pb * ((tb + L * dh) / tb) ** (-k / L)

    def state(self, z: float) -> tuple[float, float, float]:
        """Temperature K, pressure Pa, density kg/m^3 at geometric altitude ``z`` (m)."""
        H = R0_GEOPOT * z / (R0_GEOPOT + z)
        j = max(0, bisect_right(self.hb, H) - 1)
        dh = H - self.hb[j]
        T = self.tb[j] + self.lapse[j] * dh
        p = self._p_in_layer(j, dh)
        return T, p, p * M_AIR / (R_STAR * T)

    def sound(self, T: float) -> float:
        return math.sqrt(GAMMA * R_STAR * T / M_AIR)


STANDARD = Atmosphere()


def pressure_table(altitudes=None):
    """(geometric altitudes m, pressure Pa, density kg/m^3) of the standard atmosphere."""
    hs = np.arange(0.0, 60_001.0, 1000.0) if altitudes is None else np.asarray(altitudes, float)
    rows = [STANDARD.state(float(z)) for z in hs]
    return hs, np.array([r[1] for r in rows]), np.array([r[2] for r in rows])


# ---------------------------------------------------------------- hidden effects
@dataclass(frozen=True)
class Hidden:
    """Effects in the truth that the model does not have (defaults: none)."""

    hot_motor: float = 1.0                  # k: thrust k P_tab(k t), mass flow with it
    A_e: float = 0.0                        # nozzle exit area, m^2: thrust P_tab + A_e (p_sl - p_a(h))
    jet: tuple | None = None                # (peak wind m/s, + downrange, altitude m, half-width below m, above m)
    dT: float = 0.0                         # temperature offset of the whole column, K
    delta: float = 0.0                      # thrust misalignment, rad, from t = 0
    bias_h: tuple = (0.0, 0.0)              # altimeter reads h + b0 + b1 t (m, m/s)
    scale_v: float = 0.0                    # speed channel reads (1 + k) v
    rotation: tuple | None = None           # (latitude deg, launch azimuth deg from north)
    tau: float = 0.0                        # time tags late by tau s: z(t) = y(t - tau)
    dm0: float = 0.0                        # start mass above the declared, kg
    drag_bump: tuple | None = None          # (dCD, Mach centre, half-width at half-height)


def jet_wind(h: float, jet) -> float:
    """Horizontal wind (m/s, + downrange) of a jet stream: a bell in altitude, half its peak
    ``hw_below`` under the core and ``hw_above`` over it (it decays more slowly aloft)."""
    peak, core, below, above = jet
    hw = below if h < core else above
    return peak * 2.0 ** (-((h - core) / hw) ** 2)


_PHI_T, _PHI_V = O.program_table()
_PHI_T = np.asarray(_PHI_T, float)
_PHI_V = np.asarray(_PHI_V, float)
_P_T = np.asarray(O.THRUST_TIMES, float)
_P_V = np.asarray(O.THRUST_VALUES, float)
_CD_K = np.asarray(O.CD_KNOTS, float)
_CLA_K = np.asarray(O.CLA_KNOTS, float)


def _interp(x: float, xs: np.ndarray, ys) -> float:
    """Piecewise linear through (xs, ys), constant beyond the ends."""
    return float(np.interp(x, xs, ys))


class Flight:
    """Osprey-A's truth at given coefficients and hidden effects."""

    def __init__(self, hidden: Hidden = Hidden(), cd=O.CD_TRUTH, cla=O.CLA_TRUTH):
        self.hd = hidden
        self.cd = np.asarray(cd, float)
        self.cla = np.asarray(cla, float)
        self.atm = Atmosphere(hidden.dT)
        self.k = hidden.hot_motor
        if hidden.rotation is not None:
            lat, az = (math.radians(a) for a in hidden.rotation)
            # plane axes: 1 = downrange at launch, 2 = up at launch, 3 = 1 x 2; Omega in them
            self.om = (OMEGA_EARTH * math.cos(lat) * math.cos(az), OMEGA_EARTH * math.sin(lat),
                       -OMEGA_EARTH * math.cos(lat) * math.sin(az))
        else:
            self.om = None

    # ---- the motor
    def thrust_massflow(self, t: float, p_amb: float) -> tuple[float, float]:
        k = self.k
        p_tab = k * _interp(k * t, _P_T, _P_V)
        mdot = p_tab / (O.ISP * O.G0)
        thrust = p_tab + self.hd.A_e * (P_SEA - p_amb)
        return thrust, mdot

    # ---- the equations of motion: y = (X, Y, VX, VY, m), Earth's centre at (0, -RE)
    def rhs(self, t, y):
        X, Y, VX, VY, m = y
        RX, RY = X, Y + RE
        r = math.hypot(RX, RY)
        h = r - RE
        ux, uy = RX / r, RY / r                     # local up
        ex, ey = uy, -ux                            # local horizontal, downrange
        T, p_amb, rho = self.atm.state(h)
        wind = jet_wind(h, self.hd.jet) if self.hd.jet is not None else 0.0
        ax_, ay_ = VX - wind * ex, VY - wind * ey   # air-relative velocity
        va = math.hypot(ax_, ay_)
        dx, dy = ax_ / va, ay_ / va                 # its direction
        gamma_air = math.atan2(dx * ux + dy * uy, dx * ex + dy * ey)
        nx, ny = -dy, dx                            # normal to it, turned toward the vertical
        phi = _interp(t, _PHI_T, _PHI_V)
        mach = va / self.atm.sound(T)
        q = 0.5 * rho * va * va
        cd = _interp(mach, _CD_K, self.cd)
        if self.hd.drag_bump is not None:
            d, mc, hw = self.hd.drag_bump
            cd += d * 2.0 ** (-((mach - mc) / hw) ** 2)
        cl_wing = _interp(mach, _CLA_K, self.cla) * (phi - gamma_air)     # on the wing's area
        thrust, mdot = self.thrust_massflow(t, p_amb)
        b = phi + self.hd.delta
        bx, by = math.cos(b) * ex + math.sin(b) * ux, math.cos(b) * ey + math.sin(b) * uy
        D, L = q * O.S_REF * cd, q * O.S_WING * cl_wing
        g = GM / (r * r)
        fx = (thrust * bx - D * dx + L * nx) / m - g * ux
        fy = (thrust * by - D * dy + L * ny) / m - g * uy
        if self.om is not None:
            o1, o2, o3 = self.om
            # Coriolis -2 Omega x V and centrifugal -Omega x (Omega x R), in-plane parts
            fx += 2.0 * o3 * VY
            fy -= 2.0 * o3 * VX
            od = o1 * RX + o2 * RY
            w2 = o1 * o1 + o2 * o2 + o3 * o3
            fx -= o1 * od - RX * w2
            fy -= o2 * od - RY * w2
        return [VX, VY, fx, fy, -mdot]

    def breakpoints(self) -> np.ndarray:
        """Times where a known input has a kink (the attitude program's and the thrust table's samples)."""
        k = self.k
        pts = np.concatenate([_PHI_T, _P_T / k, [O.TF]])
        return np.unique(pts[(pts >= 0.0) & (pts <= O.TF)])

    def start(self) -> list:
        x0, h0, v0, th0 = O.START
        assert x0 == 0.0
        return [0.0, h0, v0 * math.cos(th0), v0 * math.sin(th0), O.M_START + self.hd.dm0]

    def states_at(self, times) -> np.ndarray:
        """The state vectors (X, Y, VX, VY, m) at ``times`` (sorted, within [0, TF])."""
        times = np.asarray(times, float)
        if times.size and (times[0] < 0.0 or times[-1] > O.TF + 1e-12 or np.any(np.diff(times) < 0)):
            raise ValueError("times must be sorted within the horizon")
        bps = self.breakpoints()
        out = np.empty((times.size, 5))
        y = self.start()
        for a, b in zip(bps[:-1], bps[1:]):
            last = b == bps[-1]
            sel = np.nonzero((times >= a) & ((times < b) | (last & (times <= b))))[0]
            ends_at_b = bool(sel.size) and times[sel[-1]] == b
            t_eval = times[sel] if ends_at_b else np.append(times[sel], b)   # b closes the list: the next start
            sol = solve_ivp(self.rhs, (a, b), y, method="DOP853", rtol=1e-11, atol=1e-9, t_eval=t_eval)
            if not sol.success:
                raise RuntimeError(sol.message)
            out[sel] = sol.y[:, :sel.size].T
            y = sol.y[:, -1]
        return out

    def outputs_from_states(self, Y: np.ndarray) -> dict:
        RX, RY = Y[:, 0], Y[:, 1] + RE
        r = np.hypot(RX, RY)
        return {"x": RE * np.arctan2(RX, RY), "h": r - RE, "v": np.hypot(Y[:, 2], Y[:, 3])}


def exact_outputs(hidden: Hidden, times) -> dict:
    """Noise-free x, h, v at the sample tags ``times``, every hidden effect (sensors included) applied."""
    times = np.asarray(times, float)
    flight = Flight(hidden)
    true_times = times - hidden.tau                 # the tag says t, the value is from t - tau
    out = flight.outputs_from_states(flight.states_at(true_times))
    b0, b1 = hidden.bias_h
    out["h"] = out["h"] + b0 + b1 * times
    out["v"] = out["v"] * (1.0 + hidden.scale_v)
    return out


def measurements(hidden: Hidden, seed: int, times=None) -> "ri.Measurements":
    """The case's data: exact outputs plus N(0, sigma) noise (seeded), the vehicle's sigmas."""
    times = O.sample_times() if times is None else np.asarray(times, float)
    # time tags early (tau < 0): a tag near the end stands for a moment past the flight's record, which ends at TF
    times = times[times - hidden.tau <= O.TF + 1e-12]
    return with_noise(exact_outputs(hidden, times), times, O.SIGMA, seed)
