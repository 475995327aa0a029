"""Independent truth simulator for the blind study (Halcyon-8).

Written without rocketid's simulator, effects or diagnostics: the vehicle is a point mass over
a spherical, non-rotating Earth, integrated in **Earth-centred Cartesian coordinates**
(position X, Y; velocity VX, VY; mass m; optionally a speed-sensor state) with the forces as
vectors:

- gravity ``-g0 (Re/r)^2 r_hat`` (g0 = 9.80665 m/s^2, Re = 6 371 km, the model's constants);
- thrust ``P f(t)`` along the body axis, whose pitch phi(t) above the local horizontal is the
  vehicle's sampled attitude program (np.interp of the same table the flight computer holds);
- drag ``-qbar S CD(M) V_air_hat`` and lift ``qbar S CL_alpha alpha`` normal to the air-relative
  velocity (rotated towards local up), alpha = phi - (flight-path angle of V_air);
- the US Standard Atmosphere 1976 written here (geopotential layers to 47 km, hydrostatic
  pressure, density p M0 / (R* T), speed of sound sqrt(gamma R* T / M0)).

The measured quantities are derived from the Cartesian state: downrange ``x = Re * central
angle`` (arc at the ground), altitude ``h = r - Re``, speed ``v = |V|``.

Hidden effects are switched on through a dict ``effects`` (see :func:`simulate`); sensor effects
are applied to the outputs, noise is seeded Gaussian.
"""

from __future__ import annotations

import math
import os
import sys

import numpy as np
from scipy.integrate import solve_ivp

sys.path.insert(0, os.path.join(os.path.dirname(__file__), "..", "vehicles"))
import halcyon as V  # the vehicle's constants and its attitude table only

G0 = 9.80665
RE = 6_371_000.0
# US 1976 constants
R_STAR = 8.31432
M_AIR = 0.0289644
GAMMA = 1.4
R0_GEOPOT = 6_356_766.0
P_SL = 101_325.0
LAYERS = ((0.0, 288.15, -0.0065), (11_000.0, 216.65, 0.0), (20_000.0, 216.65, 0.001),
          (32_000.0, 228.65, 0.0028), (47_000.0, 270.65, 0.0))


def _layer_bases(dT: float = 0.0):
    """(H_b, T_b, L_b, p_b) for a hydrostatic atmosphere with every temperature shifted by dT."""
    out = []
    p = P_SL
    k = G0 * M_AIR / R_STAR
    for i, (hb, tb, lb) in enumerate(LAYERS):
        tb = tb + dT
        out.append((hb, tb, lb, p))
        if i + 1 < len(LAYERS):
            dh = LAYERS[i + 1][0] - hb
            if lb == 0.0:
                p = p * math.exp(-k * dh / tb)
            else:
                p = p * ((tb + lb * dh) / tb) ** (-k / lb)
    return tuple(out)


_BASES = {0.0: _layer_bases(0.0)}


def atmosphere(h: float, dT: float = 0.0):
    """Temperature (K), pressure (Pa), density (kg/m^3), speed of sound (m/s) at geometric h."""
    if dT not in _BASES:
        _BASES[dT] = _layer_bases(dT)
    bases = _BASES[dT]
    H = R0_GEOPOT * h / (R0_GEOPOT + h)
    k = G0 * M_AIR / R_STAR
    i = 0
    for j in range(len(bases)):
        if H >= bases[j][0]:
            i = j
    hb, tb, lb, pb = bases[i]
    T = tb + lb * (H - hb)
    if lb == 0.0:
        p = pb * math.exp(-k * (H - hb) / tb)
    else:
        p = pb * (T / tb) ** (-k / lb)
    rho = p * M_AIR / (R_STAR * T)
    a = math.sqrt(GAMMA * R_STAR * T / M_AIR)
    return T, p, rho, a


PHI_T, PHI_V = V.program_table()


def cd_table(mach: float) -> float:
    return float(np.interp(mach, V.MACH_KNOTS, V.CD_TRUTH))


def _smooth_window(t, t_on, t_off, ramp):
    """0 outside [t_on, t_off], 1 inside after linear ramps of length ramp."""
    up = min(max((t - t_on) / ramp, 0.0), 1.0)
    down = min(max((t_off - t) / ramp, 0.0), 1.0)
    return min(up, down)


def wind_profile(h: float, e: dict) -> float:
    """Horizontal wind, m/s, positive downrange."""
    w = e["wind_shear"]
    return (w["surface"] * math.tanh(h / 300.0)
            - w["jet"] * math.exp(-0.5 * ((h - w["jet_alt"]) / w["jet_width"]) ** 2))


def _rhs(t, y, e):
    X, Y, VX, VY, m = y[:5]
    r = math.hypot(X, Y)
    er = np.array([X / r, Y / r])            # local up
    ee = np.array([Y / r, -X / r])           # local horizontal, downrange (launch at (0, Re), flying +X)
    h = r - RE
    Vv = np.array([VX, VY])
    # propulsion
    f = 1.0
    if "throttle" in e:
        b = e["throttle"]
        f = 1.0 - b["depth"] * _smooth_window(t, b["t_on"], b["t_off"], b["ramp"])
    thrust = V.THRUST_SL * f * (1.0 + e.get("thrust_eps", 0.0))
    mdot = V.MDOT * f
    phi = float(np.interp(t, PHI_T, PHI_V))
    dthr = e["misalign"]["delta"] if ("misalign" in e and t >= e["misalign"]["t_on"]) else 0.0
    tdir = math.cos(phi + dthr) * ee + math.sin(phi + dthr) * er
    # aerodynamics
    _, _, rho, a = atmosphere(h, e.get("dT", 0.0))
    w = wind_profile(h, e) if "wind_shear" in e else 0.0
    Vair = Vv - w * ee
    va = math.hypot(*Vair)
    theta_air = math.atan2(Vair @ er, Vair @ ee)
    alpha = phi - theta_air
    mach = va / a
    cd = cd_table(mach) + e.get("induced_k", 0.0) * alpha ** 2
    cl = V.CL_ALPHA_TRUTH * alpha
    q = 0.5 * rho * va ** 2
    uv = Vair / va
    un = np.array([-uv[1], uv[0]])           # +90 deg from the air velocity
    if un @ er < 0:                          # towards local up
        un = -un
    F = thrust * tdir - q * V.AREA * cd * uv + q * V.AREA * cl * un
    acc = F / m - G0 * (RE / r) ** 2 * er
    out = [VX, VY, acc[0], acc[1], -mdot]
    if len(y) > 5:                           # first-order speed sensor
        out.append((math.hypot(VX, VY) - y[5]) / e["v_lag"])
    return out


def simulate(times, effects: dict | None = None):
    """Exact (noise-free) outputs x, h, v at ``times`` for the hidden ``effects``.

    effects keys: thrust_eps, throttle{depth,t_on,t_off,ramp}, misalign{delta,t_on},
    dT, wind_shear{surface,jet,jet_alt,jet_width}, induced_k, drop{t,dm}, v_lag (s),
    h_scale, b_h, b_x, b_v (sensor, applied to outputs).
    """
    e = dict(effects or {})
    times = np.asarray(times, float)
    x0, h0, v0, th0 = V.START
    r0 = RE + h0
    # launch at central angle x0/RE = 0: position (0, r0); local up (0,1), downrange (1,0)
    y0 = [0.0, r0, v0 * math.cos(th0), v0 * math.sin(th0), V.M0]
    if "v_lag" in e:
        y0.append(v0)
    # breakpoints: the attitude table's samples, the effect switch times, the horizon
    bps = set(np.round(PHI_T, 9).tolist()) | {V.TF}
    for key in ("throttle",):
        if key in e:
            b = e[key]
            bps |= {b["t_on"], b["t_on"] + b["ramp"], b["t_off"] - b["ramp"], b["t_off"]}
    if "misalign" in e:
        bps.add(e["misalign"]["t_on"])
    if "drop" in e:
        bps.add(e["drop"]["t"])
    bps = sorted(b for b in bps if 0.0 <= b <= V.TF)
    ts, ys = [], []
    y = np.array(y0, float)
    for a, b in zip(bps[:-1], bps[1:]):
        if "drop" in e and abs(a - e["drop"]["t"]) < 1e-9:
            y[4] -= e["drop"]["dm"]
        sel = times[(times >= a) & (times <= b)] if b == bps[-1] else times[(times >= a) & (times < b)]
        sol = solve_ivp(_rhs, (a, b), y, method="DOP853", rtol=1e-10, atol=1e-8,
                        t_eval=sel if sel.size else None, args=(e,))
        if not sol.success:
            raise RuntimeError(sol.message)
        if sel.size:
            ts.append(sol.t)
            ys.append(sol.y)
        y = sol.y[:, -1].copy() if sel.size == 0 or sol.t[-1] == b else _endpoint(a, b, y, e)
    T = np.concatenate(ts)
    Yy = np.concatenate(ys, axis=1)
    assert np.allclose(T, times), "sample times lost"
    X, Y, VX, VY = Yy[0], Yy[1], Yy[2], Yy[3]
    r = np.hypot(X, Y)
    x = RE * np.arctan2(X, Y)
    h = r - RE
    v = np.hypot(VX, VY)
    if "v_lag" in e:
        v = Yy[5]
    h = h * (1.0 + e.get("h_scale", 0.0)) + e.get("b_h", 0.0)
    x = x + e.get("b_x", 0.0)
    v = v + e.get("b_v", 0.0)
    return {"t": times, "x": x, "h": h, "v": v}


def _endpoint(a, b, y, e):
    sol = solve_ivp(_rhs, (a, b), y, method="DOP853", rtol=1e-10, atol=1e-8, args=(e,))
    return sol.y[:, -1].copy()


def measurements(times, effects=None, seed=0, sigma=None):
    """Noisy measurements (seeded Gaussian, the vehicle's sigmas by default)."""
    sigma = sigma or V.SIGMA
    out = simulate(times, effects)
    rng = np.random.default_rng(seed)
    for c in ("x", "h", "v"):
        out[c] = out[c] + rng.normal(0.0, sigma[c], out[c].size)
    return out


def write_csv(path, data):
    arr = np.column_stack([data["t"], data["x"], data["h"], data["v"]])
    np.savetxt(path, arr, delimiter=",", header="t,x,h,v", comments="", fmt="%.10g")
