"""Kestrel-S's truth: the flight written apart from rocketid's ascent builders and effect catalogue.

The estimation model (``tests/vehicles/kestrel.py``) flies speed and flight-path angle (v, theta)
with rocketid's ascent equations. The truth here integrates the horizontal and vertical velocity
components (u, w) in the local frame of a spherical non-rotating Earth, with the forces as vectors:
thrust along the body axis at the commanded pitch angle, drag against the air-relative velocity,
lift normal to it, gravity ``g0 (Re / (Re + h))^2`` and the curvature terms ``-u w / (Re + h)``,
``u^2 / (Re + h)``. With no hidden effect it reproduces the estimation model to well under a
millimetre (``tests/test_unseen_study.py``).

Hidden effects (``Hidden``), each in its own shape, none of them a catalogue expression:

- ``hot_motor``: a warm grain burns faster: the thrust curve runs ``k`` times faster and ``k`` times
  higher, ``P(t) = k P_table(k t)`` (same total impulse), and the mass flow with it;
- ``A_e``: nozzle back-pressure: the tabulated thrust is a sea-level static-firing figure; in flight
  ``P + A_e (p_sl - p(h))`` with ``p(h)`` log-linearly interpolated in a 1 km table of the 1976
  standard's pressure integrated here from its temperature profile (not rocketid's atmosphere);
- ``wind``: a headwind profile ``W(h) = -(W_s + W_g (1 - exp(-h / 5 km)))`` (surface value at the
  rail, growing monotonically aloft), the forces from the air-relative velocity (u - W, w), Mach and
  dynamic pressure from the airspeed, the attack angle from the air-relative path;
- ``warm_dT``: a warm day: density times the ratio of a hydrostatic atmosphere ``dT`` kelvin warmer
  than the standard to the standard (same sea-level pressure), tabulated every 1 km and interpolated
  linearly (speed of sound unchanged, so that the effect is a pure density deviation);
- ``delta``: thrust misalignment: the thrust at the commanded pitch plus ``delta`` from t = 0;
- ``rotation``: Earth rotation at latitude ``lat`` launching on azimuth ``az``: the Coriolis
  ``-2 Omega x V`` and centrifugal ``-Omega x (Omega x r)`` accelerations as cross products in the
  launch site's east-north-up frame, projected on the trajectory plane;
- ``drag_bump``: a drag hump ``dCD (1 - ((M - M_c)/w)^2)^2`` between the table's Mach knots;
- ``tailoff``: the grain's last sliver burning out early: thrust and mass flow sag by a fraction
  along a smoothstep in time;
- ``jet``: a tailwind with a surface value and a ``sech^2`` jet, added to the headwind profile;
- ``dm0``: a start mass ``dm0`` kg above the declared one (a heavier payload; not a catalogue effect);
- sensor effects applied to the sampled trajectory (``sensor``): an altitude bias drifting linearly
  ``b0 + b1 t``, and a time-tag offset (the trajectory sampled at ``t - tau``, not a first-order
  expansion).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import sympy as sp

import rocketid as ri
from rocketid.physics.atmosphere import us76_density, us76_speed_of_sound

import kestrel as K

RE = 6_371_000.0
OMEGA = 7.2921159e-5
P_SL = 101_325.0


@dataclass(frozen=True)
class Hidden:
    """The hidden effects of one case (zero: absent)."""

    hot_motor: float = 1.0            # time/level factor k of the thrust curve
    A_e: float = 0.0                  # m^2, nozzle exit area (thrust stated at sea level)
    wind: tuple[float, float] = (0.0, 0.0)   # (W_s, W_g) m/s of the headwind profile
    warm_dT: float = 0.0              # K
    delta: float = 0.0                # rad
    rotation: tuple[float, float] | None = None   # (latitude deg, azimuth deg)
    dm0: float = 0.0                  # kg
    bias_h: tuple[float, float] = (0.0, 0.0)      # (b0 m, b1 m/s)
    tau: float = 0.0                  # s
    drag_bump: tuple[float, float, float] = (0.0, 1.15, 0.1)   # (dCD, Mach centre, Mach half-width)
    tailoff: tuple[float, float, float] = (0.0, 30.0, 34.0)    # (fraction lost, ramp start s, ramp end s)
    jet: tuple[float, float, float, float] = (0.0, 0.0, 9000.0, 2500.0)  # (surface, peak m/s, at m, half-width m)


def _interp(var, xs, ys):
    """Piecewise-linear interpolation of the table (xs, ys) in ``var``, flat beyond the ends (Piecewise)."""
    pieces = [(float(ys[0]), var < float(xs[0]))]
    for j in range(len(xs) - 1):
        x0, x1, y0, y1 = map(float, (xs[j], xs[j + 1], ys[j], ys[j + 1]))
        pieces.append((y0 + (y1 - y0) * (var - x0) / (x1 - x0), var < x1))
    pieces.append((float(ys[-1]), True))
    return sp.Piecewise(*pieces)


def pressure_table(dT: float = 0.0, top_km: int = 30):
    """Pressure (Pa) and density (kg/m^3) every 1 km, integrated hydrostatically from the 1976
    standard's temperature profile (geopotential layers 0-11-20-32 km: -6.5, 0, +1 K/km) plus dT."""
    r0, g0, R = 6_356_766.0, 9.80665, 287.05287
    hs = np.arange(0.0, top_km + 1.0) * 1000.0
    fine = np.linspace(0.0, hs[-1], 30_001)
    H = r0 * fine / (r0 + fine)                                 # geopotential altitude
    T_std = np.where(H < 11e3, 288.15 - 6.5e-3 * H, np.where(H < 20e3, 216.65, 216.65 + 1e-3 * (H - 20e3)))
    T = T_std + dT
    dH = np.diff(H)
    integrand = g0 / (R * T)
    lnp = np.concatenate([[0.0], -np.cumsum(0.5 * (integrand[1:] + integrand[:-1]) * dH)])
    p = P_SL * np.exp(lnp)
    rho = p / (R * T)
    idx = np.searchsorted(fine, hs)
    return hs, p[idx], rho[idx]


def thrust_table_extended():
    """The static-firing table, continued past the burn by its last slope (for a motor burning faster)."""
    times = list(K.THRUST_TIMES) + [41.0, 42.0, 43.0]
    slope = K.THRUST_VALUES[-1] - K.THRUST_VALUES[-2]
    values = list(K.THRUST_VALUES) + [K.THRUST_VALUES[-1] + slope * j for j in (1, 2, 3)]
    return times, values


def truth_model(hidden: Hidden = Hidden()):
    """Kestrel-S's truth with the hidden (non-sensor) effects, as a frozen ``ModelSpec``."""
    m = ri.Model("Kestrel-S truth", 0.0, K.T_BURN)
    theta0 = K.START[3]
    x = m.state("x", K.START[0])
    h = m.state("h", K.START[1])
    u = m.state("u", K.START[2] * math.cos(theta0))
    w = m.state("w", K.START[2] * math.sin(theta0))
    mass = m.state("mass_kg", K.M_START + hidden.dm0)
    t = m.t
    k = hidden.hot_motor
    times, values = thrust_table_extended()
    tab = _interp(k * t, times, values)
    brk = sorted({tt / k for tt in times if tt / k <= K.T_BURN} | set(K.PITCH_TIMES))
    p_table = m.input("P_table", k * tab, breakpoints=brk)
    pitch = m.input("pitch", _interp(t, K.PITCH_TIMES, [math.radians(d) for d in K.PITCH_DEG]), breakpoints=brk)
    thrust = p_table
    lost, t1, t2 = hidden.tailoff
    if lost:                                                   # a sliver burning out early: the thrust sags late
        ramp = sp.Piecewise((0.0, t < t1), ((t - t1) / (t2 - t1), t < t2), (1.0, True))
        ramp = ramp ** 2 * (3 - 2 * ramp)
        thrust = thrust * (1 - lost * ramp)
    p_motor = thrust                                           # the motor's own thrust: the mass flow follows it
    if hidden.A_e:
        hs, p, _ = pressure_table()
        lnp = _interp(h, hs, np.log(p))
        thrust = thrust + hidden.A_e * (P_SL - sp.exp(lnp))
    rho = us76_density(h)
    if hidden.warm_dT:
        hs, _, rho_warm = pressure_table(hidden.warm_dT)
        _, _, rho_std = pressure_table(0.0)
        rho = rho * _interp(h, hs, rho_warm / rho_std)
    W = 0
    if any(hidden.wind):
        ws, wg = hidden.wind
        W = -(ws + wg * (1 - sp.exp(-h / 5000.0)))
    if hidden.jet[0] or hidden.jet[1]:
        surface, peak, at, half = hidden.jet
        W = W + surface + peak * sp.sech((h - at) / half) ** 2 * 1.0
    ua = u - W
    va = sp.sqrt(ua ** 2 + w ** 2)
    mach = va / us76_speed_of_sound(h)
    q = rho * va ** 2 / 2
    S = math.pi * K.DIAMETER ** 2 / 4
    cd = _interp(mach, K.CD_KNOTS, K.CD_TRUTH)
    bump, centre, width = hidden.drag_bump
    if bump:                                                   # a drag hump between the table's knots
        cd = cd + bump * sp.Max(0, 1 - ((mach - centre) / width) ** 2) ** 2
    cla = _interp(mach, K.CLA_KNOTS, K.CLA_TRUTH)
    theta_air = sp.atan2(w, ua)
    alpha_air = pitch - theta_air
    drag = q * S * cd
    lift = q * S * cla * alpha_air
    body = pitch + hidden.delta
    fu = thrust * sp.cos(body) - drag * ua / va - lift * w / va
    fw = thrust * sp.sin(body) - drag * w / va + lift * ua / va
    r = RE + h
    g = 9.80665 * (RE / r) ** 2
    au, aw = 0, 0
    if hidden.rotation is not None:
        lat, az = (math.radians(a) for a in hidden.rotation)
        Om = sp.Matrix([0.0, OMEGA * math.cos(lat), OMEGA * math.sin(lat)])        # east, north, up
        e_d = sp.Matrix([math.sin(az), math.cos(az), 0.0])
        e_u = sp.Matrix([0.0, 0.0, 1.0])
        V = u * e_d + w * e_u
        R = r * e_u
        acc = -2 * Om.cross(V) - Om.cross(Om.cross(R))
        au, aw = acc.dot(e_d), acc.dot(e_u)
    m.ode({
        x: RE / r * u,
        h: w,
        u: fu / mass - u * w / r + au,
        w: fw / mass - g + u ** 2 / r + aw,
        mass: -p_motor / (K.ISP * K.G0),
    })
    m.output("x", x, sigma=K.SIGMA["x"])
    m.output("h", h, sigma=K.SIGMA["h"])
    m.output("v", sp.sqrt(u ** 2 + w ** 2), sigma=K.SIGMA["v"])
    return m.freeze()


def exact_outputs(hidden: Hidden, times) -> dict[str, np.ndarray]:
    """x, h, v at ``times`` from the truth (sensor effects applied), without noise."""
    times = np.asarray(times, dtype=float)
    spec = truth_model(hidden)
    sample = times - hidden.tau
    traj = ri.simulate(spec, {}, sample)
    if not traj.success:
        raise RuntimeError(f"truth simulation failed: {traj.message}")
    out = {name: np.array(values, dtype=float) for name, values in traj.outputs().items()}
    b0, b1 = hidden.bias_h
    out["h"] = out["h"] + b0 + b1 * times
    return out


def measurements(hidden: Hidden, seed: int):
    """Noisy measurements at Kestrel-S's sample times: the exact outputs plus N(0, sigma^2), seeded."""
    times = K.sample_times()
    exact = exact_outputs(hidden, times)
    rng = np.random.default_rng(seed)
    noisy = {name: exact[name] + rng.normal(0.0, K.SIGMA[name], times.size) for name in ("x", "h", "v")}
    return ri.Measurements.from_arrays(times, noisy, sigma=dict(K.SIGMA))
