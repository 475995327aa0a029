"""High-accuracy simulation of a model with SciPy, and synthetic measurements.

This is the source of truth data. It shares nothing with the collocation
code used to estimate: it integrates the model's equations, solved for the
derivatives, with ``scipy.integrate.solve_ivp``.

Two details make tight tolerances meaningful on ascent models (docs/design.md
section 1):

* the integrator works on deviations from the initial state, ``s - s(t0)``,
  so that a flight-path angle near 1.57 rad does not eat the relative
  tolerance;
* an implicit equation ``a(s) ds/dt = b(s)`` whose coefficient vanishes
  (``v dtheta/dt = ...`` at rest) is guarded: while ``|a|`` is below
  ``guard`` the derivative is held at zero. At a launch from rest this picks
  the solution that leaves the pad vertically (the constant ``C = 0`` of the
  homogeneous ``C t^(g/a)`` family).

The integration is split at every breakpoint of the model (parameter
families, input kinks), where the right-hand side is not smooth.
"""

from __future__ import annotations

import functools
import time
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np
import sympy as sp
from scipy.integrate import solve_ivp

from .data import Channel, Measurements
from .errors import ModelError, RocketidError, SettingsError
from .model import ModelSpec
from .printing import WherePrinter

__all__ = ["Trajectory", "simulate", "simulate_measurements"]


@dataclass(frozen=True)
class Trajectory:
    """A simulated trajectory.

    Attributes
    ----------
    spec : ModelSpec
    p : ndarray, shape (n_p,)
        Parameters it was simulated with.
    times : ndarray, shape (n,)
    states : ndarray, shape (n, n_states)
    success : bool
    message : str
    derivatives : ndarray, shape (n, n_states), or None
        ``ds/dt`` at :attr:`times`, when an output uses a state derivative.
    """

    spec: ModelSpec
    p: np.ndarray
    times: np.ndarray
    states: np.ndarray
    success: bool = True
    message: str = ""
    derivatives: np.ndarray | None = None

    def value(self, symbol: sp.Symbol | str) -> np.ndarray:
        """A state's history, or a definition/output expression evaluated along it."""
        sym = self.spec.symbol(symbol)
        if sym in self.spec.state_symbols:
            return self.states[:, self.spec.state_symbols.index(sym)]
        for d, expr in self.spec.definitions:
            if d == sym:
                return evaluate_along(self.spec, expr, self.times, self.states, self.p)
        raise ModelError(f"{sym} is not a state or definition of model {self.spec.name!r}")

    def outputs(self) -> dict[str, np.ndarray]:
        """Each output's noise-free values at :attr:`times`."""
        return {o.name: evaluate_along(self.spec, o.expr, self.times, self.states, self.p, self.derivatives)
                for o in self.spec.outputs}


def _locals_at(spec: ModelSpec, t: np.ndarray, p: np.ndarray) -> list[np.ndarray]:
    """Local parameter values (families interpolated) at times t."""
    values = spec.parameter_dict(p)
    fams = {f.symbol: f for f in spec.families}
    out = []
    for sym in spec.local_symbols:
        if sym in fams:
            out.append(fams[sym].evaluate(t, values))
        else:
            out.append(np.full(np.shape(t), values[sym]))
    return out


_ALONG_PRINTER = WherePrinter({"fully_qualified_modules": True, "inline": True, "allow_unknown_functions": True})


def evaluate_along(spec: ModelSpec, expr: sp.Expr, times: np.ndarray, states: np.ndarray,
                   p: np.ndarray, derivatives: np.ndarray | None = None) -> np.ndarray:
    """Evaluate an expression of (t, states, derivatives, inputs, parameters) along a trajectory."""
    expr = spec.expand(expr)
    times = np.asarray(times, dtype=float)
    # only the symbols the expression holds are arguments, so that a model with more parameters (an effect
    # added) evaluates an unchanged expression with the function already compiled: the cache is keyed on them
    # (scalar parameters may appear directly, in outputs: they are local symbols too)
    used = expr.free_symbols
    groups = (((spec.t,), lambda: (times,)),
              (spec.state_symbols, lambda: tuple(states.T)),
              (spec.derivative_symbols,
               lambda: tuple((derivatives if derivatives is not None else np.full_like(states, np.nan)).T)),
              (spec.input_symbols, lambda: tuple(spec.input_values(times).T)),
              (spec.local_symbols, lambda: tuple(_locals_at(spec, times, p))))
    args, values = [], []
    for symbols, make in groups:
        pick = [j for j, sym in enumerate(symbols) if sym in used]
        if pick:
            made = make()
            args += [symbols[j] for j in pick]
            values += [made[j] for j in pick]
    key = (expr, tuple(args))
    fn = _ALONG_CACHE.get(key)
    if fn is None:
        if len(_ALONG_CACHE) >= 4 * _CACHE_MAX:
            _ALONG_CACHE.clear()
        # nested numpy.where for Piecewise: an output may hold the dynamics (time_offset_2), whose layered
        # atmosphere inside a Mach table's conditions numpy.select cannot take
        fn = _ALONG_CACHE[key] = sp.lambdify(args, expr, modules=[{"functools": functools, "numpy": np}, "numpy"],
                                             printer=_ALONG_PRINTER, cse=True)
    with np.errstate(all="ignore"):
        val = fn(*values)
    return np.broadcast_to(np.asarray(val, dtype=float), times.shape).copy()


#: Compiled right-hand sides by model content: a diagnosis simulates the same model many times (the
#: start of every fit, the noise band, the hold-out predictions), and ``lambdify`` with common
#: subexpressions costs 0.1-0.2 s on an ascent model each time. Pure: the same function for the same
#: equations and argument order.
_RHS_CACHE: dict = {}
_INPUT_CACHE: dict = {}
_ALONG_CACHE: dict = {}
_CACHE_MAX = 64


def _compiled_rhs(spec: ModelSpec) -> tuple:
    """``(fn, diagonal, n)``: ``fn(t, s, u, l)`` returns the entries of ``A`` (row-major) and ``b``
    of ``F = A ds/dt + b``; ``diagonal`` when ``A`` is."""
    ders = spec.derivative_symbols
    F = spec.expanded_equations
    args = (spec.t, *spec.state_symbols, *spec.input_symbols, *spec.local_symbols)
    key = (F, ders, args)
    hit = _RHS_CACHE.get(key)
    if hit is not None:
        return hit
    A = sp.Matrix([[sp.diff(f, d) for d in ders] for f in F])
    b = sp.Matrix([f.xreplace({d: 0 for d in ders}) for f in F])
    if any(dd in A.free_symbols for dd in ders):
        raise ModelError("the equations are not linear in the state derivatives")
    diagonal = all(A[i, j] == 0 for i in range(len(F)) for j in range(len(F)) if i != j)
    exprs = list(A) + list(b)
    try:
        fn = sp.lambdify(args, exprs, modules=["math"], cse=True)
        fn(spec.t0 + 0.0, *([0.5] * (len(args) - 1)))
    except (TypeError, NameError, ValueError, ZeroDivisionError, OverflowError):
        fn = sp.lambdify(args, exprs, modules="numpy", cse=True)
    if len(_RHS_CACHE) >= _CACHE_MAX:
        _RHS_CACHE.clear()
    _RHS_CACHE[key] = hit = (fn, diagonal, len(F))
    return hit


def _compiled_input(t: sp.Symbol, expr: sp.Expr):
    key = (t, expr)
    fn = _INPUT_CACHE.get(key)
    if fn is None:
        if len(_INPUT_CACHE) >= _CACHE_MAX:
            _INPUT_CACHE.clear()
        fn = _INPUT_CACHE[key] = sp.lambdify(t, expr, modules=["math"])
    return fn


class _GaveUp(Exception):
    """Raised inside the right-hand side when the simulation's wall-time limit has passed."""

    def __init__(self, t: float):
        super().__init__(t)
        self.t = float(t)


class _RHS:
    """``ds/dt`` from the residuals ``F = A(s) ds/dt + b(s)``, with the guard."""

    def __init__(self, spec: ModelSpec, p: np.ndarray, guard: float):
        self.spec = spec
        self._fn, self.diagonal, self.n = _compiled_rhs(spec)
        self.p = p
        self.guard = guard
        self.values = spec.parameter_dict(p)
        self.families = {f.symbol: f for f in spec.families}
        # the local values in argument order: a family's is interpolated at each call, a scalar's is fixed
        self._locals = tuple((sym, self.families.get(sym)) for sym in spec.local_symbols)
        self._inputs = []
        for u in spec.inputs:
            if u.expr is not None:
                f = _compiled_input(spec.t, u.expr)
                self._inputs.append(f)
            else:
                tt, vv = np.asarray(u.times), np.asarray(u.values)
                self._inputs.append(lambda t, tt=tt, vv=vv: float(np.interp(t, tt, vv)))
        self.s0 = None
        self.guarded = False
        self.deadline = None

    def locals_(self, t: float) -> list[float]:
        values = self.values
        return [values[sym] if fam is None else float(fam.evaluate(t, values)) for sym, fam in self._locals]

    def __call__(self, t: float, ds: np.ndarray) -> np.ndarray:
        if self.deadline is not None and time.perf_counter() > self.deadline:
            raise _GaveUp(t)
        s = self.s0 + ds
        vals = self._fn(t, *s, *(f(t) for f in self._inputs), *self.locals_(t))
        n = self.n
        if self.diagonal:
            # ds_i/dt = -b_i / a_ii, held at zero where |a_ii| is below the guard (element by element in
            # Python: the same IEEE operations as NumPy's, without its per-call overhead on n = 4)
            out = np.empty(n)
            guard = self.guard
            for i in range(n):
                a = float(vals[i * (n + 1)])
                if abs(a) < guard:
                    out[i] = 0.0
                    self.guarded = True
                else:
                    out[i] = -float(vals[n * n + i]) / a
            return out
        A = np.asarray(vals[: n * n], dtype=float).reshape(n, n)
        b = np.asarray(vals[n * n:], dtype=float)
        return np.linalg.solve(A, -b)


#: A sampled input's sample is a kink where its slope changes by more than this many times the
#: slope changes at the two samples either side (a smooth signal sampled at step h changes slope
#: by about h |u''| at every sample, nearly the same from one sample to the next; a kink changes
#: it by a finite amount whatever h).
KINK_FACTOR = 10.0


def sampled_kinks(times: np.ndarray, values: np.ndarray) -> np.ndarray:
    """The interior sample times of a sampled input where it has a kink (see :data:`KINK_FACTOR`).

    The integrator restarts only there: across the other samples the linear interpolant is
    smooth enough for its step-size control (restarting at every sample of a 10 ms input made
    a 66 s simulation 6600 integrations).
    """
    t = np.asarray(times, float)
    v = np.asarray(values, float)
    if t.size < 3:
        return np.empty(0)
    slope = np.diff(v) / np.diff(t)
    change = np.abs(np.diff(slope))
    floor = 1e-9 * max(1e-300, float(np.max(np.abs(slope))))   # rounding, not a kink
    padded = np.concatenate([np.zeros(2), change, np.zeros(2)])
    around = np.max(np.stack([padded[k:k + change.size] for k in (0, 1, 3, 4)]), axis=0)
    return t[1:-1][(change > floor) & (change > KINK_FACTOR * around)]


def _segment_points(spec: ModelSpec) -> list[float]:
    """Where the integration restarts: the horizon's ends, the families' breakpoints, the
    declared kinks of expression inputs and the kinks of sampled inputs."""
    pts = {spec.t0, spec.tf}
    for f in spec.families:
        pts.update(f.breakpoints)
    for u in spec.inputs:
        if u.expr is not None:
            pts.update(u.breakpoints)
        else:
            pts.update(float(b) for b in sampled_kinks(np.asarray(u.times), np.asarray(u.values)))
    return sorted(b for b in pts if spec.t0 <= b <= spec.tf)


def simulate(spec: ModelSpec, p: Sequence[float] | Mapping | None = None, times: Sequence[float] | None = None,
             *, rtol: float = 1e-12, atol: float = 1e-12, method: str = "DOP853",
             initial_state: Sequence[float] | None = None, guard: float = 1e-9,
             max_wall_time: float | None = None) -> Trajectory:
    """Integrate ``spec`` at parameters ``p`` with SciPy.

    Parameters
    ----------
    spec : ModelSpec
    p : mapping or sequence, optional
        Parameters (default: the model's guesses). A mapping may give a subset.
    times : sequence of float, optional
        Output times (default: 1001 points over the horizon).
    rtol, atol : float
        Tolerances of ``solve_ivp`` (on deviations from the initial state).
    method : str
        ``solve_ivp`` method.
    initial_state : sequence of float, optional
        Overrides the model's initial state (Table 7.3's perturbed starts).
    guard : float
        Below this magnitude an implicit derivative coefficient is treated as zero.
    max_wall_time : float, optional
        Give up after this many seconds of wall time: the trajectory is then
        returned with ``success`` False, NaN beyond the time reached and a
        message that says so (a stiff or crawling integration cannot hang a caller).

    Returns
    -------
    Trajectory
    """
    pvec = spec.parameter_vector(p)
    if times is None:
        times = np.linspace(spec.t0, spec.tf, 1001)
    times = np.asarray(times, dtype=float)
    if times.ndim != 1 or np.any(np.diff(times) < 0):
        raise SettingsError("simulation times must be a sorted 1-D sequence")
    if times.size and (times[0] < spec.t0 - 1e-12 or times[-1] > spec.tf + 1e-12):
        raise SettingsError(f"simulation times must lie in [{spec.t0:g}, {spec.tf:g}]")
    s0 = spec.initial_state(pvec) if initial_state is None else np.asarray(initial_state, dtype=float)
    rhs = _RHS(spec, pvec, guard)
    rhs.s0 = s0
    if max_wall_time is not None:
        if not max_wall_time > 0:
            raise SettingsError(f"max_wall_time must be a positive number of seconds, got {max_wall_time!r}")
        rhs.deadline = time.perf_counter() + float(max_wall_time)
    bps = _segment_points(spec)
    out = np.full((times.size, s0.size), np.nan)
    ds = np.zeros_like(s0)
    ok, msg = True, "integration successful"
    for a, b in zip(bps[:-1], bps[1:]):
        sel = (times >= a) & (times <= b) if b == bps[-1] else (times >= a) & (times < b)
        try:
            sol = solve_ivp(rhs, (a, b), ds, method=method, rtol=rtol, atol=atol, dense_output=True)
        except _GaveUp as stop:
            ok, msg = False, (f"gave up after {max_wall_time:g} s of wall time (max_wall_time) at t = {stop.t:.4g} s "
                              f"of [{spec.t0:g}, {spec.tf:g}]")
            break
        except (ZeroDivisionError, OverflowError, ValueError) as exc:
            # the right-hand side evaluated where it is not defined (a division by a mass or speed that
            # reached zero, a square root of a negative number): the trajectory ends here, as a failure
            # the callers report (Wren-H with 1.5 kg of oxidiser vented: the start simulation crashed)
            ok, msg = False, (f"integration failed on [{a:g}, {b:g}]: the equations could not be evaluated "
                              f"({type(exc).__name__}: {exc})")
            break
        if not sol.success:
            ok, msg = False, f"integration failed on [{a:g}, {b:g}]: {sol.message}"
            break
        if sel.any():
            out[sel] = s0 + sol.sol(times[sel]).T
        ds = sol.y[:, -1]
    if ok and rhs.guarded:
        msg += f"; implicit derivatives held at zero where their coefficient was below {guard:g} (singular start)"
    ders = None
    if any(set(spec.derivative_symbols) & spec.expand(o.expr).free_symbols for o in spec.outputs):
        # outputs such as x + b dx/dt need ds/dt along the trajectory
        ders = np.full_like(out, np.nan)
        for i, (ti, si) in enumerate(zip(times, out)):
            if np.all(np.isfinite(si)):
                ders[i] = rhs(float(ti), si - s0)
    return Trajectory(spec, pvec, times, out, ok, msg, ders)


def simulate_measurements(spec: ModelSpec, p: Sequence[float] | Mapping | None = None,
                          times: Sequence[float] | None = None, *, seed: int | None = 0,
                          noise: bool = True, rtol: float = 1e-12, atol: float = 1e-12,
                          sigma: Mapping[str, float] | None = None) -> Measurements:
    """Synthetic measurements: a high-accuracy simulation plus seeded Gaussian noise.

    Noise is drawn with ``numpy.random.default_rng(seed)``, channel after
    channel in the order of the model's outputs, N(0, sigma^2) with each
    output's sigma (or ``sigma[name]``).

    Returns
    -------
    Measurements
    """
    if seed is not None and (isinstance(seed, bool) or not isinstance(seed, (int, np.integer)) or seed < 0):
        raise SettingsError(f"seed must be a non-negative integer or None, got {seed!r}")
    traj = simulate(spec, p, times, rtol=rtol, atol=atol)
    if not traj.success:
        raise RocketidError(f"cannot make measurements: {traj.message}")
    rng = np.random.default_rng(seed)
    sigma = dict(sigma or {})
    chans = []
    for name, y in traj.outputs().items():
        sd = sigma.get(name, next(o.sigma for o in spec.outputs if o.name == name))
        val = y + rng.normal(0.0, sd, y.size) if noise else y
        chans.append(Channel(name, traj.times, val, sd))
    return Measurements(tuple(chans))
