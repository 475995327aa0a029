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
drag                   CD(Mach), piecewise linear on Mach 0, 0.8, 1.1, 1.5, 2.5, 4 (estimated;
                       other knots with ``mach_knots``)
lift and attitude      no lift; the thrust direction relative to the velocity ``alpha(t)`` is
                       piecewise linear in time on knots every ``alpha_step`` = 10 s within
                       +-``alpha_max`` = 3 deg (estimated): the broadcast gives no attitude, so
                       the flight path is what the altitude asks for. Optional (``q_alpha``): a
                       bound that widens as the dynamic pressure falls, ``alpha = u(t) q_alpha /
                       (qbar + q_alpha / alpha_max)`` with ``|u| <= 1`` (a load limit q alpha)
flight                 Earth-relative speed (the broadcast's speed is 0 at lift-off), a
                       non-rotating Earth (optional ``earth_rotation``: the centrifugal and
                       Coriolis accelerations at 28.5 deg N, heading 45 deg from north, for the
                       ISS's 51.6 deg inclination), the 1976 standard atmosphere, no wind
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

The optional model changes (a wider or q-alpha attitude bound, finer attitude knots, Earth
rotation, finer drag knots) were each tried against the misfit after 90 s and none reduced it
(docs/real-telemetry.md, ``benchmarks/falcon9_study.py --variants``): the defaults are the model
without them. The noise is best estimated with the fit (``sigma="estimate"``);
:func:`reading_noise` and :func:`smooth_residuals` are model-free references for it.
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
from ..physics.gravity import EARTH_RADIUS, G0

__all__ = ["FLIGHTS", "falcon9_data_path", "falcon9_events", "falcon9_measurements", "falcon9_model", "reading_noise",
           "smooth_residuals",
           "LIFTOFF_MASS", "THRUST_VAC", "THRUST_SL", "ISP_VAC", "AREA", "MACH_KNOTS", "QUANTIZATION", "LOAD_LIMIT"]

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
#: A load-limited attitude instead (``falcon9_model(data, **LOAD_LIMIT)``): the bound ``q_alpha / (qbar +
#: q_alpha / alpha_max)`` with ``q_alpha`` = 1571 Pa rad and ``alpha_max`` = 15 degrees: 2.5 degrees at 30 kPa
#: (about max-q), 8 at 5 kPa, 15 in vacuum. On CRS-12 it takes the
#: altitude after 110 s to its reading noise with a plausible drag table, where the +-3 degree bound holds
#: the drag at Mach 2.5 at its upper bound (docs/real-telemetry.md).
LOAD_LIMIT = {"q_alpha": math.radians(3.0) * 30_000.0, "alpha_max": math.radians(15.0)}
MACH_KNOTS = (0.0, 0.8, 1.1, 1.5, 2.5, 4.0)
#: Quantization steps of the broadcast's numbers: altitude 0.1 km, speed 1 km/h.
QUANTIZATION = {"h": 100.0, "v": 1000.0 / 3600.0}
SEA_LEVEL_PRESSURE = 101325.0
OMEGA_EARTH = 7.2921159e-5
LAUNCH_LATITUDE = 28.5
LAUNCH_HEADING = 45.0


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
                  alpha_step: float = 10.0, alpha_max: float = ALPHA_MAX, q_alpha: float | None = None,
                  earth_rotation: bool = False, mach_knots=MACH_KNOTS,
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
    alpha_step : float
        Spacing of the attitude knots, s.
    alpha_max : float
        Bound of the attitude, rad (with ``q_alpha``: its bound at zero dynamic pressure).
    q_alpha : float, optional
        A load limit ``qbar |alpha|``, Pa rad: the attitude becomes ``u(t) q_alpha / (qbar +
        q_alpha / alpha_max)`` with knots ``alpha_u<k>`` of ``u`` in [-1, 1].
    earth_rotation : bool
        Add the centrifugal and Coriolis accelerations of the rotating Earth (the speed stays
        Earth-relative) at Cape Canaveral, heading north-east.
    mach_knots : sequence of float
        Mach numbers of the drag table's knots.
    name : str
        The model's name.
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
    cd = m.table("CD", fc.mach, mach_knots, 0.4, bounds=(0.05, 1.5), nominal=0.4)
    knots = np.unique(np.concatenate([np.arange(t0, tf, alpha_step), [tf]]))
    if q_alpha is None:
        alpha = m.piecewise_linear("alpha", knots, 0.0, bounds=(-alpha_max, alpha_max), nominal=0.01)
    else:
        u = m.piecewise_linear("alpha_u", knots, 0.0, bounds=(-1.0, 1.0), nominal=0.1)
        alpha = m.define("alpha_program", u * q_alpha / (fc.qbar + q_alpha / alpha_max))
    ascent_dynamics(m, st, fc, thrust=thrust, mass=mass, area=m.constant("S_ref", AREA), cd=cd, cl=0, alpha=alpha)
    if earth_rotation:
        lat, psi = math.radians(LAUNCH_LATITUDE), math.radians(LAUNCH_HEADING)
        r = EARTH_RADIUS + h
        # in the Earth-fixed frame: the centrifugal acceleration (away from the axis) along the
        # velocity; across it, in the vertical plane, the centrifugal and the Coriolis
        # acceleration 2 Omega v cos(lat) sin(heading) (the Coriolis force does no work)
        cf = OMEGA_EARTH ** 2 * r * math.cos(lat)
        m.add_term(v, cf * (math.cos(lat) * sp.sin(th) - math.sin(lat) * math.cos(psi) * sp.cos(th)))
        m.add_term(th, (2 * OMEGA_EARTH * v * math.cos(lat) * math.sin(psi)
                        + cf * (math.cos(lat) * sp.cos(th) + math.sin(lat) * math.cos(psi) * sp.sin(th))) / v)
    sig = {k: q / math.sqrt(12.0) for k, q in QUANTIZATION.items()}
    m.output("h", h, sigma=sig["h"])
    m.output("v", v, sigma=sig["v"])
    if priors:
        m.prior(k_P, 0.0, 0.03, source="static firing")
        m.prior(k_mdot, 0.0, 0.03, source="static firing")
        m.prior(dm0, 0.0, 5000.0, source="public lift-off mass, payloads differ")
        for j in range(len(mach_knots)):
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


def smooth_residuals(data: Measurements, step: float = 5.0) -> dict:
    """Residuals of each channel about a least-squares cubic spline with knots every ``step`` s.

    A model-free reference for what a smooth curve reaches: the vehicle's acceleration changes
    smoothly between events, so a model that follows the flight should do about as well as a
    spline with knots every few seconds where no event happens. Unlike :func:`reading_noise`
    (independent cubics on short pieces) the spline is continuous, so it does not follow
    reading errors that last a second or two.

    Returns
    -------
    dict
        ``{channel: residuals}`` (measured minus spline), at the channel's sample times.
    """
    from scipy.interpolate import LSQUnivariateSpline

    out = {}
    for ch in data.channels:
        knots = np.arange(ch.times[0] + step, ch.times[-1] - 1e-6, step)
        out[ch.name] = ch.values - LSQUnivariateSpline(ch.times, ch.values, knots, k=3)(ch.times)
    return out
