"""The chapter's point-mass ascent model (7.1) as ordinary model building blocks.

Point mass in the vertical plane, no sideslip; states x (downrange, m),
h (altitude, m), v (speed, m/s), theta (flight-path angle, rad)::

    dx/dt     = Re/(Re+h) v cos(theta)
    dh/dt     = v sin(theta)
    dv/dt     = P cos(alpha)/m - q Sm CD/m - g sin(theta)
    v dtheta/dt = P sin(alpha)/m + q Sm CL/m - g cos(theta) + v^2 cos(theta)/(Re+h)

with q = rho v^2 / 2. The theta equation is declared in its v-multiplied
form, which is regular at the launch from rest (docs/design.md, the problem). Lift is
CL times dynamic pressure (the chapter's form: CL is not multiplied by alpha;
an aerodynamic model that wants CL_alpha * alpha passes that as ``cl``).
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import sympy as sp

from ..model import Model
from .atmosphere import us76_speed_of_sound, yang1983_density, us76_density
from .gravity import EARTH_RADIUS, G0, inverse_square_gravity

__all__ = ["AscentStates", "AscentForces", "FlightConditions", "ascent_states", "flight_conditions",
           "ascent_dynamics", "DENSITY_MODELS"]

DENSITY_MODELS = {"yang1983": yang1983_density, "us76": us76_density}


@dataclass(frozen=True)
class AscentStates:
    """The four state symbols of the ascent model."""

    x: sp.Symbol
    h: sp.Symbol
    v: sp.Symbol
    theta: sp.Symbol


@dataclass(frozen=True)
class FlightConditions:
    """Defined symbols for the flight condition (usable in expressions and diagnostics)."""

    rho: sp.Symbol
    g: sp.Symbol
    qbar: sp.Symbol
    mach: sp.Symbol


def ascent_states(m: Model, initial=(0.0, 0.0, 0.0, math.pi / 2)) -> AscentStates:
    """Declare x, h, v, theta with their initial values."""
    x0, h0, v0, th0 = initial
    st = AscentStates(m.state("x", x0), m.state("h", h0), m.state("v", v0), m.state("theta", th0))
    for role, sym in (("downrange", st.x), ("altitude", st.h), ("speed", st.v), ("flight_path_angle", st.theta)):
        m.declare_role(role, sym)
    return st


def flight_conditions(m: Model, st: AscentStates, *, atmosphere: str = "yang1983",
                      g0: float = G0, radius: float = EARTH_RADIUS) -> FlightConditions:
    """Define air density ``rho``, gravity ``g``, dynamic pressure ``qbar`` and ``mach``.

    Parameters
    ----------
    atmosphere : {"yang1983", "us76"}
        Density model (speed of sound always from the 1976 standard).
    """
    if atmosphere not in DENSITY_MODELS:
        from ..errors import ModelError
        raise ModelError(f"unknown atmosphere {atmosphere!r}; choose one of {', '.join(DENSITY_MODELS)}")
    rho = m.define("rho", DENSITY_MODELS[atmosphere](st.h))
    g = m.define("g", inverse_square_gravity(st.h, g0, radius))
    qbar = m.define("qbar", rho * st.v ** 2 / 2)
    sound = m.define("a_sound", us76_speed_of_sound(st.h))
    mach = m.define("mach", st.v / sound)
    for role, sym in (("density", rho), ("gravity", g), ("dynamic_pressure", qbar), ("sound_speed", sound),
                      ("mach", mach)):
        m.declare_role(role, sym)
    return FlightConditions(rho, g, qbar, mach)


def _named(m: Model, name: str, expr) -> sp.Symbol:
    """``expr`` as the definition ``name`` (reused when it already is that definition)."""
    if isinstance(expr, sp.Symbol) and str(expr) == name and m.has(name):
        return expr
    return m.define(name, expr)


@dataclass(frozen=True)
class AscentForces:
    """The named force terms of the ascent model (definitions effects can redefine)."""

    thrust: sp.Symbol
    mass: sp.Symbol
    alpha_thrust: sp.Symbol
    cd: sp.Symbol
    cl: sp.Symbol
    drag: sp.Symbol
    lift: sp.Symbol


def ascent_dynamics(m: Model, st: AscentStates, fc: FlightConditions, *, thrust, mass, area, cd, cl, alpha,
                    radius: float = EARTH_RADIUS) -> AscentForces:
    """Declare the equations (7.1) on ``m`` (theta in v-multiplied implicit form).

    Every symbol gets its physical role (:data:`rocketid.model.ROLES`): the
    states, the flight condition, thrust, mass, the thrust direction, the drag
    and lift coefficients and forces, the attack angle (``alpha`` as given: an
    input symbol or an expression) and the reference area.

    The force terms become named definitions -- ``thrust``, ``mass``,
    ``alpha_thrust`` (thrust direction relative to the velocity, = alpha),
    ``cd``, ``cl``, ``drag = qbar Sm cd``, ``lift = qbar Sm cl`` -- so that a
    physical effect is added by redefining one of them
    (:meth:`rocketid.model.Model.redefine`) or by adding a term
    (:meth:`rocketid.model.Model.add_term`).
    """
    x, h, v, th = st.x, st.h, st.v, st.theta
    Re = radius
    T = _named(m, "thrust", thrust)
    M = _named(m, "mass", mass)
    aT = m.define("alpha_thrust", alpha)
    CD = _named(m, "cd", cd)
    CL = _named(m, "cl", cl)
    D = m.define("drag", fc.qbar * area * CD)
    L = m.define("lift", fc.qbar * area * CL)
    m.ode({
        x: Re / (Re + h) * v * sp.cos(th),
        h: v * sp.sin(th),
        v: T * sp.cos(aT) / M - D / M - fc.g * sp.sin(th),
    })
    m.implicit({
        th: v * m.der(th) - (T * sp.sin(aT) / M + L / M - fc.g * sp.cos(th) + v ** 2 * sp.cos(th) / (Re + h)),
    })
    for role, sym in (("thrust", T), ("mass", M), ("thrust_direction", aT), ("drag_coefficient", CD),
                      ("lift_coefficient", CL), ("drag", D), ("lift", L), ("attack_angle", sp.sympify(alpha))):
        m.declare_role(role, sym)
    if isinstance(area, sp.Symbol):
        m.declare_role("reference_area", area)
    return AscentForces(T, M, aT, CD, CL, D, L)
