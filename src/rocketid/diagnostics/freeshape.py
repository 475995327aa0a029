"""The free-shape check: when the catalogue leaves the fit above the noise, the free shape the verdict names,
fitted.

::

    screen -> refit -> accept -> step -> free shape -> report

A verdict of "partly explained" with the final model above the noise, or "not explained by the catalogue",
ends with what to try: a term of free shape of the kind of the search's first effect added that has one
(the screen's first candidate when it added none; ``api._lead``): a thrust error in time for a propulsion or mass effect,
a wind or density profile in altitude for the environment, a drag correction in Mach for the aerodynamics.
(The screen alone misled: on Wren-H's cold tank it ranked a density profile first, and its free shape
beside the search's effects reached the noise with the density 36-72 % low at every altitude.) This step makes that suggestion a measurement: the user's
model with the free shape (:func:`free_shape_for`), fitted to the same data with the same noise, and -- when
that alone stays above the noise and the search kept effects of other kinds -- those effects with it; then the
kinds of the search's other effects, the screen's first candidate's and the thrust's in turn (``api._leads``),
until one reaches the noise. A shape that reaches the noise beside the search's effects is then fitted without
each in turn, and keeps only those it needs (backward elimination to the noise); the effects of other kinds it
does without are named (:attr:`FreeShape.not_needed`): on Wren-H's grain 13 mm short with its GPS altitude 15 m
low the thrust's shape reached the noise beside the altitude bias and two drag shapes, and keeps the bias alone
(-12.2 m for -15), the drag shapes not needed.

What it says is of what **kind** the missing physics is and what it looks like, not what it is. A free shape
of tens of parameters absorbs what it can, effects of other kinds among them (measured on Wren-H: a thrust
error on the burn's element boundaries reaches chi2/dof 1.02 on a hot tank *with* a day 15 K warmer),
and its values are not judged by the catalogue's sizes: it is never an explanation, never changes the
verdict, and its reading is the shape's, for the user to name the physics that makes it and state it as an
effect of their own (:func:`~rocketid.diagnostics.effects.custom_effect`).

Measured on Wren-H's motor cases (a nitrous-oxide hybrid whose tank temperature or grain changes thrust and
mass flow through the burn, outside the catalogue's shapes; ``tests/wren_study``): the hot tank (26 C for the
static firing's 20 C) ends "partly explained" at chi2/dof 12.1; its base model with the thrust error in
time on the burn's 31 element boundaries reaches 1.011 (from 929, the noise from the data), reading +7.5 to
+12 % over 2-7.5 s (the tank's 58 bar for 50.6) and -80 % at 9.3-10.5 s (the liquid out a second early);
the cold tank, the burn-through and the pad hold reach 0.93, 0.94 and 1.00 with the truth's sigmas.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Sequence

import numpy as np

from ..errors import RocketidError
from ..solve import EstimationResult, estimate
from .accept import NoiseBand, fits_to_noise
from .effects import (DENSITY_KNOT_INTERVALS, WIND_KNOT_INTERVALS, Effect, Vehicle, _drag_mach_knots,
                      _powered_knots, _profile_knots_km, _wind_knots_km, density_profile_effect, drag_mach_effect,
                      thrust_profile_effect, wind_profile_effect, with_effects)

__all__ = ["FreeShape", "free_shape_for", "free_shape_check", "FREE_SHAPE_KINDS"]

#: The kinds of catalogue effect a free shape is tried for (a sensor's has none: its suggestion is a sensor
#: model of the failing channel).
FREE_SHAPE_KINDS = ("propulsion", "mass", "environment", "aero")

#: At most this many knots in time: the boundaries nearest to as many evenly spaced times when the burn has
#: more (a 66 s burn on 1 s elements). Wren-H's 15.5 s burn has 31.
MAX_TIME_KNOTS = 32

#: IPOPT's iteration limit for a free shape's fit (unless the options set one): the shapes that reach the noise
#: on Wren-H converge in tens of iterations; a wind on 13 knots far from the noise ran IPOPT's default 3000 to
#: no end (24 s of the 54 a vented tank's check took).
MAX_ITER = 500

#: Consecutive knots whose values lie within this of their run's median are read as one run (a thrust error
#: of 0.05: two and a half of the catalogue's realistic thrust errors).
RUN_TOLERANCE = {"propulsion": 0.05, "environment_wind": 3.0, "environment_density": 0.02, "aero": 0.03}


@dataclass(frozen=True)
class FreeShape:
    """The free shape fitted (:func:`free_shape_check`).

    Attributes
    ----------
    kind : str
        The kind of the screen's first candidate the shape stands for.
    effect : str
        The shape's name (``thrust_profile_34``).
    description : str
    kept : tuple of str
        The search's effects fitted with it (empty: the user's model with the shape alone).
    chi2_per_dof : float
        Of that fit (NaN when it failed).
    base_chi2_per_dof : float
        Of the fit it was added to.
    reaches_noise : bool
        chi2/dof inside the noise band and the residuals white.
    detail : str
        The noise band's words.
    knots : tuple of float
        Where the shape's values sit (s, km or Mach).
    values : tuple of float
        The shape's values at its knots.
    unit : str
    reading : str
        The shape in words: its runs of like values.
    seconds : float
    message : str
        Why the fit failed or gave up (empty when it did not).
    tried : tuple of FreeShape
        The fits before this one (the shape alone, when it was also fitted with the search's effects).
    not_needed : tuple of str
        When it reaches the noise: the search's effects of other kinds it does without (all of them when it
        reaches the noise alone; those :func:`free_shape_check` could drop one at a time and stay at the noise
        when it needed some). They may stand in for the shape the catalogue lacks -- or be real effects the
        free shape absorbs: unconfirmed either way.
    replaces : tuple of str
        The search's effects of the shape's own kind, which the shape takes the place of (the catalogue's
        nearest shapes of that kind: the burn rate for a thrust error in time).
    parameters : dict
        The fit's estimates, every parameter by name (empty when it failed).
    first_sample : float
        For a shape in time: the data's first sample time, before which its knots are not placed one by one
        (their values read apart); NaN otherwise.
    drag : tuple
        For a drag correction in Mach: ``(mach, cd, mach_fitted, cd_fitted)``, the model's drag coefficient
        along the base fit's nodes against their Mach number, and the drag coefficient of the fit with the
        shape (its table refitted beside the correction) along that fit's nodes (empty for the other kinds,
        or when the model has no drag-coefficient or Mach role).
    pins : tuple of float
        For a drag correction in Mach: where it is held at zero (the model's Mach table's knots), between which
        :attr:`knots` sit.
    curve : tuple
        For a thrust error: ``(times, stated, fitted)``, the model's thrust along the base fit's nodes and that
        thrust times ``1 + eps(t)``, N (empty for the other kinds, or when the thrust could not be evaluated).
    """

    kind: str
    effect: str
    description: str
    kept: tuple
    chi2_per_dof: float
    base_chi2_per_dof: float
    reaches_noise: bool
    detail: str
    knots: tuple
    values: tuple
    unit: str
    reading: str
    seconds: float
    message: str = ""
    tried: tuple = field(default=(), repr=False)
    curve: tuple = field(default=(), repr=False)
    not_needed: tuple = ()
    replaces: tuple = ()
    parameters: dict = field(default_factory=dict, repr=False, compare=False)
    first_sample: float = math.nan
    drag: tuple = field(default=(), repr=False)
    pins: tuple = ()

    def text(self) -> str:
        """One or two sentences for the verdict's explanation."""
        on = self._on()
        before = "".join((f"{t._on()} could not be fitted; " if t.message else
                          f"{t._on()} stays at chi2/dof {t.chi2_per_dof:.4g}; ") for t in self.tried)
        if self.message:
            return f"The free shape {self.effect} ({before}{on}) could not be fitted: {self.message}."
        if self.reaches_noise:
            return (f"The free shape the verdict names reaches the noise: {before}{on} fits at chi2/dof "
                    f"{self.chi2_per_dof:.4g} (from {self.base_chi2_per_dof:.4g}); what is missing acts like "
                    f"{self._what()}. It reads: {self.reading}. A free shape of {len(self.values)} values "
                    "absorbs what it can, effects of other kinds too, and is not judged by a realistic size: it "
                    "is the missing physics' trace, not its name -- name what makes that shape and state it as "
                    "your own effect (custom_effect)." + self._others())
        return (f"The free shape the verdict names does not reach the noise: {before}{on} fits at chi2/dof "
                f"{self.chi2_per_dof:.4g} (from {self.base_chi2_per_dof:.4g}; {self.detail}): what is missing "
                f"is not {self._what()} alone.")

    def _others(self) -> str:
        if not (self.not_needed or self.replaces):
            return ""
        out = ""
        if self.replaces:
            out += (f" It takes the place of the search's {_and(self.replaces)}, the catalogue's nearest "
                    f"shape{'s' if len(self.replaces) > 1 else ''} of that kind.")
        if self.not_needed:
            one = len(self.not_needed) == 1
            out += (f" Beside it the search's {_and(self.not_needed)} {'is' if one else 'are'} not needed to reach "
                    f"the noise: {'it' if one else 'they'} may stand in for the shape the catalogue lacks, or be "
                    f"real and absorbed by the free shape -- unconfirmed either way, not found.")
        return out

    def _on(self) -> str:
        return f"{self.description}" + (f" beside {', '.join(self.kept)}" if self.kept else " alone")

    def _what(self) -> str:
        return {"propulsion": "a change of the thrust in time", "mass": "a change of the thrust in time",
                "environment": "a change of the air with altitude", "aero": "a change of the drag with Mach"
                }.get(self.kind, "a change of this kind")

    def to_dict(self) -> dict:
        return {"kind": self.kind, "effect": self.effect, "description": self.description, "kept": list(self.kept),
                "chi2_per_dof": None if not math.isfinite(self.chi2_per_dof) else float(self.chi2_per_dof),
                "base_chi2_per_dof": float(self.base_chi2_per_dof), "reaches_noise": bool(self.reaches_noise),
                "detail": self.detail, "knots": [float(k) for k in self.knots],
                "values": [float(v) for v in self.values], "unit": self.unit, "reading": self.reading,
                "seconds": float(self.seconds), "message": self.message,
                "tried": [t.to_dict() for t in self.tried],
                "not_needed": list(self.not_needed), "replaces": list(self.replaces),
                "parameters": {k: float(v) for k, v in self.parameters.items()},
                "first_sample": float(self.first_sample) if math.isfinite(self.first_sample) else None,
                "drag": ({"stated": {"mach": [float(x) for x in self.drag[0]], "cd": [float(x) for x in self.drag[1]]},
                          "fitted": {"mach": [float(x) for x in self.drag[2]], "cd": [float(x) for x in self.drag[3]]}}
                         if self.drag else None), "pins": [float(x) for x in self.pins],
                "curve": ({"times": [float(x) for x in self.curve[0]], "stated": [float(x) for x in self.curve[1]],
                           "fitted": [float(x) for x in self.curve[2]]} if self.curve else None)}


def free_shape_for(kind: str, family: str, vehicle: Vehicle) -> tuple[Effect, tuple, str] | None:
    """The free shape for a candidate of ``kind`` (of catalogue ``family``) on ``vehicle``:
    ``(effect, knots, unit)``, or None when there is none (a sensor's kind; a model whose equations hold a
    time family, where the Mach-indexed variant answers; too few knots).

    - propulsion or mass: a thrust error ``P (1 + eps(t))`` piecewise linear on the mesh's element boundaries
      over the burn, from the start to the first boundary at or after the thrust's end (:func:`_spread`: the
      short elements at the start merged), at most :data:`MAX_TIME_KNOTS` of them, more than the catalogue's 9;
    - environment: a wind (the family ``wind``) or a relative density deviation (every other) piecewise linear
      in altitude on the catalogue's finest knots (at equal shares of the aerodynamic action; the wind's with
      the surface layer's top);
    - aero: a drag correction in Mach on the catalogue's finest knots (the model's Mach table with its
      intervals quartered, pinned at zero on the table's knots).

    The profiles in altitude and Mach are the catalogue's finest rungs: twice as many knots did not converge
    on Wren-H's hot tank in IPOPT's 3000 iterations (a wind on 25 knots, a drag correction on 49). What the
    check adds for them is the fit judged without the catalogue's sizes.
    """
    if vehicle is None or vehicle.time_families:
        return None
    if kind in ("propulsion", "mass"):
        knots = _spread(_powered_knots(vehicle)) if len(vehicle.knot_times) >= 3 else ()
        if len(knots) > MAX_TIME_KNOTS:
            want = np.linspace(knots[0], knots[-1], MAX_TIME_KNOTS)
            knots = tuple(sorted({min(knots, key=lambda k: abs(k - w)) for w in want}))
        if len(knots) < 3:
            return None
        return thrust_profile_effect(knots), knots, "s"
    if kind == "environment":
        wind = family == "wind"
        knots = tuple(float(k) for k in (_wind_knots_km(vehicle, max(WIND_KNOT_INTERVALS)) if wind else
                                         _profile_knots_km(vehicle, max(DENSITY_KNOT_INTERVALS))))
        if len(knots) < 3:
            return None
        if wind:
            return wind_profile_effect(knots, name=f"wind_pl_{len(knots)}"), knots, "km"
        return density_profile_effect(knots, name=f"density_pl_{len(knots)}"), knots, "km"
    if kind == "aero":
        if vehicle.mach is None:
            return None
        free, zeros = _drag_mach_knots(vehicle, 4)
        free = tuple(free)
        if len(free) < 3:
            return None
        return drag_mach_effect(free, zeros, name=f"drag_mach_{len(free)}"), free, "Mach"
    return None


def _spread(bounds) -> tuple:
    """The element boundaries ``bounds`` without those closer to the last one kept than half the median
    spacing (the short elements a mesh refines at the start: a knot 24 ms after the first one is not placed
    by the data)."""
    b = np.asarray(bounds, float)
    if b.size < 3:
        return tuple(float(x) for x in b)
    gap = 0.5 * float(np.median(np.diff(b)))
    kept = [float(b[0])]
    for x in b[1:-1]:
        if x - kept[-1] >= gap and b[-1] - x >= gap:
            kept.append(float(x))
    return tuple(kept + [float(b[-1])])


def _and(names: Sequence[str]) -> str:
    names = list(names)
    return names[0] if len(names) == 1 else f"{', '.join(names[:-1])} and {names[-1]}"


def _runs(knots: Sequence[float], values: Sequence[float], tol: float) -> list[tuple[int, int]]:
    """Runs ``(first, last)`` of consecutive knots whose values lie within ``tol`` of the run's median."""
    out, i, n = [], 0, len(values)
    while i < n:
        j = i
        while j + 1 < n and np.all(np.abs(np.asarray(values[i:j + 2]) - np.median(values[i:j + 2])) <= tol):
            j += 1
        out.append((i, j))
        i = j + 1
    return out


def read_shape(knots: Sequence[float], values: Sequence[float], unit: str, tol: float, *,
               percent: bool = True) -> str:
    """A shape in words: each run of three or more like values as its range over its knots' span, the
    largest departure elsewhere; the values in percent (``percent``) or as they are."""
    def v(x):
        if not percent:
            return f"{x:+.3g}"
        return f"{100 * x:+.1f} %" if abs(x) < 0.1 else f"{100 * x:+.0f} %"
    where = (lambda a, b: f"{a:.3g}-{b:.3g} {unit}") if unit != "Mach" else (lambda a, b: f"Mach {a:.3g}-{b:.3g}")
    parts, loose = [], []
    for a, b in _runs(knots, values, tol):
        if b - a >= 2:
            lo, hi = min(values[a:b + 1]), max(values[a:b + 1])
            parts.append(f"{v(lo)} to {v(hi)} over {where(knots[a], knots[b])}" if v(lo) != v(hi)
                         else f"{v(lo)} over {where(knots[a], knots[b])}")
        else:
            loose.extend(range(a, b + 1))
    if loose:
        k = max(loose, key=lambda j: abs(values[j]))
        parts.append(f"elsewhere up to {v(values[k])} (at {knots[k]:.3g} {unit})" if unit != "Mach"
                     else f"elsewhere up to {v(values[k])} (at Mach {knots[k]:.3g})")
    return "; ".join(parts) if parts else "flat"


def _fit_with(base: EstimationResult, effects: Sequence[Effect], start: dict, timeout: float,
              options) -> EstimationResult:
    spec = with_effects(base.spec, list(effects))
    opts = dict(options or {})
    opts["max_wall_time"] = min(float(opts.get("max_wall_time", timeout)), float(timeout))
    opts.setdefault("max_iter", MAX_ITER)
    names = set(spec.parameter_names)
    return estimate(spec, base.prepared.measurements, guess={k: v for k, v in start.items() if k in names},
                    mesh=base.prepared.transcription.mesh, options=opts)


def _one(base: EstimationResult, shape: Effect, knots: tuple, unit: str, kind: str, family: str,
         kept: Sequence[Effect], start: dict, band: NoiseBand, timeout: float, options,
         before: float) -> FreeShape:
    t0 = time.perf_counter()
    description = shape.title + (f" on {len(knots)} knots" if "knots" not in shape.title else "")
    try:
        new = _fit_with(base, list(kept) + [shape], start, timeout, options)
    except RocketidError as exc:
        return FreeShape(kind, shape.name, description, tuple(e.name for e in kept), math.nan, before, False, "",
                         knots, (), unit, "", time.perf_counter() - t0, str(exc))
    if not new.success:
        return FreeShape(kind, shape.name, description, tuple(e.name for e in kept), float(new.chi2_per_dof),
                         before, False, "", knots, (), unit, "", time.perf_counter() - t0,
                         f"IPOPT did not converge ({new.message})")
    ok, detail = fits_to_noise(new, band)
    values = tuple(float(new.value(n)) for n in shape.parameter_names)
    key = kind if kind != "environment" else f"environment_{'wind' if family == 'wind' else 'density'}"
    tol = RUN_TOLERANCE.get(key, RUN_TOLERANCE["propulsion"])
    percent = key in ("propulsion", "mass", "environment_density")
    first = _first_sample(base) if unit == "s" else math.nan
    early = _before_first_sample(first, knots) if kind in ("propulsion", "mass") else 0
    reading = read_shape(knots[early:], values[early:], unit, tol, percent=percent)
    if early:
        lo, hi = min(values[:early]), max(values[:early])
        reading += (f"; before the first sample at {first:.3g} s, {100 * lo:+.3g} to {100 * hi:+.3g} % on "
                    f"{early} knot{'s' if early > 1 else ''}, not placed one by one by the data (only through the "
                    "state they leave at that sample)")
    if kind in ("propulsion", "mass"):
        reading = f"the thrust {reading}"
    elif key == "environment_wind":
        reading = f"the wind (m/s, along the flight's heading positive) {reading}"
    elif key == "environment_density":
        reading = f"the density {reading}"
    else:
        reading = f"the drag coefficient {reading}"
    return FreeShape(kind, shape.name, description, tuple(e.name for e in kept), float(new.chi2_per_dof), before,
                     bool(ok), detail, knots, values, unit, reading, time.perf_counter() - t0,
                     curve=_thrust_curve(base, knots, values) if kind in ("propulsion", "mass") else (),
                     parameters=dict(zip(new.spec.parameter_names, (float(v) for v in new.p))),
                     first_sample=first,
                     drag=_drag_curve(base, new) if kind == "aero" else ())


def _first_sample(base: EstimationResult) -> float:
    return min(float(c.times[0]) for c in base.prepared.measurements.channels if c.times.size)


def _before_first_sample(first: float, knots: Sequence[float]) -> int:
    """How many of the time ``knots`` act only before the data's first sample -- the next knot at or before it,
    so that the knot's whole interval lies before the data (Wren-H: three knots of the first second after the
    rail, its GPS from 2 s) -- read apart: their values are placed only together, through the state they leave at
    that sample. A knot whose interval reaches into the data (a lift-off knot 0.1 s before the first sample) is
    placed. None are set apart when fewer than three knots would remain. ``first``: the data's first sample
    time (:func:`_first_sample`)."""
    n = int(sum(float(b) <= first + 1e-9 for b in knots[1:]))
    return n if len(knots) - n >= 3 else 0


def _thrust_curve(base: EstimationResult, knots: Sequence[float], values: Sequence[float]) -> tuple:
    """``(times, stated, fitted)``: the model's thrust along ``base``'s nodes, and times ``1 + eps(t)`` (linear
    between the knots, flat beyond); empty when the model has no thrust role or it cannot be evaluated."""
    from .screen import _evaluate
    expr = base.spec.role("thrust")
    if expr is None:
        return ()
    try:
        stated = np.asarray(_evaluate(base, expr), float) * np.ones_like(base.node_times)
    except (RocketidError, TypeError, ValueError, ZeroDivisionError):
        return ()
    t = np.asarray(base.node_times, float)
    fitted = stated * (1.0 + np.interp(t, knots, values))
    return tuple(t), tuple(stated), tuple(fitted)


def _drag_curve(base: EstimationResult, new: EstimationResult) -> tuple:
    """``(mach, cd, mach_fitted, cd_fitted)``: the drag coefficient against the Mach number along ``base``'s nodes
    and along ``new``'s (the fit with the correction, whose model's drag-coefficient role holds it); empty when
    the model lacks either role or they cannot be evaluated."""
    from .screen import _evaluate
    out = []
    for fit in (base, new):
        cd, mach = fit.spec.role("drag_coefficient"), fit.spec.role("mach")
        if cd is None or mach is None:
            return ()
        try:
            ones = np.ones_like(fit.node_times)
            out += [tuple(np.asarray(_evaluate(fit, mach), float) * ones),
                    tuple(np.asarray(_evaluate(fit, cd), float) * ones)]
        except (RocketidError, TypeError, ValueError, ZeroDivisionError):
            return ()
    return tuple(out)


def free_shape_check(disc, kind: str, family: str, *, timeout: float = 180.0, options=None,
                     then: Sequence[tuple[str, str]] = ()) -> FreeShape | None:
    """Fit the free shape the verdict names (:func:`free_shape_for`) to the user's model; when that stays above
    the noise and the search's final model holds effects of other kinds, fit it with those too; when that stays
    above too, the free shapes of the kinds ``then`` in turn, until one reaches the noise. The one that reaches
    it is returned, or the last tried, with those before it in :attr:`FreeShape.tried`.

    Parameters
    ----------
    disc : Discovery
        The search (:func:`~rocketid.diagnostics.step.discover`): its base fit, noise band, vehicle and final
        effects.
    kind, family : str
        The kind and family of what the missing physics looks like (the search's first effect added, else the
        screen's first candidate; what the verdict's suggestion names).
    timeout : float
        Seconds each fit may take (IPOPT's wall-time limit).
    then : sequence of (kind, family)
        Further kinds to try in turn (the search's other effects' kinds: on Wren-H with 1 kg of nitrous vented
        and a tailwind the wind came first and its free shape does not converge alone; the motor's is next).

    Returns
    -------
    FreeShape or None
        None when the kind has no free shape on this model.
    """
    tried: list[FreeShape] = []
    for k, fam in [(kind, family)] + list(then):
        made = free_shape_for(k, fam, disc.vehicle)
        if made is None:
            continue
        shape, knots, unit = made
        base = disc.base_fit
        start = dict(zip(base.spec.parameter_names, (float(v) for v in base.p)))
        fits = [_one(base, shape, knots, unit, k, fam, (), start, disc.band, timeout, options,
                     float(base.chi2_per_dof))]
        same = {"propulsion", "mass"} if k in ("propulsion", "mass") else {k}
        kept = [e for e in disc.effects if e.kind not in same]
        if not fits[0].reaches_noise and kept:
            start = dict(zip(disc.fit.spec.parameter_names, (float(v) for v in disc.fit.p)))
            fits.append(_one(base, shape, knots, unit, k, fam, kept, start, disc.band, timeout, options,
                             float(base.chi2_per_dof)))
            if fits[-1].reaches_noise and len(kept) > 1:
                fits[-1] = _without(base, shape, knots, unit, k, fam, kept, fits[-1], disc.band, timeout, options)
        tried += fits
        if fits[-1].reaches_noise:
            last = fits[-1]
            tried[-1] = replace(last, replaces=tuple(e.name for e in disc.effects if e.kind in same),
                                not_needed=tuple(e.name for e in kept if e.name not in last.kept))
            break
    if not tried:
        return None
    out = replace(tried[-1], tried=tuple(tried[:-1]))
    if out.kind == "aero":
        _, zeros = _drag_mach_knots(disc.vehicle, 4)
        out = replace(out, pins=tuple(float(z) for z in zeros if all(abs(z - k) > 1e-9 for k in out.knots)))
    return out


def _without(base, shape, knots, unit, kind, family, kept, fit: FreeShape, band, timeout, options) -> FreeShape:
    """``fit`` (the free shape beside ``kept``, at the noise) without the kept effects it does not need: each
    dropped in turn and the shape refitted from ``fit``'s estimates; of the drops that stay at the noise the one
    with the lowest chi2/dof is made, until none stays (backward elimination to the noise). A free shape reaching
    the noise beside the search's wrong effects kept them all (Wren-H's grain 13 mm short with its GPS altitude
    15 m low: the thrust's shape beside the altitude bias and two drag shapes)."""
    kept = list(kept)
    while len(kept) > 1:
        outs = []
        for e in kept:
            rest = [x for x in kept if x is not e]
            new = _one(base, shape, knots, unit, kind, family, rest, fit.parameters, band, timeout, options,
                       fit.base_chi2_per_dof)
            if new.reaches_noise:
                outs.append((new.chi2_per_dof, e.name, new, e))
        if not outs:
            break
        _, _, fit, e = min(outs, key=lambda o: o[:2])
        kept.remove(e)
    return fit
