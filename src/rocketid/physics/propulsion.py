"""Propulsion building blocks: a throttle schedule that scales thrust and mass flow together.

A liquid engine throttled to a setting ``tau`` (1 = full thrust) gives ``tau`` times its
thrust and burns ``tau`` times its propellant flow. With the setting piecewise linear in time
through the schedule's event times, the mass has a closed form::

    tau(t)  = L_0 + sum_j (s_j - s_{j-1}) max(t - b_j, 0)          (flat before b_0, after b_n)
    m(t)    = m_0 - mdot * integral_{t0}^{t} tau(s) ds
            = m_0 - mdot * (L_0 (t - t0) + sum_j (s_j - s_{j-1}) (max(t - b_j, 0)^2 - max(t0 - b_j, 0)^2) / 2)

with ``b_j`` the event times, ``L_j`` the settings there and ``s_j`` the slope of segment j
(``s_{-1} = s_n = 0``). The levels may be numbers (a known schedule: an input) or estimated
parameters (an effect to estimate); the event times are declared as model events
(:meth:`rocketid.model.Model.event`), so that the default mesh has an element boundary at
each of them.

Notation
--------
=========  ==============================================================
``tau``    throttle setting (fraction of the full thrust and mass flow)
``b_j``    event times (breakpoints of the schedule), s
``L_j``    settings at the event times
``mdot``   propellant mass flow at full throttle, kg/s
=========  ==============================================================
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Sequence

import numpy as np
import sympy as sp

from ..errors import ModelError
from ..model import Model

__all__ = ["ThrottleSchedule", "throttle_schedule", "throttled_propulsion"]


@dataclass(frozen=True)
class ThrottleSchedule:
    """A throttle schedule declared on a model.

    Attributes
    ----------
    setting : sympy.Symbol
        The definition ``throttle`` (``tau(t)``), usable in expressions.
    integral : sympy.Expr
        ``integral_{t0}^{t} tau ds`` (s), closed form.
    times : tuple of float
        The event times.
    levels : tuple
        The setting at each event time: numbers or parameter symbols.
    """

    setting: sp.Symbol
    integral: sp.Expr
    times: tuple
    levels: tuple

    def evaluate(self, t: Sequence[float], values: dict | None = None) -> np.ndarray:
        """``tau`` at times ``t`` for parameter ``values`` (``{symbol: value}``, for estimated levels)."""
        vals = dict(values or {})
        lv = [float(vals[L]) if isinstance(L, sp.Symbol) else float(L) for L in self.levels]
        return np.interp(np.asarray(t, float), self.times, lv)


def _ramp_form(t: sp.Symbol, t0: float, times: Sequence[float], levels: Sequence[sp.Expr]) -> tuple:
    """``(tau(t), integral_{t0}^t tau)`` of the piecewise-linear schedule, written with ramps."""
    b = [float(x) for x in times]
    L = [sp.sympify(x) for x in levels]
    slopes = [(L[j + 1] - L[j]) / (b[j + 1] - b[j]) for j in range(len(b) - 1)] + [sp.S.Zero]
    tau = L[0]
    integral = L[0] * (t - t0)
    prev = sp.S.Zero
    for j, bj in enumerate(b):
        c = slopes[j] - prev
        prev = slopes[j]
        if c == 0:
            continue
        ramp = sp.Max(t - bj, 0)
        tau += c * ramp
        integral += c * (ramp ** 2 - max(t0 - bj, 0.0) ** 2) / 2
    return tau, integral


def throttle_schedule(m: Model, times: Sequence[float], levels: Sequence, *, name: str = "throttle") -> ThrottleSchedule:
    """Declare a throttle setting, piecewise linear in time through ``(times[j], levels[j])``.

    Parameters
    ----------
    m : Model
    times : sequence of float
        Event times (strictly increasing), s. Before the first and after the last the setting
        is constant. Each is declared as a model event (an element boundary of the mesh).
    levels : sequence of float or sympy.Symbol
        The setting at each time: a number (known) or a parameter of ``m`` (estimated, e.g.
        ``m.parameter("tau_1", 0.8, bounds=(0.4, 1.0))``).
    name : str
        Name of the setting's definition.

    Returns
    -------
    ThrottleSchedule

    Examples
    --------
    >>> from rocketid.model import Model
    >>> m = Model("stage", 0.0, 100.0)
    >>> thr = throttle_schedule(m, [40.0, 50.0, 70.0, 80.0], [1.0, 0.7, 0.7, 1.0])
    >>> [float(v) for v in thr.evaluate([0.0, 45.0, 60.0, 90.0])]
    [1.0, 0.85, 0.7, 1.0]
    """
    b = np.asarray(times, dtype=float).ravel()
    if b.size < 1 or not np.all(np.isfinite(b)) or np.any(np.diff(b) <= 0):
        raise ModelError(f"throttle schedule {name}: times must be finite and strictly increasing, got {list(b)}")
    if len(levels) != b.size:
        raise ModelError(f"throttle schedule {name}: {len(levels)} levels for {b.size} times; give one level per time")
    params = {p.symbol for p in m._parameters}
    lv = []
    for j, L in enumerate(levels):
        if isinstance(L, sp.Symbol):
            if L not in params:
                raise ModelError(f"throttle schedule {name}: level {j} is {L}, which is not a parameter of model "
                                 f"{m.name!r}; declare it with m.parameter(...) first or give a number")
            lv.append(L)
        else:
            try:
                v = float(L)
            except (TypeError, ValueError):
                raise ModelError(f"throttle schedule {name}: level {j} must be a number or a parameter symbol, "
                                 f"got {L!r}") from None
            if not np.isfinite(v):
                raise ModelError(f"throttle schedule {name}: level {j} is not finite")
            lv.append(sp.Float(v))
    tau, integral = _ramp_form(m.t, m.t0, b, lv)
    setting = m.define(name, tau)
    for tb in b:
        m.event(float(tb))
    return ThrottleSchedule(setting, integral, tuple(float(x) for x in b),
                            tuple(L if isinstance(L, sp.Symbol) else float(L) for L in lv))


def throttled_propulsion(m: Model, throttle: ThrottleSchedule, *, thrust: sp.Expr, mass0: float | sp.Expr,
                         mass_flow: float | sp.Expr) -> tuple[sp.Expr, sp.Expr]:
    """Thrust and mass of a throttled engine: ``(thrust * tau, mass0 - mass_flow * integral tau)``.

    Parameters
    ----------
    throttle : ThrottleSchedule
        From :func:`throttle_schedule`.
    thrust : sympy.Expr
        Full-throttle thrust (may depend on altitude, e.g. vacuum thrust minus nozzle area times
        ambient pressure).
    mass0 : float or sympy.Expr
        Mass at ``t0``, kg.
    mass_flow : float or sympy.Expr
        Propellant mass flow at full throttle, kg/s (constant in time).

    Returns
    -------
    (thrust, mass) : sympy.Expr
        To pass to :func:`rocketid.physics.ascent.ascent_dynamics`.
    """
    mdot = sp.sympify(mass_flow)
    if m.t in mdot.free_symbols:
        raise ModelError("throttled_propulsion: mass_flow must be constant in time (the throttle makes it vary)")
    return sp.sympify(thrust) * throttle.setting, sp.sympify(mass0) - mdot * throttle.integral
