"""Step 1 of the discovery -- screen: rank the candidates at a fit and name the contenders to refit.

::

    screen -> refit -> accept -> step -> report

The score test (:mod:`rocketid.diagnostics.score`) ranks every candidate
effect at the current fit without refitting. The ranking is a screen, not a
decision: a linearization at a fit far from the noise can put the wrong effect
first (a +2 % thrust error ranked behind a time offset). So every candidate
that could be the answer is refitted (:mod:`rocketid.diagnostics.refit`): a
**contender** is a significant candidate (Holm-corrected p below the level)
that leads its confounded group, or whose predicted fall of the objective is
within a factor :data:`WITHIN` of the leader's.

The vehicle's scales (:class:`~rocketid.diagnostics.effects.Vehicle`: thrust,
mass flow, speed, the altitude and Mach ranges flown) are read from the fit
through the model's physical roles; the realistic size of each effect is
stated against them.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from ..errors import ModelError, RocketidError
from ..simulate import evaluate_along
from ..solve import EstimationResult
from .effects import Effect, Vehicle
from .score import CandidateRanking, rank_candidates

__all__ = ["Contender", "Screen", "screen", "vehicle_of", "WITHIN", "MAX_CONTENDERS"]

WITHIN = 10.0
"""A significant candidate whose predicted fall of the objective is within this factor of the leader's is a contender."""

MAX_CONTENDERS = 10
"""At most this many contenders per step (best ranked first)."""


@dataclass(frozen=True)
class Contender:
    """A candidate to refit.

    Attributes
    ----------
    effect : Effect
        The effect to add.
    why : str
        Why it is refitted ("leads group 1", "predicted fall within 10x of the leader's").
    start : dict
        Starting values of its parameters (the score test's one-step estimate, held
        within 5 realistic sizes and the bounds; 0 otherwise).
    """

    effect: Effect
    why: str
    start: dict = field(default_factory=dict)


@dataclass(frozen=True)
class Screen:
    """The candidates ranked at one fit, and the contenders to refit.

    Attributes
    ----------
    ranking : CandidateRanking or None
        None when no candidate could be scored (see :attr:`notes`).
    contenders : tuple of Contender
    notes : tuple of str
    failed : str
        Why the ranking could not be made (empty when it was).
    """

    ranking: CandidateRanking | None
    contenders: tuple
    notes: tuple = ()
    failed: str = ""

    @property
    def names(self) -> tuple:
        return tuple(c.effect.name for c in self.contenders)


def _evaluate(fit: EstimationResult, expr) -> np.ndarray:
    spec = fit.spec
    return evaluate_along(spec, spec.expand(expr), fit.node_times, fit.state_trajectories, fit.p)


def vehicle_of(fit: EstimationResult) -> Vehicle:
    """The scales of the vehicle flown in ``fit``, read through the model's roles (thrust, mass,
    speed, altitude, Mach); a scale whose role the model lacks is NaN (sizes that need it fall
    back to RA-66's)."""
    spec = fit.spec
    t = fit.node_times

    def along(role):
        expr = spec.role(role)
        if expr is None:
            return None
        try:
            return _evaluate(fit, expr)
        except (RocketidError, TypeError, ValueError, ZeroDivisionError):
            return None

    thrust, mass, speed = along("thrust"), along("mass"), along("speed")
    alt, mach = along("altitude"), along("mach")
    qbar = along("dynamic_pressure")
    nan = math.nan
    span = float(t[-1] - t[0]) if t.size > 1 else nan
    flow = abs(float(mass[0] - mass[-1])) / span if mass is not None and span > 0 else nan
    times = np.concatenate([c.times for c in fit.prepared.measurements.channels])
    dt = float(np.median(np.diff(np.unique(times)))) if times.size > 1 else nan
    sig = {n: float(s) for n, s in zip(fit.nlp.channel_names, fit.nlp.channel_sigmas)}
    return Vehicle(
        thrust=float(abs(thrust[0])) if thrust is not None else nan,
        mass=float(mass[0]) if mass is not None else nan, mass_flow=flow,
        speed=float(np.max(np.abs(speed))) if speed is not None else nan,
        start_speed=float(speed[0]) if speed is not None else nan, duration=float(spec.tf - spec.t0),
        altitude=(float(np.min(alt)), float(np.max(alt))) if alt is not None else (0.0, 30000.0),
        mach=(float(np.min(mach)), float(np.max(mach))) if mach is not None and np.all(np.isfinite(mach)) else None,
        sigma=sig, sample_interval=dt,
        knot_times=tuple(float(b) for b in fit.prepared.transcription.mesh.boundaries),
        mach_knots=_mach_knots(spec), aero_altitudes=_aero_altitudes(np.asarray(t, float), alt, qbar))


def _aero_altitudes(t, alt, qbar) -> tuple:
    """Altitudes by which the aerodynamic action ``integral |qbar| dt`` reaches 0, 1, ..., 100 % of its
    total along the flight (empty without the altitude and dynamic-pressure roles)."""
    if alt is None or qbar is None or len(t) < 2 or not np.all(np.isfinite(qbar)) or not np.all(np.isfinite(alt)):
        return ()
    q = np.abs(np.asarray(qbar, float))
    cum = np.concatenate([[0.0], np.cumsum(0.5 * (q[1:] + q[:-1]) * np.diff(t))])
    if cum[-1] <= 0:
        return ()
    cum = cum / cum[-1]
    keep = np.concatenate([[True], np.diff(cum) > 0])
    return tuple(float(x) for x in np.interp(np.linspace(0.0, 1.0, 101), cum[keep], np.maximum.accumulate(alt)[keep]))


def _mach_knots(spec) -> tuple:
    """Knots of the model's drag-coefficient table in Mach (empty when it has none)."""
    cd = spec.role("drag_coefficient")
    used = spec.expand(cd).free_symbols if cd is not None else set()
    for tab in getattr(spec, "tables", ()):
        if tab.variable_role == "mach" and set(tab.parameters) & used:
            return tuple(float(k) for k in tab.knots)
    return ()


def _finite_sizes(effect: Effect, vehicle: Vehicle | None) -> dict:
    try:
        sizes = effect.sizes(vehicle)
    except (TypeError, ValueError, ZeroDivisionError):
        sizes = dict(effect.realistic)
    return {k: v for k, v in sizes.items() if math.isfinite(v) and v > 0}


def _start(c, effect: Effect, vehicle: Vehicle | None, spec) -> dict:
    sizes = _finite_sizes(effect, vehicle)
    out = {}
    for name, v in c.one_step.items():
        if not math.isfinite(v):
            continue
        cap = 5 * sizes[name] if name in sizes else abs(v)
        v = float(np.clip(v, -cap, cap))
        out[name] = v
    return out


def screen(fit: EstimationResult, candidates: Sequence[Effect], *, level: float = 0.05,
           vehicle: Vehicle | None = None, ranking: CandidateRanking | None = None) -> Screen:
    """Rank ``candidates`` at ``fit`` (the score test) and pick the contenders (module notes).

    Parameters
    ----------
    fit : EstimationResult
        The current fit (the base model, or the model with the effects added so far).
    candidates : sequence of Effect
        Effects not in the model yet.
    level : float
        Level of the Holm-corrected score test.
    vehicle : Vehicle, optional
        Scales for the starting values (default: read from ``fit``).
    ranking : CandidateRanking, optional
        A ranking already made at ``fit`` (reused).

    Returns
    -------
    Screen
    """
    notes = []
    if ranking is None:
        try:
            ranking = rank_candidates(fit, list(candidates), level=level)
        except (ModelError, RocketidError) as exc:
            # the score test needs the sensitivities at the fit, which a fit far from any trajectory of its
            # parameters (a base fit that did not converge) cannot give; the refits decide instead: every
            # candidate is a contender, started from zero (measured: Stage-30 with a 0.25 deg misalignment
            # from the start, base fit locally infeasible at chi2/dof 1.4e6, found nothing without this)
            return Screen(None, tuple(Contender(e, "the ranking could not be made: every candidate is refitted")
                                      for e in candidates),
                          (f"the candidate ranking failed ({exc}); every candidate is refitted",), failed=str(exc))
    vehicle = vehicle if vehicle is not None else vehicle_of(fit)
    sig = [c for c in ranking.candidates if c.significant]
    if not sig:
        return Screen(ranking, (), (f"no candidate is significant at {level:g}: nothing is refitted",))
    lead = max(c.predicted_drop for c in sig)
    leaders = set()
    chosen = []
    for c in sig:
        why = []
        if c.group not in leaders:
            leaders.add(c.group)
            why.append(f"leads confounded group {c.group}")
        if c.predicted_drop >= lead / WITHIN:
            why.append(f"predicted fall of J within {WITHIN:g}x of the leader's")
        if why:
            chosen.append((c, "; ".join(why)))
    if len(chosen) > MAX_CONTENDERS:
        notes.append(f"{len(chosen)} candidates qualify; the {MAX_CONTENDERS} best ranked are refitted "
                     f"({', '.join(c.name for c, _ in chosen[MAX_CONTENDERS:])} are not)")
        chosen = chosen[:MAX_CONTENDERS]
    contenders = tuple(Contender(ranking.effect(c.name), why, _start(c, ranking.effect(c.name), vehicle, fit.spec))
                       for c, why in chosen)
    return Screen(ranking, contenders, tuple(notes))
