"""A model of the Falcon 9 first stage from public figures, for the broadcast telemetry shipped here.

The data (``rocketid/examples/data``, see its README) are speed and altitude read from the
launch broadcasts of two flights (CRS-11, CRS-12). Nothing about the vehicle is published
exactly; every number below is a public estimate or an assumption, and the fit says what the
data make of it.

=====================  =====================================================================
lift-off mass          549 t + ``dm0`` (public figure: stage, second stage and payload, fuelled;
                       ``dm0`` estimated, per flight: the payloads differ)
thrust                 nine Merlin 1D: 914 kN each in vacuum, 845 kN at sea level, so
                       ``P(h) = 9 (914 kN - 69 kN p_a(h) / p0)`` (``p_a`` the 1976 standard's
                       pressure): a nozzle term, scaled by ``1 + k_P`` (estimated)
mass flow              at full thrust ``9 x 914 kN / (311 s x g0)`` = 2697 kg/s (vacuum specific
                       impulse 311 s, a public estimate), scaled by ``1 + k_mdot`` (estimated)
reference area         pi (3.7 m / 2)^2 = 10.75 m^2
drag                   CD(Mach), piecewise linear on Mach 0, 0.8, 1.1, 1.5, 2.5, 4 (estimated)
lift and attitude      no lift; the thrust direction relative to the velocity ``alpha(t)`` is
                       piecewise linear in time on knots every 20 s (estimated): the broadcast
                       gives no attitude, so the flight path is what the altitude asks for
flight                 Earth-relative speed (the broadcast's speed is 0 at lift-off), a
                       non-rotating Earth, the 1976 standard atmosphere, no wind
window                 from ``t0`` (default 20 s, where the vehicle has turned and speed and
                       altitude are well resolved) to ``tf`` (default 140 s, before main-engine
                       cut-off); the states at ``t0`` are estimated (guesses from the data)
outputs                ``h`` and ``v``; sigma: the quantization step / sqrt(12) (100 m steps of
                       altitude: 28.9 m; 1 km/h steps of speed: 0.080 m/s) unless given
=====================  =====================================================================

Priors (what an engineer knows before the flight): ``k_P ~ N(0, 0.03^2)`` (a static firing
gives thrust to about 3 %), ``k_mdot ~ N(0, 0.03^2)``, and ``CD ~ N(0.4, 0.1^2)`` at each
Mach knot (a generic slender launcher's wind-tunnel drag, loosely known). Without them thrust,
mass flow and drag trade against each other along directions the speed and altitude barely see.
"""

from __future__ import annotations

import json
import math
from importlib import resources
from pathlib import Path

import numpy as np
import sympy as sp

from ..data import Measurements, read_csv
from ..errors import DataError, ModelError
from ..model import Model, ModelSpec
from ..physics.ascent import AscentStates, ascent_dynamics, flight_conditions
from ..physics.atmosphere import us76_pressure
from ..physics.gravity import G0

__all__ = ["FLIGHTS", "falcon9_data_path", "falcon9_events", "falcon9_measurements", "falcon9_model", "reading_noise",
           "LIFTOFF_MASS", "THRUST_VAC", "THRUST_SL", "ISP_VAC", "AREA", "MACH_KNOTS", "QUANTIZATION"]

#: The flights shipped: label -> file stem.
FLIGHTS = {"CRS-11": "falcon9_crs11_stage1", "CRS-12": "falcon9_crs12_stage1"}
LIFTOFF_MASS = 549_000.0
N_ENGINES = 9
THRUST_VAC = 914_000.0
THRUST_SL = 845_000.0
ISP_VAC = 311.0
AREA = math.pi * (3.7 / 2) ** 2
#: Largest thrust direction off the velocity, rad: a launcher flies near zero attack angle through
#: the dense atmosphere (structural loads), 3 degrees allows for steering and winds.
ALPHA_MAX = math.radians(3.0)
MACH_KNOTS = (0.0, 0.8, 1.1, 1.5, 2.5, 4.0)
#: Quantization steps of the broadcast's numbers: altitude 0.1 km, speed 1 km/h.
QUANTIZATION = {"h": 100.0, "v": 1000.0 / 3600.0}
SEA_LEVEL_PRESSURE = 101325.0


def falcon9_data_path(flight: str, kind: str = "csv") -> Path:
    """The shipped file of ``flight`` (``"CRS-11"`` or ``"CRS-12"``): ``kind`` ``"csv"`` or ``"events"``."""
    if flight not in FLIGHTS:
        raise DataError(f"unknown flight {flight!r}; the shipped flights are {', '.join(FLIGHTS)}")
    name = FLIGHTS[flight] + (".csv" if kind == "csv" else "_events.json")
    return Path(str(resources.files("rocketid.examples") / "data" / name))


def falcon9_events(flight: str) -> dict:
    """The broadcast's event times of ``flight`` (whole seconds): the answer key, not an input."""
    return json.loads(falcon9_data_path(flight, "events").read_text())


def falcon9_measurements(flight: str, t0: float = 20.0, tf: float = 140.0,
                         sigma: dict | None = None) -> Measurements:
    """The flight's speed and altitude in ``[t0, tf]``, sigma the quantization step / sqrt(12)
    unless ``sigma`` gives another."""
    sig = {k: q / math.sqrt(12.0) for k, q in QUANTIZATION.items()}
    sig.update(sigma or {})
    return read_csv(falcon9_data_path(flight), ("h", "v"), sigma=sig).window(t0, tf)


def _start_guess(data: Measurements, t0: float) -> tuple[float, float, float]:
    """h, v and flight-path angle at ``t0`` from the data (a straight line through 4 s of samples;
    ``sin(theta) = (dh/dt) / v``)."""
    out = []
    for name in ("h", "v"):
        ch = data[name]
        keep = ch.times <= t0 + 4.0
        slope, icpt = np.polyfit(ch.times[keep] - t0, ch.values[keep], 1)
        out.append((icpt, slope))
    (h0, hdot), (v0, _) = out
    return h0, v0, math.asin(min(0.999, max(0.05, hdot / v0)))


def falcon9_model(data: Measurements | None = None, *, t0: float = 20.0, tf: float = 140.0, priors: bool = True,
                  alpha_step: float = 10.0,
                  name: str = "Falcon 9 stage 1") -> ModelSpec:
    """The first-stage model (the module's table); the start states are guessed from ``data``.

    Parameters
    ----------
    data : Measurements, optional
        The flight's data (for the guesses of the start states; default: CRS-11's).
    t0, tf : float
        The window, s after lift-off.
    priors : bool
        Declare the priors of the module notes.
    """
    if not 5.0 <= t0 < tf <= 146.0:
        raise ModelError(f"the window must lie in [5, 146] s (lift-off to main-engine cut-off), got [{t0:g}, {tf:g}]")
    data = data if data is not None else falcon9_measurements("CRS-11", t0, tf)
    h0, v0, th0 = _start_guess(data, t0)
    # the window starts in flight: the states at t0 are estimated, guessed from the data
    m = Model(name, t0, tf, description="Falcon 9 first stage from public figures (rocketid.examples.falcon9)")
    x = m.state("x", 0.0)
    # within a few quantization steps of the data's own start values
    h = m.state("h", h0, free=True, bounds=(h0 - 300.0, h0 + 300.0), nominal=max(h0, 1000.0))
    v = m.state("v", v0, free=True, bounds=(v0 - 3.0, v0 + 3.0), nominal=v0)
    th = m.state("theta", th0, free=True, bounds=(0.0, math.pi / 2), nominal=1.0)
    for role, sym in (("downrange", x), ("altitude", h), ("speed", v), ("flight_path_angle", th)):
        m.declare_role(role, sym)
    st = AscentStates(x, h, v, th)
    fc = flight_conditions(m, st, atmosphere="us76")
    k_P = m.parameter("k_P", 0.0, bounds=(-0.3, 0.3), nominal=0.03)
    k_mdot = m.parameter("k_mdot", 0.0, bounds=(-0.3, 0.3), nominal=0.03)
    pa = m.define("p_ambient", us76_pressure(h))
    thrust = N_ENGINES * (THRUST_VAC - (THRUST_VAC - THRUST_SL) * pa / SEA_LEVEL_PRESSURE) * (1 + k_P)
    mdot = N_ENGINES * THRUST_VAC / (ISP_VAC * G0)
    dm0 = m.parameter("dm0", 0.0, bounds=(-50_000.0, 50_000.0), nominal=5000.0)
    mass = m.constant("m_liftoff", LIFTOFF_MASS) + dm0 - mdot * (1 + k_mdot) * m.t
    cd = m.table("CD", fc.mach, MACH_KNOTS, 0.4, bounds=(0.05, 1.5), nominal=0.4)
    knots = np.unique(np.concatenate([np.arange(t0, tf, alpha_step), [tf]]))
    alpha = m.piecewise_linear("alpha", knots, 0.0, bounds=(-ALPHA_MAX, ALPHA_MAX), nominal=0.01)
    ascent_dynamics(m, st, fc, thrust=thrust, mass=mass, area=m.constant("S_ref", AREA), cd=cd, cl=0, alpha=alpha)
    sig = {k: q / math.sqrt(12.0) for k, q in QUANTIZATION.items()}
    m.output("h", h, sigma=sig["h"])
    m.output("v", v, sigma=sig["v"])
    if priors:
        m.prior(k_P, 0.0, 0.03, source="static firing")
        m.prior(k_mdot, 0.0, 0.03, source="static firing")
        m.prior(dm0, 0.0, 5000.0, source="public lift-off mass, payloads differ")
        for j in range(len(MACH_KNOTS)):
            m.prior(f"CD_{j}", 0.4, 0.1, source="generic wind-tunnel drag")
    return m.freeze()


def reading_noise(data: Measurements, window: float = 2.0) -> dict:
    """An estimate of each channel's reading noise from the data alone (no model).

    A cubic is fitted to the samples of each ``window``-second piece; the standard deviation of
    the scatter about the cubics is the noise. It includes the quantization and the screen's
    refresh jitter, and is what a model that follows the flight can reach.

    Returns
    -------
    dict
        ``{channel: sigma}``.
    """
    out = {}
    for ch in data.channels:
        t, y = ch.times, ch.values
        res = []
        for a in np.arange(t[0], t[-1], window):
            k = (t >= a) & (t < a + window)
            if k.sum() > 8:
                c = np.polyfit(t[k] - a, y[k], 3)
                res.append(y[k] - np.polyval(c, t[k] - a))
        if not res:
            raise DataError(f"channel {ch.name!r}: too few samples per {window:g} s to estimate the noise")
        r = np.concatenate(res)
        out[ch.name] = float(np.sqrt(np.sum(r ** 2) / max(1, r.size - 4 * len(res))))
    return out
