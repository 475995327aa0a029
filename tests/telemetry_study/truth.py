"""The truth of the real-telemetry study: Corvid-L flown in another state space than rocketid's.

Written from the vehicle's declaration (``tests/vehicles/corvid.py``) and physics, not from rocketid's
code. State: Cartesian position ``r = (X, Y)`` and velocity ``u`` in the flight plane about the centre of
a spherical, non-rotating Earth (radius 6371 km, launch point at ``(0, R)``), and the mass. Forces as
vectors: inverse-square gravity, thrust along the body axis (the stored pitch attitude above the local
horizon), drag against the air-relative velocity, lift normal to it; the 1976 standard atmosphere from
its own hydrostatic layers (with a temperature offset for the hot day). Every hidden effect has its
own physical shape (:class:`Hidden`). ``solve_ivp`` (DOP853) at rtol 1e-12, restarted at every corner
of the pitch program and the throttle schedule.

``measurements(hidden, seed)`` makes the telemetry as it comes: each channel at its own rate from
T+12 s, drop-outs, the radar's hand-over gap, seeded Gaussian noise at ``corvid.SIGMA`` (the speed's
larger after ``T_VIBRATION`` when asked), quantized to the telemetry word's step, and no sigma on the
channels (the diagnosis must estimate them).
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

import corvid as V  # noqa: E402

EARTH_RADIUS = 6_371_000.0
STD_GRAVITY = 9.80665
SEA_LEVEL_PRESSURE = 101_325.0
#: 1976 standard: geopotential radius, gas constant, molar mass of air, ratio of specific heats.
GEOPOTENTIAL_RADIUS = 6_356_766.0
R_STAR = 8.31432
MOLAR_MASS = 0.0289644
GAMMA = 1.4
#: Layers of the 1976 standard: base geopotential altitude (m), base temperature (K), lapse rate (K/m).
LAYERS = ((0.0, 288.15, -0.0065), (11_000.0, 216.65, 0.0), (20_000.0, 216.65, 0.001),
          (32_000.0, 228.65, 0.0028), (47_000.0, 270.65, 0.0), (51_000.0, 270.65, -0.0028),
          (71_000.0, 214.65, -0.002))
#: Normal gravity at the launch site's latitude (Somigliana's formula, WGS-84), m/s^2.
SITE_GRAVITY = 9.7803253359 * (1 + 0.00193185265241 * math.sin(math.radians(V.SITE_LATITUDE_DEG)) ** 2) / \
    math.sqrt(1 - 0.00669437999013 * math.sin(math.radians(V.SITE_LATITUDE_DEG)) ** 2)
#: When the speed's noise grows in the vibration case (s), the loss of signal every case has (s).
T_VIBRATION = 60.0
LOS = (57.0, 59.0)
RADAR_GAP = (40.0, 48.0)
DROPOUT_SHARE = 0.03


@dataclass(frozen=True)
class Hidden:
    """The hidden effects (zero: the vehicle as declared)."""

    eps_thrust: float = 0.0             # thrust (1 + eps) at the stated mass flow: a specific-impulse error
    bucket_level: float | None = None   # the throttle the engine delivered in the bucket (commanded 0.72)
    A_e: float = 0.0                    # nozzle exit area, m^2: thrust tau F_sl + A_e (tau p0 - p_a)
    wind: tuple | None = None           # (at 10 m, at the 11 km core), m/s, + downrange
    dT: float = 0.0                     # air warmer than the 1976 standard over the column, K
    dm0: float = 0.0                    # lift-off mass above the declared, kg
    bias_v: float = 0.0                 # speed channel bias, m/s
    scale_h: float = 0.0                # altitude channel scale error
    tau: float = 0.0                    # every channel's time tags late by tau, s
    gravity: float | None = None        # surface gravity instead of the standard one, m/s^2
    v_noise_late: float = 1.0           # the speed's noise times this after T_VIBRATION
    radar_offset: float = 0.0           # the downrange channel is the ground range from a radar this far (m)
                                        # to the side of the ground track, abeam the pad
    filter_s: float = 0.0               # every channel's errors through a first-order filter of this time
                                        # constant (s; a navigation filter), their standard deviation the same


class Air:
    """The 1976 standard atmosphere, ``dT`` K warmer at every geopotential altitude, hydrostatic from the
    standard sea-level pressure (layer by layer in closed form)."""

    def __init__(self, dT: float = 0.0):
        self.dT = dT
        k = STD_GRAVITY * MOLAR_MASS / R_STAR
        bases = [SEA_LEVEL_PRESSURE]
        for (H0, T0, L), (H1, _, _) in zip(LAYERS[:-1], LAYERS[1:]):
            Tb = T0 + dT
            if L == 0.0:
                bases.append(bases[-1] * math.exp(-k * (H1 - H0) / Tb))
            else:
                bases.append(bases[-1] * ((Tb + L * (H1 - H0)) / Tb) ** (-k / L))
        self.bases = bases
        self.k = k

    def at(self, z: float):
        """Temperature (K), pressure (Pa), density (kg/m^3) and speed of sound (m/s) at geometric altitude z."""
        H = GEOPOTENTIAL_RADIUS * z / (GEOPOTENTIAL_RADIUS + z)
        j = 0
        while j + 1 < len(LAYERS) and H >= LAYERS[j + 1][0]:
            j += 1
        H0, T0, L = LAYERS[j]
        Tb = T0 + self.dT
        T = Tb + L * (H - H0)
        if L == 0.0:
            p = self.bases[j] * math.exp(-self.k * (H - H0) / Tb)
        else:
            p = self.bases[j] * (T / Tb) ** (-self.k / L)
        rho = p * MOLAR_MASS / (R_STAR * T)
        return T, p, rho, math.sqrt(GAMMA * R_STAR * T / MOLAR_MASS)


def wind_speed(h: float, wind) -> float:
    """Horizontal wind (m/s, + downrange): ``w10 (h / 10 m)^(1/7)`` up to 1 km, then linear to ``w_core``
    at 11 km, halving every 5 km above it (a Gaussian core)."""
    if not wind:
        return 0.0
    w10, core = wind
    if h <= 0.0:
        return 0.0
    if h <= 1_000.0:
        return w10 * (h / 10.0) ** (1.0 / 7.0)
    w1 = w10 * 100.0 ** (1.0 / 7.0)
    if h <= 11_000.0:
        return w1 + (core - w1) * (h - 1_000.0) / 10_000.0
    return core * 2.0 ** (-((h - 11_000.0) / 5_000.0) ** 2)


class Flight:
    """One flight with its hidden effects."""

    def __init__(self, hidden: Hidden):
        self.hidden = hidden
        self.air = Air(hidden.dT)
        levels = list(V.THROTTLE_LEVELS)
        if hidden.bucket_level is not None:
            levels[1] = levels[2] = hidden.bucket_level
        self.levels = tuple(levels)
        g = STD_GRAVITY if hidden.gravity is None else hidden.gravity
        self.mu = g * EARTH_RADIUS ** 2

    def throttle(self, t: float) -> float:
        return float(np.interp(t, V.THROTTLE_TIMES, self.levels))

    def thrust(self, t: float, p_ambient: float) -> float:
        tau = self.throttle(t)
        return (1.0 + self.hidden.eps_thrust) * V.THRUST_FULL * tau + \
            self.hidden.A_e * (tau * SEA_LEVEL_PRESSURE - p_ambient)

    def rhs(self, t, y):
        X, Y, U, W, mass = y
        r = math.hypot(X, Y)
        up = np.array([X / r, Y / r])
        east = np.array([up[1], -up[0]])                     # downrange, in the plane
        h = r - EARTH_RADIUS
        _, p, rho, a = self.air.at(h)
        u = np.array([U, W])
        air_u = u - wind_speed(h, self.hidden.wind) * east
        speed = float(np.hypot(*air_u))
        phi = float(V.pitch_program(t))
        body = math.cos(phi) * east + math.sin(phi) * up
        force = self.thrust(t, p) * body
        if speed > 1e-9:
            theta_air = math.atan2(float(air_u @ up), float(air_u @ east))
            mach = speed / a
            q = 0.5 * rho * speed ** 2
            cd = float(np.interp(mach, V.CD_KNOTS, V.CD_TRUTH))
            cl = V.CL_ALPHA * (phi - theta_air)
            along = air_u / speed
            normal = -math.sin(theta_air) * east + math.cos(theta_air) * up
            force = force + q * V.S_REF * (-cd * along + cl * normal)
        acc = force / mass - self.mu / r ** 2 * up
        return [U, W, acc[0], acc[1], -V.MASS_FLOW * self.throttle(t)]

    def states(self, times):
        """The Cartesian state at ``times`` (sorted, >= 0), integrated from lift-off segment by segment."""
        times = np.asarray(times, float)
        corners = sorted(set(V.PITCH_TIMES) | set(V.THROTTLE_TIMES) | {0.0})
        end = max(float(times.max()), V.TF)
        corners = [c for c in corners if c < end] + [end]
        y = np.array([0.0, EARTH_RADIUS, 0.0, 0.0, V.M_LIFTOFF + self.hidden.dm0])
        out = np.full((times.size, 5), np.nan)
        for a, b in zip(corners[:-1], corners[1:]):
            sel = (times >= a) & (times <= b)
            sol = solve_ivp(self.rhs, (a, b), y, method="DOP853", rtol=1e-12, atol=1e-9, dense_output=True)
            if not sol.success:
                raise RuntimeError(sol.message)
            if sel.any():
                out[sel] = sol.sol(times[sel]).T
            y = sol.y[:, -1]
        return out


def outputs_of(states) -> dict:
    """Downrange (arc length on the surface), altitude and ground speed of Cartesian states."""
    X, Y, U, W = states[:, 0], states[:, 1], states[:, 2], states[:, 3]
    return {"x": EARTH_RADIUS * np.arctan2(X, Y), "h": np.hypot(X, Y) - EARTH_RADIUS, "v": np.hypot(U, W)}


def exact_outputs(hidden: Hidden, times, per_channel: dict | None = None) -> dict:
    """The sensors' exact readings (hidden sensor errors included, no noise): at ``times`` for every
    channel, or at each channel's own times (``per_channel``)."""
    flight = Flight(hidden)
    wanted = per_channel or {name: np.asarray(times, float) for name in ("x", "h", "v")}
    result = {}
    for name, t in wanted.items():
        tt = np.asarray(t, float) - hidden.tau                 # a late time tag reads the flight earlier
        y = outputs_of(flight.states(tt))[name]
        if name == "v":
            y = y + hidden.bias_v
        if name == "h":
            y = y * (1.0 + hidden.scale_h)
        if name == "x" and hidden.radar_offset:
            y = np.hypot(y, hidden.radar_offset)
        result[name] = y
    return result


def telemetry_times(seed: int) -> dict:
    """Each channel's sample times as received: the nominal rates less the radar's hand-over gap (downrange),
    the loss of signal (every channel) and seeded random drop-outs of single frames."""
    rng = np.random.default_rng(10_000 + seed)
    kept = {}
    for name, t in V.channel_times().items():
        keep = ~((t > LOS[0]) & (t < LOS[1]))
        if name == "x":
            keep &= ~((t > RADAR_GAP[0]) & (t < RADAR_GAP[1]))
        keep &= rng.random(t.size) >= DROPOUT_SHARE
        kept[name] = t[keep]
    return kept


def filtered(t: np.ndarray, white: np.ndarray, tau: float) -> np.ndarray:
    """Unit white noise ``white`` at the times ``t`` through a first-order filter of time constant ``tau``
    (a Gauss-Markov error, stationary with unit variance): each error keeps ``exp(-dt / tau)`` of the one
    before, ``dt`` the interval between them (longer across a gap)."""
    out = np.empty(t.size)
    out[0] = white[0]
    for i in range(1, t.size):
        keep = math.exp(-(t[i] - t[i - 1]) / tau)
        out[i] = keep * out[i - 1] + math.sqrt(1.0 - keep * keep) * white[i]
    return out


def measurements(hidden: Hidden, seed: int):
    """The case's telemetry (``rocketid.Measurements`` without sigmas): noise, quantization, gaps."""
    import rocketid as ri
    times = telemetry_times(seed)
    exact = exact_outputs(hidden, None, per_channel=times)
    rng = np.random.default_rng(seed)
    channels = []
    for name in ("x", "h", "v"):
        t = times[name]
        sigma = np.full(t.size, V.SIGMA[name])
        if name == "v":
            sigma[t > T_VIBRATION] *= hidden.v_noise_late
        white = rng.standard_normal(t.size)
        noisy = exact[name] + sigma * (filtered(t, white, hidden.filter_s) if hidden.filter_s else white)
        q = V.QUANTUM[name]
        channels.append(ri.Channel(name, t, np.round(np.round(noisy / q) * q, 6)))
    return ri.Measurements(tuple(channels))
