"""The truth of the booster study: Auk-B flown in polar coordinates, hidden effects included.

rocketid's model (``tests/vehicles/auk.py``) integrates speed and flight-path angle with the vehicle's
mass in closed form. This truth is written independently of rocketid's physics: it integrates the
vehicle's **radius and central angle about the Earth's centre and its radial and horizontal velocity
components** over a spherical, non-rotating Earth::

    dr/dt   = u                              (u: radial velocity, up)
    dpsi/dt = w / r                          (w: horizontal velocity, downrange)
    du/dt   = w^2 / r - GM / r^2 + a_up
    dw/dt   = -u w / r + a_horizontal

with the forces as vectors in the local (horizontal, up) frame: each engine's thrust along its own axis
(the body axis at the commanded attitude ``phi`` above the local horizon; the core engine's tilted by
its misalignment when hidden), drag against the **air-relative** velocity ``(w + W_head(h), u)``, lift
normal to it (turned toward the local vertical) with ``CL_alpha (phi - gamma_air)``, Mach number and
dynamic pressure from the airspeed. The core's propellant and the boosters' grain are two more states
(mass flows from each motor's own law); the boosters are a configuration: up to separation their grain
and casings are part of the mass and their cross-sections part of the area, after it neither, and the
integration is split there (a discontinuity of the right-hand side), as at every corner of a known
input (the thrust table's and the attitude program's samples, the throttle schedule's events).

The atmosphere is this file's own US Standard Atmosphere 1976 (NOAA-S/T 76-1562): the defining
constants and the layer table of geopotential base altitudes and lapse rates up to 84.852 km,
pressure by the hydrostatic equation in closed form per layer (written for the log of the pressure),
density from the gas law, speed of sound ``sqrt(gamma R* T / M0)``; a day ``dT`` colder or warmer is the
whole temperature profile shifted, the pressure from the same hydrostatics from 101 325 Pa at sea level.
Downrange ``x`` is the arc along the Earth's surface, ``h`` the height above the sphere, ``v`` the speed.

Every hidden effect is written in its own physical shape (``Hidden``); none is the catalogue's. Nothing
here comes from ``rocketid.physics`` or ``rocketid.diagnostics``: only the vehicle's published numbers
(``auk.py``'s tables and constants) and ``study_harness.with_noise`` (the data as ``rocketid.Measurements``).
"""

from __future__ import annotations

import math
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from scipy.integrate import solve_ivp

_VEHICLES = Path(__file__).resolve().parent.parent / "vehicles"
if str(_VEHICLES) not in sys.path:
    sys.path.insert(0, str(_VEHICLES))

import auk as A  # noqa: E402
from study_harness import with_noise  # noqa: E402

# ---------------------------------------------------------------- the Earth
R_EARTH = 6_371_000.0              # radius of the sphere the flight is measured over, m
G_SEA = 9.80665                    # gravity at its surface, m/s^2
MU = G_SEA * R_EARTH ** 2          # so that GM / R_EARTH^2 = G_SEA

# ---------------------------------------------------------------- US Standard Atmosphere 1976
RSTAR = 8.31432                    # J/(mol K), the standard's gas constant
M0 = 0.0289644                     # kg/mol, sea-level molar mass
KAPPA = 1.4                        # ratio of specific heats
R_GEOPOTENTIAL = 6_356_766.0       # m, the standard's Earth radius for geopotential altitude
P0 = 101_325.0                     # Pa
T0 = 288.15                        # K
G0_ATM = 9.80665                   # m/s^2, the geopotential's reference gravity
#: Layer table: base geopotential altitude (m), lapse rate (K/m).
US76_LAYERS = ((0.0, -6.5e-3), (11_000.0, 0.0), (20_000.0, 1.0e-3), (32_000.0, 2.8e-3),
               (47_000.0, 0.0), (51_000.0, -2.8e-3), (71_000.0, -2.0e-3), (84_852.0, 0.0))


class Air:
    """The 1976 standard's temperature profile, shifted by ``dT`` K over the whole column; pressure by
    the hydrostatic equation from ``P0`` at sea level."""

    def __init__(self, dT: float = 0.0):
        self.dT = float(dT)
        self.base_h = np.array([h for h, _ in US76_LAYERS])
        self.lapse = np.array([lam for _, lam in US76_LAYERS])
        self.base_T = np.empty(len(US76_LAYERS))
        self.base_lnp = np.empty(len(US76_LAYERS))
        self.base_T[0], self.base_lnp[0] = T0 + self.dT, math.log(P0)
        for j in range(1, len(US76_LAYERS)):
            dh = self.base_h[j] - self.base_h[j - 1]
            self.base_T[j] = self.base_T[j - 1] + self.lapse[j - 1] * dh
            self.base_lnp[j] = self._lnp(j - 1, dh)

    def _lnp(self, j: int, dh: float) -> float:
        """ln p at ``dh`` above the base of layer ``j``: d ln p / dH = -g0 M0 / (R* T(H))."""
        beta = G0_ATM * M0 / RSTAR
        lam, tb = self.lapse[j], self.base_T[j]
        if lam == 0.0:
            return self.base_lnp[j] - beta * dh / tb
        return self.base_lnp[j] - (beta / lam) * math.log((tb + lam * dh) / tb)

    def at(self, z: float) -> tuple[float, float, float, float]:
        """(temperature K, pressure Pa, density kg/m^3, speed of sound m/s) at geometric altitude ``z``."""
        H = R_GEOPOTENTIAL * z / (R_GEOPOTENTIAL + z)          # geopotential altitude
        j = int(np.searchsorted(self.base_h, H, side="right")) - 1
        j = min(max(j, 0), len(US76_LAYERS) - 1)
        dh = H - self.base_h[j]
        T = self.base_T[j] + self.lapse[j] * dh
        p = math.exp(self._lnp(j, dh))
        return T, p, p * M0 / (RSTAR * T), math.sqrt(KAPPA * RSTAR * T / M0)


STANDARD_DAY = Air()


# ---------------------------------------------------------------- hidden effects
@dataclass(frozen=True)
class Hidden:
    """Effects in the truth that the model does not have (defaults: none)."""

    sep_delay: float = 0.0               # s: the boosters separate this much after the declared 40 s
    cold_boosters: tuple = (1.0, 1.0)    # (thrust factor f, burn-time factor k): each booster f P(t/k),
    #                                      its grain burnt at mdot(t/k)/k -- the same grain, burnt slower
    core_misalign: float = 0.0           # rad: the core engine's thrust axis above the body axis, from lift-off
    jet: tuple | None = None             # (peak headwind m/s, its altitude m, surface wind m/s): a headwind
    bias_h: float = 0.0                  # m: the GNSS altitude reads h + bias_h
    dT: float = 0.0                      # K: the day's temperature offset over the whole column
    bucket_level: float | None = None    # the core's delivered setting where the bucket commands 0.75
    latency: float = 0.0                 # s: every channel's value at tag t is the flight's at t - latency
    weak_booster: float = 0.0            # fraction of ONE booster's thrust and grain flow missing over its
    #                                      whole burn (a partial ignition of its grain); the grain not burnt
    #                                      is carried to separation and leaves with the casing


def headwind(h: float, jet) -> float:
    """Headwind (m/s, blowing toward -downrange) at altitude ``h``: a uniform surface-layer wind plus a
    jet core whose excess falls to half 3 km below the core and 5 km above it."""
    peak, core, surface = jet
    half = 3_000.0 if h < core else 5_000.0
    return surface + (peak - surface) * 0.5 ** (((h - core) / half) ** 2)


_PHI_T, _PHI_V = (np.asarray(a, float) for a in A.program_table())
_B_T = np.asarray(A.BOOSTER_TIMES, float)
_B_P = np.asarray(A.BOOSTER_THRUST, float)
_CD_M = np.asarray(A.CD_KNOTS, float)
_BUCKET_COMMANDED = 0.75


class Ascent:
    """Auk-B's truth at given coefficients and hidden effects."""

    def __init__(self, hidden: Hidden = Hidden(), cd=A.CD_TRUTH, cl_alpha=A.CLA_TRUTH):
        self.hd = hidden
        self.cd = np.asarray(cd, float)
        self.cla = float(cl_alpha)
        self.air = Air(hidden.dT)
        self.t_sep = A.T_SEP + hidden.sep_delay
        self.f_cold, self.k_cold = hidden.cold_boosters

    # ---- propulsion
    def core_setting(self, t: float) -> float:
        """The core engine's delivered throttle setting: the command, its bucket deeper when hidden."""
        cmd = float(np.interp(t, A.THROTTLE_TIMES, A.THROTTLE_LEVELS))
        if self.hd.bucket_level is None:
            return cmd
        return 1.0 - (1.0 - cmd) * (1.0 - self.hd.bucket_level) / (1.0 - _BUCKET_COMMANDED)

    def boosters(self, t: float) -> tuple[float, float]:
        """Both boosters' thrust (N) and grain flow (kg/s) at ``t``."""
        k = self.k_cold
        p_one = float(np.interp(t / k, _B_T, _B_P, right=0.0))
        flow_one = p_one / (A.BOOSTER_ISP * A.G0) / k
        share = A.N_BOOSTERS - self.hd.weak_booster             # one booster short of its share
        return share * self.f_cold * p_one, share * flow_one

    # ---- equations of motion: y = (r, psi, u, w, core mass, booster grain left)
    def rhs(self, t, y, attached: bool):
        r, _psi, u, w, m_core, grain = y
        h = r - R_EARTH
        _T, _p, rho, a_sound = self.air.at(h)
        wind = headwind(h, self.hd.jet) if self.hd.jet is not None else 0.0
        wa, ua = w + wind, u                                     # air-relative velocity (horizontal, up)
        va = math.hypot(wa, ua)
        phi = float(np.interp(t, _PHI_T, _PHI_V))
        setting = self.core_setting(t)
        p_core = A.CORE_THRUST * setting
        flow_core = A.CORE_MASS_FLOW * setting
        if attached:
            p_b, flow_b = self.boosters(t)
            mass = m_core + grain + A.N_BOOSTERS * A.BOOSTER_CASING
            area = A.S_CORE + A.N_BOOSTERS * A.S_BOOSTER
        else:
            p_b, flow_b = 0.0, 0.0
            mass = m_core
            area = A.S_CORE
        tilt = phi + self.hd.core_misalign
        f_h = p_b * math.cos(phi) + p_core * math.cos(tilt)
        f_up = p_b * math.sin(phi) + p_core * math.sin(tilt)
        if va > 1e-9:
            gamma_air = math.atan2(ua, wa)
            cd = float(np.interp(va / a_sound, _CD_M, self.cd))
            cl = self.cla * (phi - gamma_air)
            k_air = 0.5 * rho * area * va                        # q S / va
            f_h += k_air * (-cd * wa - cl * ua)                  # drag along -V_air, lift along (-ua, wa)
            f_up += k_air * (-cd * ua + cl * wa)
        g = MU / (r * r)
        du = w * w / r - g + f_up / mass
        dw = -u * w / r + f_h / mass
        return [u, w / r, du, dw, -flow_core, -flow_b if attached else 0.0]

    def corners(self) -> np.ndarray:
        """Times where a known input or the configuration has a corner or a step."""
        pts = np.concatenate([_PHI_T, _B_T * self.k_cold, A.THROTTLE_TIMES, [self.t_sep, A.TF]])
        return np.unique(pts[(pts >= 0.0) & (pts <= A.TF)])

    def start(self) -> list:
        x0, h0, v0, _th0 = A.START
        assert x0 == 0.0 and v0 == 0.0
        return [R_EARTH + h0, 0.0, 0.0, 0.0, A.M_CORE, A.N_BOOSTERS * A.BOOSTER_GRAIN]

    def states_at(self, times) -> np.ndarray:
        """The state vectors at ``times`` (sorted, within [0, TF])."""
        times = np.asarray(times, float)
        if times.size and (times[0] < 0.0 or times[-1] > A.TF + 1e-12 or np.any(np.diff(times) < 0)):
            raise ValueError("times must be sorted within the horizon")
        cuts = self.corners()
        out = np.empty((times.size, 6))
        y = self.start()
        for a, b in zip(cuts[:-1], cuts[1:]):
            attached = b <= self.t_sep + 1e-12
            last = b == cuts[-1]
            sel = np.nonzero((times >= a) & ((times < b) | (last & (times <= b))))[0]
            t_eval = np.append(times[sel], b) if not (sel.size and times[sel[-1]] == b) else times[sel]
            sol = solve_ivp(self.rhs, (a, b), y, method="DOP853", rtol=1e-11, atol=1e-8, t_eval=t_eval,
                            args=(attached,))
            if not sol.success:
                raise RuntimeError(sol.message)
            out[sel] = sol.y[:, :sel.size].T
            y = list(sol.y[:, -1])
        return out

    @staticmethod
    def outputs_from_states(Y: np.ndarray) -> dict:
        return {"x": R_EARTH * Y[:, 1], "h": Y[:, 0] - R_EARTH, "v": np.hypot(Y[:, 2], Y[:, 3])}


def exact_outputs(hidden: Hidden, times) -> dict:
    """Noise-free x, h, v at the tags ``times``, every hidden effect (sensors included) applied."""
    times = np.asarray(times, float)
    flight = Ascent(hidden)
    # a GNSS latency: the tag says t, the value is the flight's at t - latency (on the pad before lift-off)
    flown = np.clip(times - hidden.latency, 0.0, None)
    out = flight.outputs_from_states(flight.states_at(flown))
    out["h"] = out["h"] + hidden.bias_h
    return out


def measurements(hidden: Hidden, seed: int, times=None):
    """The case's data (``rocketid.Measurements``): exact outputs plus N(0, sigma) noise, seeded."""
    times = A.sample_times() if times is None else np.asarray(times, float)
    times = times[times - hidden.latency <= A.TF + 1e-12]
    return with_noise(exact_outputs(hidden, times), times, A.SIGMA, seed)
