"""Declaring a model: states, inputs, constants, parameters, dynamics, outputs.

This is the first stage of rocketid's pipeline. A :class:`Model` is a mutable
builder in the style of Pyomo: every component is a SymPy symbol held by the
model (and reachable as an attribute, ``m.v``), and everything attached to a
component (bounds, guesses, measurements, results) is keyed by that symbol.
:meth:`Model.freeze` validates the declaration and returns an immutable
:class:`ModelSpec`, which is what every later stage consumes.

Notation
--------
========================  ====================================================
``t``                     time (the model's independent variable)
``s``                     states, ``ds/dt`` their derivatives (``m.der(s)``)
``u(t)``                  known inputs (symbolic in ``t`` or sampled)
``p``                     estimated parameters (scalar, or knots of families)
``l(t)``                  local parameter values: a scalar parameter is its own
                          local value; a time family (piecewise linear on
                          breakpoints) has the interpolated knot value
``F(t, s, ds/dt, u, l)``  one residual per state, ``F = 0`` (explicit
                          dynamics ``ds/dt = f`` become ``F = ds/dt - f``)
``g_k(t, s, p)``          measured outputs, noise standard deviation sigma_k
========================  ====================================================

Examples
--------
>>> import sympy as sp
>>> from rocketid.model import Model
>>> m = Model("decay", t0=0.0, tf=2.0)
>>> y = m.state("y", initial=1.0)
>>> k = m.parameter("k", guess=0.5, bounds=(0.0, 10.0))
>>> m.ode({y: -k * y})
>>> m.output("y", y, sigma=0.01)
>>> spec = m.freeze()
>>> [str(s) for s in spec.parameter_symbols]
['k']
"""

from __future__ import annotations

import copy
import hashlib
import math
from dataclasses import dataclass, field, replace
from functools import cached_property
from typing import Iterable, Mapping, Sequence

import numpy as np
import sympy as sp

from .data import SIGMA_RANGE
from .errors import ModelError
from .summary import Section, Summary, Text

__all__ = [
    "Model",
    "ModelSpec",
    "StateSpec",
    "ParameterSpec",
    "FamilySpec",
    "InputSpec",
    "OutputSpec",
    "TableSpec",
    "PriorSpec",
    "ROLES",
]

#: Physical roles a model's symbols can play, and what each is. The physics builders
#: (:mod:`rocketid.physics.ascent`) declare them; a model written by hand declares them with
#: :meth:`Model.declare_role`. Diagnostics and candidate effects find the physics through the
#: roles (never through a symbol's name) and say which analysis a model without a role cannot have.
ROLES = {
    "downrange": "downrange distance (state), m",
    "altitude": "altitude above the launch site (state), m",
    "speed": "speed relative to the ground (state), m/s",
    "flight_path_angle": "flight-path angle (state), rad",
    "density": "air density (definition), kg/m^3",
    "gravity": "gravitational acceleration (definition), m/s^2",
    "dynamic_pressure": "dynamic pressure (definition), Pa",
    "sound_speed": "speed of sound (definition), m/s",
    "mach": "Mach number (definition)",
    "attack_angle": "attack angle (an input, definition or expression), rad",
    "thrust": "thrust (definition), N",
    "thrust_direction": "thrust direction relative to the velocity (definition), rad",
    "mass": "vehicle mass (definition), kg",
    "drag_coefficient": "drag coefficient (definition)",
    "lift_coefficient": "lift coefficient (definition)",
    "drag": "drag force (definition), N",
    "lift": "lift force (definition), N",
    "reference_area": "aerodynamic reference area (constant), m^2",
}


# ---------------------------------------------------------------------------
# Immutable specification (what later stages consume)
# ---------------------------------------------------------------------------


@dataclass(frozen=True)
class StateSpec:
    """A differential state.

    Attributes
    ----------
    symbol : sympy.Symbol
        The state.
    derivative : sympy.Symbol
        The symbol that stands for ``d symbol / dt`` in residuals.
    initial : float
        Initial value (the guess, when ``initial_parameter`` is set; the declared value an
        ``offset`` is added to).
    initial_parameter : sympy.Symbol or None
        Parameter holding the initial value when the initial state is free.
    offset : bool
        The parameter is an offset from ``initial`` (the start is ``initial + p``), not the
        initial value itself: a declared start estimated as a correction
        (:meth:`Model.start_offset`).
    """

    symbol: sp.Symbol
    derivative: sp.Symbol
    initial: float
    initial_parameter: sp.Symbol | None = None
    offset: bool = False

    @property
    def free(self) -> bool:
        """Whether the initial value is estimated."""
        return self.initial_parameter is not None


@dataclass(frozen=True)
class ParameterSpec:
    """A scalar estimated parameter (also each knot of a family).

    Attributes
    ----------
    symbol : sympy.Symbol
    guess : float
        Initial guess (p0).
    lower, upper : float
        Bounds (may be infinite).
    nominal : float
        Typical magnitude, used when parameters are scaled.
    family : sympy.Symbol or None
        The time family the parameter is a knot of, if any.
    """

    symbol: sp.Symbol
    guess: float
    lower: float = -math.inf
    upper: float = math.inf
    nominal: float = 1.0
    family: sp.Symbol | None = None


@dataclass(frozen=True)
class FamilySpec:
    """A time-varying parameter, piecewise linear in time on breakpoints (7.4).

    Attributes
    ----------
    symbol : sympy.Symbol
        The local value ``l(t)`` used in expressions.
    breakpoints : tuple of float
        Knot times, increasing, the first at ``t0`` and the last at ``tf``.
    knots : tuple of sympy.Symbol
        The parameter whose value the family takes at each breakpoint; tied
        knots (the chapter's ``CL0 = CL1``) share one parameter.
    """

    symbol: sp.Symbol
    breakpoints: tuple[float, ...]
    knots: tuple[sp.Symbol, ...]

    def weights(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """Interpolation weights at times ``t``.

        Returns
        -------
        left, right : ndarray of int, shape (n,)
            Index of the knot at the start and end of the segment holding t.
        w_right : ndarray, shape (n,)
            Weight of the right knot (the left one has ``1 - w_right``).
        """
        bp = np.asarray(self.breakpoints)
        t = np.asarray(t, dtype=float)
        seg = np.clip(np.searchsorted(bp, t, side="right") - 1, 0, len(bp) - 2)
        w = (t - bp[seg]) / (bp[seg + 1] - bp[seg])
        return seg, seg + 1, w

    def evaluate(self, t: np.ndarray, values: Mapping[sp.Symbol, float]) -> np.ndarray:
        """The family's value at times ``t`` for parameter ``values``."""
        knot_vals = np.array([float(values[k]) for k in self.knots])
        return np.interp(np.asarray(t, dtype=float), np.asarray(self.breakpoints), knot_vals)


@dataclass(frozen=True)
class InputSpec:
    """A known input ``u(t)``: a SymPy expression of ``t``, or sampled values.

    Attributes
    ----------
    symbol : sympy.Symbol
    expr : sympy.Expr or None
        Expression in the model's time symbol.
    times, values : tuple of float
        Samples, linearly interpolated (when ``expr`` is None).
    breakpoints : tuple of float
        Times where the input has a kink or jump (simulators split there).
    """

    symbol: sp.Symbol
    expr: sp.Expr | None
    times: tuple[float, ...] = ()
    values: tuple[float, ...] = ()
    breakpoints: tuple[float, ...] = ()


@dataclass(frozen=True)
class OutputSpec:
    """A measured output ``g(t, s, p)`` with noise standard deviation ``sigma``."""

    name: str
    expr: sp.Expr
    sigma: float


@dataclass(frozen=True)
class TableSpec:
    """A coefficient table made by :meth:`Model.table`: piecewise linear in a flight-condition variable.

    Attributes
    ----------
    name : str
        The table's name (its knots are ``<name>_<j>``).
    variable : sympy.Expr
        The independent variable (e.g. the ``mach`` definition).
    variable_role : str or None
        The role of that variable (``"mach"``, ``"dynamic_pressure"``, ...; see :data:`ROLES`), if it has one.
    knots : tuple of float
        Knot positions in the variable.
    parameters : tuple of sympy.Symbol
        The knot parameters, in knot order.
    """

    name: str
    variable: sp.Expr
    variable_role: str | None
    knots: tuple[float, ...]
    parameters: tuple[sp.Symbol, ...]


@dataclass(frozen=True)
class PriorSpec:
    """What is known about a parameter before the flight: a Gaussian prior.

    The estimation adds the penalty ``((p - mean) / sd)^2 / 2`` to the objective (7.5); the
    reduced Hessian gains ``1 / sd^2`` on the parameter's diagonal (the prior's share of the
    information, reported apart from the data's).

    Attributes
    ----------
    symbol : sympy.Symbol
        The estimated parameter.
    mean, sd : float
        Mean and standard deviation (same units as the parameter).
    source : str
        Where the knowledge comes from (``"wind tunnel"``, ``"static firing"``), for reports.
    """

    symbol: sp.Symbol
    mean: float
    sd: float
    source: str = ""


@dataclass(frozen=True)
class ModelSpec:
    """An immutable, validated model: the value handed to every later stage.

    Build one with :meth:`Model.freeze`; get an editable copy back with
    :meth:`to_model` (to add a physical effect and refit).
    """

    name: str
    t: sp.Symbol
    t0: float
    tf: float
    states: tuple[StateSpec, ...]
    inputs: tuple[InputSpec, ...]
    constants: tuple[tuple[sp.Symbol, float], ...]
    parameters: tuple[ParameterSpec, ...]
    families: tuple[FamilySpec, ...]
    definitions: tuple[tuple[sp.Symbol, sp.Expr], ...]
    equations: tuple[sp.Expr, ...]
    outputs: tuple[OutputSpec, ...]
    description: str = ""
    _builder: "Model | None" = field(default=None, repr=False, compare=False)
    roles: tuple[tuple[str, sp.Expr], ...] = ()
    tables: tuple[TableSpec, ...] = ()
    priors: tuple[PriorSpec, ...] = ()
    events: tuple[float, ...] = ()

    # -- priors ------------------------------------------------------------------
    def prior_arrays(self) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        """The priors as arrays over the parameter vector.

        Returns
        -------
        has : ndarray of bool, shape (n_p,)
            Which parameters have a prior.
        mean : ndarray, shape (n_p,)
            Prior means (0 where there is none).
        weight : ndarray, shape (n_p,)
            ``1 / sd^2`` (0 where there is none).
        """
        n = len(self.parameters)
        has, mean, weight = np.zeros(n, bool), np.zeros(n), np.zeros(n)
        index = {s: i for i, s in enumerate(self.parameter_symbols)}
        for pr in self.priors:
            i = index[pr.symbol]
            has[i], mean[i], weight[i] = True, pr.mean, 1.0 / pr.sd ** 2
        return has, mean, weight

    def prior_objective(self, p: Sequence[float]) -> float:
        """The priors' share of the objective, ``sum ((p - mean) / sd)^2 / 2``."""
        if not self.priors:
            return 0.0
        _, mean, weight = self.prior_arrays()
        d = np.asarray(p, float) - mean
        return 0.5 * float(np.sum(weight * d * d))

    # -- physical roles --------------------------------------------------------
    def role(self, role: str) -> sp.Expr | None:
        """The symbol (or expression) playing ``role`` (one of :data:`ROLES`), or None."""
        if role not in ROLES:
            raise ModelError(f"unknown role {role!r}; roles are {', '.join(ROLES)}")
        return dict(self.roles).get(role)

    def require_role(self, role: str, analysis: str) -> sp.Expr:
        """The symbol playing ``role``; a :class:`ModelError` saying that ``analysis`` needs it otherwise."""
        expr = self.role(role)
        if expr is None:
            raise ModelError(missing_role_message(self.name, role, analysis))
        return expr

    def table_of(self, parameter: sp.Symbol | str) -> TableSpec | None:
        """The :class:`TableSpec` holding ``parameter`` as a knot, or None."""
        sym = self.symbol(parameter) if isinstance(parameter, str) else parameter
        return next((tb for tb in self.tables if sym in tb.parameters), None)

    # -- symbols -----------------------------------------------------------
    @property
    def state_symbols(self) -> tuple[sp.Symbol, ...]:
        return tuple(s.symbol for s in self.states)

    @property
    def derivative_symbols(self) -> tuple[sp.Symbol, ...]:
        return tuple(s.derivative for s in self.states)

    @property
    def parameter_symbols(self) -> tuple[sp.Symbol, ...]:
        """All estimated parameters, in the order of the decision vector."""
        return tuple(p.symbol for p in self.parameters)

    @property
    def parameter_names(self) -> tuple[str, ...]:
        return tuple(str(p.symbol) for p in self.parameters)

    @property
    def input_symbols(self) -> tuple[sp.Symbol, ...]:
        return tuple(u.symbol for u in self.inputs)

    @property
    def output_names(self) -> tuple[str, ...]:
        return tuple(o.name for o in self.outputs)

    @property
    def local_symbols(self) -> tuple[sp.Symbol, ...]:
        """Symbols of local parameter values ``l``: families, then scalar parameters
        that are not knots of a family and not free initial states."""
        fam = tuple(f.symbol for f in self.families)
        init = {s.initial_parameter for s in self.states if s.free}
        scal = tuple(p.symbol for p in self.parameters if p.family is None and p.symbol not in init)
        return fam + scal

    def parameter(self, symbol: sp.Symbol | str) -> ParameterSpec:
        """The :class:`ParameterSpec` of ``symbol`` (a name is accepted too)."""
        sym = self.symbol(symbol)
        for p in self.parameters:
            if p.symbol == sym:
                return p
        raise ModelError(f"{sym} is not an estimated parameter of model {self.name!r}; "
                         f"its parameters are {', '.join(self.parameter_names)}")

    def family(self, symbol: sp.Symbol | str) -> FamilySpec:
        """The :class:`FamilySpec` whose local value is ``symbol``."""
        sym = self.symbol(symbol)
        for f in self.families:
            if f.symbol == sym:
                return f
        raise ModelError(f"{sym} is not a time family of model {self.name!r}")

    def symbol(self, key: sp.Symbol | str) -> sp.Symbol:
        """Resolve a component by symbol or name; unknown keys are an error that names them."""
        table = self._symbol_table()
        if isinstance(key, sp.Symbol):
            if key in table.values():
                return key
            raise ModelError(f"symbol {key} is not a component of model {self.name!r}")
        if isinstance(key, str):
            if key in table:
                return table[key]
            import difflib
            lower = {k.lower(): k for k in table}
            close = [lower[c] for c in difflib.get_close_matches(key.lower(), list(lower), n=3)]
            hint = f"; did you mean {', '.join(close)}?" if close else ""
            raise ModelError(f"model {self.name!r} has no component named {key!r}{hint}")
        raise ModelError(f"expected a SymPy symbol or a name, got {type(key).__name__}")

    def _symbol_table(self) -> dict[str, sp.Symbol]:
        syms = [self.t, *self.state_symbols, *self.derivative_symbols, *self.input_symbols,
                *(c for c, _ in self.constants), *self.parameter_symbols,
                *(f.symbol for f in self.families), *(d for d, _ in self.definitions)]
        return {str(s): s for s in syms}

    # -- parameter vectors -------------------------------------------------
    @property
    def guess(self) -> np.ndarray:
        """p0, shape (n_p,)."""
        return np.array([p.guess for p in self.parameters], dtype=float)

    @property
    def lower(self) -> np.ndarray:
        return np.array([p.lower for p in self.parameters], dtype=float)

    @property
    def upper(self) -> np.ndarray:
        return np.array([p.upper for p in self.parameters], dtype=float)

    @property
    def nominal(self) -> np.ndarray:
        return np.array([p.nominal for p in self.parameters], dtype=float)

    def parameter_vector(self, values: Mapping[sp.Symbol | str, float] | Sequence[float] | np.ndarray | None = None) -> np.ndarray:
        """A full parameter vector: p0 updated by ``values`` (a mapping keyed by
        symbol or name, or a full sequence in :attr:`parameter_symbols` order)."""
        if values is None:
            return self.guess
        if isinstance(values, Mapping):
            p = self.guess.copy()
            index = {s: i for i, s in enumerate(self.parameter_symbols)}
            for key, val in values.items():
                sym = self.symbol(key)
                if sym not in index:
                    raise ModelError(f"{sym} is not an estimated parameter of model {self.name!r}; "
                                     f"its parameters are {', '.join(self.parameter_names)}")
                try:
                    p[index[sym]] = float(val)
                except (TypeError, ValueError):
                    raise ModelError(f"the value {val!r} of parameter {sym} is not a number") from None
            return p
        if isinstance(values, (str, bytes)):
            raise ModelError(f"parameter values {values!r}: give a sequence of {len(self.parameters)} numbers or a "
                             f"{{name: value}} mapping ({', '.join(self.parameter_names)})")
        try:
            p = np.asarray(values, dtype=float).ravel()
        except (TypeError, ValueError):
            raise ModelError(f"parameter values {values!r} are not numbers; give a sequence of "
                             f"{len(self.parameters)} numbers or a {{name: value}} mapping") from None
        if p.shape != (len(self.parameters),):
            raise ModelError(f"parameter vector has {p.size} values; model {self.name!r} has "
                             f"{len(self.parameters)} ({', '.join(self.parameter_names)})")
        return p

    def parameter_dict(self, p: Sequence[float]) -> dict[sp.Symbol, float]:
        """``{symbol: value}`` for a parameter vector."""
        return {s: float(v) for s, v in zip(self.parameter_symbols, p)}

    def initial_state(self, p: Sequence[float] | None = None) -> np.ndarray:
        """Initial state vector, with free initial values taken from ``p``."""
        p = self.guess if p is None else np.asarray(p, dtype=float)
        index = {s: i for i, s in enumerate(self.parameter_symbols)}
        return np.array([p[index[s.initial_parameter]] + (s.initial if s.offset else 0.0) if s.free else s.initial
                         for s in self.states], dtype=float)

    # -- expressions ---------------------------------------------------------
    def expand(self, expr: sp.Expr) -> sp.Expr:
        """Substitute definitions and constants: the expression in terms of
        t, states, derivatives, inputs and local parameters only."""
        expr = sp.sympify(expr)
        defs = self._expanded_definitions
        hit = {s: defs[s] for s in expr.free_symbols if s in defs}
        if hit:
            expr = expr.xreplace(hit)
        return expr.xreplace({c: sp.Float(v) for c, v in self.constants})

    @cached_property
    def expanded_equations(self) -> tuple[sp.Expr, ...]:
        """The residuals ``F`` of :attr:`equations` expanded (:meth:`expand`), computed once per model: the
        simulation, the code generation, the fingerprint and the checks of a frozen model all need them."""
        return tuple(self.expand(e) for e in self.equations)

    @cached_property
    def _expanded_definitions(self) -> dict[sp.Symbol, sp.Expr]:
        """Each definition with the definitions it uses substituted, computed once
        (an expression such as ``Max(mach - 0.6, 0)`` is then built once per spec,
        not once per use); a definition may use one declared after it."""
        raw = dict(self.definitions)
        done: dict[sp.Symbol, sp.Expr] = {}

        def visit(sym: sp.Symbol, path: tuple) -> sp.Expr:
            if sym in done:
                return done[sym]
            if sym in path:
                cycle = " -> ".join(str(s) for s in (*path[path.index(sym):], sym))
                raise ModelError(f"model {self.name!r}: definitions refer to each other in a cycle ({cycle})")
            expr = raw[sym]
            deps = sorted((d for d in expr.free_symbols if d in raw), key=str)
            sub = {d: visit(d, (*path, sym)) for d in deps}
            done[sym] = _substituted(expr, sub) if sub else expr
            return done[sym]

        for sym in raw:
            visit(sym, ())
        return done

    @property
    def breakpoints(self) -> tuple[float, ...]:
        """Times where the right-hand side has kinks (families and inputs)."""
        pts = {self.t0, self.tf}
        for f in self.families:
            pts.update(f.breakpoints)
        for u in self.inputs:
            pts.update(u.breakpoints)
        pts.update(self.events)
        return tuple(sorted(b for b in pts if self.t0 <= b <= self.tf))

    def input_values(self, t: np.ndarray) -> np.ndarray:
        """Inputs evaluated at times t, shape (n, n_inputs)."""
        t = np.atleast_1d(np.asarray(t, dtype=float))
        out = np.empty((t.size, len(self.inputs)))
        for j, u in enumerate(self.inputs):
            if u.expr is not None:
                fn = sp.lambdify(self.t, u.expr, modules="numpy")
                out[:, j] = np.broadcast_to(np.asarray(fn(t), dtype=float), t.shape)
            else:
                out[:, j] = np.interp(t, u.times, u.values)
        return out

    def fingerprint(self) -> str:
        """A content hash of everything generated code depends on."""
        states = tuple((s.symbol, s.derivative) for s in self.states)
        inputs = tuple(u.symbol for u in self.inputs)
        local = tuple(self.local_symbols)
        equations = self.expanded_equations
        outputs = tuple((o.name, self.expand(o.expr)) for o in self.outputs)
        # the hash of a large expression's text costs 0.1-0.4 s on an ascent model with effects, and the
        # same model is prepared many times (each refit, its retry, the hold-out): kept by content
        key = (states, inputs, local, equations, outputs, self.t)
        hit = _FINGERPRINTS.get(key)
        if hit is None:
            parts = ["states", list(states), "inputs", list(inputs), "locals", list(local),
                     "equations", list(equations), "outputs", list(outputs), "time", self.t]
            hit = hashlib.sha256(sp.srepr(parts).encode()).hexdigest()
            if len(_FINGERPRINTS) >= 256:
                _FINGERPRINTS.clear()
            _FINGERPRINTS[key] = hit
        return hit

    def to_model(self) -> "Model":
        """An editable :class:`Model` with this specification's content."""
        if self._builder is None:
            raise ModelError("this ModelSpec was not made by Model.freeze()")
        return self._builder.copy()

    def with_guess(self, values: Mapping[sp.Symbol | str, float] | Sequence[float]) -> "ModelSpec":
        """A copy whose initial guesses are replaced."""
        p = self.parameter_vector(values)
        params = tuple(replace(ps, guess=float(v)) for ps, v in zip(self.parameters, p))
        builder = None
        if self._builder is not None:
            builder = self._builder.copy()
            builder._parameters = list(params)
        new = replace(self, parameters=params, _builder=builder)
        check_guess(new)
        return new

    def windowed(self, t0: float, tf: float, *, initial: Mapping[sp.Symbol | str, float] | None = None,
                 free: Iterable[sp.Symbol | str] = ()) -> "ModelSpec":
        """The same model on the window ``[t0, tf]`` of its horizon, starting in flight.

        Parameters
        ----------
        t0, tf : float
            The window, inside ``[self.t0, self.tf]``.
        initial : mapping, optional
            ``{state: value at t0}`` (default: the declared initial values); for a free state,
            its guess.
        free : iterable of states
            States whose value at ``t0`` is estimated: each gets a parameter ``<state>_0``
            (appended to the parameters, unbounded) with the guess from ``initial``. States
            that were free stay free.

        Returns
        -------
        ModelSpec
            Tables and inputs are unchanged. A time family's knot whose hat function vanishes
            on the window (it acts only outside it) is no longer a parameter: the knot takes
            the parameter of the nearest knot that acts in the window (the family is
            unchanged inside the window); :meth:`idle_knots` names them beforehand.

        Raises
        ------
        ModelError
            A window outside the horizon or empty, an unknown state, a non-finite value.
        """
        t0, tf = _float(t0, "window start"), _float(tf, "window end")
        tol = 1e-9 * max(1.0, abs(self.tf))
        if not tf > t0:
            raise ModelError(f"the window [{t0:g}, {tf:g}] is empty: its end must be after its start")
        if t0 < self.t0 - tol or tf > self.tf + tol:
            raise ModelError(f"the window [{t0:g}, {tf:g}] is not inside model {self.name!r}'s horizon "
                             f"[{self.t0:g}, {self.tf:g}]; choose a window inside it")
        t0, tf = max(t0, self.t0), min(tf, self.tf)
        init = {self.symbol(k) if isinstance(k, str) else k: _float(v, f"initial value of {k}")
                for k, v in (initial or {}).items()}
        free_syms = {self.symbol(k) if isinstance(k, str) else k for k in free}
        unknown = [str(k) for k in list(init) + list(free_syms) if k not in self.state_symbols]
        if unknown:
            raise ModelError(f"{', '.join(unknown)} is not a state of model {self.name!r}; its states are "
                             f"{', '.join(map(str, self.state_symbols))}")
        bad = [str(k) for k, v in init.items() if not math.isfinite(v)]
        if bad:
            raise ModelError(f"the initial value of {', '.join(bad)} at t = {t0:g} is not finite")
        builder = self.to_model()
        builder.t0, builder.tf = t0, tf
        states = []
        for st in self.states:
            value = init.get(st.symbol, st.initial)
            if st.free and st.offset:
                states.append(replace(st, initial=value))       # the offset now corrects the window's start
            elif st.free:
                builder._parameters = [replace(ps, guess=value) if ps.symbol == st.initial_parameter else ps
                                       for ps in builder._parameters]
                states.append(replace(st, initial=value))
            elif st.symbol in free_syms:
                ipar = builder._add_parameter(f"{st.symbol}_0", value, (-math.inf, math.inf), None)
                states.append(replace(st, initial=value, initial_parameter=ipar))
            else:
                states.append(replace(st, initial=value))
        builder._states = states
        idle = set(self.idle_knots(t0, tf))
        if idle:
            families = []
            for f in builder._families:
                active = [i for i, k in enumerate(f.knots) if k not in idle]
                knots = tuple(k if k not in idle else f.knots[min(active, key=lambda a: abs(a - i))]
                              for i, k in enumerate(f.knots))
                families.append(replace(f, knots=knots))
            builder._families = families
            builder._parameters = [ps for ps in builder._parameters if ps.symbol not in idle]
            for k in idle:
                builder._names.pop(str(k), None)
        return builder.freeze()

    def idle_knots(self, t0: float, tf: float) -> list[sp.Symbol]:
        """Knot parameters of time families whose hat functions all vanish on ``(t0, tf)``."""
        out = []
        for f in self.families:
            bp = np.asarray(f.breakpoints, float)
            idle: dict = {}
            for i, sym in enumerate(f.knots):
                lo, hi = bp[max(i - 1, 0)], bp[min(i + 1, bp.size - 1)]
                idle[sym] = idle.get(sym, True) and not (hi > t0 and lo < tf)
            out += [k for k, v in idle.items() if v and k not in out]
        return out

    def with_priors(self, priors: Mapping[sp.Symbol | str, Sequence]) -> "ModelSpec":
        """A copy with Gaussian priors added (or replaced): ``{parameter: (mean, sd)}`` or
        ``{parameter: (mean, sd, source)}`` (see :meth:`Model.prior`)."""
        m = self.to_model()
        for key, value in priors.items():
            try:
                mean, sd, *rest = value
            except (TypeError, ValueError):
                raise ModelError(f"prior on {key}: give (mean, sd) or (mean, sd, source), got {value!r}") from None
            m.prior(key, mean, sd, source=rest[0] if rest else "")
        return m.freeze()

    def summary(self) -> Summary:
        """A short description of the model: its components and coefficient families."""
        rows = [("states", ", ".join(map(str, self.state_symbols))),
                ("inputs", ", ".join(map(str, self.input_symbols)) or "-"),
                ("parameters", ", ".join(self.parameter_names)),
                ("outputs", ", ".join(f"{o.name} (sigma {o.sigma:g})" for o in self.outputs))]
        rows += [Text(f"family {f.symbol}: breakpoints {list(f.breakpoints)} -> knots {', '.join(map(str, f.knots))}")
                 for f in self.families]
        rows += [Text(f"prior {pr.symbol} ~ N({pr.mean:g}, {pr.sd:g}^2)" + (f" ({pr.source})" if pr.source else ""))
                 for pr in self.priors]
        if self.events:
            rows.append(("events", ", ".join(f"{e:g}" for e in self.events) + " s"))
        return Summary(f"Model {self.name!r}: t in [{self.t0:g}, {self.tf:g}]", (Section("", rows),), rule=False,
                       key_width=11)


# ---------------------------------------------------------------------------
# The builder
# ---------------------------------------------------------------------------


def _float(value, what: str) -> float:
    try:
        out = float(value)
    except (TypeError, ValueError):
        raise ModelError(f"{what} must be a number, got {value!r}") from None
    if math.isnan(out):
        raise ModelError(f"{what} is NaN")
    return out


class Model:
    """A mutable model declaration (the builder of a :class:`ModelSpec`).

    Parameters
    ----------
    name : str
        Model name (used in reports and cache keys).
    t0, tf : float
        Time horizon.
    time : str
        Name of the time symbol.
    description : str
        Free text shown in summaries.
    """

    def __init__(self, name: str, t0: float, tf: float, *, time: str = "t", description: str = ""):
        t0 = _float(t0, "t0")
        tf = _float(tf, "tf")
        if not tf > t0:
            raise ModelError(f"the time horizon must have tf > t0, got t0={t0}, tf={tf}")
        self.name = str(name)
        self.description = description
        self.t0, self.tf = t0, tf
        self.t = sp.Symbol(time)
        self._names: dict[str, sp.Symbol] = {time: self.t}
        self._states: list[StateSpec] = []
        self._inputs: list[InputSpec] = []
        self._constants: list[tuple[sp.Symbol, float]] = []
        self._parameters: list[ParameterSpec] = []
        self._families: list[FamilySpec] = []
        self._definitions: list[tuple[sp.Symbol, sp.Expr]] = []
        self._equations: dict[sp.Symbol, sp.Expr] = {}
        self._outputs: list[OutputSpec] = []
        self._roles: dict[str, sp.Expr] = {}
        self._tables: list[TableSpec] = []
        self._priors: list[PriorSpec] = []
        self._events: list[float] = []

    # -- attribute access ----------------------------------------------------
    def __getattr__(self, name: str) -> sp.Symbol:
        names = self.__dict__.get("_names")
        if names is not None and name in names:
            return names[name]
        raise AttributeError(f"model has no component named {name!r}")

    def copy(self) -> "Model":
        """An independent copy (SymPy expressions are immutable and shared)."""
        new = copy.copy(self)
        new._names = dict(self._names)
        new._states = list(self._states)
        new._inputs = list(self._inputs)
        new._constants = list(self._constants)
        new._parameters = list(self._parameters)
        new._families = list(self._families)
        new._definitions = list(self._definitions)
        new._equations = dict(self._equations)
        new._outputs = list(self._outputs)
        new._roles = dict(self.__dict__.get("_roles", {}))
        new._tables = list(self.__dict__.get("_tables", []))
        new._priors = list(self.__dict__.get("_priors", []))
        new._events = list(self.__dict__.get("_events", []))
        return new

    def remove_family(self, family: sp.Symbol | str) -> None:
        """Remove a time family and its knot parameters (to replace it by another
        parameterization: redefine every expression that uses it first).

        Raises
        ------
        ModelError
            Not a family of the model, or still used by an equation, definition or output.
        """
        sym = self._names.get(family) if isinstance(family, str) else family
        fam = next((f for f in self._families if f.symbol == sym), None)
        if fam is None:
            raise ModelError(f"{family} is not a family of model {self.name!r}")
        used = [str(k) for k, e in self._equations.items() if sym in e.free_symbols]
        used += [str(d) for d, e in self._definitions if sym in e.free_symbols]
        used += [o.name for o in self._outputs if sym in o.expr.free_symbols]
        if used:
            raise ModelError(f"family {sym} of model {self.name!r} is still used by {', '.join(used)}; redefine them "
                             "before removing it")
        knots = set(fam.knots)
        self._families = [f for f in self._families if f is not fam]
        self._parameters = [p for p in self._parameters if p.symbol not in knots]
        for s in knots | {sym}:
            self._names.pop(str(s), None)

    # -- physical roles --------------------------------------------------------
    def declare_role(self, role: str, expr: sp.Expr | str) -> None:
        """Declare that ``expr`` (a component, or an expression of them) plays ``role``.

        Parameters
        ----------
        role : str
            One of :data:`ROLES` (``"altitude"``, ``"speed"``, ``"mach"``, ``"thrust"``, ...).
        expr : sympy.Expr or str
            A symbol of this model (or its name), or an expression of its symbols
            (an attack angle written as ``theta_cmd - theta``).

        Examples
        --------
        >>> m = Model("user", 0.0, 10.0)
        >>> alt = m.state("alt", 0.0)
        >>> m.declare_role("altitude", alt)
        """
        if role not in ROLES:
            raise ModelError(f"unknown role {role!r}; roles are {', '.join(ROLES)}")
        if isinstance(expr, str):
            if expr not in self._names:
                raise ModelError(f"role {role!r}: model {self.name!r} has no component named {expr!r}")
            expr = self._names[expr]
        expr = sp.sympify(expr)
        unknown = {str(x) for x in expr.free_symbols} - set(self._names)
        if unknown:
            raise ModelError(f"role {role!r}: {', '.join(sorted(unknown))} is not a component of model {self.name!r}")
        self._roles[role] = expr

    def role(self, role: str) -> sp.Expr | None:
        """The symbol (or expression) declared for ``role``, or None."""
        if role not in ROLES:
            raise ModelError(f"unknown role {role!r}; roles are {', '.join(ROLES)}")
        return self._roles.get(role)

    def require_role(self, role: str, analysis: str) -> sp.Expr:
        """The symbol playing ``role``; a :class:`ModelError` saying that ``analysis`` needs it otherwise."""
        expr = self.role(role)
        if expr is None:
            raise ModelError(missing_role_message(self.name, role, analysis))
        return expr

    def _new_symbol(self, name: str) -> sp.Symbol:
        if not isinstance(name, str) or not name.isidentifier():
            raise ModelError(f"component names must be Python identifiers, got {name!r}")
        if name in self._names:
            raise ModelError(f"model {self.name!r} already has a component named {name!r}")
        sym = sp.Symbol(name)
        self._names[name] = sym
        return sym

    def _state(self, state: sp.Symbol | str) -> StateSpec:
        sym = self._names.get(state) if isinstance(state, str) else state
        for s in self._states:
            if s.symbol == sym:
                return s
        raise ModelError(f"{state} is not a state of model {self.name!r}; its states are "
                         f"{', '.join(str(s.symbol) for s in self._states) or 'none yet'}")

    # -- components ------------------------------------------------------------
    def state(self, name: str, initial: float, *, free: bool = False,
              bounds: tuple[float, float] = (-math.inf, math.inf), nominal: float | None = None) -> sp.Symbol:
        """Declare a state with its initial value.

        Parameters
        ----------
        name : str
        initial : float
            Initial value at ``t0`` (the guess when ``free``).
        free : bool
            Estimate the initial value: a parameter ``<name>_0`` is created.
        bounds, nominal
            Bounds and magnitude of that parameter.

        Returns
        -------
        sympy.Symbol
        """
        sym = self._new_symbol(name)
        der = self._new_symbol(f"d{name}_dt")
        initial = _float(initial, f"initial value of state {name}")
        ipar = None
        if free:
            ipar = self._add_parameter(f"{name}_0", initial, bounds, nominal)
        self._states.append(StateSpec(sym, der, initial, ipar))
        return sym

    def start_offset(self, state: sp.Symbol | str, name: str, *, nominal: float | None = None,
                     bounds: tuple[float, float] = (-math.inf, math.inf)) -> sp.Symbol:
        """Estimate a correction to a state's declared initial value: the start becomes
        ``initial + name`` (guess 0).

        For a start that was computed or read, not measured -- a rail-exit speed worked out for the
        nominal mass, a launch rail's elevation read off an inclinometer -- the correction's size
        says how far off the declaration was.

        Raises
        ------
        ModelError
            ``state`` is not a state, or its initial value is already estimated.
        """
        st = self._state(state)
        if st.free:
            raise ModelError(f"the initial value of state {st.symbol} is already estimated "
                             f"(parameter {st.initial_parameter}); it cannot take an offset too: declare the state "
                             "with its value and without free=True to estimate a correction to it, or keep it free")
        par = self._add_parameter(name, 0.0, bounds, nominal)
        self._states = [replace(s, initial_parameter=par, offset=True) if s.symbol == st.symbol else s
                        for s in self._states]
        return par

    def der(self, state: sp.Symbol | str) -> sp.Symbol:
        """The symbol standing for ``d state / dt`` (use it in implicit residuals)."""
        return self._state(state).derivative

    def input(self, name: str, expr: sp.Expr | None = None, *, times: Sequence[float] | None = None,
              values: Sequence[float] | None = None, breakpoints: Iterable[float] = ()) -> sp.Symbol:
        """Declare a known input: ``expr`` (a SymPy expression of ``m.t``) or
        sampled ``times``/``values`` (linearly interpolated).

        ``breakpoints`` lists times where the input has a kink; sampled inputs
        use their sample times.
        """
        sym = self._new_symbol(name)
        if (expr is None) == (times is None):
            raise ModelError(f"input {name}: give either expr=... or times=/values=, not both or neither")
        if expr is not None:
            expr = sp.sympify(expr)
            extra = expr.free_symbols - {self.t}
            if extra:
                raise ModelError(f"input {name} may depend on {self.t} only; it uses {', '.join(map(str, extra))}")
            self._inputs.append(InputSpec(sym, expr, breakpoints=tuple(sorted(float(b) for b in breakpoints))))
        else:
            tt = np.asarray(times, dtype=float).ravel()
            vv = np.asarray(values, dtype=float).ravel()
            if tt.shape != vv.shape or tt.size < 2:
                raise ModelError(f"input {name}: times and values must be 1-D of equal length >= 2")
            if not (np.all(np.isfinite(tt)) and np.all(np.isfinite(vv))):
                raise ModelError(f"input {name}: times and values must be finite (found NaN or inf)")
            if np.any(np.diff(tt) <= 0):
                raise ModelError(f"input {name}: times must be strictly increasing")
            self._inputs.append(InputSpec(sym, None, tuple(tt), tuple(vv), tuple(tt)))
        return sym

    def constant(self, name: str, value: float) -> sp.Symbol:
        """Declare a named constant (substituted by its value in generated code)."""
        sym = self._new_symbol(name)
        self._constants.append((sym, _float(value, f"constant {name}")))
        return sym

    def parameter(self, name: str, guess: float, *, bounds: tuple[float, float] = (-math.inf, math.inf),
                  nominal: float | None = None) -> sp.Symbol:
        """Declare a scalar parameter to estimate, with its guess and bounds."""
        return self._add_parameter(name, guess, bounds, nominal)

    def _add_parameter(self, name, guess, bounds, nominal, family=None) -> sp.Symbol:
        sym = self._new_symbol(name)
        guess = _float(guess, f"guess of parameter {name}")
        try:
            lo, hi = (_float(b, f"bound of parameter {name}") for b in bounds)
        except (TypeError, ValueError):
            raise ModelError(f"bounds of parameter {name} must be a pair (lower, upper), got {bounds!r}") from None
        if lo > hi:
            raise ModelError(f"parameter {name}: lower bound {lo} exceeds upper bound {hi}")
        if nominal is None:
            nominal = abs(guess) if guess != 0 else 1.0
        self._parameters.append(ParameterSpec(sym, guess, lo, hi, _float(nominal, f"nominal of {name}"), family))
        return sym

    def piecewise_linear(self, name: str, breakpoints: Sequence[float], guess: float | Sequence[float], *,
                         bounds: tuple[float, float] = (-math.inf, math.inf),
                         ties: Sequence[Sequence[int]] = (), nominal: float | None = None) -> sp.Symbol:
        """Declare a time-varying parameter, piecewise linear in time (7.4).

        Parameters
        ----------
        name : str
            Name of the family; knots are named ``<name>0``, ``<name>1``, ...
            (a family whose knots are all tied is constant in time: it is
            declared as one scalar parameter named ``<name>``).
        breakpoints : sequence of float
            Knot times, strictly increasing, from ``t0`` to ``tf``.
        guess : float or sequence of float
            Guess per knot (or one value for all).
        bounds : (float, float)
            Bounds of every knot value.
        ties : sequence of sequences of int
            Groups of knot indices that share one value, e.g. ``[(0, 1)]``.

        Returns
        -------
        sympy.Symbol
            The family's local value, to use in expressions.
        """
        bp = np.asarray(breakpoints, dtype=float).ravel()
        if bp.size < 2 or np.any(np.diff(bp) <= 0):
            raise ModelError(f"family {name}: breakpoints must be strictly increasing, at least two")
        if abs(bp[0] - self.t0) > 1e-12 or abs(bp[-1] - self.tf) > 1e-12:
            raise ModelError(f"family {name}: breakpoints must start at t0={self.t0:g} and end at tf={self.tf:g}")
        g = np.broadcast_to(np.asarray(guess, dtype=float), bp.shape) if np.ndim(guess) == 0 else np.asarray(guess, dtype=float)
        if g.shape != bp.shape:
            raise ModelError(f"family {name}: {g.size} guesses for {bp.size} breakpoints")
        owner = list(range(bp.size))
        for group in ties:
            group = sorted(int(i) for i in group)
            if any(i < 0 or i >= bp.size for i in group):
                raise ModelError(f"family {name}: tie {group} refers to a knot outside 0..{bp.size - 1}")
            for i in group:
                owner[i] = owner[group[0]]
        if len(set(owner)) == 1:
            # all knots tied: the family is a constant, declared as one scalar parameter
            if np.ptp(g) != 0:
                raise ModelError(f"family {name}: all knots are tied but their guesses differ ({list(g)})")
            return self._add_parameter(name, g[0], bounds, nominal)
        fam = self._new_symbol(name)
        knot_syms: dict[int, sp.Symbol] = {}
        for i in range(bp.size):
            o = owner[i]
            if o not in knot_syms:
                knot_syms[o] = self._add_parameter(f"{name}{o}", g[o], bounds, nominal, family=fam)
        self._families.append(FamilySpec(fam, tuple(float(b) for b in bp), tuple(knot_syms[owner[i]] for i in range(bp.size))))
        return fam

    def define(self, name: str, expr: sp.Expr) -> sp.Symbol:
        """Name an intermediate expression (air density, Mach, dynamic pressure...).

        The symbol can be used in dynamics and outputs and is substituted before
        differentiation; diagnostics evaluate definitions along trajectories.
        """
        sym = self._new_symbol(name)
        self._definitions.append((sym, sp.sympify(expr)))
        return sym

    def redefine(self, symbol: sp.Symbol | str, expr: sp.Expr) -> None:
        """Replace the expression of a definition (e.g. ``thrust`` by ``thrust -
        A_e p_a(h)``); the old expression may appear in the new one via
        :meth:`definition`."""
        sym = self._names.get(symbol) if isinstance(symbol, str) else symbol
        for i, (d, _) in enumerate(self._definitions):
            if d == sym:
                self._definitions[i] = (d, sp.sympify(expr))
                return
        raise ModelError(f"{symbol} is not a definition of model {self.name!r}; its definitions are "
                         f"{', '.join(str(d) for d, _ in self._definitions) or 'none'}")

    def definition(self, symbol: sp.Symbol | str) -> sp.Expr:
        """The current expression of a definition."""
        sym = self._names.get(symbol) if isinstance(symbol, str) else symbol
        for d, e in self._definitions:
            if d == sym:
                return e
        raise ModelError(f"{symbol} is not a definition of model {self.name!r}")

    def prior(self, parameter: sp.Symbol | str, mean: float, sd: float, *, source: str = "") -> None:
        """A Gaussian prior on an estimated parameter: what is known before the flight.

        Parameters
        ----------
        parameter : sympy.Symbol or str
            An estimated parameter (a knot of a family or table included).
        mean, sd : float
            The prior's mean and standard deviation (``sd > 0``), in the parameter's units.
        source : str
            Where the knowledge comes from (shown in reports), e.g. ``"wind tunnel"``.

        Examples
        --------
        >>> m = Model("decay", 0.0, 1.0)
        >>> y = m.state("y", 1.0)
        >>> k = m.parameter("k", 0.5, bounds=(0.0, 10.0))
        >>> m.ode({y: -k * y})
        >>> m.output("y", y, sigma=0.01)
        >>> m.prior(k, 1.2, 0.1, source="bench test")
        >>> m.freeze().priors[0].sd
        0.1
        """
        sym = self._names.get(parameter) if isinstance(parameter, str) else parameter
        if sym is None or sym not in {p.symbol for p in self._parameters}:
            raise ModelError(f"prior on {parameter}: not an estimated parameter of model {self.name!r}; its "
                             f"parameters are {', '.join(str(p.symbol) for p in self._parameters) or 'none'}")
        mean = _float(mean, f"prior mean of {sym}")
        sd = _float(sd, f"prior sd of {sym}")
        if not (math.isfinite(mean) and math.isfinite(sd) and sd > 0):
            raise ModelError(f"prior on {sym}: the mean must be finite and the sd positive and finite, got "
                             f"mean={mean:g}, sd={sd:g}")
        self._priors = [pr for pr in self.__dict__.get("_priors", []) if pr.symbol != sym]
        self._priors.append(PriorSpec(sym, mean, sd, str(source)))

    def event(self, time: float) -> None:
        """Declare an event time (a throttle change, a staging): the right-hand side may have a
        kink there, so the default mesh puts an element boundary and the simulator a stop at it."""
        t = _float(time, "event time")
        if not self.t0 <= t <= self.tf:
            return  # outside the horizon (a window of the flight): nothing to align
        events = self.__dict__.setdefault("_events", [])
        if t not in events:
            events.append(t)

    def has(self, name: str) -> bool:
        """Whether the model has a component with this name."""
        return name in self._names

    def table(self, name: str, variable: sp.Expr, knots: Sequence[float], guess: float | Sequence[float], *,
              bounds: tuple[float, float] = (-math.inf, math.inf), nominal: float | None = None) -> sp.Expr:
        """A coefficient that is piecewise linear in a flight-condition variable
        (Mach number, dynamic pressure, ...): one scalar parameter per knot
        ``<name>_<j>``, held constant beyond the first and last knot.

        Parameters
        ----------
        name : str
        variable : sympy.Expr
            The independent variable (e.g. the ``mach`` definition).
        knots : sequence of float
            Strictly increasing knot positions.
        guess : float or sequence of float
            Value at each knot.

        Returns
        -------
        sympy.Expr
            The interpolated coefficient: ``p_0 + sum_j (s_j - s_{j-1}) max(X - M_j, 0)``
            with ``s_j`` the slope of segment j (0 beyond the ends).
        """
        kn = np.asarray(knots, dtype=float).ravel()
        if kn.size < 2 or np.any(np.diff(kn) <= 0):
            raise ModelError(f"table {name}: knots must be strictly increasing, at least two")
        g = np.broadcast_to(np.asarray(guess, dtype=float), kn.shape) if np.ndim(guess) == 0 else np.asarray(guess, float)
        if g.shape != kn.shape:
            raise ModelError(f"table {name}: {g.size} guesses for {kn.size} knots")
        ps = [self._add_parameter(f"{name}_{j}", g[j], bounds, nominal) for j in range(kn.size)]
        X = sp.sympify(variable)
        vrole = next((r for r, e in self._roles.items() if e == X), None)
        self._tables.append(TableSpec(str(name), X, vrole, tuple(float(k) for k in kn), tuple(ps)))
        # exact piecewise-linear interpolation with flat ends, written with ramps
        # max(X - M_j, 0) instead of Piecewise conditions (cheap to substitute and
        # differentiate when X is itself piecewise, as Mach is)
        slopes = [(ps[j + 1] - ps[j]) / float(kn[j + 1] - kn[j]) for j in range(kn.size - 1)]
        expr = ps[0]
        prev = sp.S.Zero
        for j in range(kn.size - 1):
            expr += (slopes[j] - prev) * sp.Max(X - float(kn[j]), 0)
            prev = slopes[j]
        expr -= prev * sp.Max(X - float(kn[-1]), 0)
        return expr

    # -- equations ---------------------------------------------------------------
    def ode(self, rhs: Mapping[sp.Symbol, sp.Expr]) -> None:
        """Explicit dynamics ``d state/dt = rhs`` for each state given."""
        for state, expr in rhs.items():
            s = self._state(state)
            self._equations[s.symbol] = s.derivative - sp.sympify(expr)

    def implicit(self, residuals: Mapping[sp.Symbol, sp.Expr | sp.Eq]) -> None:
        """Implicit dynamics ``F(t, s, ds/dt, u, l) = 0``, one residual per state.

        A residual may be an expression (meaning ``expr = 0``) or a
        :class:`sympy.Eq`. It must contain the state's derivative symbol
        (``m.der(state)``), linearly.
        """
        for state, expr in residuals.items():
            s = self._state(state)
            if isinstance(expr, sp.Equality):
                expr = expr.lhs - expr.rhs
            expr = sp.sympify(expr)
            if s.derivative not in expr.free_symbols:
                raise ModelError(f"the implicit equation given for {s.symbol} does not contain "
                                 f"{s.derivative}; use m.der({s.symbol}) in it")
            self._equations[s.symbol] = expr

    def add_term(self, state: sp.Symbol | str, term: sp.Expr) -> None:
        """Add ``term`` to the right-hand side of ``d state/dt`` (for implicit
        equations the term is scaled by the derivative's coefficient)."""
        s = self._state(state)
        if s.symbol not in self._equations:
            raise ModelError(f"state {s.symbol} has no equation yet; declare it with ode() or implicit() first")
        eq = self._equations[s.symbol]
        coeff = sp.diff(eq, s.derivative)
        self._equations[s.symbol] = eq - coeff * sp.sympify(term)

    def substitute(self, mapping: Mapping[sp.Symbol, sp.Expr]) -> None:
        """Replace symbols by expressions in every equation, definition and output."""
        mapping = {k: sp.sympify(v) for k, v in mapping.items()}
        self._equations = {k: e.xreplace(mapping) for k, e in self._equations.items()}
        self._definitions = [(s, e.xreplace(mapping)) for s, e in self._definitions]
        self._outputs = [replace(o, expr=o.expr.xreplace(mapping)) for o in self._outputs]

    def output(self, name: str, expr: sp.Expr, sigma: float) -> None:
        """Declare a measured output (a data column named ``name``) with noise sigma."""
        if any(o.name == name for o in self._outputs):
            raise ModelError(f"model {self.name!r} already has an output named {name!r}")
        sigma = _float(sigma, f"sigma of output {name}")
        if not (sigma > 0 and math.isfinite(sigma)):
            raise ModelError(f"sigma of output {name} must be positive and finite, got {sigma}")
        if not SIGMA_RANGE[0] <= sigma <= SIGMA_RANGE[1]:
            raise ModelError(f"sigma of output {name} = {sigma:g} is out of scale (the weight 1/sigma^2 must be a "
                             f"finite positive number: {SIGMA_RANGE[0]:g} <= sigma <= {SIGMA_RANGE[1]:g})")
        self._outputs.append(OutputSpec(str(name), sp.sympify(expr), sigma))

    @property
    def output_names(self) -> tuple[str, ...]:
        """Names of the outputs declared so far."""
        return tuple(o.name for o in self._outputs)

    def output_expression(self, name: str) -> sp.Expr:
        """The current expression of the output ``name``."""
        for o in self._outputs:
            if o.name == name:
                return o.expr
        raise ModelError(f"model {self.name!r} has no output named {name!r}; its outputs are "
                         f"{', '.join(o.name for o in self._outputs) or 'none'}")

    def redefine_output(self, name: str, expr: sp.Expr) -> None:
        """Replace the expression of an output, keeping its sigma (a sensor effect:
        ``h`` becomes ``h + b_h``); the old expression is :meth:`output_expression`."""
        for i, o in enumerate(self._outputs):
            if o.name == name:
                self._outputs[i] = replace(o, expr=sp.sympify(expr))
                return
        raise ModelError(f"model {self.name!r} has no output named {name!r}; its outputs are "
                         f"{', '.join(o.name for o in self._outputs) or 'none'}")

    def set_sigma(self, name: str, sigma: float) -> None:
        """Change the noise standard deviation of an output."""
        for i, o in enumerate(self._outputs):
            if o.name == name:
                sigma = _float(sigma, f"sigma of output {name}")
                if not (sigma > 0 and math.isfinite(sigma)):
                    raise ModelError(f"sigma of output {name} must be positive and finite, got {sigma}")
                self._outputs[i] = replace(o, sigma=sigma)
                return
        raise ModelError(f"model {self.name!r} has no output named {name!r}")

    # -- freeze ------------------------------------------------------------------
    def freeze(self) -> ModelSpec:
        """Validate and return the immutable :class:`ModelSpec`."""
        if not self._states:
            raise ModelError(f"model {self.name!r} has no states")
        missing = [str(s.symbol) for s in self._states if s.symbol not in self._equations]
        if missing:
            raise ModelError(f"model {self.name!r}: no equation for state(s) {', '.join(missing)}; "
                             "add them with m.ode({state: rhs}) or m.implicit({state: residual})")
        if not self._outputs:
            raise ModelError(f"model {self.name!r} has no measured outputs; declare them with m.output(...)")
        spec = ModelSpec(
            name=self.name, t=self.t, t0=self.t0, tf=self.tf,
            states=tuple(self._states), inputs=tuple(self._inputs),
            constants=tuple(self._constants), parameters=tuple(self._parameters),
            families=tuple(self._families), definitions=tuple(self._definitions),
            equations=tuple(self._equations[s.symbol] for s in self._states),
            outputs=tuple(self._outputs), description=self.description, _builder=self.copy(),
            roles=tuple(self._roles.items()),
            # a table's variable gets its role also when the role is declared after the table
            tables=tuple(replace(tb, variable_role=next((r for r, e in self._roles.items() if e == tb.variable),
                                                        tb.variable_role)) for tb in self._tables),
            priors=tuple(pr for pr in self.__dict__.get("_priors", [])
                         if pr.symbol in {p.symbol for p in self._parameters}),
            events=tuple(sorted(self.__dict__.get("_events", []))),
        )
        _check_symbols(spec)
        check_guess(spec)
        return spec


#: A pure cache of definition substitutions: ``(expression, substitution) -> result``. A model
#: extended by an effect (and each of the many such models a diagnosis builds) repeats most of its
#: base model's substitutions; rebuilding ``Max(mach - 0.6, 0)`` of an expanded Mach number costs
#: SymPy about 0.1 s each time. Results are the same SymPy objects xreplace would build.
_SUBSTITUTED: dict = {}
_SUBSTITUTED_MAX = 20000

#: Fingerprints by model content (:meth:`ModelSpec.fingerprint`).
_FINGERPRINTS: dict = {}


def _substituted(expr: sp.Expr, sub: Mapping[sp.Symbol, sp.Expr]) -> sp.Expr:
    key = (expr, tuple(sub.items()))
    hit = _SUBSTITUTED.get(key)
    if hit is None:
        hit = expr.xreplace(sub)
        if len(_SUBSTITUTED) >= _SUBSTITUTED_MAX:
            _SUBSTITUTED.clear()
        _SUBSTITUTED[key] = hit
    return hit


def missing_role_message(model: str, role: str, analysis: str) -> str:
    """The error text for a model without the role an analysis needs."""
    return (f"{analysis} needs the {ROLES[role].split(' (')[0]} (role {role!r}), which model {model!r} does not "
            f"declare; the physics builders of rocketid.physics.ascent declare it, or declare it yourself with "
            f"m.declare_role({role!r}, symbol)")


def _check_symbols(spec: ModelSpec) -> None:
    allowed_dyn = ({spec.t} | set(spec.state_symbols) | set(spec.derivative_symbols)
                   | set(spec.input_symbols) | set(spec.local_symbols))
    for s, eq in zip(spec.states, spec.expanded_equations):
        extra = eq.free_symbols - allowed_dyn
        if extra:
            raise ModelError(_unknown_msg(spec, f"the equation of {s.symbol}", extra))
        d = sp.diff(eq, s.derivative)
        if set(spec.derivative_symbols) & d.free_symbols:
            raise ModelError(f"the equation of {s.symbol} is not linear in {s.derivative}")
    allowed_out = ({spec.t} | set(spec.state_symbols) | set(spec.derivative_symbols)
                   | {p.symbol for p in spec.parameters if p.family is None})
    for o in spec.outputs:
        extra = spec.expand(o.expr).free_symbols - allowed_out
        if extra:
            raise ModelError(_unknown_msg(spec, f"output {o.name}", extra)
                             + " (outputs may use t, states, their derivatives and scalar parameters)")


def _unknown_msg(spec: ModelSpec, where: str, extra: set) -> str:
    names = ", ".join(sorted(map(str, extra)))
    return (f"{where} of model {spec.name!r} uses {names}, which is not declared there; declare it "
            "with m.state, m.input, m.constant, m.parameter, m.piecewise_linear or m.define")


GUESS_SLACK = 1e-7
"""A guess this far outside a bound (relative to ``max(1, |bound|)``) is taken as on it: IPOPT relaxes every
bound by ``bound_relax_factor`` (1e-8 relative) and may return an estimate just past it, and a fit's estimates
given back as the next fit's guess must not be refused for that (the estimating function moves it onto the
bound)."""


def check_guess(spec: ModelSpec, values: Sequence[float] | None = None, *, where: str = "",
                error: type[Exception] = ModelError) -> None:
    """Refuse a guess outside the parameters' bounds (the one bounds check of a guess).

    Parameters
    ----------
    spec : ModelSpec
    values : sequence of float, optional
        A full parameter vector (default: the spec's own guesses).
    where : str
        Prefix of the message naming the input (``"--guess CL=2"``).
    error : exception type
        Raised with a message that names the parameter, its bounds and the fix.
    """
    p = spec.guess if values is None else np.asarray(values, dtype=float)
    for ps, v in zip(spec.parameters, p):
        lo, hi = ps.lower - GUESS_SLACK * max(1.0, abs(ps.lower)), ps.upper + GUESS_SLACK * max(1.0, abs(ps.upper))
        if not lo <= v <= hi:
            raise error((f"{where}: " if where else "") + f"the guess {v:g} of parameter {ps.symbol} lies outside "
                        f"its bounds [{ps.lower:g}, {ps.upper:g}]; move the guess inside or widen the bounds")
