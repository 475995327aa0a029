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
from dataclasses import dataclass, field, replace
from types import MappingProxyType
from typing import Callable, Iterable, Mapping, Sequence

import numpy as np
import sympy as sp
from scipy.integrate import cumulative_trapezoid, trapezoid

from ..errors import ModelError
from ..model import ROLES, Model, ModelSpec, missing_role_message
from ..tables import table_function
from ..physics.atmosphere import us76_offset_log_pressure_ratio, us76_pressure, us76_temperature
from ..physics.gravity import EARTH_RADIUS, G0

__all__ = ["Effect", "Vehicle", "back_pressure_effect", "thrust_profile_effect", "throttle_effect", "wind_profile_effect",
           "sensor_lag_effect",
           "density_profile_effect", "drag_mach_effect", "piecewise_linear", "CATALOGUE", "KINDS", "custom_effect", "with_effects", "apply_effect", "resolve_effects",
           "is_present", "check_effect_parameters", "effect_parameter_problems", "wind_effect", "density_effect", "earth_rotation_effect",
           "liftoff_fade", "EARTH_RATE", "LIFTOFF_FADE_TIME", "misalignment_onset_effect", "mass_jettison_effect", "throttle_step_effect", "onset_step",
           "ONSET_STARTS", "temperature_effect", "burn_rate_effect", "earth_rotation_site_effect", "rotation_reading", "base_drag_mach_effect", "TEMPERATURE_REALISTIC_K",
           "thrust_motors", "motor_level_effect", "motor_burn_effect",
           "motor_misalignment_effect"]

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
        (empty when unknown, as for most custom effects), for RA-66's vehicle.
    relative : callable, optional
        ``relative(vehicle) -> {parameter: realistic magnitude}`` for another
        vehicle (:class:`Vehicle`: its thrust, mass flow, speed, ...); the
        sizes the decision judges plausibility by (:meth:`sizes`).
    refine : callable, optional
        ``refine(vehicle) -> list of Effect``: more flexible shapes of the same
        physics (more knots, a surface value), tried when this effect leaves a
        residual (the knot count is chosen by BIC).
    least : mapping of str to float
        The smallest plausible magnitude of a parameter whose size physics fixes
        (Earth's rotation rate factor ``k_rot``); empty for most effects.
    most : mapping of str to float
        The largest magnitude of a parameter that physics allows anywhere, whatever the vehicle (a
        wind's knot: :data:`WIND_MOST`); beyond it the size is implausible, as beyond five realistic
        sizes. Empty for most effects.
    starts : tuple of mapping
        Starting values to refit the effect from, each a ``{parameter: value}``; the refit
        with the lowest objective is kept. Empty (one refit, from the guesses) for most
        effects; an onset time needs several (:data:`ONSET_STARTS`).
    scan : OnsetScan, optional
        For an event shape: the bank that scores its onset at many times at once, where its
        refits start (the starts above when the scan cannot be made).
    reading : callable, optional
        ``reading({parameter: (estimate, standard error)}) -> str``: what the estimates say in the
        field's own terms (a launch site's latitude and azimuth from their offsets), added to the
        explanation; None for most effects.
    changes : mapping of (str, str) to float
        The realistic size of the change ``b - a`` between two of its parameters, keyed ``(a, b)``: a
        profile's change between neighbouring knots (a wind's shear across the altitude between them).
        A change beyond :data:`~rocketid.diagnostics.accept.SIZE_FACTOR` times it is implausible, as a
        parameter's size is. Empty for most effects.
    positive : tuple of mapping of str to float
        Weighted means of its parameters that its physics makes positive, each ``{parameter: weight}``
        (weights summing to one): a power-off base drag averaged over the Mach range flown -- once the jet
        stops filling the base, the base pressure falls and the drag rises. A mean below zero by more than
        :data:`~rocketid.diagnostics.accept.SIGN_SIGMAS` times its standard error (bounded by
        ``sum |w_i| std_i``, whatever the estimates' correlation) is the wrong sign: implausible, as a size
        beyond five realistic sizes is. The parameters are judged together, not one by one: a profile's
        single knot may fall below zero while the profile does not (a true base drag, fitted on 5 Mach
        knots, ended -0.043 +- 0.004 at its highest knot). Empty for most effects.
    rung : bool
        As a refined shape: a more flexible version of its family's shape, climbed in order of flexibility
        (True, most); False for another form of the same physics, as flexible as the catalogue's (the
        back-pressure's vacuum reference beside its sea-level one), tried beside the ladder.
    """

    name: str
    title: str
    kind: str
    apply: Callable[[Model], tuple] = field(compare=False, repr=False)
    description: str = ""
    realistic: Mapping[str, float] = field(default_factory=dict, compare=False)
    relative: Callable | None = field(default=None, compare=False, repr=False)
    refine: Callable | None = field(default=None, compare=False, repr=False)
    least: Mapping[str, float] = field(default_factory=dict, compare=False)
    most: Mapping[str, float] = field(default_factory=dict, compare=False)
    starts: tuple = field(default=(), compare=False)
    scan: "OnsetScan | None" = field(default=None, compare=False, repr=False)
    reading: Callable | None = field(default=None, compare=False, repr=False)
    changes: Mapping[tuple, float] = field(default_factory=dict, compare=False)
    rung: bool = field(default=True, compare=False)
    positive: tuple = field(default=(), compare=False)

    def __post_init__(self):
        if not isinstance(self.name, str) or not self.name.isidentifier():
            raise ModelError(f"an effect's name must be an identifier, got {self.name!r}")
        if self.kind not in KINDS:
            raise ModelError(f"effect {self.name!r}: unknown kind {self.kind!r}; choose one of {', '.join(KINDS)}")
        if not callable(self.apply):
            raise ModelError(f"effect {self.name!r}: apply must be a function apply(model) -> parameters")
        object.__setattr__(self, "realistic", MappingProxyType({str(k): float(v) for k, v in self.realistic.items()}))
        object.__setattr__(self, "least", MappingProxyType({str(k): float(v) for k, v in self.least.items()}))
        object.__setattr__(self, "most", MappingProxyType({str(k): float(v) for k, v in self.most.items()}))
        object.__setattr__(self, "starts", tuple(MappingProxyType({str(k): float(v) for k, v in st.items()})
                                                 for st in self.starts))
        positive = tuple(MappingProxyType({str(k): float(v) for k, v in group.items()}) for group in self.positive)
        for group in positive:
            if not group or not math.isclose(sum(group.values()), 1.0, rel_tol=1e-9):
                raise ModelError(f"effect {self.name!r}: each group of positive gives weights summing to one, "
                                 f"got {dict(group)}")
        object.__setattr__(self, "positive", positive)

    @property
    def parameter_names(self) -> tuple[str, ...]:
        """Names of the parameters the effect declares (known for catalogue effects)."""
        return tuple(self.realistic)

    @property
    def event_time(self) -> str | None:
        """The event-time parameter of an event shape (s after the start; :attr:`scan`), else None; for a
        window, the time it opens."""
        return self.scan.time if self.scan is not None and self.scan.unit == "s" else None

    @property
    def locations(self) -> dict[str, str]:
        """The parameters that place a located shape (its :attr:`scan`'s), with their unit: an event's times
        (``"s"`` after the start: the onset, and a window's end) or a drag hump's Mach number."""
        if self.scan is None:
            return {}
        names = (self.scan.time,) + ((self.scan.end,) if self.scan.end else ())
        return {n: self.scan.unit for n in names}

    def sizes(self, vehicle: "Vehicle | None" = None) -> dict[str, float]:
        """Realistic magnitude of each parameter for ``vehicle`` (RA-66's without one)."""
        out = dict(self.realistic)
        if vehicle is not None and self.relative is not None:
            out.update({k: abs(float(v)) for k, v in self.relative(vehicle).items()})
        return out

    def refinements(self, vehicle: "Vehicle | None" = None) -> list["Effect"]:
        """More flexible shapes of this effect (empty when it has none)."""
        return list(self.refine(vehicle)) if self.refine is not None else []


@dataclass(frozen=True)
class Vehicle:
    """The scales of a vehicle's flight that realistic effect sizes are stated against.

    Attributes
    ----------
    thrust : float
        Thrust at the start, N.
    mass : float
        Mass at the start, kg.
    mass_flow : float
        Mean mass flow over the flight, kg/s (0 when the mass does not change).
    speed : float
        Largest speed, m/s.
    start_speed : float
        Speed at the start, m/s.
    duration : float
        The model's horizon, s.
    altitude : (float, float)
        Altitude range flown, m.
    mach : (float, float) or None
        Mach range flown.
    sigma : dict
        Noise sigma of each measured channel.
    sample_interval : float
        Median time between samples, s.
    knot_times : tuple of float
        Element boundaries of the fit's mesh (where time knots of a refined shape may sit).
    mach_knots : tuple of float
        Knots of the model's drag table in Mach (``Model.table`` on the Mach role), empty when it has none.
    aero_altitudes : tuple of float
        The altitudes by which the aerodynamic action ``integral |qbar| dt`` reaches 0, 1, ..., 100 %
        of its total, m (empty when unknown): refined wind and density profiles put their knots at
        equal shares of it, where the data can pin them.
    time_families : bool
        The model has coefficients in time (time families: RA-66's drag), which an output cannot hold
        (no ``time_offset_2``).
    powered : (float, float) or ()
        First and last time the thrust role is above 0.1 % of its largest value along the fit, s (empty
        when unknown): a thrust error in time has its knots there, not over a coast.
    rail_exit : bool
        The declared start is a rail exit: a moving start after ignition that the stated thrust reaches
        along a rail (:func:`_rail_exit_ratio`); the exit's shapes (``start_exit``, ``start_mass_exit``)
        are offered only then.
    motors : tuple of str
        The thrust's motors among others (:func:`thrust_motors`: a booster's thrust table beside a core's
        thrust), each offered its own level, burn-rate and misalignment shapes; empty for a vehicle with one
        thrust.
    """

    thrust: float
    mass: float
    mass_flow: float
    speed: float
    start_speed: float
    duration: float
    altitude: tuple
    mach: tuple | None
    sigma: Mapping[str, float]
    sample_interval: float
    knot_times: tuple = ()
    mach_knots: tuple = ()
    aero_altitudes: tuple = ()
    time_families: bool = False
    powered: tuple = ()
    rail_exit: bool = False
    motors: tuple = ()


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


def _role(m: Model, role: str, effect: str) -> sp.Expr:
    """The symbol (or expression) playing ``role`` in ``m``; a ModelError naming the effect otherwise."""
    expr = m.role(role)
    if expr is None:
        raise ModelError(missing_role_message(m.name, role, f"effect {effect!r}"))
    return expr


def _role_definition(m: Model, role: str, effect: str) -> tuple[sp.Symbol, sp.Expr]:
    """``(symbol, expression)`` of the definition playing ``role``."""
    sym = _role(m, role, effect)
    try:
        return sym, m.definition(sym)
    except ModelError:
        raise ModelError(f"effect {effect!r} redefines the {ROLES[role].split(' (')[0]} (role {role!r}), so it must "
                         f"be a definition (m.define) of model {m.name!r}; it is {sym}") from None


def _role_state(m: Model, role: str, effect: str) -> sp.Symbol:
    """The state playing ``role``."""
    sym = _role(m, role, effect)
    try:
        m.der(sym)
    except ModelError:
        raise ModelError(f"effect {effect!r} needs the {ROLES[role].split(' (')[0]} (role {role!r}) to be a state of "
                         f"model {m.name!r}; it is {sym}") from None
    return sym


def _initial_value(m: Model, state: sp.Symbol) -> float:
    return float(next(s.initial for s in m._states if s.symbol == state))


def _expanded(m: Model, expr: sp.Expr) -> sp.Expr:
    """``expr`` with the model's definitions substituted, recursively."""
    defs = dict(m._definitions)
    for _ in range(50):
        hit = {s: defs[s] for s in expr.free_symbols if s in defs}
        if not hit:
            return expr
        expr = expr.xreplace(hit)
    return expr


def _output_of(m: Model, role: str, channel: str, effect: str) -> tuple[str, sp.Expr]:
    """The measured output that reads the state playing ``role`` (the output named ``channel`` when no
    output is that state alone)."""
    sym = m.role(role)
    if sym is not None:
        for name in m.output_names:
            if m.output_expression(name) == sym:
                return name, sym
    return channel, _output(m, channel, effect)


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


SEA_LEVEL_PRESSURE = 101325.0
"""p0 of the 1976 standard atmosphere, Pa."""


NOZZLE_FULL_SHARE = 0.4
"""The share of its peak above which a motor's stated thrust is taken to come from a nozzle flowing full
(:func:`_nozzle_flowing`)."""


def _nozzle_flowing(m: Model, thrust: sp.Expr, level: np.ndarray | None = None) -> sp.Expr:
    """How much of the back-pressure correction applies: 1 while the nozzle flows full, ``P / (0.4 P_max)``
    below 40 % of the stated thrust's peak ``P_max`` (the tail-off), 0 when the motor is off.

    The correction ``A_e (p0 - p_a)`` is the difference between the thrust in flight and at the
    pressure the stated figure holds at, for the same flow. When the motor stops the jet stops and
    the correction with it (a constant ``A_e p0`` through a coast would be thrust from nothing); in
    the tail-off the exit pressure falls with the chamber pressure, and a nozzle expanded near
    sea-level pressure separates when its exit pressure falls below about 0.4 of the ambient
    (Summerfield's criterion): below 40 % of the running thrust the static firing's figure no longer
    comes from a nozzle flowing full, and the correction shrinks with the thrust. The factor is 1
    (exactly, not a gate that rounds to it) when the stated thrust does not change in time or stays
    above 40 % of its peak over the horizon (judged with the states at their start values and the
    parameters at their guesses: :func:`_stated_thrust_levels`, or ``level`` when already computed).
    """
    level = _stated_thrust_levels(m, thrust) if level is None else level
    if level is None or level.min() >= NOZZLE_FULL_SHARE * level.max():
        return sp.S.One
    share = thrust / (NOZZLE_FULL_SHARE * float(level.max()))
    return share - sp.Max(share - 1, 0)          # min(share, 1)


def _stated_thrust_levels(m: Model, thrust: sp.Expr) -> np.ndarray | None:
    """``|P(t)|`` of the stated thrust on a grid over the horizon (every sample of a sampled input on it), or
    None when it is constant or depends on more than time, known inputs, the states and the parameters (or is
    never positive). States are held at their start values and parameters at their guesses (an effect applied
    before, a nozzle term in altitude: the level judged is whether the motor runs, not its exact value)."""
    x = _held(m, thrust)
    inputs = [u for u in m._inputs if u.symbol in x.free_symbols]
    if x.free_symbols - {m.t} - {u.symbol for u in inputs} or not x.free_symbols:
        return None
    samples = [t for u in inputs for t in u.times if m.t0 <= t <= m.tf]
    tt = np.union1d(np.linspace(m.t0, m.tf, 801), samples)       # a sampled curve's peak is at a sample
    level = np.abs(_along(m, x, inputs, tt))
    return level if level.max() > 0 else None


def _held(m: Model, expr: sp.Expr) -> sp.Expr:
    """``expr`` expanded, with the constants at their values, the states at their start values and the
    parameters at their guesses: what is left depends on time and the known inputs."""
    held = {c: sp.Float(v) for c, v in m._constants}
    held.update({st.symbol: sp.Float(st.initial) for st in m._states})
    held.update({ps.symbol: sp.Float(ps.guess) for ps in m._parameters})
    return _expanded(m, expr).xreplace(held)


def _along(m: Model, x: sp.Expr, inputs: Sequence, tt: np.ndarray) -> np.ndarray:
    """The values of ``x`` (of time and ``inputs`` only, :func:`_held`) at the times ``tt``."""
    values = [np.interp(tt, u.times, u.values) if u.expr is None
              else np.broadcast_to(sp.lambdify(m.t, u.expr, "numpy")(tt), tt.shape) for u in inputs]
    return np.broadcast_to(sp.lambdify([m.t, *(u.symbol for u in inputs)], x, "numpy")(tt, *values), tt.shape)


MOTOR_OFF_SHARE = 0.01
"""A stated thrust below this share of its peak is a motor that has stopped (:func:`_base_drag`)."""


def _power_off(m: Model, effect: str) -> sp.Expr:
    """``1 - f_noz``: 0 while the nozzle flows full, 1 once the motor has stopped; a ModelError unless the
    model's motor stops inside the horizon (a power-off phase to act in)."""
    thrust = _role_definition(m, "thrust", effect)[1]
    level = _stated_thrust_levels(m, thrust)
    if level is None or level.min() > MOTOR_OFF_SHARE * level.max():
        raise ModelError(f"effect {effect!r} needs a motor that stops inside the horizon (a burn-out, then a "
                         f"coast); the stated thrust of model {m.name!r} does not fall below "
                         f"{100 * MOTOR_OFF_SHARE:g} % of its peak")
    return 1 - _nozzle_flowing(m, thrust, level)


def _base_drag(m: Model) -> tuple:
    """Power-off drag: ``cd + dCD_base (1 - f_noz)`` once the motor stops (module notes of the catalogue)."""
    off = _power_off(m, "base_drag")
    sym, cd = _role_definition(m, "drag_coefficient", "base_drag")
    dcd = m.parameter("dCD_base", 0.0, nominal=0.1)
    m.redefine(sym, cd + dcd * off)
    return (dcd,)


def base_drag_mach_effect(knots: Sequence[float]) -> Effect:
    """Power-off base drag that changes with the Mach number: ``cd + c(M) (1 - f_noz)``, ``c`` piecewise linear
    through ``dCD_base_j`` at ``knots`` (the base pressure of a blunt base falls with Mach: the increment
    is largest transonic and shrinks supersonic)."""
    kn = tuple(float(k) for k in knots)
    name = f"base_drag_mach_{len(kn)}"
    names = tuple(f"dCD_base_{j}" for j in range(len(kn)))

    def apply(m: Model) -> tuple:
        off = _power_off(m, name)
        sym, cd = _role_definition(m, "drag_coefficient", name)
        mach = _role(m, "mach", name)
        ps = tuple(m.parameter(n, 0.0, nominal=0.1) for n in names)
        m.redefine(sym, cd + piecewise_linear(mach, kn, ps) * off)
        return ps

    return Effect(name, f"power-off base drag in Mach ({len(kn)} knots)", "aero", apply,
                  f"cd + c(M) (1 - f_noz), c piecewise linear in Mach through {', '.join(f'{k:.3g}' for k in kn)}; "
                  "its average over these Mach numbers positive", {n: 0.1 for n in names},
                  positive=(dict(zip(names, _trapezoid_weights(kn))),))


def _trapezoid_weights(knots: Sequence[float]) -> tuple:
    """Weights of a piecewise-linear function's values at ``knots`` in its average over them (the trapezoid
    rule, exact for such a function); one knot: weight 1."""
    kn = np.asarray(knots, float)
    if kn.size == 1:
        return (1.0,)
    w = np.zeros(kn.size)
    d = np.diff(kn)
    w[:-1] += d / 2
    w[1:] += d / 2
    return tuple(float(x) for x in w / w.sum())


def _refine_base_drag(vehicle: "Vehicle | None") -> list[Effect]:
    if vehicle is None or vehicle.mach is None or not vehicle.mach[1] > vehicle.mach[0]:
        return []
    lo, hi = vehicle.mach
    return [base_drag_mach_effect(np.linspace(lo, hi, n)) for n in (2, 3, 5)]


def back_pressure_effect(reference: str = "sea_level", *, fade: bool = False, name: str | None = None) -> Effect:
    """Nozzle back-pressure: the thrust changes with the ambient pressure ``p_a(h)``.

    Parameters
    ----------
    reference : {"sea_level", "vacuum"}
        The pressure at which the model's stated thrust ``P`` holds.
        ``"sea_level"`` (a static firing's figure, the default): ``P + A_e (p0 - p_a(h))``,
        the thrust rises as the vehicle climbs. ``"vacuum"``: ``P - A_e p_a(h)``, the
        stated thrust is the vacuum thrust and the atmosphere takes ``A_e p_a`` off it.
    fade : bool
        Estimate where the correction fades out in the tail-off (a refined shape, see the notes):
        one more parameter, ``d_fade``.
    name : str, optional
        Default ``back_pressure`` (sea level) or ``back_pressure_vacuum``, with ``_fade`` appended
        for the refined shape.

    Notes
    -----
    ``A_e >= 0`` is the nozzle exit area. When the model's thrust already depends on
    altitude (it has a nozzle term), the effect is a correction ``dA_e`` of that area,
    of either sign, written the same way.

    In the tail-off the correction fades with the stated thrust: it is multiplied by
    ``min(1, P / (s P_max))``, ``P_max`` the stated thrust's peak. The catalogue's shape takes
    ``s = 0.4`` (:data:`NOZZLE_FULL_SHARE`: below 40 % of its peak a nozzle expanded for sea level
    no longer flows full); how an engine's pressure term actually dies away is its own (an engine
    team may scale it with the chamber pressure from the start of the shutdown), so the refined
    shape (``fade=True``) estimates ``s = 0.4 + d_fade`` in ``[0.1, 1]``. It is offered only for a
    motor that stops inside the horizon, where the data see the tail-off.
    """
    if reference not in ("sea_level", "vacuum"):
        raise ModelError(f"back-pressure reference must be 'sea_level' or 'vacuum', got {reference!r}")
    base_name = "back_pressure" if reference == "sea_level" else "back_pressure_vacuum"
    name = name or (base_name + ("_fade" if fade else ""))
    suffix = "" if reference == "sea_level" else "_vac"

    def apply(m: Model) -> tuple:
        sym, thrust = _role_definition(m, "thrust", name)
        h = _role_state(m, "altitude", name)
        nozzle = h in _expanded(m, thrust).free_symbols
        if nozzle:
            # the model has a nozzle term already: estimate a correction of its area, either sign
            area = m.parameter("dA_e" + suffix, 0.0, nominal=0.1)
        else:
            area = m.parameter("A_e" + suffix, 0.0, bounds=(0.0, math.inf), nominal=0.4)   # an area: not negative
        pa = _define(m, "p_ambient", us76_pressure(h), name)
        change = area * (SEA_LEVEL_PRESSURE - pa) if reference == "sea_level" else -area * pa
        if not fade:
            m.redefine(sym, thrust + change * _nozzle_flowing(m, thrust))
            return (area,)
        level = _stated_thrust_levels(m, thrust)
        if level is None or level.min() >= NOZZLE_FULL_SHARE * level.max():
            raise ModelError(f"effect {name!r} estimates where the back-pressure correction fades in the tail-off, "
                             f"but the stated thrust of model {m.name!r} does not fall below "
                             f"{100 * NOZZLE_FULL_SHARE:g} % of its peak inside the horizon: use {base_name!r}")
        d = m.parameter("d_fade" + suffix, 0.0, bounds=(FADE_SHARES[0] - NOZZLE_FULL_SHARE,
                                                       FADE_SHARES[1] - NOZZLE_FULL_SHARE), nominal=0.2)
        share = thrust / ((NOZZLE_FULL_SHARE + d) * float(level.max()))
        # min(share, 1), rounded over FADE_ROUNDING of the share: the kink's time moves with d_fade, and a
        # corner there leaves IPOPT cycling (a hard min stopped on its iteration limit at Petrel-V's tail-off)
        r = FADE_ROUNDING
        m.redefine(sym, thrust + change * (share + 1 - sp.sqrt((share - 1) ** 2 + r * r)) / 2)
        return (area, d)

    what = ("P + A_e (p0 - p_a(h)): the stated thrust P holds at sea level (p0 = 101325 Pa) and rises as the "
            "ambient pressure falls" if reference == "sea_level" else
            "P - A_e p_a(h): the stated thrust P is the vacuum thrust")
    desc = (f"thrust {what}; p_a the 1976 standard's pressure; A_e >= 0 the nozzle exit area, m^2 (a correction "
            "dA_e of either sign when the model's thrust already has a nozzle term); in the tail-off the "
            f"correction fades as min(1, P / (s P_max)), " + (
                f"s = {NOZZLE_FULL_SHARE:g} + d_fade estimated in [{FADE_SHARES[0]:g}, {FADE_SHARES[1]:g}]"
                if fade else f"s = {NOZZLE_FULL_SHARE:g}"))
    title = "nozzle back-pressure" + (" (vacuum thrust stated)" if reference == "vacuum" else "") + \
        (", its tail-off fade estimated" if fade else "")
    area_size = {"A_e" + suffix: 0.4}
    shape = {"d_fade" + suffix: FADE_SHARES[1] - FADE_SHARES[0]} if fade else {}

    def relative(veh):
        a = 0.1 * veh.thrust / SEA_LEVEL_PRESSURE
        return {"A_e" + suffix: a, "dA_e" + suffix: a, **shape}

    refine = None if fade else (lambda veh: ([replace(back_pressure_effect("vacuum"), rung=False)]
                                             if reference == "sea_level" else [])
                                + ([back_pressure_effect(reference, fade=True)] if _stops(veh) else []))
    return Effect(name, title, "propulsion", apply, desc, {**area_size, **shape}, relative=relative, refine=refine)


FADE_SHARES = (0.1, 1.0)
"""The range of the share ``s`` of the stated thrust's peak below which the refined back-pressure shape fades
its correction out (:func:`back_pressure_effect` with ``fade=True``). Its realistic size is the whole range:
where in it the fade sits is a shape, not a magnitude to judge."""


FADE_ROUNDING = 0.01
"""Half-width, in the share ``P / (s P_max)``, over which the refined shape's ``min(share, 1)`` is rounded
(``(share + 1 - sqrt((share - 1)^2 + r^2)) / 2``): 0.5 % below 1 at ``share = 1``, 0.02 % at 1.25. (0.05 was
tried: its 1.2 % shaved off the correction near the fade biased the fade 14 % early and the area 9 % low on Tern-2.)"""


def _stops(vehicle: "Vehicle | None") -> bool:
    """Whether the motor stops inside the horizon: the thrust's last powered time (:attr:`Vehicle.powered`) more
    than 1 % of the horizon before its end."""
    if vehicle is None or not vehicle.powered or not vehicle.knot_times:
        return False
    return float(vehicle.powered[1]) < float(vehicle.knot_times[-1]) - 0.01 * float(vehicle.duration)


def _thrust_level(m: Model) -> tuple:
    sym, thrust = _role_definition(m, "thrust", "thrust_level")
    eps = m.parameter("eps_thrust", 0.0, nominal=0.02)
    m.redefine(sym, thrust * (1 + eps))
    return (eps,)


def _mass_flow(m: Model) -> tuple:
    sym, mass = _role_definition(m, "mass", "mass_flow")
    m0 = _expanded(m, mass).xreplace({m.t: m.t0})
    if m.t not in _expanded(m, mass).free_symbols:
        raise ModelError(f"effect 'mass_flow' scales the mass consumed since t0, but the mass of model {m.name!r} "
                         f"does not change with time ({mass})")
    eps = m.parameter("eps_mdot", 0.0, nominal=0.015)
    # m(t) = m(t0) - (m(t0) - m(t)) (1 + eps): the mass flow scaled by 1 + eps
    m.redefine(sym, mass - eps * (m0 - mass))
    return (eps,)


def _start_mass(m: Model) -> tuple:
    sym, mass = _role_definition(m, "mass", "start_mass")
    dm = m.parameter("dm_start", 0.0, nominal=100.0)
    # the whole mass history shifted by dm_start: a heavier (or lighter) vehicle at the start, burning the
    # same propellant (a payload, a ballast, a propellant load off its stated value)
    m.redefine(sym, mass + dm)
    return (dm,)


def _explicit_rhs(m: Model, state: sp.Symbol, effect: str) -> sp.Expr:
    """The right-hand side of an explicit ODE ``d state/dt = f`` (a ModelError for an implicit one)."""
    eq = m._equations[state]
    der = next(s.derivative for s in m._states if s.symbol == state)
    if sp.diff(eq, der) != 1 or der in (eq - der).free_symbols:
        raise ModelError(f"effect {effect!r} scales the equation of state {state} of model {m.name!r}, which must "
                         f"be explicit (m.ode); it is the implicit {eq} = 0")
    return der - eq


def _input_table(u) -> type:
    """The table function (:mod:`rocketid.tables`) of a sampled input: its samples, evaluable at any
    expression, with its slope as derivative."""
    return table_function(u.times, u.values, str(u.symbol))


def _input_at(u, clock: sp.Expr, t: sp.Symbol) -> sp.Expr:
    """Input ``u`` read at ``clock``: its expression of ``t`` there, or its samples through their table function."""
    return u.expr.xreplace({t: clock}) if u.expr is not None else _input_table(u)(clock)


@dataclass(frozen=True)
class _Motor:
    """What a motor-clock edit reads: the ``thrust`` and ``mass`` definitions (their symbols and expanded
    expressions), a mass state's flow (``{state: f}`` of ``d state/dt = f``), the inputs they read, and those
    inputs' values at the model's start (``at_start``: a substitution that also sets ``t = t0``)."""

    thrust_symbol: sp.Symbol
    thrust: sp.Expr
    mass_symbol: sp.Symbol
    mass: sp.Expr
    flows: dict
    inputs: tuple
    at_start: dict

    def warp(self, clock: sp.Expr, t: sp.Symbol) -> dict:
        """The substitution that reads the motor at ``clock``: time, and each sampled input through its table
        function (one function, not a sum of a ramp per sample -- a 249-sample static-firing table made CSE
        70 % of a Wren-H diagnosis that way)."""
        out = {t: clock}
        for u in self.inputs:
            out[u.symbol] = _input_at(u, clock, t)
        return out

    def flow_at_start(self) -> sp.Expr:
        """The mass states' rate at the start (negative: burning)."""
        return sum((f.xreplace(self.at_start) for f in self.flows.values()), sp.S.Zero)


def _motor(m: Model, effect: str) -> _Motor:
    t_sym, thrust = _role_definition(m, "thrust", effect)
    m_sym, mass = _role_definition(m, "mass", effect)
    thrust_x, mass_x = _expanded(m, thrust), _expanded(m, mass)
    states = {s.symbol for s in m._states}
    flows = {s: _expanded(m, _explicit_rhs(m, s, effect)) for s in mass_x.free_symbols & states}
    read = thrust_x.free_symbols | mass_x.free_symbols | set().union(*(f.free_symbols for f in flows.values()))
    inputs = tuple(u for u in m._inputs if u.symbol in read)
    at_start = {m.t: sp.Float(m.t0), **{u.symbol: (u.expr.xreplace({m.t: m.t0}) if u.expr is not None
                                                    else sp.Float(np.interp(m.t0, u.times, u.values)))
                                         for u in inputs}}
    return _Motor(t_sym, thrust_x, m_sym, mass_x, flows, inputs, at_start)


def _burn_rate(m: Model) -> tuple:
    """The motor on a clock ``(1 + eps_burn)`` times faster (module notes of :func:`burn_rate_effect`)."""
    mo = _motor(m, "burn_rate")
    # the motor's clock starts at ignition: where its sampled curve starts (a window cut in flight keeps it),
    # else at the model's start
    origin = min([m.t0] + [u.times[0] for u in mo.inputs if u.expr is None])
    eps = m.parameter("eps_burn", 0.0, bounds=(-0.3, 0.3), nominal=0.02)
    k = 1 + eps
    warp = mo.warp(origin + k * (m.t - origin), m.t)
    # a mass state starts at its declared value, which is what the stated curve leaves at t0; on the faster
    # clock the motor has burnt for (1 + eps)(t0 - t_i) by then: eps (t0 - t_i) dm/dt(t0) more (to first order)
    m.redefine(mo.thrust_symbol, k * mo.thrust.xreplace(warp))
    m.redefine(mo.mass_symbol, mo.mass.xreplace(warp) + eps * mo.flow_at_start() * (m.t0 - origin))
    for state, flow in mo.flows.items():
        m.ode({state: k * flow.xreplace(warp)})
    return (eps,)


def burn_rate_effect() -> Effect:
    """The motor burns ``1 + eps_burn`` times faster than stated: thrust and mass flow together.

    A solid motor's burn rate moves with its grain temperature (a hot motor burns faster, a cold one
    slower, by 0.1-0.3 % per kelvin): its thrust curve is then compressed in time and raised by the
    same factor, ``P(t) = k P_stated(t_i + k (t - t_i))`` with ``k = 1 + eps_burn`` and ``t_i`` the
    ignition, and the propellant is consumed on the same faster clock -- the total impulse and the
    propellant load are those stated, delivered sooner. A liquid engine running at a higher chamber
    pressure than stated is the same change without the curve's shape (a constant thrust and mass
    flow scaled together, at the stated specific impulse).

    The edit: every time-dependent part of the ``thrust`` and ``mass`` definitions (an expression of
    ``t``, a sampled input such as a thrust table, a mass falling linearly in time) is evaluated at
    the motor's clock ``t_i + k (t - t_i)``, the thrust is multiplied by ``k``, and a mass that is a
    state has its equation ``dm/dt = f`` replaced by ``k f`` on that clock. ``t_i`` is the first time
    of a sampled thrust curve (a window cut in flight keeps the motor's ignition) and otherwise the
    model's start. When the data start after ignition (``t0 > t_i``: a rail exit, a window), a mass
    state's declared start value is what the stated curve leaves at ``t0``; the faster clock has burnt
    ``eps_burn (t0 - t_i) |f(t0)|`` more by then (to first order), which the ``mass`` definition takes off. Unlike ``thrust_level``, which changes the thrust at the stated mass flow (a
    specific-impulse error), this keeps the specific impulse.
    """
    return Effect("burn_rate", "burn-rate error (thrust and mass flow together)", "propulsion", _burn_rate,
                  "thrust k P(t_i + k (t - t_i)) and the mass consumed on the same clock, k = 1 + eps_burn: "
                  "the motor's curve run k times faster (a hot or cold solid grain; a liquid engine off its "
                  "stated chamber pressure), the stated specific impulse and propellant kept",
                  {"eps_burn": 0.02})


def thrust_motors(spec) -> tuple[str, ...]:
    """The thrust's motors among others: each known input (a motor's thrust table, a thrust written as an
    expression of time) that the ``thrust`` role reads beside another time-varying thrust that does not read
    it, in proportion to it -- a strap-on booster's table beside a throttled core, one motor of a cluster with its
    own table (an input read through a nonlinear function, an attitude in a cosine, is not a motor). A
    vehicle whose thrust is one motor's (the thrust proportional to one table) has none: its thrust errors
    are the whole thrust's (``thrust_level``, ``burn_rate``). ``spec`` is a :class:`~rocketid.model.ModelSpec`
    or :class:`~rocketid.model.Model`; names in declaration order."""
    expand = spec.expand if hasattr(spec, "expand") else (lambda e: _expanded(spec, e))
    role = spec.role("thrust")
    inputs = tuple(spec.inputs if hasattr(spec, "inputs") else spec._inputs)
    if role is None or len(inputs) == 0:
        return ()
    thrust = expand(role)
    symbols = {u.symbol for u in inputs}
    out = []
    for u in inputs:
        # a motor's thrust adds to the others' in proportion to its input (not an attitude read through a cosine)
        if u.symbol not in thrust.free_symbols or sp.diff(thrust, u.symbol, 2) != 0:
            continue
        rest = thrust.xreplace({u.symbol: sp.S.Zero})
        if rest.free_symbols & ((symbols - {u.symbol}) | {spec.t}):
            out.append(str(u.symbol))
    return tuple(out)


def _motor_input(m: Model, motor: str, effect: str):
    """The known input named ``motor`` that the thrust reads beside another thrust (:func:`thrust_motors`)."""
    if motor not in thrust_motors(m):
        raise ModelError(f"effect {effect!r} scales the motor whose thrust is the input {motor!r}, which the "
                         f"thrust of model {m.name!r} does not read beside another thrust (its motors: "
                         f"{', '.join(thrust_motors(m)) or 'none'}); use thrust_level or burn_rate for the whole thrust")
    return next(u for u in m._inputs if str(u.symbol) == motor)


def _edit_motor(m: Model, mo: "_Motor", sub: dict, mass_extra: sp.Expr = sp.S.Zero) -> None:
    """Redefine thrust, mass and mass-state flows with the input substitution ``sub``."""
    m.redefine(mo.thrust_symbol, mo.thrust.xreplace(sub))
    m.redefine(mo.mass_symbol, mo.mass.xreplace(sub) + mass_extra)
    for state, flow in mo.flows.items():
        m.ode({state: flow.xreplace(sub)})


def motor_level_effect(motor: str) -> Effect:
    """One motor's thrust and mass flow ``1 + eps`` times their stated values, the others' as stated.

    For a vehicle with more than one thrust (:func:`thrust_motors`: a strap-on booster's thrust table beside
    a throttled core), a level error of one of them: the input ``u`` -- the motor's stated thrust, from a
    static firing -- read as ``(1 + eps) u`` everywhere the thrust, the mass and the mass states' equations
    read it. A propellant burnt at ``u / (Isp g0)`` then burns ``1 + eps`` times as fast: the specific impulse
    is kept (a grain lit on part of its surface, a motor from another lot; ``eps < 0`` leaves propellant
    unburnt, which a mass written with the motor's jettison carries to it). Realistic size 0.02 of that
    motor's thrust, like :data:`CATALOGUE`'s ``thrust_level`` of the whole thrust. Offered as a refined
    shape of ``thrust_level`` when the vehicle has motors; name ``thrust_level_<input>``, parameter
    ``eps_thrust_<input>``.
    """
    name, par = f"thrust_level_{motor}", f"eps_thrust_{motor}"

    def apply(m: Model) -> tuple:
        u = _motor_input(m, motor, name)
        mo = _motor(m, name)
        eps = m.parameter(par, 0.0, bounds=(-0.5, 0.5), nominal=0.02)
        _edit_motor(m, mo, {u.symbol: (1 + eps) * u.symbol})
        return (eps,)

    return Effect(name, f"level error of the motor {motor} (thrust and mass flow)", "propulsion", apply,
                  f"{motor} read as (1 + {par}) {motor} in the thrust, the mass and the mass flow: one motor's "
                  "thrust and propellant flow off their stated values together, the others' as stated",
                  {par: 0.02})


def motor_burn_effect(motor: str) -> Effect:
    """One motor burning ``1 + eps`` times faster than stated, the others as stated.

    :func:`burn_rate_effect` for one motor among others (:func:`thrust_motors`): the input ``u`` is read as
    ``k u(t_i + k (t - t_i))``, ``k = 1 + eps``, ``t_i`` the first time of its table (its ignition; the
    model's start for an expression), everywhere the thrust, the mass and the mass states' equations read it
    -- a solid booster whose grain is colder (slower, lower) or hotter than its static firing's, the other
    motors unaffected. When the data start after ``t_i`` a mass state has burnt ``eps (t0 - t_i)`` times
    that motor's flow more by ``t0`` (first order), which the mass takes off. Realistic size 0.02. Offered as
    a refined shape of ``thrust_level`` when the vehicle has motors; name ``burn_rate_<input>``, parameter
    ``eps_burn_<input>``.
    """
    name, par = f"burn_rate_{motor}", f"eps_burn_{motor}"

    def apply(m: Model) -> tuple:
        u = _motor_input(m, motor, name)
        mo = _motor(m, name)
        origin = float(u.times[0]) if u.expr is None else float(m.t0)
        eps = m.parameter(par, 0.0, bounds=(-0.3, 0.3), nominal=0.02)
        k = 1 + eps
        clock = origin + k * (m.t - origin)
        warped = _input_at(u, clock, m.t)
        start = {**mo.at_start}
        alone = sum((f.xreplace(start) - f.xreplace({u.symbol: sp.S.Zero}).xreplace(start)
                     for f in mo.flows.values()), sp.S.Zero)
        _edit_motor(m, mo, {u.symbol: k * warped}, eps * alone * (float(m.t0) - origin))
        return (eps,)

    return Effect(name, f"burn-rate error of the motor {motor}", "propulsion", apply,
                  f"{motor} read as k {motor}(t_i + k (t - t_i)), k = 1 + {par}, in the thrust, the mass and the "
                  "mass flow: one motor's curve run k times faster (a hot or cold grain), the others as stated",
                  {par: 0.02})


def motor_misalignment_effect(motor: str, *, other: bool = False) -> Effect:
    """One motor's thrust turned off the body axis, the others' along it (``other``: every thrust but that
    motor's turned -- a core engine's gimbal bias beside aligned boosters).

    For a vehicle with more than one thrust (:func:`thrust_motors`), the turned part's share of the thrust,
    ``s(t) = P_part / P``, turns the resultant by ``delta_thrust s(t)`` (to first order in ``delta_thrust``:
    a quarter of a degree off is 4e-3 rad, whose second-order error is 1e-5 of the force): the thrust direction
    ``alpha_thrust + delta_thrust s(t)``, phased in at lift-off from rest as the catalogue's ``misalignment``
    is. ``P_part`` is the thrust with every other motor's input at zero (``other``: with that motor's input at
    zero). Offered as refined shapes of ``misalignment`` when the vehicle has motors, beside its ladder; names
    ``misalignment_<input>`` and ``misalignment_other_than_<input>``, parameter ``delta_thrust`` (0.25 deg).
    """
    name = f"misalignment_other_than_{motor}" if other else f"misalignment_{motor}"

    def apply(m: Model) -> tuple:
        u = _motor_input(m, motor, name)
        sym, at = _role_definition(m, "thrust_direction", name)
        thrust = _expanded(m, _role(m, "thrust", name))
        without = thrust.xreplace({u.symbol: sp.S.Zero})
        part = without if other else thrust - without
        # the share of the thrust turned; a vanishing thrust (all motors out) turns nothing
        share = part / sp.Max(thrust, 1e-3)
        delta = m.parameter("delta_thrust", 0.0, nominal=math.radians(0.25))
        v = m.role("speed")
        moving = v is not None and m.has(str(v)) and _initial_value(m, v) > 0
        m.redefine(sym, at + delta * share * (1 if moving else liftoff_fade(m.t - m.t0)))
        return (delta,)

    whose = f"every thrust but {motor}'s" if other else f"the motor {motor}'s thrust"
    return Effect(name, f"thrust misalignment of {whose}", "propulsion", apply,
                  f"thrust direction alpha_thrust + delta_thrust s(t), s the share of {whose} in the thrust (the "
                  "resultant turned to first order), phased in at lift-off from rest", {"delta_thrust": math.radians(0.25)},
                  rung=False)


TRANSONIC_MACH = 1.1
TRANSONIC_WIDTH = 0.2


def _transonic_drag(m: Model) -> tuple:
    sym, cd = _role_definition(m, "drag_coefficient", "transonic_drag")
    mach = _role(m, "mach", "transonic_drag")
    dcd = m.parameter("dCD_transonic", 0.0, nominal=0.2)
    m.redefine(sym, cd + dcd * _gauss(mach, TRANSONIC_MACH, TRANSONIC_WIDTH))
    return (dcd,)


def _misalignment(m: Model) -> tuple:
    sym, at = _role_definition(m, "thrust_direction", "misalignment")
    delta = m.parameter("delta_thrust", 0.0, nominal=math.radians(0.25))
    v = m.role("speed")
    # from rest the flight-path equation is singular and a normal force needs the lift-off fade (module
    # notes); a vehicle that starts moving (a start speed > 0) takes the misalignment from t0 on
    moving = v is not None and m.has(str(v)) and _initial_value(m, v) > 0
    m.redefine(sym, at + (delta if moving else delta * liftoff_fade(m.t - m.t0)))
    return (delta,)


def _misalignment_fade(m: Model) -> tuple:
    """Misalignment phased in over an estimated time: ``f(t) = t^4 / (t^4 + (t_r e^s)^4)``, ``t_r`` = 3 s."""
    sym, at = _role_definition(m, "thrust_direction", "misalignment_fade")
    delta = m.parameter("delta_thrust", 0.0, nominal=math.radians(0.25))
    s = m.parameter("s_fade", 0.0, bounds=(-3.0, 3.0), nominal=1.0)
    tt = m.t - m.t0
    m.redefine(sym, at + delta * tt ** 4 / (tt ** 4 + (LIFTOFF_FADE_TIME * sp.exp(s)) ** 4))
    return (delta, s)


ONSET_STARTS = (0.1, 0.3, 0.5, 0.7)
"""Starting onset times of an event shape, as shares of the horizon, when its scan cannot be made: its refit is
started from each and the best kept (the objective is not convex in an event time, and at zero size it does
not depend on it)."""

SCAN_TIMES = 32
"""Onset times on which the scan of an event shape scores the effect (:class:`OnsetScan`), evenly over the
horizon."""


def onset_step(t: sp.Expr, t_on: sp.Expr, width: float) -> sp.Expr:
    """``(1 + tanh((t - t_on) / width)) / 2``: a switch from 0 to 1 at ``t_on``, smoothed over ``width`` s
    (an event inside the flight -- a gimbal bias appearing, a valve opening -- at a time the data fix)."""
    return (1 + sp.tanh((t - t_on) / float(width))) / 2


@dataclass(frozen=True)
class OnsetScan:
    """Where an event shape's refits start: its size scored at many fixed onset times at once.

    ``bank`` is the effect's change repeated at each of ``times`` (s after the start), each copy with its own
    size ``<size>_<k>``: at the current fit, with every size at zero, one sensitivity solve gives the score
    statistic and the one-step size of each onset time (:func:`rocketid.diagnostics.score.onset_starts`). The
    refits start at the best local maxima of that profile, with their one-step sizes.

    Attributes
    ----------
    bank : Effect
    times : tuple of float
    size, time : str
        The event shape's size and onset-time parameters.
    bounds : (float, float)
        The size's bounds (a start is held within them).
    end : str, optional
        For a window (a change at ``time`` undone at ``end``): the end-time parameter. The window's score
        at each pair of onset times ``a < b`` is that of the bank's copy at ``a`` minus its copy at ``b``,
        from the same sensitivity solve.
    unit : str
        What ``times`` and the location parameters are: ``"s"`` (after the start) for an event in time,
        ``"Mach"`` for a feature placed in Mach number (:func:`drag_bump_effect`).
    """

    bank: "Effect"
    times: tuple
    size: str
    time: str
    bounds: tuple = (-math.inf, math.inf)
    end: str | None = None
    unit: str = "s"


def _event_shape(name: str, time_name: str, title: str, kind: str, edit: Callable, size: tuple, t0: float,
                 tf: float, width: float, description: str, relative: Callable | None = None,
                 end_name: str | None = None) -> Effect:
    """An effect that sets in ``time_name`` s after the start: ``edit(m, size_symbol, t_on_expr)`` makes the
    model change, ``size = (name, realistic, bounds)``; the onset time is bounded to ``[-3 width, tf - t0]``
    (at 0 or below, the change acts from the start). With ``end_name`` it is a window, undone at that time
    (``edit(m, size_symbol, t_on_expr, t_off_expr)``; the same bounds). It carries the :class:`OnsetScan`
    bank and the fallback starts."""
    horizon = max(1e-9, float(tf) - float(t0))
    w = float(width)
    size_name, realistic, bounds = size

    def apply(m: Model) -> tuple:
        a = m.parameter(size_name, 0.0, bounds=bounds, nominal=realistic)
        t_on = m.parameter(time_name, 0.0, bounds=(-3.0 * w, horizon), nominal=horizon / 4)
        if end_name is None:
            edit(m, a, t_on)
            return (a, t_on)
        t_off = m.parameter(end_name, 0.0, bounds=(-3.0 * w, horizon), nominal=horizon / 2)
        edit(m, a, t_on, t_off)
        return (a, t_on, t_off)

    times = tuple(horizon * (k + 0.5) / SCAN_TIMES for k in range(SCAN_TIMES))

    def bank(m: Model) -> tuple:
        sizes = tuple(m.parameter(f"{size_name}_{k}", 0.0, bounds=bounds, nominal=realistic)
                      for k in range(len(times)))
        screen = {"screen": True} if getattr(edit, "screens", False) else {}
        for a, t in zip(sizes, times):
            edit(m, a, sp.Float(t), **screen)
        return sizes

    scan = OnsetScan(Effect(f"{name}_scan", f"{title} (scan)", kind, bank, "", {}), times, size_name, time_name,
                     tuple(float(b) for b in bounds), end_name)
    if end_name is None:
        realistic_all = {size_name: realistic, time_name: horizon}
        starts = tuple({time_name: f * horizon} for f in ONSET_STARTS)
    else:
        realistic_all = {size_name: realistic, time_name: horizon, end_name: horizon}
        starts = tuple({time_name: a * horizon, end_name: b * horizon}
                       for i, a in enumerate(ONSET_STARTS) for b in ONSET_STARTS[i + 1:])
    return Effect(name, title, kind, apply, description, realistic_all, relative=relative, starts=starts, scan=scan)


def misalignment_onset_effect(t0: float, tf: float, width: float, *, from_rest: bool = False) -> Effect:
    """A thrust misalignment that appears at an estimated time inside the flight.

    ``alpha_thrust = alpha + delta_thrust s(t)``, ``s`` the switch :func:`onset_step` at
    ``t0 + t_misalign`` (``t_misalign``, s after the start, bounded to ``[-3 width, tf - t0]``: at 0 or
    below the misalignment acts from the start, the catalogue's constant shape). From rest it is also
    phased in by the lift-off fade. The refits start where its scan (:class:`OnsetScan`) puts them.

    Parameters
    ----------
    t0, tf : float
        The flight's horizon, s.
    width : float
        Time over which the misalignment switches on, s (at least the length of a collocation
        element, so that the mesh resolves it).
    from_rest : bool
        The vehicle starts at zero speed.
    """
    w = float(width)

    def edit(m: Model, delta, t_on) -> None:
        sym, at = _role_definition(m, "thrust_direction", "misalignment_onset")
        switch = onset_step(m.t - m.t0, t_on, w)
        if from_rest:
            switch = switch * liftoff_fade(m.t - m.t0)
        m.redefine(sym, at + delta * switch)

    return _event_shape("misalignment_onset", "t_misalign", "thrust misalignment from an estimated onset time", "propulsion", edit,
                        ("delta_thrust", math.radians(0.25), (-math.inf, math.inf)), t0, tf, w,
                        f"thrust direction alpha_thrust = alpha + delta_thrust (1 + tanh((t - t0 - t_misalign) / {w:.3g} s)) "
                        "/ 2: a misalignment that appears t_misalign s after the start (a gimbal or nozzle bias after an "
                        "event)" + (", phased in by the lift-off fade f_lo(t)" if from_rest else ""))


def mass_jettison_effect(t0: float, tf: float, width: float) -> Effect:
    """A mass released at an estimated time inside the flight (a fairing, an adapter, ballast, propellant
    dumped): ``m(t) - dm_jettison s(t)``, ``s`` the switch :func:`onset_step` at ``t0 + t_jettison``.

    ``dm_jettison`` >= 0 is the mass lost (realistic size 1 % of the start mass; a vehicle does not gain mass
    in flight, and a mass gained would act like a throttle-down); ``t_jettison``, s after the
    start, is bounded to ``[-3 width, tf - t0]`` (at 0 or below, a lighter vehicle from the start, the
    ``start_mass`` shape). The refits start where its scan (:class:`OnsetScan`) puts them.
    """
    w = float(width)

    def edit(m: Model, dm, t_on) -> None:
        sym, mass = _role_definition(m, "mass", "mass_jettison")
        m.redefine(sym, mass - dm * onset_step(m.t - m.t0, t_on, w))

    return _event_shape("mass_jettison", "t_jettison", "mass released at an estimated time", "mass", edit,
                        ("dm_jettison", 200.0, (0.0, math.inf)), t0, tf, w,
                        f"mass m(t) - dm_jettison (1 + tanh((t - t0 - t_jettison) / {w:.3g} s)) / 2, kg: a mass released "
                        "t_jettison s after the start (a fairing, an adapter, ballast)",
                        relative=lambda veh: {"dm_jettison": 0.01 * veh.mass})


def _throttle_edit(name: str, size_name: str, w: float) -> Callable:
    """``edit(m, d, t_on[, t_off])``: thrust and mass flow scaled by ``1 - d s(t)``, ``s`` the switch
    :func:`onset_step` at ``t_on`` (minus the switch at ``t_off`` for a window); the mass follows
    (:func:`_throttled_mass`: in closed form, the integral of ``s`` with log cosh, for a constant mass flow;
    as a state otherwise)."""

    def integral(tau, t_on):
        return (tau + w * (sp.log(sp.cosh((tau - t_on) / w)) - sp.log(sp.cosh(t_on / w)))) / 2

    def edit(m: Model, d, t_on, t_off=None, *, screen: bool = False) -> None:
        t_sym, thrust = _role_definition(m, "thrust", name)
        tau = m.t - m.t0
        switch, S = onset_step(tau, t_on, w), integral(tau, t_on)
        if t_off is not None:
            switch, S = switch - onset_step(tau, t_off, w), S - integral(tau, t_off)
        m.redefine(t_sym, thrust * (1 - d * switch))
        _throttled_mass(m, name, size_name, d * switch, d * S, f"{d}_unburnt", screen=screen)

    edit.screens = True
    return edit


def _throttled_mass(m: Model, effect: str, size_prefix: str, reduction: sp.Expr, integral: sp.Expr | None,
                    state_name: str, *, screen: bool = False) -> None:
    """The mass when the mass flow is scaled by ``1 - reduction(t)`` with the thrust. A mass that is a state
    (burnt at a thrust table's rate) has its equation ``dm/dt = f`` replaced by ``f (1 - reduction)``. A mass
    written in time: ``m(t) + int mdot reduction dt`` from the start, ``mdot = -dm/dt`` of the base model --
    in closed form ``m + mdot integral`` when ``mdot`` is constant (``integral``: the integral of
    ``reduction`` from ``t0``); otherwise (a commanded throttle schedule's mass) the propellant not burnt
    is a new state ``state_name`` from 0. ``size_prefix``: the parameters of earlier copies of the change (a
    scan's), which vanish in the base flow. ``screen``: for an onset scan's bank (many copies at once, scored
    at zero size), ``m + mdot(t) integral`` also when the flow varies -- its rate is off by ``mdot'
    integral``, small where the flow varies slowly, and the scan only places the refits' starts; a state
    per copy would make the bank's model many times larger. The refits use the state."""
    m_sym, mass = _role_definition(m, "mass", effect)
    mass_x = _expanded(m, mass)
    held = mass_x.free_symbols & {s.symbol for s in m._states}
    if held:
        # a mass state: its own equation takes the factor (as the thrust does), no new state
        for st in held:
            m.ode({st: _explicit_rhs(m, st, effect) * (1 - reduction)})
        return
    mdot = -sp.diff(mass_x, m.t)
    mdot = mdot.xreplace({q: 0 for q in mdot.free_symbols if str(q).startswith(size_prefix)})
    constant = not (mdot.free_symbols - {c for c, _ in m._constants} - {p.symbol for p in m._parameters})
    if integral is not None and (constant or screen):
        m.redefine(m_sym, mass + mdot * integral)
        return
    unburnt = m.state(state_name, 0.0)
    m.ode({unburnt: mdot * reduction})
    m.redefine(m_sym, mass + unburnt)


def _throttle_width(t0: float, tf: float, width: float) -> float:
    """The switch width of a throttle shape: ``width``, at least 1/300 of the horizon (``|t - t_on| / w``
    stays far below cosh's overflow)."""
    return max(float(width), max(1e-9, float(tf) - float(t0)) / 300.0)


def throttle_step_effect(t0: float, tf: float, width: float) -> Effect:
    """A throttle change at an estimated time: thrust **and** mass flow scaled by ``1 - d s(t)`` from then on.

    ``s`` is the switch :func:`onset_step` at ``t0 + t_step`` (``t_step``, s after the start, bounded to
    ``[-3 width, tf - t0]``): an early tail-off of a solid motor's last sliver, a throttle-down that lasts
    to the end of the data, an engine running at another setting from an event on. Thrust becomes
    ``P (1 - d s)`` and mass ``m + mdot d S``, ``S(t) = (tau + w (L((tau - t_step)/w) - L(t_step/w))) / 2``
    the integral of ``s`` from t0 (``tau = t - t0``, ``L = log cosh``), ``mdot = -dm/dt`` of the base model
    when it is constant (a commanded schedule's or a mass state's flow: the propellant not burnt carried as
    a state, :func:`_throttled_mass`). ``d_step`` > 0 is a throttle-down (realistic 0.05, bounded to (-1, 1)). The
    refits start where its scan (:class:`OnsetScan`) puts them.
    """
    w = _throttle_width(t0, tf, width)
    return _event_shape("throttle_step", "t_step", "throttle change at an estimated time", "propulsion",
                        _throttle_edit("throttle_step", "d_step", w), ("d_step", 0.05, (-1.0, 1.0)), t0, tf, w,
                        f"thrust and mass flow scaled by 1 - d_step (1 + tanh((t - t0 - t_step) / {w:.3g} s)) / 2 (a "
                        "tail-off or a throttle-down from an event on); mass m + mdot d_step integral of the switch")


def throttle_window_effect(t0: float, tf: float, width: float) -> Effect:
    """A throttle window with estimated times: thrust **and** mass flow scaled by ``1 - d (s_on - s_off)``.

    ``s_on``, ``s_off`` are the switches :func:`onset_step` at ``t0 + t_win_on`` and ``t0 + t_win_off``
    (s after the start, each bounded to ``[-3 width, tf - t0]``): a throttle bucket through max-q, an
    engine held at another setting for a while. ``d_window`` > 0 is a throttle-down (realistic 0.1,
    bounded to (-1, 1)); the mass follows in closed form as for :func:`throttle_step_effect`, whose
    constant mass flow it needs too. The objective is sharply multimodal in the two times, so the refits
    start at the best local maxima of the window's score over **pairs** of the scan's onset times (a copy
    at ``t_win_on`` minus a copy at ``t_win_off``; :class:`OnsetScan`, one sensitivity solve).
    """
    w = _throttle_width(t0, tf, width)
    window = _event_shape("throttle_window", "t_win_on", "throttle window with estimated times", "propulsion",
                          _throttle_edit("throttle_window", "d_window", w), ("d_window", 0.1, (-1.0, 1.0)), t0, tf, w,
                          f"thrust and mass flow scaled by 1 - d_window (s(t - t0 - t_win_on) - s(t - t0 - t_win_off)), "
                          f"s(u) = (1 + tanh(u / {w:.3g} s)) / 2 (a throttle bucket); mass m + mdot d_window integral "
                          "of the window", end_name="t_win_off")
    # the window's scan is the step's: the same bank of steps, scored in pairs (one build, one solve for both)
    step = throttle_step_effect(t0, tf, width)
    return replace(window, scan=replace(window.scan, bank=step.scan.bank))


def _onset_width(vehicle: "Vehicle") -> float:
    """Time over which an onset effect switches on: one element of the fit's mesh, at least 1 s."""
    return max(1.0, float(np.median(np.diff(np.asarray(vehicle.knot_times, float)))))


def _moving(vehicle: "Vehicle | None") -> bool:
    return vehicle is not None and math.isfinite(vehicle.start_speed) and vehicle.start_speed > 0


def _refine_start_mass(vehicle: "Vehicle | None") -> list[Effect]:
    """On a rail exit (:attr:`Vehicle.rail_exit`), the mass with the exit's speed and time
    (:func:`start_mass_exit_effect`);
    a mass change at an estimated time (:func:`mass_jettison_effect`) on a vehicle with a mesh."""
    out = [start_mass_exit_effect(vehicle)] if vehicle is not None and vehicle.rail_exit else []
    if vehicle is not None and len(vehicle.knot_times) >= 2:
        out.append(mass_jettison_effect(vehicle.knot_times[0], vehicle.knot_times[-1], _onset_width(vehicle)))
    return out


def _refine_misalignment(vehicle: "Vehicle | None") -> list[Effect]:
    """From rest the misalignment is phased in at lift-off, and its fade time is estimated; on every vehicle
    it may also appear at an estimated time inside the flight (:func:`misalignment_onset_effect`); on a vehicle
    with motors (:attr:`Vehicle.motors`) one motor's thrust, or every other, may be the one turned
    (:func:`motor_misalignment_effect`)."""
    moving = _moving(vehicle)
    out = [] if moving else [
        Effect("misalignment_fade", "thrust misalignment, fade time estimated", "propulsion", _misalignment_fade,
               "thrust direction alpha_thrust = alpha + delta_thrust t^4 / (t^4 + (t_r exp(s_fade))^4), "
               f"t_r = {LIFTOFF_FADE_TIME:g} s: the time the launcher holds the path vertical, estimated",
               {"delta_thrust": math.radians(0.25), "s_fade": 1.0})]
    if vehicle is not None and len(vehicle.knot_times) >= 2:
        out.append(misalignment_onset_effect(vehicle.knot_times[0], vehicle.knot_times[-1], _onset_width(vehicle),
                                             from_rest=not moving))
    motors = vehicle.motors if vehicle is not None else ()
    return out + [motor_misalignment_effect(mo, other=o) for mo in motors for o in (False, True)]


_CHANNEL_ROLE = {"x": "downrange", "h": "altitude", "v": "speed"}


def _bias(channel: str) -> Callable[[Model], tuple]:
    def apply(m: Model) -> tuple:
        name, expr = _output_of(m, _CHANNEL_ROLE[channel], channel, f"bias_{channel}")
        b = m.parameter(f"b_{channel}", 0.0, nominal=1.0)
        m.redefine_output(name, m.output_expression(name) + b)
        return (b,)
    apply.__name__ = f"_bias_{channel}"
    return apply


def _bias_drift(channel: str) -> Callable[[Model], tuple]:
    def apply(m: Model) -> tuple:
        name, expr = _output_of(m, _CHANNEL_ROLE[channel], channel, f"bias_{channel}_drift")
        b = m.parameter(f"b_{channel}", 0.0, nominal=1.0)
        d = m.parameter(f"db_{channel}", 0.0, nominal=0.1)
        m.redefine_output(name, m.output_expression(name) + b + d * (m.t - m.t0))
        return (b, d)
    apply.__name__ = f"_bias_{channel}_drift"
    return apply


def _refine_bias(channel: str, unit: str, floor: float, sigmas: float) -> Callable:
    """A sensor bias that drifts linearly in time: ``z = y + b + db (t - t0)`` (realistic drift: the
    realistic bias over the flight's duration)."""
    def refine(vehicle: "Vehicle | None") -> list[Effect]:
        size = floor if vehicle is None else max(floor, sigmas * float(vehicle.sigma.get(channel, 0.0)))
        dur = vehicle.duration if vehicle is not None and math.isfinite(vehicle.duration) and vehicle.duration > 0 else 66.0
        return [Effect(f"bias_{channel}_drift", f"{_CHANNEL_ROLE[channel]} sensor bias drifting in time", "sensor",
                       _bias_drift(channel), f"z_{channel} = {channel} + b_{channel} + db_{channel} (t - t0), {unit}",
                       {f"b_{channel}": size, f"db_{channel}": size / dur})]
    return refine


def _scale(channel: str) -> Callable[[Model], tuple]:
    def apply(m: Model) -> tuple:
        name, expr = _output_of(m, _CHANNEL_ROLE[channel], channel, f"scale_{channel}")
        k = m.parameter(f"k_{channel}", 0.0, nominal=1e-3)
        m.redefine_output(name, (1 + k) * m.output_expression(name))
        return (k,)
    apply.__name__ = f"_scale_{channel}"
    return apply


def _time_offset(m: Model) -> tuple:
    return _time_offset_edit(m, "time_offset", second=False)


def sensor_lag_effect(channel: str) -> Effect:
    """The latency of one measured channel: ``z_c(t) = y_c(t - tau_c) ~ y_c - tau_c dy_c/dt``, the other
    channels on time (``time_offset`` moves every channel).

    A sensor's own delay or smoothing: a GPS receiver's velocity filter, a pitot-static system's pneumatic
    lag, a barometric altimeter's. A first-order lag of time constant ``T`` reads, to first order in ``T``, as
    a latency ``T``. Not in the catalogue's screen (three more candidates for every data set); pass it as a
    candidate when the verdict locates the misfit in one channel (``diagnose(candidates=[*CATALOGUE.values(),
    sensor_lag_effect("v")])``, or a model file's ``candidates()`` on the command line).

    Parameters
    ----------
    channel : {"x", "h", "v"}
        The output that reads the downrange, altitude or speed state (found by its role).

    Returns
    -------
    Effect
        ``sensor_lag_<channel>``, parameter ``tau_<channel>`` (s; realistic size the larger of 0.05 s and one
        sample interval).
    """
    if channel not in _CHANNEL_ROLE:
        raise ModelError(f"sensor_lag_effect: channel must be one of {', '.join(_CHANNEL_ROLE)}, got {channel!r}")
    name = f"sensor_lag_{channel}"

    def apply(m: Model) -> tuple:
        out, _ = _output_of(m, _CHANNEL_ROLE[channel], channel, name)
        tau = m.parameter(f"tau_{channel}", 0.0, nominal=0.05)
        return _time_offset_edit(m, name, second=False, tau=tau, outputs=(out,), compose=True)

    return Effect(name, f"latency of channel {channel}", "sensor", apply,
                  f"output {channel} only: z(t) = y(t - tau_{channel}) ~ y - tau_{channel} dy/dt, tau in s",
                  {f"tau_{channel}": 0.05},
                  relative=lambda veh: {f"tau_{channel}": max(0.05, float(veh.sample_interval))})


def _time_offset_second(m: Model) -> tuple:
    return _time_offset_edit(m, "time_offset_2", second=True)


def _second_derivative(m: Model, expr: sp.Expr, effect: str) -> sp.Expr:
    """``d2 expr / dt2`` along the model's equations, in closed form: every state's rate from its equation
    (solved for it: the equation must be linear in the rate), every known input through its own derivative
    (a sampled input's slope: its table function of time, :mod:`rocketid.tables`). The result holds time,
    the states and scalar parameters only (what an output may hold). Raises ModelError for an equation that
    is not linear in its rate or a rate that holds a time family."""
    rates = {}
    for st in m._states:
        # the rate from the equation, which is linear in it (an explicit ODE, or the flight-path angle's
        # v dtheta/dt = ... form, singular only at rest)
        eq = m._equations[st.symbol]
        a = sp.diff(eq, st.derivative)
        if a == 0 or st.derivative in a.free_symbols:
            raise ModelError(f"effect {effect!r} needs the rate of state {st.symbol} of model {m.name!r} from its "
                             f"equation, which is not linear in d{st.symbol}/dt: {eq} = 0")
        rates[st.symbol] = _expanded(m, -eq.xreplace({st.derivative: 0}) / a)
    fams = {f.symbol for f in m._families}
    if any(r.free_symbols & fams for r in rates.values()):
        raise ModelError(f"effect {effect!r} writes the outputs' second derivative from the equations, and model "
                         f"{m.name!r}'s equations hold a time family (a coefficient in time), which an output cannot")
    inputs = {u.symbol: (u.expr, sp.diff(u.expr, m.t)) if u.expr is not None else
              (_input_table(u)(m.t), _input_table(u).slope(m.t)) for u in m._inputs}

    def ddt(e: sp.Expr) -> sp.Expr:
        out = sp.diff(e, m.t)
        for s in e.free_symbols:
            if s in rates:
                out += sp.diff(e, s) * rates[s]
            elif s in inputs:
                out += sp.diff(e, s) * inputs[s][1]
        return out

    second = ddt(ddt(_expanded(m, expr)))
    return second.xreplace({u: value for u, (value, _) in inputs.items()})


def _time_offset_edit(m: Model, effect: str, *, second: bool, tau: sp.Symbol | None = None,
                      outputs: Sequence[str] | None = None, compose: bool = False) -> tuple:
    """``z(t) = y(t - tau)``: to first order ``y - tau dy/dt`` (``dy/dt`` through the state derivatives, the
    collocation polynomial's), with ``second`` also ``+ tau^2/2 d2y/dt2`` (:func:`_second_derivative`).
    ``tau`` an existing parameter (a start delay's), else one named ``tau`` is declared; ``outputs`` the
    outputs delayed (default: every one). ``compose``: an output already delayed to first order
    (``y - tau0 dy/dt``) is delayed further, ``- tau dy/dt`` with the same ``dy/dt`` (the two delays add, to
    first order); otherwise such an output is refused."""
    if not m.output_names:
        raise ModelError(f"effect {effect!r} needs measured outputs; model {m.name!r} has none yet")
    names = tuple(m.output_names if outputs is None else outputs)
    states = {}
    for name in names:
        for s in m.output_expression(name).free_symbols:
            if m.has(str(s)):
                try:
                    states[s] = m.der(s)
                except ModelError:
                    pass
    derivs = set(states.values())
    exprs, bases = {}, {}
    for name in names:
        expr = m.output_expression(name)
        if expr.free_symbols & derivs and not compose:
            raise ModelError(f"effect {effect!r} cannot apply: a time offset is already present in model {m.name!r}, "
                             f"or output {name!r} uses a state derivative already: z(t) = y(t - tau) ~ y - tau dy/dt "
                             "needs outputs that are functions of the states")
        exprs[name], bases[name] = expr, expr.xreplace({d: 0 for d in derivs})
    curvature = {name: _second_derivative(m, expr, effect) for name, expr in bases.items()} if second else {}
    tau = m.parameter("tau", 0.0, nominal=0.01) if tau is None else tau
    for name, expr in exprs.items():
        base = bases[name]
        dydt = sp.diff(base, m.t) + sum((sp.diff(base, s) * d for s, d in states.items()), sp.S.Zero)
        m.redefine_output(name, expr - tau * dydt + (tau ** 2 / 2 * curvature[name] if second else 0))
    return (tau,)


WIND_MOST = 120.0
"""The largest horizontal wind physics allows at any knot, m/s (:attr:`Effect.most`): the strongest jet-stream
cores measured are about 110-120 m/s (400-430 km/h at 9-12 km). Five realistic sizes of a knot (150 m/s) lie
beyond them: on Auk-B with its boosters dropped 1.5 s late beside a 35 m/s jet, a 10-knot wind with one knot at
-147 +- 3.4 m/s near 11 km, beside an 18-knot drag correction, reached the noise and was called explained -- the
spike carrying the separation's lost impulse. (In the earlier studies' records on disk the wind explanations'
largest knots were 15-58 m/s, besides this one and an early Petrel-V record with 107-108 m/s at the ground for a
4 m/s surface wind.)"""

WIND_CENTRES_KM = (3.0, 8.0, 13.0, 18.0)
WIND_WIDTH_KM = 2.5
SURFACE_LAYER_M = 500.0
WIND_SHEAR = 0.02
"""Realistic vertical shear of a horizontal wind, 1/s (20 m/s per km): a strong shear at the 1 km scale.
The design envelopes of launch ranges put the 99th percentile of 1 km shears near 0.03-0.05 1/s in the jet
stream; the implausibility line, :data:`~rocketid.diagnostics.accept.SIZE_FACTOR` times this (0.1 1/s, a
wind change of 100 m/s across one kilometre), lies well beyond any of them."""
WIND_SHEAR_FLOOR = 2.0
"""Realistic wind change between knots closer than 100 m, m/s (gusts; the profiles' knots are at least
100 m apart, so this only keeps a stated size for a user's finer profile)."""
WIND_SPEED_EPS = 0.1


def _air_relative(m: Model, name: str, wind: Callable, air_mach: bool = True, air_alpha: bool = True) -> tuple:
    """Apply a horizontal wind ``W`` to ``m`` (air-relative velocity, forces, Mach, attack angle; see
    :func:`wind_effect`). ``wind(m, h, v, theta) -> (W, parameters)`` builds the wind profile."""
    h = _role_state(m, "altitude", name)
    v = _role_state(m, "speed", name)
    th = _role_state(m, "flight_path_angle", name)
    rho = _role(m, "density", name)
    qbar, qdef = _role_definition(m, "dynamic_pressure", name)
    mach, mdef = _role_definition(m, "mach", name)
    dsym, drag = _role_definition(m, "drag", name)
    lsym, lift = _role_definition(m, "lift", name)
    clsym, cl = _role_definition(m, "lift_coefficient", name)
    for what, expr in (("drag", drag), ("lift", lift)):
        if sp.diff(expr, qbar, 2) != 0 or expr.xreplace({qbar: 0}) != 0:
            raise ModelError(f"effect {name!r} needs {what} proportional to the dynamic pressure {qbar}; model "
                             f"{m.name!r} has {what} = {expr}")
    alpha = m.role("attack_angle")
    if air_alpha and alpha is None:
        raise ModelError(missing_role_message(m.name, "attack_angle", f"effect {name!r} (the lift coefficient at "
                                              "the air-relative attack angle)"))
    # a vehicle declared without lift flies at its attack angle to the air: in a wind its body, and the thrust
    # along it, turn into the airflow (a fin-stabilized rocket weathercocks); one with lift holds its attitude
    no_lift = _expanded(m, cl)
    weathercock = no_lift == 0 or no_lift.is_zero is True
    W, params = wind(m, h, v, th)
    # air-relative velocity (u, w) = (v cos theta - W, v sin theta); its norm V_a written so that
    # W = 0 gives V_a = v exactly and derivatives exist at v = 0:
    # V_a = v + Q / (v + sqrt(v^2 + Q + eps^2)), Q = V_a^2 - v^2 = W (W - 2 v cos theta)
    Q = W * (W - 2 * v * sp.cos(th))
    Va = m.define(f"{name}_airspeed", v + Q / (v + sp.sqrt(v ** 2 + Q + WIND_SPEED_EPS ** 2)))
    along = v - W * sp.cos(th)      # V_a cos(Delta): air-relative velocity along the flight path
    across = W * sp.sin(th)         # V_a sin(Delta)
    m.redefine(qbar, qdef.xreplace({v: Va}))
    if air_mach:
        m.redefine(mach, mdef.xreplace({v: Va}))
    delta = sp.atan2(across, along)      # Delta = theta_air - theta, the airflow's angle to the flight path
    if weathercock:
        tsym, tdir = _role_definition(m, "thrust_direction", name)
        m.redefine(tsym, tdir + delta)
    elif air_alpha:
        # alpha_air = alpha + (theta - theta_air) = alpha - Delta
        new_cl = cl.xreplace({alpha: alpha - delta})
        if new_cl == cl and not isinstance(alpha, sp.Symbol):
            new_cl = cl.subs(alpha, alpha - delta)
        if new_cl == cl and _expanded(m, alpha).free_symbols & _expanded(m, cl).free_symbols:
            raise ModelError(f"effect {name!r}: the lift coefficient {cl} of model {m.name!r} does not contain "
                             f"its attack angle {alpha} (role 'attack_angle') as such, so the air-relative "
                             "attack angle cannot replace it; write the lift coefficient with that expression, or "
                             "declare the role as the expression it uses")
        m.redefine(clsym, new_cl)
    # forces along the air-relative velocity (drag) and normal to it (lift), projected on the
    # flight path (drag) and its normal (lift):
    # per unit (rho/2 V_a) the tangential force is -(cd along + cl across) S, the normal (cl along - cd across) S
    half = rho * Va / 2
    m.redefine(dsym, drag.xreplace({qbar: half * along}) + lift.xreplace({qbar: half * across}))
    m.redefine(lsym, lift.xreplace({qbar: half * along}) - drag.xreplace({qbar: half * across}))
    return params


def wind_effect(centres_km: Sequence[float] = WIND_CENTRES_KM, width_km: float = WIND_WIDTH_KM, *,
                name: str = "wind", prefix: str = "wind_", realistic_speed: float = 30.0,
                air_mach: bool = True, air_alpha: bool = True, surface: bool = False) -> Effect:
    """A horizontal wind profile ``W(h) = w_0 + tanh(h / 500 m) sum_j w_j exp(-((h - c_j)/s)^2 / 2)``.

    Parameters
    ----------
    centres_km : sequence of float
        Centres ``c_j`` of the altitude basis functions, km (at least 3 for the catalogue).
    width_km : float
        Their standard width ``s``, km.
    name, prefix : str
        Effect name, and parameter names ``<prefix>1 ..`` (``<prefix>0`` the surface wind).
    realistic_speed : float
        Realistic magnitude of each coefficient, m/s.
    air_mach, air_alpha : bool
        Use the airspeed in the Mach number, and the air-relative attack angle
        ``alpha + (theta - theta_air)`` in the lift coefficient (both physical;
        switch off only to study their share).
    surface : bool
        Add a surface wind ``w_0`` (constant in altitude; without it the wind
        vanishes at the pad through the surface layer).

    Notes
    -----
    The altitude-varying part is carried as the state ``<name>_speed`` with
    ``dW/dt = W'(h) v sin(theta)`` from 0: the launch is at ``h = 0``, where the surface
    layer makes it vanish. The lift uses the air-relative attack angle: the model's
    attack angle (role ``attack_angle``, a symbol or an expression) is replaced in the
    lift coefficient; a model whose lift coefficient does not contain it is refused,
    with the reason, rather than silently keeping the ground-relative angle.

    A model whose lift coefficient is zero (a vehicle declared without lift) flies at its attack
    angle to the air: in a wind its body, and the thrust along it, turn into the airflow
    (the thrust direction, role ``thrust_direction``, gains ``Delta = theta_air - theta``;
    a fin-stabilized rocket weathercocks), and its lift stays zero. A model with lift holds its
    attitude: the thrust as declared, the lift at the air-relative attack angle.
    """
    centres = tuple(float(c) * 1000.0 for c in centres_km)
    width = float(width_km) * 1000.0
    names = tuple(f"{prefix}{j + 1}" for j in range(len(centres)))

    def build(m: Model, h, v, th) -> tuple:
        ws = tuple(m.parameter(n, 0.0, nominal=realistic_speed) for n in names)
        w0 = m.parameter(f"{prefix}0", 0.0, nominal=realistic_speed / 3) if surface else sp.S.Zero
        profile = sp.tanh(h / SURFACE_LAYER_M) * sum((w * _gauss(h, c, width) for w, c in zip(ws, centres)), sp.S.Zero)
        # the altitude-varying part is carried as a state, dW/dt = W'(h) dh/dt, from 0 (the surface layer
        # vanishes at the pad): the same profile along the trajectory, with far smaller derivative
        # expressions than W(h) inlined into every force term (code generation ~20 s instead of ~130 s)
        Wv = m.state(f"{name}_speed", 0.0)
        m.ode({Wv: sp.diff(profile, h) * v * sp.sin(th)})
        W = Wv + w0
        return W, ws + ((w0,) if surface else ())

    def apply(m: Model) -> tuple:
        return _air_relative(m, name, build, air_mach, air_alpha)

    desc = (f"horizontal wind W(h) = {'w_0 + ' if surface else ''}tanh(h/{SURFACE_LAYER_M:g} m) sum_j {prefix}j "
            f"exp(-((h - c_j)/{width_km:g} km)^2/2), c_j = {', '.join(f'{c:g}' for c in centres_km)} km (positive "
            "downrange). Air-relative velocity (v cos theta - W, v sin theta); qbar and Mach from the air-relative "
            "speed V_a; drag along the air-relative velocity, lift normal to it; alpha_air = alpha + (theta - "
            "theta_air) in the lift coefficient.")
    realistic = {n: realistic_speed for n in names}
    if surface:
        realistic[f"{prefix}0"] = realistic_speed / 3
    return Effect(name, "horizontal wind profile" + (" with a surface wind" if surface else ""), "environment",
                  apply, desc, realistic, most={n: WIND_MOST for n in realistic})


def piecewise_linear(x: sp.Expr, knots: Sequence[float], values: Sequence) -> sp.Expr:
    """Exact piecewise-linear interpolation of ``values`` at ``knots`` in ``x``, flat beyond the ends.

    Written with ramps ``max(x - k_j, 0)`` (as :meth:`~rocketid.model.Model.table` does): cheap to
    differentiate, and a value of 0 at a knot pins the function there.
    """
    kn = [float(k) for k in knots]
    if len(kn) < 2 or any(b <= a for a, b in zip(kn, kn[1:])):
        raise ModelError(f"piecewise-linear knots must be strictly increasing, at least two; got {kn}")
    vals = [sp.sympify(v) for v in values]
    slopes = [(vals[j + 1] - vals[j]) / (kn[j + 1] - kn[j]) for j in range(len(kn) - 1)]
    expr, prev = vals[0], sp.S.Zero
    for j in range(len(kn) - 1):
        expr += (slopes[j] - prev) * sp.Max(x - kn[j], 0)
        prev = slopes[j]
    return expr - prev * sp.Max(x - kn[-1], 0)


def wind_profile_effect(knots_km: Sequence[float], *, name: str | None = None, prefix: str = "W_",
                        realistic_speed: float = 30.0, surface: bool = True) -> Effect:
    """A horizontal wind piecewise linear in altitude: ``W(h)`` through ``W_j`` at ``knots_km``.

    Parameters
    ----------
    knots_km : sequence of float
        Knot altitudes, km, increasing; the first is where the flight starts: the ground (0), where
        ``W_0`` is the surface wind, or the start altitude of a flight that starts aloft (an air launch,
        a window cut in flight), where ``W_0`` is the wind met there. ``W`` is held constant below the
        first knot and above the last.
    name : str, optional
        Default ``wind_pl_<number of knots>``.
    prefix : str
        Parameter names ``<prefix>0`` (surface) ... ``<prefix>n``.
    realistic_speed : float
        Realistic magnitude of each knot value, m/s (a third of it for the surface wind).
    surface : bool
        Estimate the surface wind ``W_0``; without it the wind is 0 at the first knot.

    Notes
    -----
    The wind acts as :func:`wind_effect`'s does (air-relative velocity, drag along it, lift normal
    to it, the air-relative attack angle in the lift coefficient, Mach and dynamic pressure from
    the airspeed). Hat functions do not overlap beyond their neighbours, so the knot values are far
    better conditioned than overlapping Gaussians of width equal to their spacing, which can reach
    the noise with alternating +-500 m/s coefficients traded against the lift slope.
    """
    knots = tuple(float(k) for k in knots_km)
    if len(knots) < 2 or any(b <= a for a, b in zip(knots, knots[1:])):
        raise ModelError(f"wind knots must be increasing altitudes in km, at least two; got {list(knots)}")
    name = name or f"wind_pl_{len(knots)}"
    first = 0 if surface else 1
    names = tuple(f"{prefix}{j}" for j in range(first, len(knots)))

    def build(m: Model, h, v, th) -> tuple:
        ws = tuple(m.parameter(n, 0.0, nominal=realistic_speed) for n in names)
        vals = ((ws[0],) if surface else (sp.S.Zero,)) + (ws[1:] if surface else ws)
        profile = piecewise_linear(h, [1000.0 * k for k in knots], vals)
        # as wind_effect does: W(h) - W(0) carried as a state, dW/dt = W'(h) dh/dt from 0 at the pad (h = 0),
        # plus the surface value -- far smaller derivative expressions than W(h) inlined in every force term
        Wv = m.state(f"{name}_speed", 0.0)
        m.ode({Wv: sp.diff(profile, h) * v * sp.sin(th)})
        return Wv + vals[0], ws

    def apply(m: Model) -> tuple:
        return _air_relative(m, name, build)

    realistic = {n: realistic_speed for n in names}
    # the wind's change between neighbouring knots: a shear across their altitude difference (a profile that
    # alternates +-100 m/s from knot to knot fits anything and is no wind)
    heights = dict(zip(names, knots[first:]))
    changes = {(a, b): max(WIND_SHEAR_FLOOR, WIND_SHEAR * 1000.0 * (heights[b] - heights[a]))
               for a, b in zip(names, names[1:])}
    aloft = knots[0] * 1000.0 >= SURFACE_LAYER_M
    if surface and not aloft:
        realistic[names[0]] = realistic_speed / 3          # a surface wind; aloft, a wind like the others
    where = "the wind at the start altitude" if aloft else "the surface wind"
    desc = (f"horizontal wind W(h) piecewise linear in altitude through {prefix}j at "
            f"{', '.join(f'{k:g}' for k in knots)} km ({prefix}0 {where}{'' if surface else ', fixed at 0'}; "
            "constant above the last knot), positive downrange; air-relative velocity, drag along it, lift normal "
            "to it, alpha_air in the lift coefficient, qbar and Mach from the airspeed")
    return Effect(name, f"wind piecewise linear in altitude ({len(knots)} knots)", "environment", apply, desc, realistic,
                  changes=changes, most={n: WIND_MOST for n in realistic})


def density_profile_effect(knots_km: Sequence[float], *, name: str | None = None, prefix: str = "rho_",
                           realistic: float = 0.05) -> Effect:
    """A relative density deviation piecewise linear in altitude: ``rho (1 + d(h))``, ``d`` through
    ``<prefix>j`` at ``knots_km`` (constant beyond the ends)."""
    knots = tuple(float(k) for k in knots_km)
    if len(knots) < 2 or any(b <= a for a, b in zip(knots, knots[1:])):
        raise ModelError(f"density knots must be increasing altitudes in km, at least two; got {list(knots)}")
    name = name or f"density_pl_{len(knots)}"
    names = tuple(f"{prefix}{j}" for j in range(len(knots)))

    def apply(m: Model) -> tuple:
        sym, rho = _role_definition(m, "density", name)
        h = _role_state(m, "altitude", name)
        ds = tuple(m.parameter(n, 0.0, nominal=realistic) for n in names)
        m.redefine(sym, rho * (1 + piecewise_linear(h, [1000.0 * k for k in knots], ds)))
        return ds

    desc = (f"air density rho(h) (1 + d(h)), d piecewise linear in altitude through {prefix}j at "
            f"{', '.join(f'{k:g}' for k in knots)} km")
    return Effect(name, f"density deviation piecewise linear in altitude ({len(knots)} knots)", "environment",
                  apply, desc, {n: realistic for n in names})


def drag_mach_effect(knots: Sequence[float], zeros: Sequence[float] = (), *, name: str | None = None,
                     prefix: str = "dCD_M", realistic: float = 0.1) -> Effect:
    """A drag-coefficient correction piecewise linear in Mach: ``cd + c(M)``.

    Parameters
    ----------
    knots : sequence of float
        Mach numbers where the correction has a free value ``<prefix><j>``.
    zeros : sequence of float
        Mach numbers where it is pinned at 0 -- the knots of the model's own CD(Mach) table, so that
        the correction adds shape *between* them (the table on a finer grid) instead of trading
        with the table's values. Beyond the outermost knot the correction is constant.
    """
    free = tuple(sorted(float(k) for k in knots))
    pins = tuple(sorted(float(z) for z in zeros if all(abs(z - k) > 1e-9 for k in free)))
    if not free:
        raise ModelError("a drag correction in Mach needs at least one free knot")
    name = name or f"drag_mach_{len(free)}"
    names = tuple(f"{prefix}{j}" for j in range(len(free)))
    allk = sorted([(k, j) for j, k in enumerate(free)] + [(z, None) for z in pins])

    def apply(m: Model) -> tuple:
        sym, cd = _role_definition(m, "drag_coefficient", name)
        mach = _role(m, "mach", name)
        ps = tuple(m.parameter(n, 0.0, nominal=realistic) for n in names)
        ks = [k for k, _ in allk]
        vals = [sp.S.Zero if j is None else ps[j] for _, j in allk]
        m.redefine(sym, cd + piecewise_linear(mach, ks, vals))
        return ps

    desc = (f"drag coefficient cd + c(M), c piecewise linear in Mach with free values {prefix}j at "
            f"{', '.join(f'{k:g}' for k in free)}" + (f" and 0 at {', '.join(f'{z:g}' for z in pins)} (the model's "
                                                       "table knots)" if pins else ""))
    return Effect(name, f"drag correction in Mach ({len(free)} knots)", "aero", apply, desc,
                  {n: realistic for n in names})


DRAG_BUMP_WIDTH = 0.1
"""The Mach half-width (1/e) of :func:`drag_bump_effect`'s hump in its scan and at its start."""


def drag_bump_effect(mach_lo: float, mach_hi: float, width: float = DRAG_BUMP_WIDTH) -> Effect:
    """A drag hump at an estimated Mach number: ``cd + dCD_bump exp(-((M - M_bump) / (w e^s_bump))^2)``.

    The drag rise of a real vehicle peaks where its shape puts it (a shoulder, a fairing, a shock on a
    protuberance), not at the catalogue's Mach 1.1: ``M_bump`` is estimated in ``[0, mach_hi]`` (the scan
    covers the Mach range flown, ``[mach_lo, mach_hi]``), the width by ``s_bump`` (realistic 1, bounded to
    +-1.5: a half-width of 0.22 to 4.5 times ``width``), the height ``dCD_bump`` >= 0 (realistic 0.1: a hump; a table too high somewhere is
    what the pinned correction :func:`drag_mach_effect` mends -- a free-sign bump with a free place and width
    is a dip anywhere, and imitated Kestrel-S's throttle tail-off at 33 s as a drag dip of 0.083 around Mach
    2.4, BIC 3053.3 against the throttle's 3053.9). It is the aerodynamic counterpart of a
    throttle window -- a force placed in Mach rather than in time -- and a refit is started the same way,
    where its scan over 32 Mach numbers (:class:`OnsetScan`, unit ``"Mach"``) puts it, the Mach number held
    in a first solve.
    """
    lo, hi = float(mach_lo), float(mach_hi)
    if not hi > lo:
        raise ModelError(f"a drag hump needs a Mach range, got [{lo:g}, {hi:g}]")
    w = float(width)

    def bump(m: Model, a, centre, s=0) -> None:
        sym, cd = _role_definition(m, "drag_coefficient", "drag_bump")
        mach = _role(m, "mach", "drag_bump")
        m.redefine(sym, cd + a * sp.exp(-((mach - centre) / (w * sp.exp(s))) ** 2))

    def apply(m: Model) -> tuple:
        a = m.parameter("dCD_bump", 0.0, bounds=(0.0, math.inf), nominal=0.1)
        centre = m.parameter("M_bump", 0.0, bounds=(min(0.0, lo), hi), nominal=1.0)
        s = m.parameter("s_bump", 0.0, bounds=(-1.5, 1.5), nominal=1.0)
        bump(m, a, centre, s)
        return (a, centre, s)

    centres = tuple(lo + (hi - lo) * (k + 0.5) / SCAN_TIMES for k in range(SCAN_TIMES))

    def bank(m: Model) -> tuple:
        sizes = tuple(m.parameter(f"dCD_bump_{k}", 0.0, bounds=(0.0, math.inf), nominal=0.1)
                      for k in range(len(centres)))
        for a, c in zip(sizes, centres):
            bump(m, a, sp.Float(c))
        return sizes

    scan = OnsetScan(Effect("drag_bump_scan", "drag hump (scan)", "aero", bank, "", {}), centres, "dCD_bump",
                     "M_bump", (0.0, math.inf), unit="Mach")
    return Effect("drag_bump", "drag hump at an estimated Mach number", "aero", apply,
                  f"drag coefficient cd + dCD_bump exp(-((M - M_bump) / ({w:g} e^s_bump))^2), dCD_bump >= 0: a drag rise that peaks "
                  f"at an estimated Mach number M_bump in [0, {hi:.3g}]",
                  {"dCD_bump": 0.1, "M_bump": hi, "s_bump": 1.0},
                  starts=tuple({"M_bump": lo + f * (hi - lo)} for f in ONSET_STARTS), scan=scan)


DENSITY_CENTRES_KM = (0.0, 6.0, 12.0, 18.0)
DENSITY_WIDTH_KM = 3.0


def density_effect(centres_km: Sequence[float] = DENSITY_CENTRES_KM, width_km: float = DENSITY_WIDTH_KM, *,
                   name: str = "density", prefix: str = "drho_", realistic: float = 0.05) -> Effect:
    """A density deviation ``rho (1 + sum_j d_j exp(-((h - c_j)/s)^2 / 2))`` (relative, per basis function)."""
    centres = tuple(float(c) * 1000.0 for c in centres_km)
    width = float(width_km) * 1000.0
    names = tuple(f"{prefix}{j + 1}" for j in range(len(centres)))

    def apply(m: Model) -> tuple:
        sym, rho = _role_definition(m, "density", name)
        h = _role_state(m, "altitude", name)
        ds = tuple(m.parameter(n, 0.0, nominal=realistic) for n in names)
        m.redefine(sym, rho * (1 + sum((d * _gauss(h, c, width) for d, c in zip(ds, centres)), sp.S.Zero)))
        return ds

    desc = (f"air density rho(h) (1 + sum_j {prefix}j exp(-((h - c_j)/{width_km:g} km)^2/2)), "
            f"c_j = {', '.join(f'{c:g}' for c in centres_km)} km")
    return Effect(name, "density deviation profile", "environment", apply, desc, {n: realistic for n in names})


TEMPERATURE_REALISTIC_K = 10.0
"""Realistic size of an air-temperature offset, K: a hot or a cold day against the standard atmosphere."""


def temperature_effect(*, name: str = "temperature", realistic: float = TEMPERATURE_REALISTIC_K) -> Effect:
    """The air ``dT_air`` kelvin warmer (or colder) than the standard at every altitude, at the standard's
    sea-level pressure: a hot or a cold day.

    Temperature ``T = T_std(h) + dT_air``; the hydrostatic equation then gives the pressure ratio
    ``p / p_std`` in closed form (:func:`~rocketid.physics.atmosphere.us76_offset_log_pressure_ratio`); the
    density is ``rho (p / p_std) T_std / T`` and the speed of sound ``a sqrt(T / T_std)`` (so the Mach number
    changes too). The model's own density and speed-of-sound
    definitions (roles ``density`` and ``sound_speed``) are scaled, whichever density model they use; a model
    without the ``sound_speed`` role gets the density change alone. ``T_std`` is the 1976 standard's.

    Notes
    -----
    It is a refined shape of the ``density`` family (tried when that family is significant), not a candidate
    of its own: as a candidate its one parameter won on BIC against a density profile it did not explain
    (RA-66M with a 6 % tanh density profile: 6.7 K warm, accepted at the step, then failing the hold-out,
    where the profile had been explained). A density deviation of any shape (:func:`density_effect`) changes
    only the density; a temperature offset lowers the density at low altitude and raises it aloft (warm day)
    while the speed of sound follows the temperature. Both are the same physical family (the atmosphere off the standard) for the diagnosis.
    """
    def apply(m: Model) -> tuple:
        sym, rho = _role_definition(m, "density", name)
        h = _role_state(m, "altitude", name)
        dT = m.parameter("dT_air", 0.0, bounds=(-4.0 * realistic, 4.0 * realistic), nominal=realistic)
        t_std = us76_temperature(h)
        m.redefine(sym, rho * sp.exp(us76_offset_log_pressure_ratio(h, dT)) * t_std / (t_std + dT))
        sound = m.role("sound_speed")
        if isinstance(sound, sp.Symbol) and sound in {d for d, _ in m._definitions}:
            m.redefine(sound, m.definition(sound) * sp.sqrt(1 + dT / t_std))
        return (dT,)

    desc = ("air temperature T_std(h) + dT_air, K, at the standard's sea-level pressure: density rho (p/p_std) "
            "T_std/T with the hydrostatic pressure ratio, speed of sound a sqrt(T/T_std) (Mach changes with it)")
    # started from a warm and a cold day (the density change's sign flips with altitude, so the fit from 0 can
    # settle on the wrong side); with starts it is its own ladder among the density family's refined shapes
    return Effect(name, "air temperature offset (hot or cold day)", "environment", apply, desc,
                  {"dT_air": float(realistic)}, starts=({"dT_air": -float(realistic)}, {"dT_air": float(realistic)}))


def _rotation_terms(m: Model, k: sp.Expr, phi: sp.Expr, az: sp.Expr, name: str) -> None:
    """Add the in-plane Coriolis and centrifugal accelerations of an Earth turning at ``k * EARTH_RATE`` to the
    speed and flight-path equations, for a launch at latitude ``phi`` toward azimuth ``az`` (radians; numbers
    or expressions of the effect's parameters)."""
    h = _role_state(m, "altitude", name)
    v = _role_state(m, "speed", name)
    th = _role_state(m, "flight_path_angle", name)
    om = k * EARTH_RATE
    r = EARTH_RADIUS + h
    cphi, sphi, saz, caz = sp.cos(phi), sp.sin(phi), sp.sin(az), sp.cos(az)
    m.add_term(v, om ** 2 * r * cphi * (sp.sin(th) * cphi - sp.cos(th) * sphi * caz))
    # from rest the Coriolis term is phased in by the lift-off fade (module notes); a vehicle that
    # starts moving takes it from t0 on
    fade = sp.S.One if _initial_value(m, v) > 0 else liftoff_fade(m.t - m.t0)
    normal = (fade * 2 * om * v * cphi * saz
              + om ** 2 * r * cphi * (sp.cos(th) * cphi + sp.sin(th) * sphi * caz))
    # add_term adds to d theta/dt: the model's v-multiplied form gets v * (normal / v) = normal, exactly
    m.add_term(th, normal / v)


def earth_rotation_effect(latitude_deg: float = 28.5, azimuth_deg: float = 90.0, *,
                          name: str = "earth_rotation") -> Effect:
    """Coriolis and centrifugal accelerations in the vertical plane of a launch at
    ``latitude_deg``, flying toward ``azimuth_deg`` (from north; 90 = east).

    With ``Omega = k_rot * EARTH_RATE``, ``r = Re + h``, ``phi`` the latitude and
    ``A`` the azimuth (Vinh's equations, out-of-plane terms dropped)::

        dv/dt       += Omega^2 r cos(phi) (sin(theta) cos(phi) - cos(theta) sin(phi) cos(A))
        v dtheta/dt += f_lo(t) 2 Omega v cos(phi) sin(A)
                       + Omega^2 r cos(phi) (cos(theta) cos(phi) + sin(theta) sin(phi) cos(A))

    ``k_rot`` = 1 is the real Earth; from rest the Coriolis term is phased in by the lift-off fade,
    from a moving start it acts from ``t0``. ``k_rot`` is fixed by physics: an estimate below
    0.2 (another latitude or azimuth changes it by a factor of order one, not by 100) is not
    Earth's rotation (:attr:`Effect.least`), and neither is one beyond ``SITE_RATE[1]`` (1.3) either
    way, its bounds: no site turns the in-plane Coriolis term more than ``1 / cos(latitude)`` times the
    stated site's (1.14 at 28.5 deg; a westward launch flips its sign), so a refit held at a bound is
    implausible (:func:`~rocketid.diagnostics.accept.accept`). (Unbounded, Stage-30's thrust error,
    jet-stream wind and altitude bias at once took ``k_rot`` = -4.18 in the second step of a search that
    never reached the noise.) The catalogue's entry is at 28.5 N toward the east and, for a
    vehicle whose site is not stated, is refined by :func:`earth_rotation_site_effect` (the site estimated).

    Its reading (:attr:`Effect.reading`, :func:`rotation_reading`) says what ``k_rot`` means for the
    launch: Earth's rotation at the stated site when it is 1 within its error, else the azimuths at the
    stated latitude whose in-plane Coriolis term the estimate is -- a negative ``k_rot`` is the term
    reversed, a flight toward the west of north-south when the stated one flies east (an air launch due
    west at 35 N, taken as the catalogue's 28.5 N eastward site, refits ``k_rot`` -0.935: azimuth 249 or
    291 deg at 28.5 N), and the user should state the site and refit.
    """
    phi = math.radians(latitude_deg)
    az = math.radians(azimuth_deg)

    def apply(m: Model) -> tuple:
        k = m.parameter("k_rot", 0.0, bounds=(-SITE_RATE[1], SITE_RATE[1]), nominal=1.0)
        _rotation_terms(m, k, sp.Float(phi), sp.Float(az), name)
        return (k,)

    desc = (f"Earth rotation at latitude {latitude_deg:g} deg, azimuth {azimuth_deg:g} deg: Coriolis "
            "(2 Omega v cos(lat) sin(az) in v dtheta/dt, phased in by the lift-off fade) and centrifugal "
            "(Omega^2 r cos(lat) ...) accelerations, Omega = k_rot * 7.292e-5 rad/s")
    return Effect(name, "Earth rotation", "kinematics", apply, desc, {"k_rot": 1.0}, least={"k_rot": 0.2},
                  reading=lambda est: rotation_reading(est["k_rot"], latitude_deg, azimuth_deg))


#: A rate factor within this of 1 (beyond three standard errors) is read as Earth's rotation at the stated site.
ROTATION_AS_STATED = 0.1


def rotation_reading(k_rot: tuple, latitude_deg: float, azimuth_deg: float) -> str:
    """What an estimate ``k_rot = (value, standard error)`` of :func:`earth_rotation_effect` at a stated
    site says about the launch, in words.

    In the vertical plane the Coriolis term is ``2 Omega v cos(phi) sin(A)``: a rate factor ``k`` at the
    stated latitude ``phi`` is the term of a flight toward ``A`` with ``sin(A) = k sin(A_stated)`` (two
    azimuths, ``A`` and ``180 - A``; the centrifugal terms are some hundred times smaller at launch speeds
    and do not decide it). ``k`` near 1 is the stated site; a negative ``k`` is the term reversed (the flight
    went to the other side of north-south); ``|k sin(A_stated)| > 1`` is more than any azimuth gives there
    (a site nearer the equator, or the terms taking up something else).

    Examples
    --------
    >>> rotation_reading((-0.9355, 0.0088), 28.5, 90.0)[:93]
    'the Coriolis term reversed: the term of a flight toward 249 or 291 deg at the stated latitude'
    """
    k, s = float(k_rot[0]), float(k_rot[1]) if math.isfinite(k_rot[1]) else 0.0
    lat = f"{abs(latitude_deg):g} {'N' if latitude_deg >= 0 else 'S'}"
    if abs(k - 1.0) <= 3.0 * s + ROTATION_AS_STATED:
        return f"Earth's rotation at the stated site ({lat}, toward {azimuth_deg % 360.0:g} deg)"
    state = ("state the launch site (earth_rotation_effect(latitude_deg, azimuth_deg), a candidate of the model "
             "file) and refit")
    coriolis = math.sin(math.radians(azimuth_deg))
    if abs(coriolis) < 0.05:
        return (f"k_rot {k:.3g} times Earth's rate at the stated site ({lat}, toward {azimuth_deg % 360.0:g} deg, "
                f"whose in-plane Coriolis term is nil): not Earth's rotation there; if the site is right, the terms "
                "took up something else")
    sine = k * coriolis
    if abs(sine) > 1.0:
        where = (f"more than any azimuth gives at the stated latitude {lat} (|sin(A)| would be {abs(sine):.2f}): a "
                 "site nearer the equator, or the terms took up something else")
    else:
        a1 = math.degrees(math.asin(sine)) % 360.0
        a2 = (180.0 - a1) % 360.0
        lo, hi = sorted((a1, a2))
        where = (f"the term of a flight toward {lo:.0f} or {hi:.0f} deg at the stated latitude {lat}, not toward the "
                 f"stated {azimuth_deg % 360.0:g} deg (the plane shows only cos(latitude) sin(azimuth))")
    head = ("the Coriolis term reversed" if k < 0 else
            f"the Coriolis term at k_rot {k:.3g} times the stated site's")
    return f"{head}: {where}; {state}"


SITE_REALISTIC = {"k_rot": 1.0, "dlat_rot": 30.0, "daz_rot": 90.0}
"""Realistic sizes of :func:`earth_rotation_site_effect`'s parameters: the rate factor 1, a site some tens of
degrees of latitude and azimuth from the one stated."""


SITE_RATE = (0.7, 1.3)
"""The rate factors :func:`earth_rotation_site_effect` takes for Earth's rotation: below the first it is judged
implausible (:attr:`Effect.least`), the second is its upper bound (a refit held there is rejected). With the
site free to take the geometry, the rate is Earth's own: measured 1.02 +- 0.06 on a sounding rocket from an
independent 3-D truth; the fixed-site entry's ``k_rot`` of 0.5 (a weathercocking headwind, an altimeter scale
error, taken up by the rotation's terms) or -1.4 (a throttle bucket) is not a rotation of the Earth."""


def earth_rotation_site_effect(latitude_deg: float = 28.5, azimuth_deg: float = 90.0, *,
                               name: str = "earth_rotation_site") -> Effect:
    """Earth rotation at a launch site that is estimated: :func:`earth_rotation_effect`'s accelerations at
    latitude ``latitude_deg + dlat_rot`` toward azimuth ``azimuth_deg + daz_rot`` (degrees), with the rate
    factor ``k_rot`` free as well, within :data:`SITE_RATE`.

    In the vertical plane the site enters through three numbers: the Coriolis term's ``cos(phi) sin(A)``
    and the centrifugal terms' ``cos(phi)^2`` and ``cos(phi) sin(phi) cos(A)``. ``k_rot``, ``dlat_rot`` and
    ``daz_rot`` are these three in another form: a fit that reaches the noise with ``k_rot`` near 1 has found
    Earth's rotation and the site's latitude and azimuth; ``k_rot`` far from 1 says the terms took up
    something else. Latitude ``phi`` and azimuth ``A`` give the same accelerations in the plane as
    ``-phi`` and ``180 - A`` (the hemisphere cannot be told from in-plane data; the fit stays on the side
    it starts from, the stated site's).

    It refines the catalogue's ``earth_rotation`` (28.5 N, east): on a sounding rocket launched at 37.84 N
    toward 120 deg (an independent 3-D truth), ``earth_rotation`` fits ``k_rot`` 0.68 and leaves chi2/dof
    1.09, which a wind profile then took up; this shape gives ``k_rot`` 1.02 +- 0.06, latitude 38.5 +- 5 N,
    azimuth 120.5 +- 2.8 deg and chi2/dof 1.028. A vehicle whose site is known states it with
    :func:`earth_rotation_effect` instead (one parameter, ``k_rot``).
    """
    lat0, az0 = float(latitude_deg), float(azimuth_deg)

    def apply(m: Model) -> tuple:
        k = m.parameter("k_rot", 0.0, bounds=(0.0, SITE_RATE[1]), nominal=1.0)
        dlat = m.parameter("dlat_rot", 0.0, bounds=(-90.0 - lat0, 90.0 - lat0), nominal=SITE_REALISTIC["dlat_rot"])
        daz = m.parameter("daz_rot", 0.0, bounds=(-180.0, 180.0), nominal=SITE_REALISTIC["daz_rot"])
        _rotation_terms(m, k, sp.pi * (lat0 + dlat) / 180, sp.pi * (az0 + daz) / 180, name)
        return (k, dlat, daz)

    desc = (f"Earth rotation at an estimated site: latitude {lat0:g} + dlat_rot deg, azimuth {az0:g} + daz_rot deg, "
            "Omega = k_rot * 7.292e-5 rad/s (the accelerations of earth_rotation; the mirror site -lat, "
            "180 - az gives the same in the vertical plane)")

    def reading(est: Mapping[str, tuple]) -> str:
        (dlat, s_lat), (daz, s_az) = est["dlat_rot"], est["daz_rot"]
        lat, az = lat0 + dlat, (az0 + daz) % 360.0
        hemi, mirror = ("N", "S") if lat >= 0 else ("S", "N")
        return (f"the launch site: latitude {abs(lat):.1f} +- {s_lat:.2g} deg {hemi}, azimuth {az:.1f} +- {s_az:.2g} deg "
                f"(or {abs(lat):.1f} deg {mirror} toward {(180.0 - az) % 360.0:.1f} deg: the same in the vertical plane)")

    # started from the real Earth at the stated site (from k_rot = 0 the site angles have no gradient)
    return Effect(name, "Earth rotation, site estimated", "kinematics", apply, desc, dict(SITE_REALISTIC),
                  least={"k_rot": SITE_RATE[0]}, starts=({"k_rot": 1.0},), reading=reading)


def thrust_profile_effect(knot_times: Sequence[float], *, name: str | None = None) -> Effect:
    """A thrust error that varies in time: ``P (1 + eps(t))``, ``eps`` piecewise linear on ``knot_times``.

    The knots should be element boundaries of the fit's mesh (``Vehicle.knot_times``). Knots from the
    model's start to its end make ``eps`` a time family (:meth:`~rocketid.model.Model.piecewise_linear`);
    knots that end before it -- over a burn that stops inside the horizon -- make it flat after the last
    knot, each ``eps_Pj >= -1`` (a thrust error cannot turn the thrust around: measured on Wren-H's burn
    through, a profile over the whole flight took -1.6 to -2.0 after burn-out, a negative thrust standing in
    for drag).
    """
    knots = tuple(float(k) for k in knot_times)
    name = name or f"thrust_profile_{len(knots)}"
    names = tuple(f"eps_P{j}" for j in range(len(knots)))

    def apply(m: Model) -> tuple:
        sym, thrust = _role_definition(m, "thrust", name)
        if abs(knots[0] - float(m.t0)) < 1e-9 and abs(knots[-1] - float(m.tf)) < 1e-9:
            eps = m.piecewise_linear("eps_P", knots, 0.0, nominal=0.02)
            m.redefine(sym, thrust * (1 + eps))
            return tuple(getattr(m, n) for n in names)
        ps = tuple(m.parameter(n, 0.0, bounds=(-1.0, math.inf), nominal=0.02) for n in names)
        m.redefine(sym, thrust * (1 + piecewise_linear(m.t, knots, ps)))
        return ps

    return Effect(name, f"thrust error in time ({len(knots)} knots)", "propulsion", apply,
                  f"thrust P (1 + eps(t)), eps piecewise linear in time on {', '.join(f'{k:g}' for k in knots)} s",
                  {n: 0.02 for n in names})


def throttle_effect(times: Sequence[float], *, name: str = "throttle", open_ends: bool = False) -> Effect:
    """A throttle-down the model lacks: thrust **and** mass flow scaled by ``1 - d(t)``.

    ``d`` is piecewise linear in time through ``times`` (the event times, declared as model events so
    that the default mesh has element boundaries there): zero at the first and last time (the engine
    at its nominal setting outside the window) unless ``open_ends``, and an estimated value
    ``d_throttle_j`` (guess 0: the base model) at every time in between. Thrust becomes
    ``P (1 - d(t))`` and mass ``m(t) + mdot integral d``, with ``mdot = -dm/dt`` of the base model,
    whatever its form (constant: in closed form; a commanded schedule's or a mass state's: the propellant not
    burnt carried as a state). See :func:`rocketid.physics.propulsion.throttle_schedule`.

    Parameters
    ----------
    times : sequence of float
        Event times of the schedule (at least three with closed ends), s.
    name : str
    open_ends : bool
        Estimate the first and last value too (the setting then stays at them beyond the window).
    """
    knots = tuple(float(k) for k in times)
    if len(knots) < (1 if open_ends else 3) or any(b <= a for a, b in zip(knots[:-1], knots[1:])):
        raise ModelError(f"throttle effect {name!r}: give strictly increasing event times, at least "
                         f"{1 if open_ends else 3} (the ends are fixed at the nominal setting)")
    free = range(len(knots)) if open_ends else range(1, len(knots) - 1)
    names = tuple(f"d_{name}_{j}" for j in free)

    def apply(m: Model) -> tuple:
        from ..physics.propulsion import throttle_schedule
        t_sym, thrust = _role_definition(m, "thrust", name)
        params = {j: m.parameter(f"d_{name}_{j}", 0.0, bounds=(-1.0, 1.0), nominal=0.1) for j in free}
        levels = [params.get(j, 0.0) for j in range(len(knots))]
        sched = throttle_schedule(m, knots, levels, name=f"{name}_reduction")
        m.redefine(t_sym, thrust * (1 - sched.setting))
        _throttled_mass(m, name, f"d_{name}_", sched.setting, sched.integral, f"{name}_unburnt")
        return tuple(params.values())

    return Effect(name, f"throttle change ({len(names)} levels)", "propulsion", apply,
                  f"thrust and mass flow scaled by 1 - d(t), d piecewise linear in time through "
                  f"{', '.join(f'{k:g}' for k in knots)} s" + ("" if open_ends else " (0 at the ends)"),
                  {n: 0.2 for n in names})


def _spread(lo: float, hi: float, n: int) -> list[float]:
    return [lo + (hi - lo) * (j + 0.5) / n for j in range(n)]


WIND_KNOT_INTERVALS = (4, 8, 12)
"""Refined wind and density profiles: knot counts tried (intervals holding equal shares of the
aerodynamic action, :func:`_profile_knots_km`), fewest first; the stepwise search keeps the count BIC
prefers."""

DENSITY_KNOT_INTERVALS = (3, 6, 9)


def _profile_knots_km(vehicle: "Vehicle | None", n: int) -> list[float]:
    """``n + 1`` knot altitudes, km, from the lowest altitude flown: at equal shares of the aerodynamic action
    along the flight (:attr:`Vehicle.aero_altitudes`) -- a knot where the air barely acts on the vehicle
    cannot be pinned by the data (measured on Stage-30, flying to 31 km: with knots of equal height the top
    one went to -196 m/s) -- or of equal height up to the highest altitude flown when that is unknown.

    The first knot is the ground (0) for a flight that starts within :data:`SURFACE_LAYER_M` of it, else the
    altitude where the flight starts (an air launch, a window cut in flight): a knot below the flight is not
    seen by the data. (Measured on an air-launched stage starting at 11.8 km: with knots at 0 and 0.5 km the
    wind profile's knot values had a direction of standard error 2e5 m/s -- a common shift of every knot
    above the ground, which the wind carried from the start cancels -- and a cold atmosphere was called
    explained by that wind.)"""
    lev = list(vehicle.aero_altitudes) if vehicle is not None else []
    low = vehicle.altitude[0] if vehicle is not None and math.isfinite(vehicle.altitude[0]) else 0.0
    base = float(lev[0]) if len(lev) == 101 else float(low)
    base = 0.0 if base < SURFACE_LAYER_M else base
    if len(lev) == 101 and lev[-1] > base:
        raw = [base] + [lev[round(100 * k / n)] for k in range(1, n + 1)]
    else:
        top = vehicle.altitude[1] if vehicle is not None and math.isfinite(vehicle.altitude[1]) else 30000.0
        raw = list(np.linspace(base, max(top, base + 2000.0), n + 1))
    knots = [base]
    for z in raw[1:]:
        if z - knots[-1] >= 100.0:
            knots.append(float(z))
    return [k / 1000.0 for k in knots]


def _wind_knots_km(vehicle: "Vehicle | None", n: int) -> list[float]:
    """A wind profile's knots for ``n`` intervals (:func:`_profile_knots_km`), with a knot at the top of the
    surface layer (500 m), where a wind grows from its ground value (measured: RA-66M, launched from rest into a
    wind grown over 300 m, took a spurious misalignment to follow the lift-off when the first knot above the
    ground was at 2.3 km); a flight that starts aloft has none."""
    k = _profile_knots_km(vehicle, n)
    if len(k) > 1 and k[0] == 0.0 and k[1] > 2 * SURFACE_LAYER_M / 1000.0:
        k = [0.0, SURFACE_LAYER_M / 1000.0] + k[1:]
    return k


def _refine_wind(vehicle: "Vehicle | None") -> list[Effect]:
    out = []
    for n in WIND_KNOT_INTERVALS:
        k = _wind_knots_km(vehicle, n)
        if len(k) >= 2 and all(len(k) > len(e.realistic) for e in out):
            out.append(wind_profile_effect(k, name=f"wind_pl_{len(k)}"))
    return out


def _refine_density(vehicle: "Vehicle | None") -> list[Effect]:
    # the temperature offset first: one parameter, the physics of a hot or cold day (a ladder of its own,
    # started from both signs; see temperature_effect), then the profiles on more knots
    out = [temperature_effect()]
    for n in DENSITY_KNOT_INTERVALS:
        k = _profile_knots_km(vehicle, n)
        if len(k) >= 2 and all(len(k) > len(e.realistic) for e in out[1:]):
            out.append(density_profile_effect(k, name=f"density_pl_{len(k)}"))
    return out


def _refine_drag(vehicle: "Vehicle | None") -> list[Effect]:
    """CD(M) on a finer grid: the model's Mach table with its intervals halved, then quartered (a
    correction pinned at 0 on the table's own knots); without a table, interior knots spread over
    the Mach range flown, pinned at 0 at its ends."""
    if vehicle is None or vehicle.mach is None:
        return []
    lo, hi = (float(x) for x in vehicle.mach)
    out = []
    for level in (1, 2):
        free, zeros = _drag_mach_knots(vehicle, 2 ** level)
        if free:
            out.append(drag_mach_effect(free, zeros, name=f"drag_mach_{len(free)}"))
    return out + ([drag_bump_effect(lo, hi)] if hi > lo else [])


def _drag_mach_knots(vehicle: "Vehicle", parts: int) -> tuple[list[float], list[float]]:
    """``(free, zeros)`` of a drag correction in Mach: the model's Mach table's intervals over the Mach range flown
    cut in ``parts`` (the correction pinned at 0 on the table's knots); without a table, the range in four
    intervals so cut, pinned at its ends."""
    lo, hi = (float(x) for x in vehicle.mach)
    table = sorted(float(k) for k in vehicle.mach_knots)
    if len(table) >= 2:
        segs = [(a, b) for a, b in zip(table, table[1:]) if b > lo and a < hi]
        zeros = table
    else:
        segs, zeros = [(lo + (hi - lo) * j / 4, lo + (hi - lo) * (j + 1) / 4) for j in range(4)], [lo, hi]
    return sorted({a + (b - a) * i / parts for a, b in segs for i in range(1, parts)}), zeros


def _powered_knots(vehicle: "Vehicle") -> np.ndarray:
    """The mesh's element boundaries over the burn: from the start to the first boundary at or after the
    thrust's end (:attr:`Vehicle.powered`), all of them when the burn lasts the horizon or is unknown."""
    bounds = np.asarray(vehicle.knot_times, float)
    if len(vehicle.powered) != 2 or not vehicle.powered[1] < bounds[-1]:
        return bounds
    end = bounds[min(int(np.searchsorted(bounds, vehicle.powered[1] - 1e-9)), bounds.size - 1)]
    return bounds[bounds <= end]


def _refine_thrust(vehicle: "Vehicle | None") -> list[Effect]:
    """The thrust's refined shapes: a faster or slower burn (:func:`burn_rate_effect`), a thrust error in time
    on 3, 5 and 9 knots and a throttle step or window, each over the burn (the mesh's boundaries up to the
    thrust's end, :func:`_powered_knots`): on a vehicle that coasts two thirds of its flight, knots over the
    whole horizon left the burn one segment (Wren-H: knots at 0.59, 22 and 44 s for a 15.5 s burn)."""
    if vehicle is None or len(vehicle.knot_times) < 3:
        return [burn_rate_effect()] + _motor_shapes(vehicle)
    bounds = _powered_knots(vehicle)
    if bounds.size < 3:
        return [burn_rate_effect()] + _motor_shapes(vehicle)
    out = []
    for n in (3, 5, 9):
        want = np.linspace(bounds[0], bounds[-1], n)
        knots = sorted({float(bounds[np.argmin(np.abs(bounds - w))]) for w in want})
        if len(knots) >= 2:
            out.append(thrust_profile_effect(knots))
    w = _onset_width(vehicle)
    return ([burn_rate_effect()] + out + [throttle_step_effect(bounds[0], bounds[-1], w),
                                          throttle_window_effect(bounds[0], bounds[-1], w)] + _motor_shapes(vehicle))


def _motor_shapes(vehicle: "Vehicle | None") -> list[Effect]:
    """Each motor's level and burn-rate errors (:attr:`Vehicle.motors`), each tried beside the thrust's ladder
    (``rung`` False): one parameter each, not a rung more flexible than the 9-knot profile. (Measured on
    Auk-B's cold boosters with them as the ladder's last rungs: the ladder stopped at the motor's level, whose
    BIC is above the 9-knot profile's, and the motor's burn rate -- the truth's shape -- was never refitted.)"""
    motors = vehicle.motors if vehicle is not None else ()
    return [replace(e, rung=False) for mo in motors for e in (motor_level_effect(mo), motor_burn_effect(mo))]


def time_offset_second_effect(vehicle: "Vehicle | None" = None) -> Effect:
    """The time-tag offset to second order: ``z(t) = y - tau dy/dt + tau^2/2 d2y/dt2``.

    The refined shape of ``time_offset`` for a latency long against the flight's changes (a GPS
    receiver's 0.1-0.3 s, across a motor's tail-off): the first-order shape neglects ``tau^2/2 d2y/dt2``,
    about 1 m/s in speed for 0.2 s across a hybrid's thrust knee. The second derivative is written from
    the model's own equations (:func:`_second_derivative`), so the outputs hold the dynamics: a larger
    model, tried only when the first-order shape leaves a residual. Not for a model whose equations hold a
    time family (RA-66's drag in time).
    """
    size = {"tau": 0.01} if vehicle is None else {"tau": max(0.01, float(vehicle.sample_interval))}
    return Effect("time_offset_2", "time-tag offset, second order", "sensor", _time_offset_second,
                  "every output z(t) = y(t - tau) ~ y - tau dy/dt + tau^2/2 d2y/dt2 (the second derivative "
                  "from the model's equations), tau in s", size)


START_ANGLE = math.radians(1.0)
"""Realistic error of a declared start's flight-path angle, rad: a launch rail's elevation read off by a
degree (an inclinometer on a sagging rail), a release attitude."""

START_SPEED_SHARE = 0.03
"""Realistic error of a declared start's speed, as a share of it: a rail-exit speed worked out from the
static firing for the nominal mass and rail friction, a release speed."""


def _start_offset(effect: str, role: str, name: str, nominal: float) -> Callable[[Model], tuple]:
    """``apply`` of a correction to the declared start of the state playing ``role`` (a moving start only:
    from rest the start is the launcher's, held by it, and other effects describe its release)."""
    def apply(m: Model) -> tuple:
        _moving_start(m, effect)
        return (m.start_offset(_role_state(m, role, effect), name, nominal=nominal),)
    apply.__name__ = f"_{effect}"
    return apply


RAIL_CONSISTENCY = 0.25
"""The declared start's speed and what the stated thrust gives along a rail from ignition may differ by at most
this share for the start to be taken as a rail exit (:func:`_rail_exit_ratio`)."""


def _moving_start(m: Model, effect: str) -> None:
    """Raise ModelError unless the model's declared start moves (speed > 0)."""
    v0 = _initial_value(m, _role_state(m, "speed", effect))
    if not v0 > 0:
        raise ModelError(f"effect {effect!r} corrects a declared moving start (a rail exit, a release); model "
                         f"{m.name!r} starts at rest, where the launcher holds the vehicle")


def _rail_exit_ratio(m: Model, effect: str, motor: "_Motor | None" = None) -> float:
    """``dt/dv``: how much later a rail exit comes per m/s it is slower, from the model's own motor.

    A declared moving start after ignition is taken as the exit of a rail of fixed length, reached from rest
    along the start's flight-path angle: ``a(t) = P(t)/m(t) - g sin(gamma0)`` from the first instant it is
    positive (the launcher holds the vehicle until the thrust exceeds the weight's component), the thrust
    and mass as stated (states held at their start values, parameters at their guesses; a mass state
    integrated back from its start value), the drag neglected (a few per cent of the weight at rail-exit
    speeds). A change of the acceleration shaped like ``P/m`` -- a mass or a thrust off its stated value --
    moves the exit speed by ``dv_r = int f`` and the distance covered by ``t0`` by ``ds = int (t0 - t) f``;
    the rail's end is then reached ``dt = -ds/v0`` later, at ``dv = dv_r + a(t0) dt``. Wren-H's rail: -0.02028
    s per m/s (its truth simulator's own rail gives -0.02047 for 1.5 kg of ballast).

    Raises ModelError when the start is not such an exit: no sampled thrust curve starting before the
    model's start (a release before ignition, a motor declared only from the start), or a declared start
    speed more than :data:`RAIL_CONSISTENCY` off what the stated thrust gives along a rail."""
    mo = _motor(m, effect) if motor is None else motor
    sampled = [u for u in mo.inputs if u.expr is None]
    t_i = min((u.times[0] for u in sampled), default=math.inf)
    if not t_i < m.t0:
        raise ModelError(f"effect {effect!r} moves a rail exit along the motor's curve from ignition; model "
                         f"{m.name!r} has no sampled thrust curve that starts before its start at t = {m.t0:g}")
    samples = [t for u in sampled for t in u.times if t_i <= t <= m.t0]
    tt = np.union1d(np.linspace(t_i, m.t0, 4001), samples)
    thrust = _held(m, mo.thrust)
    inputs = [u for u in m._inputs if u.symbol in thrust.free_symbols]
    P = _along(m, thrust, inputs, tt)
    if mo.flows:
        rate = _held(m, sum(mo.flows.values(), sp.S.Zero))
        flow = _along(m, rate, [u for u in m._inputs if u.symbol in rate.free_symbols], tt)
        burnt = cumulative_trapezoid(flow, tt, initial=0.0)           # the flow is negative: mass falls
        mass = float(_held(m, mo.mass)) - (burnt[-1] - burnt)
    else:
        held = _held(m, mo.mass)
        mass = _along(m, held, [u for u in m._inputs if u.symbol in held.free_symbols], tt)
    gamma0 = _initial_value(m, _role_state(m, "flight_path_angle", effect))
    v0 = _initial_value(m, _role_state(m, "speed", effect))
    acc = P / mass - G0 * math.sin(gamma0)
    moving = np.cumsum(acc > 0) > 0
    acc, shape = np.where(moving, acc, 0.0), np.where(moving, P / mass, 0.0)
    v_rail = float(trapezoid(acc, tt))
    if not abs(v_rail - v0) <= RAIL_CONSISTENCY * v0:
        raise ModelError(f"effect {effect!r}: model {m.name!r}'s declared start speed {v0:.4g} m/s is not what its "
                         f"stated thrust gives along a rail from ignition ({v_rail:.4g} m/s): not a rail exit")
    dv_r, ds = float(trapezoid(shape, tt)), float(trapezoid((m.t0 - tt) * shape, tt))
    dt = -ds / v0
    return dt / (dv_r + float(acc[-1]) * dt)


def _start_delay(m: Model, effect: str, dt: sp.Expr, motor: "_Motor") -> None:
    """The vehicle leaves its declared (moving) start ``dt`` later than declared, on the motor's clock.

    In the model's time ``s`` the flight starts from the declared state at ``t0``; the motor had been running
    ``dt`` longer then, so every time-dependent part of the ``thrust`` and ``mass`` definitions and of a mass
    state's equation is read at ``s + dt`` (a sampled curve through its table function); a mass state's
    declared start is what the stated curve leaves at ``t0``, and the later start has burnt ``dt |dm/dt(t0)|``
    more by then. The measurements are on the motor's clock ``t = s + dt``: every output is read at
    ``t - dt``, to first order ``y - dt dy/dt`` (as ``time_offset``). ``motor``: the model's motor parts
    (:func:`_motor`)."""
    warp = motor.warp(m.t + dt, m.t)
    m.redefine(motor.thrust_symbol, motor.thrust.xreplace(warp))
    m.redefine(motor.mass_symbol, motor.mass.xreplace(warp) + motor.flow_at_start() * dt)
    for state, flow in motor.flows.items():
        m.ode({state: flow.xreplace(warp)})
    _time_offset_edit(m, effect, second=False, tau=dt)


EXIT_AGREEMENT = 0.1
"""Realistic disagreement between a rail exit's speed change and the speed change its time goes with along
the rail (:func:`_start_exit_edit`), as a share of the realistic speed change: the rail model neglects the
drag and takes the change shaped like ``P/m`` (on Wren-H it is within 1 % of the truth simulator's rail)."""


def _start_exit_edit(m: Model, effect: str) -> tuple:
    """``dv_start`` on the declared start's speed and the exit ``r dv_exit`` later (:func:`_start_delay`, ``r``
    from :func:`_rail_exit_ratio`). The time is a parameter of its own, in the speed change it goes with
    along the rail (``dv_exit``), because a start's value and the equations take different parameters (an
    initial value cannot be an expression of another); the two must agree within :data:`EXIT_AGREEMENT`
    of the realistic speed change (the effect's ``changes``) -- a free time took a 20 ms radar time-tag
    offset on Tern-2, whose flat solid thrust cannot tell the two apart."""
    _moving_start(m, effect)
    mo = _motor(m, effect)              # a start offset and a new parameter leave the motor's definitions as they are
    ratio = _rail_exit_ratio(m, effect, mo)
    dv = m.start_offset(_role_state(m, "speed", effect), "dv_start", nominal=1.0)
    q = m.parameter("dv_exit", 0.0, bounds=(-1.0 / abs(ratio), 1.0 / abs(ratio)), nominal=1.0)
    _start_delay(m, effect, ratio * q, mo)
    return dv, q


def _start_exit(m: Model) -> tuple:
    return _start_exit_edit(m, "start_exit")


def _start_mass_exit(m: Model) -> tuple:
    (dm,) = _start_mass(m)
    return (dm, *_start_exit_edit(m, "start_mass_exit"))


def _start_speed_size(vehicle: "Vehicle | None") -> float:
    """Realistic error of a declared start's speed: :data:`START_SPEED_SHARE` of it, at least 0.3 m/s."""
    speed = vehicle.start_speed if vehicle is not None and math.isfinite(vehicle.start_speed) else 0.0
    return max(0.3, START_SPEED_SHARE * speed)


def _exit_size(vehicle: "Vehicle | None") -> dict[str, float]:
    size = _start_speed_size(vehicle)
    return {"dv_start": size, "dv_exit": size}


def _exit_changes(vehicle: "Vehicle | None") -> dict:
    return {("dv_start", "dv_exit"): EXIT_AGREEMENT * _exit_size(vehicle)["dv_start"]}


def start_exit_effect(vehicle: "Vehicle | None" = None) -> Effect:
    """A rail exit's speed corrected **with its time**: the exit worked out for another mass or thrust.

    A rail exit is a computed start: the team integrates the stated thrust and mass along the rail. When
    those are off, the vehicle leaves the rail at another speed *and* at another time on the motor's clock
    -- 1.5 kg more on Wren-H's 60 kg leaves its 6.1 m rail 0.37 m/s slower and 7.5 ms later, and at
    50 m/s^2 those 7.5 ms are another 0.37 m/s all through the burn. The shape of ``start_speed`` for such
    a start: ``v(t0) + dv_start``, and the flight from the declared start ``dt = r dv_start`` later
    (:func:`_start_delay`: the motor's curves read ``dt`` on, the outputs ``dt`` back), ``r`` from the
    model's own motor along a rail (:func:`_rail_exit_ratio`). One parameter: the time is not free -- a free
    one took a 20 ms radar time-tag offset on Tern-2, whose flat solid thrust cannot tell the two apart.
    Only for a moving start after ignition that the stated thrust reaches along a rail."""
    return Effect("start_exit", "rail exit's speed with its time", "kinematics", _start_exit,
                  "speed at the start v(t0) + dv_start, m/s, and the start r dv_start s later on the motor's clock "
                  "(thrust and mass read at t + r dv_start, every output at t - r dv_start), r the rail exit's "
                  "dt/dv from the stated motor: a rail exit worked out for another mass or thrust", _exit_size(vehicle),
                  changes=_exit_changes(vehicle))


def start_mass_exit_effect(vehicle: "Vehicle | None" = None) -> Effect:
    """A start-mass error on a vehicle whose declared rail exit was worked out for the stated mass.

    ``start_mass`` with its consequence for such a start: the heavier (lighter) vehicle leaves its rail
    slower (faster) and later (sooner): ``dm_start``, and the exit's speed and time as
    :func:`start_exit_effect` (``dv_start``, and ``dv_exit`` for the time, held to agree along the rail). Measured on Wren-H with
    1.5 kg of nose ballast (its noise-free GPS log; the truth simulator's own rail: 7.51 ms later, 0.367 m/s
    slower): ``start_mass`` + ``start_speed`` leave 2J = 54 and ``thrust_level`` + ``start_speed`` 27 -- a
    thrust error, acting through the same thrust/mass ratio, imitated the ballast better than the half of
    its physics --; with the exit's time (free) the shape left 2J = 0.13 (the clean log's own is 0.19) at
    1.498 kg, -0.368 m/s, 7.54 ms, which is -0.372 m/s along the rail (``tests/test_wren_study.py``)."""
    sizes = {"dm_start": 0.01 * vehicle.mass if vehicle is not None and math.isfinite(vehicle.mass) else 200.0,
             **_exit_size(vehicle)}
    return Effect("start_mass_exit", "start-mass error with its rail exit", "mass", _start_mass_exit,
                  "mass m(t) + dm_start, kg, and the rail exit's speed v(t0) + dv_start with its time r dv_start "
                  "(r from the stated motor along the rail): a heavier vehicle leaves its rail slower and later",
                  sizes, changes=_exit_changes(vehicle))


def _build_catalogue() -> dict[str, Effect]:
    def rel_bias(channel: str, floor: float, sigmas: float):
        return lambda veh: {f"b_{channel}": max(floor, sigmas * float(veh.sigma.get(channel, 0.0)))}

    effects = [
        back_pressure_effect("sea_level"),
        back_pressure_effect("vacuum"),
        Effect("thrust_level", "thrust-level error", "propulsion", _thrust_level,
               "thrust P (1 + eps_thrust)", {"eps_thrust": 0.02}, refine=_refine_thrust),
        Effect("mass_flow", "mass-flow error", "mass", _mass_flow,
               "mass m(t0) - (m(t0) - m(t)) (1 + eps_mdot): the mass flow scaled by 1 + eps_mdot",
               {"eps_mdot": 0.02}),
        Effect("start_mass", "start-mass error", "mass", _start_mass,
               "mass m(t) + dm_start, kg: the vehicle heavier (or lighter) than stated by a constant amount",
               {"dm_start": 200.0}, relative=lambda veh: {"dm_start": 0.01 * veh.mass}, refine=_refine_start_mass),
        Effect("base_drag", "power-off base drag", "aero", _base_drag,
               "cd + dCD_base (1 - f_noz): the drag coefficient higher once the motor stops and its jet "
               "no longer fills the base (dCD_base >= 0: a decrease is the wrong sign), faded in over the tail-off "
               "as the back-pressure fades out (f_noz); for a motor that stops inside the horizon",
               {"dCD_base": 0.1}, refine=_refine_base_drag, positive=({"dCD_base": 1.0},)),
        Effect("transonic_drag", "transonic drag rise", "aero", _transonic_drag,
               f"cd + dCD_transonic exp(-((M - {TRANSONIC_MACH:g})/{TRANSONIC_WIDTH:g})^2/2)", {"dCD_transonic": 0.2},
               refine=_refine_drag),
        replace(wind_effect(), refine=_refine_wind),
        replace(earth_rotation_effect(), refine=lambda veh: [earth_rotation_site_effect()]),
        Effect("misalignment", "thrust misalignment", "propulsion", _misalignment,
               "thrust direction alpha_thrust = alpha + delta_thrust, rad, from t0 when the vehicle starts moving "
               "(start speed > 0), else phased in by the lift-off fade f_lo(t)", {"delta_thrust": math.radians(0.25)},
               refine=_refine_misalignment),
        replace(density_effect(), refine=_refine_density),
        Effect("bias_x", "downrange sensor bias", "sensor", _bias("x"), "z_x = x + b_x, m", {"b_x": 5.0},
               relative=rel_bias("x", 5.0, 5.0), refine=_refine_bias("x", "m", 5.0, 5.0)),
        Effect("bias_h", "altitude sensor bias", "sensor", _bias("h"), "z_h = h + b_h, m", {"b_h": 5.0},
               relative=rel_bias("h", 5.0, 5.0), refine=_refine_bias("h", "m", 5.0, 5.0)),
        Effect("bias_v", "speed sensor bias", "sensor", _bias("v"), "z_v = v + b_v, m/s", {"b_v": 0.5},
               relative=rel_bias("v", 0.5, 0.5), refine=_refine_bias("v", "m/s", 0.5, 0.5)),
        Effect("scale_v", "speed scale factor", "sensor", _scale("v"), "z_v = (1 + k_v) v", {"k_v": 1e-3}),
        Effect("scale_h", "altitude scale factor", "sensor", _scale("h"),
               "z_h = (1 + k_h) h: an altimeter reading proportionally high or low (a barometric altitude on a "
               "non-standard day, a radar altimeter's scale)", {"k_h": 2e-3}),
        Effect("start_angle", "declared start's flight-path angle", "kinematics",
               _start_offset("start_angle", "flight_path_angle", "dgamma_start", START_ANGLE),
               "flight-path angle at the start gamma(t0) + dgamma_start, rad: a moving start declared turned (a "
               "launch rail's elevation misread, a release attitude)", {"dgamma_start": START_ANGLE}),
        Effect("start_speed", "declared start's speed", "kinematics",
               _start_offset("start_speed", "speed", "dv_start", 1.0),
               "speed at the start v(t0) + dv_start, m/s: a moving start declared too fast or too slow (a rail-exit "
               "speed worked out for another mass, a release speed)", {"dv_start": 1.0},
               relative=lambda veh: {"dv_start": _start_speed_size(veh)}
               if math.isfinite(veh.start_speed) and veh.start_speed > 0 else {},
               refine=lambda veh: [start_exit_effect(veh)] if veh is not None and veh.rail_exit else []),
        Effect("time_offset", "time-tag offset", "sensor", _time_offset,
               "every output z(t) = y(t - tau) ~ y - tau dy/dt, tau in s", {"tau": 0.01},
               relative=lambda veh: {"tau": max(0.01, float(veh.sample_interval))},
               refine=lambda veh: [] if veh is not None and veh.time_families else [time_offset_second_effect(veh)]),
    ]
    return {e.name: e for e in effects}


CATALOGUE: dict[str, Effect] = _build_catalogue()
"""The candidate effects, by name (``docs/effects.md`` documents each)."""


def custom_effect(name: str, apply: Callable[[Model], Iterable[sp.Symbol]], *, title: str | None = None,
                  kind: str = "custom", description: str = "", realistic: Mapping[str, float] | None = None,
                  relative: Callable | None = None) -> Effect:
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
        Realistic magnitude of each parameter, by name: the diagnosis calls an
        estimate beyond 5 times it implausible (without one, any size is accepted).
    relative : callable, optional
        ``relative(vehicle) -> {name: magnitude}`` from the vehicle's scales
        (:class:`Vehicle`), when the size depends on the vehicle.

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
    return Effect(name, title or name.replace("_", " "), kind, wrapped, description, dict(realistic or {}),
                  relative=relative)


# ---------------------------------------------------------------------------
# applying effects
# ---------------------------------------------------------------------------


def check_sizes(sizes: Mapping[str, float] | None, where: str = "sizes") -> dict[str, float]:
    """``sizes`` as ``{parameter name or pattern: positive size}``; a SettingsError naming a bad entry."""
    from ..errors import SettingsError
    out = {}
    for name, value in dict(sizes or {}).items():
        if not isinstance(name, str) or not name.strip():
            raise SettingsError(f"{where}: a realistic size needs a parameter name (or a pattern such as eps_P*), "
                                f"got {name!r}")
        try:
            v = float(value)
        except (TypeError, ValueError):
            raise SettingsError(f"{where} {name}={value!r}: give a positive number (the parameter's realistic "
                                "magnitude, in its own units)") from None
        if not (v > 0 and math.isfinite(v)):
            raise SettingsError(f"{where} {name}={value!r}: a realistic size must be positive and finite")
        out[name.strip()] = v
    return out


def _stated_for(names: Iterable[str], sizes: Mapping[str, float]) -> dict[str, float]:
    """The stated size of each of ``names`` that an entry of ``sizes`` names: its exact name first, else the
    first pattern (``fnmatch``) that matches."""
    import fnmatch
    out = {}
    for n in names:
        if n in sizes:
            out[n] = sizes[n]
            continue
        for pat, v in sizes.items():
            if fnmatch.fnmatchcase(n, pat):
                out[n] = v
                break
    return out


def state_sizes(effects: Sequence[Effect], sizes: Mapping[str, float] | None) -> list[Effect]:
    """``effects`` with the realistic sizes the user states in place of the catalogue's.

    A vehicle's own numbers are known to its engineers better than to any catalogue: a hybrid motor whose
    thrust moves 10 % with the oxidiser tank's temperature, a mass known to 5 %. ``sizes`` maps a parameter
    name (``"eps_thrust"``) or an ``fnmatch`` pattern (``"eps_P*"``: every knot of a thrust profile) to its
    realistic magnitude in the parameter's units; every judgement of size -- the acceptance test's
    :data:`~rocketid.diagnostics.accept.SIZE_FACTOR`, the screen's starting values, the report's "realistic"
    -- then uses it, for the effects and for the refined shapes they lead to.

    Parameters
    ----------
    effects : sequence of Effect
    sizes : mapping of str to float, optional

    Returns
    -------
    list of Effect
    """
    sizes = check_sizes(sizes)
    if not sizes:
        return list(effects)

    def wrap(e: Effect) -> Effect:
        own = _stated_for(e.realistic, sizes)
        base_relative, base_refine = e.relative, e.refine

        def relative(vehicle):
            out = dict(base_relative(vehicle)) if base_relative is not None else {}
            out.update(_stated_for(set(e.realistic) | set(out), sizes))
            return out

        def refine(vehicle):
            return [wrap(x) for x in base_refine(vehicle)]

        return replace(e, realistic={**e.realistic, **own},
                       relative=relative if (own or base_relative is not None) else None,
                       refine=refine if base_refine is not None else None)

    return [wrap(e) for e in effects]


def stated_names(effects: Sequence[Effect], sizes: Mapping[str, float], vehicle: "Vehicle | None") -> dict:
    """``{entry of sizes: parameter names it states}`` over ``effects`` and their refined shapes for
    ``vehicle`` (an entry that names nothing is a mistake the caller reports)."""
    names: set = set()
    for e in effects:
        names |= set(e.realistic)
        for r in e.refinements(vehicle):
            names |= set(r.realistic)
    return {k: sorted(_stated_for(names, {k: v})) for k, v in sizes.items()}


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
    for eq in spec.expanded_equations:
        used |= eq.free_symbols
    for o in spec.outputs:
        used |= spec.expand(o.expr).free_symbols
    params = {p.symbol: p for p in spec.parameters}
    # a knot of a time family enters through the family's symbol; an offset of a declared start through the
    # initial conditions
    used |= {k for f in spec.families if f.symbol in used for k in f.knots}
    used |= {s.initial_parameter for s in spec.states if s.offset}
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
                                  "(m.add_term), an output (m.redefine_output) or a start (m.start_offset)")
            if name in problems:
                break
    return problems
