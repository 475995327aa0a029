"""Truth models of the hidden-effect study, written independently of rocketid's effect catalogue.

The diagnosis (``rocketid.diagnostics``) extends a model with catalogue effects
(``rocketid/diagnostics/effects.py``). The data it is tested on here must not be made with those
same expressions, or the study would only check that the code agrees with itself. So every truth
model below is its own :class:`rocketid.model.Model` declaration, integrated by
:func:`rocketid.simulate` (SciPy, not the collocation), with the forces written in another shape:

* the force balance is a vector sum in the local (horizontal, vertical) frame, projected on the
  flight path (``e_v``) and its normal (``n_v``), not the ascent model's tangential/normal terms;
* **nozzle back-pressure**: the thrust is stated at sea level (a static firing) and rises with
  altitude, ``P(h) = P_sl + A_e (p(0) - p(h))``, ``p`` interpolated (log-linear, 1 km steps) in a
  table computed here by integrating the hydrostatic equation of the 1976 standard's temperature
  profile (:func:`pressure_table`), not the package's closed-form layers;
* **wind**: the air-relative velocity ``V - W(h) e_x``; drag along it, lift normal to it, the attack
  angle measured from it; ``W`` = a surface wind plus a jet-stream core of ``sech^2`` shape centred
  between the catalogue's basis altitudes;
* **thrust misalignment** from t = 0 (no fade), on a vehicle released at speed;
* **density deviation** ``rho (1 + a tanh((h - 8 km)/12 km))``;
* **thrust level** ``(1 + eps) P`` or a drifting error ``eps(t)``;
* **mass flow**: the mass is a fifth state, ``dm/dt = -(1 + eps) mdot``;
* **Earth rotation**: Coriolis ``-2 Omega x V`` and centrifugal ``-Omega x (Omega x r)`` as 3-D cross
  products in the launch site's east-north-up frame, projected on the trajectory plane;
* **transonic drag rise**: an asymmetric rise (cubic smoothstep from M 0.85 to its peak at 1.02,
  exponential decay above) added to the vehicle's CD(M);
* **sensor effects** are applied to the simulated measurements (:func:`measure`): altitude and
  downrange biases, a speed bias and scale factor, and a time-tag offset that samples the
  trajectory at ``t - tau`` (exactly, not a first-order expansion).

Base physics shared with the estimation model (standard atmosphere density and speed of sound,
inverse-square gravity, the vehicles' attitude programs) are the vehicles' declared physics, not
hidden effects: with no effect the truth model reproduces the base model's simulation
(``tests/test_discovery_study.py`` checks this to millimetres).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Callable, Mapping

import numpy as np
import sympy as sp

import rocketid as ri
from rocketid.data import Channel, Measurements
from rocketid.model import Model
from rocketid.physics.atmosphere import us76_speed_of_sound, us76_density, yang1983_density

EARTH_RADIUS = 6_371_000.0
G0 = 9.80665
OMEGA_EARTH = 7.2921159e-5          # rad/s, sidereal


# ---------------------------------------------------------------------------------------------
# an independent pressure table
# ---------------------------------------------------------------------------------------------

#: The 1976 standard's defining temperature profile: (geopotential base altitude m', lapse K/m').
_LAYERS = ((0.0, -6.5e-3), (11000.0, 0.0), (20000.0, 1.0e-3), (32000.0, 2.8e-3), (47000.0, 0.0),
           (51000.0, -2.8e-3), (71000.0, -2.0e-3), (84852.0, 0.0))
_R0 = 6_356_766.0                   # the standard's Earth radius for geopotential altitude
_R_AIR = 8.31432 / 0.0289644        # R* / M0, J/(kg K)


def _temperature(hgeo: np.ndarray) -> np.ndarray:
    """Molecular-scale temperature at geopotential altitudes ``hgeo`` (m'), K."""
    temp = np.full_like(hgeo, 288.15)
    t_base = 288.15
    for (b, lapse), (top, _) in zip(_LAYERS[:-1], _LAYERS[1:]):
        seg = np.clip(hgeo, b, top) - b
        temp = np.where(hgeo > b, t_base + lapse * seg, temp)
        t_base += lapse * (top - b)
    return temp


def pressure_table(top_km: int = 80) -> tuple[np.ndarray, np.ndarray]:
    """Pressure (Pa) at geometric altitudes 0, 1, ..., ``top_km`` km, integrated here.

    ``dp/dz = -p g(z) / (R T(z))`` with ``g = g0 (r0/(r0 + z))^2`` on a 5 m grid (trapezoidal rule
    on ``ln p``) from p(0) = 101 325 Pa. This is how the standard's tables are defined, but it
    shares no code with rocketid's closed-form atmosphere.
    """
    z = np.arange(0.0, top_km * 1000.0 + 1.0, 5.0)
    hgeo = _R0 * z / (_R0 + z)
    g = G0 * (_R0 / (_R0 + z)) ** 2
    dlnp = -g / (_R_AIR * _temperature(hgeo))
    lnp = math.log(101325.0) + np.concatenate([[0.0], np.cumsum(0.5 * (dlnp[1:] + dlnp[:-1]) * np.diff(z))])
    keep = (np.arange(z.size) % 200) == 0
    return z[keep], np.exp(lnp[keep])


def tabulated_pressure(h: sp.Expr) -> sp.Expr:
    """Ambient pressure (Pa) at altitude ``h``: log-linear interpolation in :func:`pressure_table`."""
    z, p = pressure_table()
    lnp = np.log(p)
    pieces = []
    for i in range(z.size - 1):
        slope = (lnp[i + 1] - lnp[i]) / (z[i + 1] - z[i])
        pieces.append((float(lnp[i]) + float(slope) * (h - float(z[i])), h < float(z[i + 1])))
    last = (lnp[-1] - lnp[-2]) / (z[-1] - z[-2])
    pieces.append((float(lnp[-1]) + float(last) * (h - float(z[-1])), True))
    return sp.exp(sp.Piecewise(*pieces))


# ---------------------------------------------------------------------------------------------
# vehicles
# ---------------------------------------------------------------------------------------------


def _pl(x: sp.Expr, knots, values) -> sp.Expr:
    """Piecewise-linear interpolation of (knots, values) at ``x``, flat outside: a sum of hat
    functions ``max(0, min(rising, falling))`` (no Piecewise, whose conditions on a Piecewise
    Mach number SymPy expands slowly)."""
    k = [float(a) for a in knots]
    out = sp.S.Zero
    for j, c in enumerate(values):
        rise = (x - k[j - 1]) / (k[j] - k[j - 1]) if j > 0 else sp.S.One
        fall = (k[j + 1] - x) / (k[j + 1] - k[j]) if j + 1 < len(k) else sp.S.One
        out += float(c) * sp.Max(0, sp.Min(rise, fall, 1))
    return out


@dataclass(frozen=True)
class Vehicle:
    """What the truth needs of a vehicle: its declared data, not its estimation model.

    Attributes
    ----------
    name : str
    model : str
        What :func:`rocketid.diagnostics.diagnose` is given: a built-in name or a model file path.
    m0, mdot, thrust, area : float
        Lift-off mass (kg), mass flow (kg/s), stated (sea-level) thrust (N), reference area (m^2).
    drag : float or (knots, values)
        A constant CD, or CD(Mach) knots and values.
    lift : ("cl", value) or ("cl_alpha", value)
        A constant CL (RA-66's form) or CL = CL_alpha * alpha.
    alpha : callable
        ``alpha(model) -> symbol``: declares the attitude program as the model's input.
    initial : (x0, h0, v0, theta0)
    atmosphere : {"yang1983", "us76"}
    times : ndarray
        Sample times of the measurements.
    """

    name: str
    model: str
    m0: float
    mdot: float
    thrust: float
    area: float
    drag: object
    lift: tuple
    alpha: Callable[[Model], sp.Symbol]
    initial: tuple
    atmosphere: str
    times: np.ndarray = field(repr=False, compare=False)

    @property
    def starts_from_rest(self) -> bool:
        return self.initial[2] == 0.0


def ra66_vehicle() -> Vehicle:
    from rocketid.cases.ra66 import ra66_alpha
    return Vehicle("RA-66", "ra66", 20000.0, 100.0, 400000.0, math.pi, 0.5, ("cl", 0.1),
                   lambda m: m.input("alpha", ra66_alpha(m.t), breakpoints=(4.0, 24.0)),
                   (0.0, 0.0, 0.0, math.pi / 2), "yang1983", ri.ra66_times())


def ra66m_vehicle() -> Vehicle:
    from rocketid.cases.ra66m import RA66M_CD_TRUTH, RA66M_CL_ALPHA_TRUTH, RA66M_MACH_KNOTS, ra66m_alpha
    return Vehicle("RA-66M", "ra66m", 20000.0, 100.0, 400000.0, math.pi, (RA66M_MACH_KNOTS, RA66M_CD_TRUTH),
                   ("cl_alpha", RA66M_CL_ALPHA_TRUTH),
                   lambda m: m.input("alpha", ra66m_alpha(m.t), breakpoints=(4.0, 24.0)),
                   (0.0, 0.0, 0.0, math.pi / 2), "yang1983", ri.ra66_times())


def stage30_vehicle() -> Vehicle:
    from .paths import STAGE30, load_stage30
    s30 = load_stage30()
    tt, aa = s30.program_table()
    return Vehicle("Stage-30", str(STAGE30), s30.M0, s30.MDOT, s30.THRUST_SL, s30.AREA,
                   (s30.MACH_KNOTS, s30.CD_TRUTH), ("cl_alpha", s30.CL_ALPHA_TRUTH),
                   lambda m: m.input("alpha", times=tt, values=aa),
                   (0.0, 0.0, s30.V0, math.radians(s30.THETA0_DEG)), "us76", s30.sample_times())


VEHICLES: dict[str, Callable[[], Vehicle]] = {"ra66": ra66_vehicle, "ra66m": ra66m_vehicle,
                                              "stage30": stage30_vehicle}


# ---------------------------------------------------------------------------------------------
# hidden effects: which ones exist, what their sizes mean
# ---------------------------------------------------------------------------------------------

#: The truth's effects; the keys of a case's ``effects`` mapping. Each maps to the catalogue
#: effect that stands for the same physics (used only to score the diagnosis).
CATALOGUE_NAME = {
    "back_pressure": "back_pressure", "thrust_level": "thrust_level", "thrust_drift": "thrust_level",
    "mass_flow": "mass_flow", "transonic_drag": "transonic_drag", "wind": "wind",
    "earth_rotation": "earth_rotation", "misalignment": "misalignment", "density": "density",
    "bias_x": "bias_x", "bias_h": "bias_h", "bias_v": "bias_v", "scale_v": "scale_v",
    "time_offset": "time_offset",
}
SENSOR = {"bias_x", "bias_h", "bias_v", "scale_v", "time_offset"}


def wind_profile(h, *, surface: float, jet: float, core_km: float, width_km: float, layer_m: float = 0.0):
    """Tailwind (m/s, along +x) at altitude ``h``: a surface wind plus a ``sech^2`` jet core.

    ``layer_m > 0`` multiplies the profile by a boundary layer ``1 - exp(-h / layer_m)`` that
    vanishes at the pad, for vehicles that start from rest (any air speed at v = 0 would be a
    normal force at the singular start; the jet's tail alone is 0.02 m/s at the ground).
    """
    mod = sp if isinstance(h, sp.Basic) else np
    profile = surface + jet / mod.cosh((h - core_km * 1000.0) / (width_km * 1000.0)) ** 2
    return profile * (1 - mod.exp(-h / layer_m)) if layer_m > 0 else profile


def density_deviation(h, *, amplitude: float):
    """Relative density deviation ``a tanh((h - 8 km)/12 km)``: -0.58 a at the ground, 0 at 8 km, +0.95 a at 30 km."""
    mod = sp if isinstance(h, sp.Basic) else np
    return amplitude * mod.tanh((h - 8000.0) / 12000.0)


def transonic_rise(mach, *, peak: float):
    """Extra drag of a transonic rise: 0 below M 0.85, a cubic smoothstep to ``peak`` at M 1.02,
    then an exponential decay (e-folding 0.25 in Mach)."""
    u = sp.Min(sp.Max((mach - 0.85) / 0.17, 0), 1)
    return peak * u ** 2 * (3 - 2 * u) * sp.exp(-sp.Max(mach - 1.02, 0) / 0.25)


# ---------------------------------------------------------------------------------------------
# the truth model
# ---------------------------------------------------------------------------------------------


def _cross(a, b):
    return sp.Matrix([a[1] * b[2] - a[2] * b[1], a[2] * b[0] - a[0] * b[2], a[0] * b[1] - a[1] * b[0]])


def truth_model(vehicle: Vehicle, effects: Mapping[str, Mapping[str, float]] | None = None):
    """The truth of ``vehicle`` with the hidden physical ``effects`` (sensor effects excluded:
    :func:`measure` applies those).

    Parameters
    ----------
    vehicle : Vehicle
    effects : mapping
        ``{effect: {size: value}}``, effects from :data:`CATALOGUE_NAME`:

        ``back_pressure: {A_e}`` (m^2), ``thrust_level: {eps_thrust}``,
        ``thrust_drift: {eps_start, eps_end}`` (linear in time), ``mass_flow: {eps_mdot}``,
        ``transonic_drag: {peak}``, ``wind: {surface, jet, core_km, width_km[, layer_m]}``,
        ``earth_rotation: {latitude_deg, azimuth_deg}``, ``misalignment: {delta_deg}``,
        ``density: {amplitude}``.

    Returns
    -------
    ModelSpec
        No parameters to estimate: everything is a stated number.
    """
    fx = {k: dict(v) for k, v in (effects or {}).items() if k not in SENSOR}
    unknown = set(fx) - set(CATALOGUE_NAME)
    if unknown:
        raise ValueError(f"unknown truth effect(s) {sorted(unknown)}")
    Re = EARTH_RADIUS
    m = Model(f"{vehicle.name} truth", 0.0, 66.0, description=f"truth with {', '.join(fx) or 'no effect'}")
    x0, h0, v0, th0 = vehicle.initial
    x, h, v, th = (m.state("x", x0), m.state("h", h0), m.state("v", v0), m.state("theta", th0))
    t = m.t
    alpha = vehicle.alpha(m)
    rho_std = us76_density(h) if vehicle.atmosphere == "us76" else yang1983_density(h)
    if "density" in fx:
        rho_std = rho_std * (1 + density_deviation(h, **fx["density"]))
    rho = m.define("rho", rho_std)
    sound = m.define("sound", us76_speed_of_sound(h))
    g = m.define("g", G0 * (Re / (Re + h)) ** 2)

    # thrust
    thrust = sp.Float(vehicle.thrust)
    if "back_pressure" in fx:
        p_amb = tabulated_pressure(h)
        thrust = thrust + fx["back_pressure"]["A_e"] * (101325.0 - p_amb)
    if "thrust_level" in fx:
        thrust = thrust * (1 + fx["thrust_level"]["eps_thrust"])
    if "thrust_drift" in fx:
        a, b = fx["thrust_drift"]["eps_start"], fx["thrust_drift"]["eps_end"]
        thrust = thrust * (1 + a + (b - a) * t / 66.0)
    P = m.define("P", thrust)

    # mass: a state when the mass flow is in error
    if "mass_flow" in fx:
        mass = m.state("mass", vehicle.m0)
        m.ode({mass: -vehicle.mdot * (1 + fx["mass_flow"]["eps_mdot"])})
    else:
        mass = m.define("mass", vehicle.m0 - vehicle.mdot * t)

    # velocity relative to the air, in the (horizontal, vertical) plane
    W = wind_profile(h, **fx["wind"]) if "wind" in fx else sp.S.Zero
    ax, ay = v * sp.cos(th) - W, v * sp.sin(th)
    speed_air = sp.sqrt(ax ** 2 + ay ** 2) if "wind" in fx else v
    mach = m.define("mach_air", speed_air / sound)
    if isinstance(vehicle.drag, tuple):
        cd = _pl(mach, *vehicle.drag)
    else:
        cd = sp.Float(vehicle.drag)
    if "transonic_drag" in fx:
        cd = cd + transonic_rise(mach, **fx["transonic_drag"])
    # attitude of the body axis, and the attack angle seen by the air
    pitch = th + alpha
    path_air = sp.atan2(ay, ax) if "wind" in fx else th
    kind, value = vehicle.lift
    cl = value if kind == "cl" else value * (pitch - path_air)
    half_rho_s = rho * vehicle.area / 2
    # drag along -V_air, lift along V_air turned +90 deg: |V_air| * (components) needs no division
    scale = speed_air if "wind" in fx else v
    ux, uy = (ax, ay) if "wind" in fx else (v * sp.cos(th), v * sp.sin(th))
    drag_vec = sp.Matrix([-half_rho_s * cd * scale * ux, -half_rho_s * cd * scale * uy])
    lift_vec = sp.Matrix([-half_rho_s * cl * scale * uy, half_rho_s * cl * scale * ux])
    delta = math.radians(fx["misalignment"]["delta_deg"]) if "misalignment" in fx else 0.0
    thrust_vec = sp.Matrix([P * sp.cos(pitch + delta), P * sp.sin(pitch + delta)])
    force = thrust_vec + drag_vec + lift_vec
    e_v = sp.Matrix([sp.cos(th), sp.sin(th)])
    n_v = sp.Matrix([-sp.sin(th), sp.cos(th)])
    a_tan = force.dot(e_v) / mass - g * sp.sin(th)
    a_nor = force.dot(n_v) / mass - g * sp.cos(th) + v ** 2 * sp.cos(th) / (Re + h)

    if "earth_rotation" in fx:
        lat = math.radians(fx["earth_rotation"]["latitude_deg"])
        azi = math.radians(fx["earth_rotation"]["azimuth_deg"])
        omega = sp.Matrix([0.0, OMEGA_EARTH * math.cos(lat), OMEGA_EARTH * math.sin(lat)])    # east, north, up
        heading = sp.Matrix([math.sin(azi), math.cos(azi), 0.0])
        up = sp.Matrix([0.0, 0.0, 1.0])
        vel = v * sp.cos(th) * heading + v * sp.sin(th) * up
        r = (Re + h) * up
        a_rot = -2 * _cross(omega, vel) - _cross(omega, _cross(omega, r))
        a_tan += a_rot.dot(sp.cos(th) * heading + sp.sin(th) * up)
        a_nor += a_rot.dot(-sp.sin(th) * heading + sp.cos(th) * up)

    m.ode({x: Re / (Re + h) * v * sp.cos(th), h: v * sp.sin(th), v: a_tan})
    m.implicit({th: v * m.der(th) - a_nor})
    for s in (x, h, v):
        m.output(str(s), s, sigma=1.0)
    return m.freeze()


def measure(vehicle: Vehicle, effects: Mapping[str, Mapping[str, float]] | None, seed: int,
            noise: bool = True) -> Measurements:
    """Measurements of the truth: simulate, apply the sensor effects, add N(0, 1) noise.

    Sensor effects: ``bias_x: {b_x}``, ``bias_h: {b_h}``, ``bias_v: {b_v}`` (added),
    ``scale_v: {k_v}`` (``z_v = (1 + k_v) v``) and ``time_offset: {tau}`` (``z(t) = y(t - tau)``:
    the trajectory is sampled ``tau`` earlier than the time tag says).
    """
    effects = dict(effects or {})
    spec = truth_model(vehicle, effects)
    tags = vehicle.times
    tau = effects.get("time_offset", {}).get("tau", 0.0)
    traj = ri.simulate(spec, times=np.clip(tags - tau, 0.0, 66.0))
    if not traj.success:
        raise RuntimeError(f"the truth simulation of {vehicle.name} failed: {traj.message}")
    y = {name: traj.value(name) for name in ("x", "h", "v")}
    y["x"] = y["x"] + effects.get("bias_x", {}).get("b_x", 0.0)
    y["h"] = y["h"] + effects.get("bias_h", {}).get("b_h", 0.0)
    y["v"] = y["v"] * (1 + effects.get("scale_v", {}).get("k_v", 0.0)) + effects.get("bias_v", {}).get("b_v", 0.0)
    rng = np.random.default_rng(seed)
    chans = []
    for name in ("x", "h", "v"):
        val = y[name] + (rng.normal(0.0, 1.0, tags.size) if noise else 0.0)
        chans.append(Channel(name, tags, val, 1.0))
    return Measurements(tuple(chans))
