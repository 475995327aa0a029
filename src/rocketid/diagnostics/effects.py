"""Candidate physical effects: small, documented model extensions for finding what a model misses.

An :class:`Effect` edits an editable :class:`~rocketid.model.Model` in place
(its ``apply``), declares its parameters with guess 0 -- the zero value gives
back the base model exactly -- and returns them. :data:`CATALOGUE` holds the
effects a 66 s first-stage ascent is likely to miss (``docs/effects.md``);
:func:`custom_effect` wraps one the user writes in a few lines of SymPy;
:func:`with_effects` applies effects to a copy of a model and freezes it.

The catalogue effects build on the ascent model's named definitions
(``thrust``, ``mass``, ``alpha_thrust``, ``cd``, ``cl``, ``drag``, ``lift``,
``rho``, ``qbar``, ``mach``), its states ``x, h, v, theta``, its input
``alpha``, its constants ``m0, mdot`` and its outputs; an effect that needs
something a model lacks raises :class:`~rocketid.errors.ModelError` saying
what (the ranking skips it with that note).

Notation
--------
=============  ================================================================
``f_lo(t)``    lift-off fade ``t^4 / (t^4 + t_r^4)``, ``t_r`` = 3 s (see below)
``p_a(h)``     ambient pressure of the US Standard Atmosphere 1976, Pa
``W(h)``       horizontal wind along +x (a tailwind), m/s
``V_a``        air-relative speed; ``Delta = theta_air - theta``
``Omega``      Earth's rate times ``k_rot``; latitude ``phi``, azimuth ``A``
=============  ================================================================

The lift-off fade. At a launch from rest the flight-path equation
``v dtheta/dt = N/m - g cos(theta)`` is singular: near ``t = 0`` every
``delta = theta - pi/2 = C t^(g/a) + (particular solution)`` solves it
(docs/design.md, the problem: ``g/a`` about 0.96). A normal force ``N`` that does not
vanish at lift-off (a thrust misalignment) has no bounded solution from
``theta(0) = 90 deg``, and one growing like ``t`` (Coriolis) leaves ``C`` to the
discretization: the simulator and the collocation would each pick their own
trajectory (measured: 0.9 m apart at 66 s for Earth rotation, 80 m for a
0.25 deg misalignment faded in as ``t^2``). Normal forces that vanish faster do
not excite ``C``; the effects whose normal force would not are phased in by
``f_lo(t)`` -- physically, the launcher holds the path vertical for the first
seconds. Even so the first collocation element should be short when such an
effect is present: ``default_mesh(spec, refine_first=3)`` brings the
collocation within 0.01-0.04 m of the simulator (``docs/effects.md``). The wind
needs no fade: its surface layer ``tanh(h / 500 m)`` vanishes at the pad.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from types import MappingProxyType
from typing import Callable, Iterable, Mapping, Sequence

import sympy as sp

from ..errors import ModelError
from ..model import Model, ModelSpec
from ..physics.atmosphere import us76_pressure
from ..physics.gravity import EARTH_RADIUS

__all__ = ["Effect", "CATALOGUE", "KINDS", "custom_effect", "with_effects", "apply_effect", "resolve_effects",
           "is_present", "check_effect_parameters", "effect_parameter_problems", "wind_effect", "density_effect", "earth_rotation_effect",
           "liftoff_fade", "EARTH_RATE", "LIFTOFF_FADE_TIME"]

#: The kinds of effect (``"custom"`` for the user's own).
KINDS = ("propulsion", "mass", "aero", "environment", "kinematics", "sensor", "custom")

EARTH_RATE = 7.2921159e-5
"""Earth's sidereal rotation rate, rad/s."""

LIFTOFF_FADE_TIME = 3.0
"""``t_r`` of the lift-off fade ``t^4 / (t^4 + t_r^4)``, s."""


@dataclass(frozen=True)
class Effect:
    """A candidate physical effect: a model extension whose zero parameters give back the base model.

    Attributes
    ----------
    name : str
        Registry key (``"back_pressure"``).
    title : str
        Short human-readable name.
    kind : str
        One of :data:`KINDS`.
    apply : callable
        ``apply(model) -> tuple of sympy.Symbol``: edits an editable
        :class:`~rocketid.model.Model` in place, declares the effect's
        parameters with guess 0 and returns them.
    description : str
        The model change, in formulas.
    realistic : mapping of str to float
        A realistic magnitude of each parameter, keyed by parameter name
        (empty when unknown, as for most custom effects).
    """

    name: str
    title: str
    kind: str
    apply: Callable[[Model], tuple] = field(compare=False, repr=False)
    description: str = ""
    realistic: Mapping[str, float] = field(default_factory=dict, compare=False)

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name.isidentifier():
            raise ModelError(f"an effect's name must be an identifier, got {self.name!r}")
        if self.kind not in KINDS:
            raise ModelError(f"effect {self.name!r}: unknown kind {self.kind!r}; choose one of {', '.join(KINDS)}")
        if not callable(self.apply):
            raise ModelError(f"effect {self.name!r}: apply must be a function apply(model) -> parameters")
        object.__setattr__(self, "realistic", MappingProxyType({str(k): float(v) for k, v in self.realistic.items()}))

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Names of the parameters the effect declares (known for catalogue effects)."""
        return tuple(self.realistic)


# ---------------------------------------------------------------------------
# helpers for writing effects
# ---------------------------------------------------------------------------


def liftoff_fade(t: sp.Symbol, t_r: float = LIFTOFF_FADE_TIME) -> sp.Expr:
    """``t^4 / (t^4 + t_r^4)``: 0 at lift-off, 1/2 at ``t_r``, then 1 (see the module notes)."""
    return t ** 4 / (t ** 4 + float(t_r) ** 4)


def _definition(m: Model, name: str, effect: str) -> sp.Expr:
    try:
        return m.definition(name)
    except ModelError:
        raise ModelError(f"effect {effect!r} needs the definition {name!r}, which model {m.name!r} does not "
                         "have (the ascent model of rocketid.physics.ascent defines it)") from None


def _component(m: Model, name: str, effect: str, what: str) -> sp.Symbol:
    if not m.has(name):
        raise ModelError(f"effect {effect!r} needs {what} named {name!r}, which model {m.name!r} does not have")
    return getattr(m, name)


def _state(m: Model, name: str, effect: str) -> sp.Symbol:
    sym = _component(m, name, effect, "the state")
    try:
        m.der(sym)
    except ModelError:
        raise ModelError(f"effect {effect!r} needs {name!r} to be a state of model {m.name!r}") from None
    return sym


def _output(m: Model, name: str, effect: str) -> sp.Expr:
    if name not in m.output_names:
        raise ModelError(f"effect {effect!r} needs a measured output named {name!r}; model {m.name!r} has "
                         f"{', '.join(m.output_names) or 'no outputs'}")
    return m.output_expression(name)


def _define(m: Model, name: str, expr: sp.Expr, effect: str) -> sp.Symbol:
    """The definition ``name`` (new, or an existing one with the same expression)."""
    if m.has(name):
        try:
            same = m.definition(name) == expr
        except ModelError:
            same = False
        if not same:
            raise ModelError(f"effect {effect!r} defines {name!r}, but model {m.name!r} already has a different "
                             f"component with that name")
        return getattr(m, name)
    return m.define(name, expr)


def _gauss(h: sp.Expr, centre: float, width: float) -> sp.Expr:
    return sp.exp(-((h - float(centre)) / float(width)) ** 2 / 2)


# ---------------------------------------------------------------------------
# the catalogue's effects
# ---------------------------------------------------------------------------


def _back_pressure(m: Model) -> tuple:
    thrust = _definition(m, "thrust", "back_pressure")
    h = _state(m, "h", "back_pressure")
    area = m.parameter("A_e", 0.0, bounds=(0.0, math.inf), nominal=0.4)   # an area: not negative
    m.redefine("thrust", thrust - area * _define(m, "p_ambient", us76_pressure(h), "back_pressure"))
    return (area,)


def _thrust_level(m: Model) -> tuple:
    thrust = _definition(m, "thrust", "thrust_level")
    eps = m.parameter("eps_thrust", 0.0, nominal=0.02)
    m.redefine("thrust", thrust * (1 + eps))
    return (eps,)


def _mass_flow(m: Model) -> tuple:
    mass = _definition(m, "mass", "mass_flow")
    mdot = _component(m, "mdot", "mass_flow", "the mass-flow constant")
    if mdot not in mass.free_symbols:
        raise ModelError(f"effect 'mass_flow' scales the constant mdot in the definition of mass, but model "
                         f"{m.name!r} has mass = {mass}")
    eps = m.parameter("eps_mdot", 0.0, nominal=0.015)
    m.redefine("mass", mass.xreplace({mdot: mdot * (1 + eps)}))
    return (eps,)


TRANSONIC_MACH = 1.1
TRANSONIC_WIDTH = 0.2


def _transonic_drag(m: Model) -> tuple:
    cd = _definition(m, "cd", "transonic_drag")
    _definition(m, "mach", "transonic_drag")
    dcd = m.parameter("dCD_transonic", 0.0, nominal=0.2)
    m.redefine("cd", cd + dcd * _gauss(m.mach, TRANSONIC_MACH, TRANSONIC_WIDTH))
    return (dcd,)


def _misalignment(m: Model) -> tuple:
    at = _definition(m, "alpha_thrust", "misalignment")
    delta = m.parameter("delta_thrust", 0.0, nominal=math.radians(0.25))
    m.redefine("alpha_thrust", at + delta * liftoff_fade(m.t))
    return (delta,)


def _bias(channel: str) -> Callable[[Model], tuple]:
    def apply(m: Model) -> tuple:
        expr = _output(m, channel, f"bias_{channel}")
        b = m.parameter(f"b_{channel}", 0.0, nominal=1.0)
        m.redefine_output(channel, expr + b)
        return (b,)
    apply.__name__ = f"_bias_{channel}"
    return apply


def _scale(channel: str) -> Callable[[Model], tuple]:
    def apply(m: Model) -> tuple:
        expr = _output(m, channel, f"scale_{channel}")
        k = m.parameter(f"k_{channel}", 0.0, nominal=1e-3)
        m.redefine_output(channel, (1 + k) * expr)
        return (k,)
    apply.__name__ = f"_scale_{channel}"
    return apply


def _time_offset(m: Model) -> tuple:
    if not m.output_names:
        raise ModelError(f"effect 'time_offset' needs measured outputs; model {m.name!r} has none yet")
    states = {}
    for name in m.output_names:
        for s in m.output_expression(name).free_symbols:
            if m.has(str(s)):
                try:
                    states[s] = m.der(s)
                except ModelError:
                    pass
    derivs = set(states.values())
    exprs = {}
    for name in m.output_names:
        expr = m.output_expression(name)
        if expr.free_symbols & derivs:
            raise ModelError(f"effect 'time_offset' is already present in model {m.name!r}, or output {name!r} "
                             "uses a state derivative already: z(t) = y(t - tau) ~ y - tau dy/dt needs outputs "
                             "that are functions of the states")
        exprs[name] = expr
    tau = m.parameter("tau", 0.0, nominal=0.01)
    for name, expr in exprs.items():
        dydt = sp.diff(expr, m.t) + sum((sp.diff(expr, s) * d for s, d in states.items()), sp.S.Zero)
        m.redefine_output(name, expr - tau * dydt)
    return (tau,)


WIND_CENTRES_KM = (3.0, 8.0, 13.0, 18.0)
WIND_WIDTH_KM = 2.5
SURFACE_LAYER_M = 500.0
WIND_SPEED_EPS = 0.1


def wind_effect(centres_km: Sequence[float] = WIND_CENTRES_KM, width_km: float = WIND_WIDTH_KM, *,
                name: str = "wind", prefix: str = "wind_", realistic_speed: float = 30.0,
                air_mach: bool = True, air_alpha: bool = True) -> Effect:
    """A horizontal wind profile ``W(h) = tanh(h / 500 m) sum_j w_j exp(-((h - c_j)/s)^2 / 2)``.

    Parameters
    ----------
    centres_km : sequence of float
        Centres ``c_j`` of the altitude basis functions, km (at least 3 for the catalogue).
    width_km : float
        Their standard width ``s``, km.
    name, prefix : str
        Effect name, and parameter names ``<prefix>1 ..``.
    realistic_speed : float
        Realistic magnitude of each coefficient, m/s.
    air_mach, air_alpha : bool
        Use the airspeed in the Mach number, and the air-relative attack angle
        ``alpha + (theta - theta_air)`` in the lift coefficient (both physical;
        switch off only to study their share).

    Notes
    -----
    ``W`` is carried as the state ``<name>_speed`` with ``dW/dt = W'(h) v
    sin(theta)`` from ``W = 0``: the launch is at ``h = 0``, where the surface
    layer makes the wind vanish.
    """
    centres = tuple(float(c) * 1000.0 for c in centres_km)
    width = float(width_km) * 1000.0
    names = tuple(f"{prefix}{j + 1}" for j in range(len(centres)))

    def apply(m: Model) -> tuple:
        h = _state(m, "h", name)
        v = _state(m, "v", name)
        th = _state(m, "theta", name)
        rho = _component(m, "rho", name, "the air-density definition")
        qbar = _component(m, "qbar", name, "the dynamic-pressure definition")
        qdef = _definition(m, "qbar", name)
        mdef = _definition(m, "mach", name)
        drag = _definition(m, "drag", name)
        lift = _definition(m, "lift", name)
        cl = _definition(m, "cl", name)
        for what, expr in (("drag", drag), ("lift", lift)):
            if sp.diff(expr, qbar, 2) != 0 or expr.xreplace({qbar: 0}) != 0:
                raise ModelError(f"effect {name!r} needs {what} proportional to qbar; model {m.name!r} has "
                                 f"{what} = {expr}")
        ws = tuple(m.parameter(n, 0.0, nominal=realistic_speed) for n in names)
        profile = sp.tanh(h / SURFACE_LAYER_M) * sum((w * _gauss(h, c, width) for w, c in zip(ws, centres)), sp.S.Zero)
        # W(h) is carried as a state, dW/dt = W'(h) dh/dt, W(0) = 0 (the surface layer vanishes at the pad):
        # the same profile along the trajectory, with far smaller derivative expressions than W(h) inlined
        # into every force term (code generation ~20 s instead of ~130 s)
        W = m.state(f"{name}_speed", 0.0)
        m.ode({W: sp.diff(profile, h) * v * sp.sin(th)})
        # air-relative velocity (u, w) = (v cos theta - W, v sin theta); its norm V_a written so that
        # W = 0 gives V_a = v exactly and derivatives exist at v = 0:
        # V_a = v + Q / (v + sqrt(v^2 + Q + eps^2)), Q = V_a^2 - v^2 = W (W - 2 v cos theta)
        Q = W * (W - 2 * v * sp.cos(th))
        Va = m.define(f"{name}_airspeed", v + Q / (v + sp.sqrt(v ** 2 + Q + WIND_SPEED_EPS ** 2)))
        along = v - W * sp.cos(th)      # V_a cos(Delta): air-relative velocity along the flight path
        across = W * sp.sin(th)         # V_a sin(Delta)
        m.redefine("qbar", qdef.xreplace({v: Va}))
        if air_mach:
            m.redefine("mach", mdef.xreplace({v: Va}))
        if air_alpha and m.has("alpha"):
            # alpha_air = alpha + (theta - theta_air) = alpha - Delta
            m.redefine("cl", cl.xreplace({m.alpha: m.alpha - sp.atan2(across, along)}))
        # drag along -(u, w), lift normal to it, projected on the flight path (drag) and its normal (lift):
        # per unit (rho/2 V_a) the tangential force is -(cd along + cl across) S, the normal (cl along - cd across) S
        half = rho * Va / 2
        m.redefine("drag", drag.xreplace({qbar: half * along}) + lift.xreplace({qbar: half * across}))
        m.redefine("lift", lift.xreplace({qbar: half * along}) - drag.xreplace({qbar: half * across}))
        return ws

    desc = (f"horizontal wind W(h) = tanh(h/{SURFACE_LAYER_M:g} m) sum_j {prefix}j exp(-((h - c_j)/{width_km:g} km)^2/2), "
            f"c_j = {', '.join(f'{c:g}' for c in centres_km)} km (positive downrange). Air-relative velocity "
            "(v cos theta - W, v sin theta); qbar and Mach from the air-relative speed V_a; drag along the air-relative "
            "velocity, lift normal to it; alpha_air = alpha + (theta - theta_air) in the lift coefficient.")
    return Effect(name, "horizontal wind profile", "environment", apply, desc, {n: realistic_speed for n in names})


DENSITY_CENTRES_KM = (0.0, 6.0, 12.0, 18.0)
DENSITY_WIDTH_KM = 3.0


def density_effect(centres_km: Sequence[float] = DENSITY_CENTRES_KM, width_km: float = DENSITY_WIDTH_KM, *,
                   name: str = "density", prefix: str = "drho_", realistic: float = 0.05) -> Effect:
    """A density deviation ``rho (1 + sum_j d_j exp(-((h - c_j)/s)^2 / 2))`` (relative, per basis function)."""
    centres = tuple(float(c) * 1000.0 for c in centres_km)
    width = float(width_km) * 1000.0
    names = tuple(f"{prefix}{j + 1}" for j in range(len(centres)))

    def apply(m: Model) -> tuple:
        rho = _definition(m, "rho", name)
        h = _state(m, "h", name)
        ds = tuple(m.parameter(n, 0.0, nominal=realistic) for n in names)
        m.redefine("rho", rho * (1 + sum((d * _gauss(h, c, width) for d, c in zip(ds, centres)), sp.S.Zero)))
        return ds

    desc = (f"air density rho(h) (1 + sum_j {prefix}j exp(-((h - c_j)/{width_km:g} km)^2/2)), "
            f"c_j = {', '.join(f'{c:g}' for c in centres_km)} km")
    return Effect(name, "density deviation profile", "environment", apply, desc, {n: realistic for n in names})


def earth_rotation_effect(latitude_deg: float = 28.5, azimuth_deg: float = 90.0, *,
                          name: str = "earth_rotation") -> Effect:
    """Coriolis and centrifugal accelerations in the vertical plane of a launch at
    ``latitude_deg``, flying toward ``azimuth_deg`` (from north; 90 = east).

    With ``Omega = k_rot * EARTH_RATE``, ``r = Re + h``, ``phi`` the latitude and
    ``A`` the azimuth (Vinh's equations, out-of-plane terms dropped)::

        dv/dt       += Omega^2 r cos(phi) (sin(theta) cos(phi) - cos(theta) sin(phi) cos(A))
        v dtheta/dt += f_lo(t) 2 Omega v cos(phi) sin(A)
                       + Omega^2 r cos(phi) (cos(theta) cos(phi) + sin(theta) sin(phi) cos(A))

    ``k_rot`` = 1 is the real Earth; the Coriolis term is phased in by the lift-off fade.
    """
    phi = math.radians(latitude_deg)
    az = math.radians(azimuth_deg)

    def apply(m: Model) -> tuple:
        h = _state(m, "h", name)
        v = _state(m, "v", name)
        th = _state(m, "theta", name)
        k = m.parameter("k_rot", 0.0, nominal=1.0)
        om = k * EARTH_RATE
        r = EARTH_RADIUS + h
        cphi, sphi, saz, caz = math.cos(phi), math.sin(phi), math.sin(az), math.cos(az)
        m.add_term(v, om ** 2 * r * cphi * (sp.sin(th) * cphi - sp.cos(th) * sphi * caz))
        normal = (liftoff_fade(m.t) * 2 * om * v * cphi * saz
                  + om ** 2 * r * cphi * (sp.cos(th) * cphi + sp.sin(th) * sphi * caz))
        # add_term adds to d theta/dt: the model's v-multiplied form gets v * (normal / v) = normal, exactly
        m.add_term(th, normal / v)
        return (k,)

    desc = (f"Earth rotation at latitude {latitude_deg:g} deg, azimuth {azimuth_deg:g} deg: Coriolis "
            "(2 Omega v cos(lat) sin(az) in v dtheta/dt, phased in by the lift-off fade) and centrifugal "
            "(Omega^2 r cos(lat) ...) accelerations, Omega = k_rot * 7.292e-5 rad/s")
    return Effect(name, "Earth rotation", "kinematics", apply, desc, {"k_rot": 1.0})


def _build_catalogue() -> dict[str, Effect]:
    effects = [
        Effect("back_pressure", "nozzle back-pressure", "propulsion", _back_pressure,
               "thrust P(h) = P - A_e p_a(h), p_a the 1976 standard's pressure; A_e >= 0 the nozzle exit area, m^2",
               {"A_e": 0.4}),
        Effect("thrust_level", "thrust-level error", "propulsion", _thrust_level,
               "thrust P (1 + eps_thrust)", {"eps_thrust": 0.02}),
        Effect("mass_flow", "mass-flow error", "mass", _mass_flow,
               "mass m0 - mdot (1 + eps_mdot) t", {"eps_mdot": 0.015}),
        Effect("transonic_drag", "transonic drag rise", "aero", _transonic_drag,
               f"cd + dCD_transonic exp(-((M - {TRANSONIC_MACH:g})/{TRANSONIC_WIDTH:g})^2/2)", {"dCD_transonic": 0.2}),
        wind_effect(),
        earth_rotation_effect(),
        Effect("misalignment", "thrust misalignment", "propulsion", _misalignment,
               "thrust direction alpha_thrust = alpha + delta_thrust f_lo(t) (an attack-angle bias of the thrust, "
               "rad, phased in by the lift-off fade)", {"delta_thrust": math.radians(0.25)}),
        density_effect(),
        Effect("bias_x", "downrange sensor bias", "sensor", _bias("x"), "z_x = x + b_x, m", {"b_x": 5.0}),
        Effect("bias_h", "altitude sensor bias", "sensor", _bias("h"), "z_h = h + b_h, m", {"b_h": 5.0}),
        Effect("bias_v", "speed sensor bias", "sensor", _bias("v"), "z_v = v + b_v, m/s", {"b_v": 0.5}),
        Effect("scale_v", "speed scale factor", "sensor", _scale("v"), "z_v = (1 + k_v) v", {"k_v": 1e-3}),
        Effect("time_offset", "time-tag offset", "sensor", _time_offset,
               "every output z(t) = y(t - tau) ~ y - tau dy/dt, tau in s", {"tau": 0.01}),
    ]
    return {e.name: e for e in effects}


CATALOGUE: dict[str, Effect] = _build_catalogue()
"""The candidate effects, by name (``docs/effects.md`` documents each)."""


def custom_effect(name: str, apply: Callable[[Model], Iterable[sp.Symbol]], *, title: str | None = None,
                  kind: str = "custom", description: str = "", realistic: Mapping[str, float] | None = None) -> Effect:
    """An effect the user writes in a few lines of SymPy.

    Parameters
    ----------
    name : str
    apply : callable
        ``apply(model)`` edits the editable model (``m.parameter(..., 0.0)``,
        ``m.redefine``, ``m.add_term``, ``m.redefine_output``) and returns the
        new parameters (a symbol or a sequence of symbols).
    title, kind, description : str
    realistic : mapping, optional
        Realistic magnitude of each parameter, by name.

    Examples
    --------
    >>> def gravity_scale(m):
    ...     eps = m.parameter("eps_g", 0.0)
    ...     m.redefine("g", m.definition("g") * (1 + eps))
    ...     return eps
    >>> effect = custom_effect("gravity_scale", gravity_scale, title="gravity-model error")
    """
    def wrapped(m: Model) -> tuple:
        out = apply(m)
        if out is None:
            raise ModelError(f"effect {name!r}: apply(model) must return the parameters it declared")
        return (out,) if isinstance(out, sp.Basic) else tuple(out)
    wrapped.__name__ = getattr(apply, "__name__", name)
    return Effect(name, title or name.replace("_", " "), kind, wrapped, description, dict(realistic or {}))


# ---------------------------------------------------------------------------
# applying effects
# ---------------------------------------------------------------------------


def resolve_effects(effects: Effect | str | Iterable[Effect | str]) -> list[Effect]:
    """Effects from names (of :data:`CATALOGUE`) or :class:`Effect` values."""
    if isinstance(effects, (Effect, str)):
        effects = [effects]
    out = []
    for e in effects:
        if isinstance(e, Effect):
            out.append(e)
        elif isinstance(e, str):
            if e not in CATALOGUE:
                import difflib
                close = difflib.get_close_matches(e, list(CATALOGUE), n=3)
                hint = f"; did you mean {', '.join(close)}?" if close else ""
                raise ModelError(f"no effect named {e!r} in the catalogue{hint} (effects: {', '.join(CATALOGUE)}; "
                                 "write your own with rocketid.diagnostics.custom_effect)")
            out.append(CATALOGUE[e])
        else:
            raise ModelError(f"expected an Effect or an effect name, got {type(e).__name__}")
    names = [e.name for e in out]
    dup = sorted({n for n in names if names.count(n) > 1})
    if dup:
        raise ModelError(f"effect {dup[0]!r} is given twice")
    return out


def is_present(model: Model | ModelSpec, effect: Effect | str) -> bool:
    """Whether ``model`` already has every parameter of a (catalogue) effect."""
    effect = resolve_effects(effect)[0]
    names = effect.parameter_names
    if not names:
        return False
    if isinstance(model, ModelSpec):
        have = set(model.parameter_names)
        return all(n in have for n in names)
    return all(model.has(n) for n in names)


def apply_effect(m: Model, effect: Effect | str) -> tuple[sp.Symbol, ...]:
    """Apply one effect to the editable model ``m``, in place; returns its parameters.

    On an error ``m`` may be left partly edited: apply effects to a copy, as
    :func:`with_effects` does (which also checks that each parameter is new,
    has guess 0 and enters the model).

    Raises
    ------
    ModelError
        The effect is already present, or needs a component the model lacks.
    """
    effect = resolve_effects(effect)[0]
    present = [n for n in effect.parameter_names if m.has(n)]
    if present:
        raise ModelError(f"effect {effect.name!r} is already present in model {m.name!r} (it has "
                         f"{', '.join(present)}); add each effect once")
    try:
        params = effect.apply(m)
    except ModelError as exc:
        if "already has a component named" in str(exc):
            raise ModelError(f"effect {effect.name!r} is already present in model {m.name!r}, or clashes with "
                             f"one of its components: {exc}") from None
        raise
    params = (params,) if isinstance(params, sp.Basic) else tuple(params or ())
    if not params:
        raise ModelError(f"effect {effect.name!r} declared no parameters (apply(model) must return them)")
    return params


def _editable(model: Model | ModelSpec) -> Model:
    if isinstance(model, ModelSpec):
        return model.to_model()
    if isinstance(model, Model):
        return model.copy()
    raise ModelError(f"expected a Model or a ModelSpec, got {type(model).__name__}")


def with_effects(spec: Model | ModelSpec, effects: Effect | str | Iterable[Effect | str],
                 values: Mapping[str | sp.Symbol, float] | None = None) -> ModelSpec:
    """``spec`` extended by ``effects``, frozen (the given model is not changed).

    Parameters
    ----------
    spec : ModelSpec or Model
        The base model (a ``Model`` is copied first).
    effects : Effect, str or sequence of them
        Catalogue names or :class:`Effect` values.
    values : mapping, optional
        Guesses (for a simulation: true values) by parameter name or symbol,
        for the effects' parameters or any other parameter.

    Returns
    -------
    ModelSpec
        The base model's guesses are kept; effect parameters start at 0
        unless ``values`` says otherwise.

    Raises
    ------
    ModelError
        An unknown or repeated effect, an effect already present, one that
        needs a component the model lacks, or one whose parameter does not
        enter the model's equations or outputs (or whose guess is not 0).
    """
    effects = resolve_effects(effects)
    m = _editable(spec)
    base_names = set(spec.parameter_names) if isinstance(spec, ModelSpec) else None
    base_guess = {p.symbol: p.guess for p in spec.parameters} if isinstance(spec, ModelSpec) else {}
    declared: dict[str, tuple[sp.Symbol, ...]] = {}
    for e in effects:
        declared[e.name] = apply_effect(m, e)
    new = m.freeze()
    if base_names is None:
        base_names = set(spec.freeze().parameter_names)
    check_effect_parameters(new, declared, base_names)
    current = {p.symbol: p.guess for p in new.parameters}
    guesses = {s: g for s, g in base_guess.items() if s in current}
    guesses.update({new.symbol(k): float(v) for k, v in (values or {}).items()})
    if all(current[s] == g for s, g in guesses.items()):
        return new
    return new.with_guess(guesses)


def check_effect_parameters(spec: ModelSpec, declared: Mapping[str, Sequence[sp.Symbol]],
                            base_names: Iterable[str] = ()) -> None:
    """Each effect's parameters are new parameters of ``spec``, with guess 0, that enter its
    equations or outputs; raises :class:`ModelError` naming the first that does not."""
    problems = effect_parameter_problems(spec, declared, base_names)
    if problems:
        raise ModelError(next(iter(problems.values())))


def effect_parameter_problems(spec: ModelSpec, declared: Mapping[str, Sequence[sp.Symbol]],
                              base_names: Iterable[str] = ()) -> dict[str, str]:
    """``{effect name: what is wrong}`` for effects whose parameters are not new
    parameters of ``spec`` with guess 0 that enter its equations or outputs."""
    base_names = set(base_names)
    used = set()
    for eq in spec.equations:
        used |= spec.expand(eq).free_symbols
    for o in spec.outputs:
        used |= spec.expand(o.expr).free_symbols
    params = {p.symbol: p for p in spec.parameters}
    problems: dict[str, str] = {}
    for name, syms in declared.items():
        for s in syms:
            if not isinstance(s, sp.Symbol) or s not in params:
                problems[name] = (f"effect {name!r} returned {s!r}, which is not a parameter of the model; declare "
                                  "it with m.parameter(name, 0.0) and return it")
            elif str(s) in base_names:
                problems[name] = f"effect {name!r} returned {s}, a parameter the model had before the effect"
            elif params[s].guess != 0.0:
                problems[name] = (f"effect {name!r}: parameter {s} must have guess 0 (the zero value gives back the "
                                  f"base model), got {params[s].guess:g}")
            elif s not in used:
                problems[name] = (f"effect {name!r}: parameter {s} does not enter the model's equations or outputs "
                                  f"(model {spec.name!r}); use it in a definition (m.redefine), an equation "
                                  "(m.add_term) or an output (m.redefine_output)")
            if name in problems:
                break
    return problems
