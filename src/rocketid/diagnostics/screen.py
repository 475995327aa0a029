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

A significant family left out by these rules that has **located shapes** (a
throttle window, a drag hump: a change placed at an estimated time or Mach
number) is also scored by their scans (:func:`~rocketid.diagnostics.score.
scan_peak`): its smooth shape can score low where its located shape scores
high (a 30 % throttle bucket over 6 s ranked the constant thrust error 8th and
confounded, while the window's scan predicted a fall of J six times the
leader's). Such a family is a contender when its best scan location is
significant after correcting for the locations scored and the candidates
(Bonferroni), and its predicted fall is within :data:`WITHIN` of the leader's;
it is marked (:attr:`Contender.located`) so that the refits try its located
shapes. When the significant candidates' largest predicted fall is less than
:data:`WIDE_SHARE` of the fall that would bring the fit to the noise band --
no constant shape the score test sees can account for the misfit -- the
families it finds *not* significant are scanned too: a change over a second or
two is invisible to its family's constant shape (Auk-B's boosters separated
1.5 s late: 3.2 t carried 1.5 s longer, the constant thrust error's statistic
0.06, not significant, the leader's predicted fall 41 of the 145 to the band,
while the throttle window's scan put a predicted fall of 259 at 39.5-43.0 s).
Otherwise they are not scanned: a scan is a sensitivity solve of a 32-copy
bank, and its code generation on a new model; a fit the constant shapes can
explain (a thrust level error) and data at the noise pay nothing.

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
from .effects import Effect, Vehicle, thrust_motors
from .score import CandidateRanking, ScanPeak, rank_candidates, scan_peak, scan_profile

__all__ = ["Contender", "Screen", "screen", "vehicle_of", "WITHIN", "MAX_CONTENDERS", "WIDE_SHARE"]

WITHIN = 10.0
"""A significant candidate whose predicted fall of the objective is within this factor of the leader's is a contender."""

MAX_CONTENDERS = 10
"""At most this many contenders per step (best ranked first)."""


WIDE_SHARE = 0.5
"""The share of the fall of ``J`` to the noise band that the significant candidates' largest predicted fall must
reach for the screen to leave the non-significant families' located shapes unscanned (module notes)."""


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
    located : str
        The located shape of its family (a refinement with a scan) whose scan makes it a
        contender, or names it as one; empty otherwise. Its family's refined shapes are tried.
    """

    effect: Effect
    why: str
    start: dict = field(default_factory=dict)
    located: str = ""


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
    scans : dict
        The scans made at the fit: bank name -> :func:`~rocketid.diagnostics.score.scan_profile` (or None),
        reused by the refits that start located shapes at the same fit.
    """

    ranking: CandidateRanking | None
    contenders: tuple
    notes: tuple = ()
    failed: str = ""
    scans: dict = field(default_factory=dict, compare=False, repr=False)

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
        mach_knots=_mach_knots(spec), aero_altitudes=_aero_altitudes(np.asarray(t, float), alt, qbar),
        time_families=bool(spec.families), powered=_powered(np.asarray(t, float), thrust),
        rail_exit=speed is not None and float(speed[0]) > 0 and _rail_exit(spec), motors=thrust_motors(spec))


def _rail_exit(spec) -> bool:
    """Whether the declared start is a rail exit (:func:`~rocketid.diagnostics.effects._rail_exit_ratio`)."""
    from .effects import _rail_exit_ratio
    try:
        _rail_exit_ratio(spec.to_model(), "the rail exit")
    except (ModelError, RocketidError, TypeError, ValueError, ZeroDivisionError):
        return False
    return True


def _powered(t, thrust) -> tuple:
    """First and last time the thrust is above 0.1 % of its largest value (empty without the role)."""
    if thrust is None or not np.all(np.isfinite(thrust)):
        return ()
    on = np.abs(np.asarray(thrust, float)) > 1e-3 * float(np.max(np.abs(thrust)))
    return (float(t[on][0]), float(t[on][-1])) if on.any() else ()


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
           vehicle: Vehicle | None = None, ranking: CandidateRanking | None = None,
           excess: float = 0.0) -> Screen:
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
    excess : float
        The fall of ``J`` that would bring ``fit`` to the noise band's upper edge (0 when it is inside). When
        the significant candidates' largest predicted fall is less than half of it, the located shapes of the
        families the score test finds **not** significant are scanned too (module notes).

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
    lead = max((c.predicted_drop for c in sig), default=0.0)
    wide = lead < WIDE_SHARE * excess
    if not sig and not wide:
        return Screen(ranking, (), (f"no candidate is significant at {level:g}: nothing is refitted",))
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
    # the significant candidates left out whose located shapes' scans qualify them (module notes)
    scans: dict = {}
    named = {c.name for c, _ in chosen[:MAX_CONTENDERS]}
    pool = ranking.candidates if wide else sig
    located = _located(fit, ranking, [c for c in pool if c.name not in named], vehicle, level, lead, scans)
    if not chosen and not located:
        return Screen(ranking, (), (f"no candidate is significant at {level:g}, and no located shape's scan is: "
                                    "nothing is refitted",), scans=scans)
    if len(chosen) > MAX_CONTENDERS:
        cut = [c.name for c, _ in chosen[MAX_CONTENDERS:] if c.name not in located]
        if cut:
            notes.append(f"{len(chosen)} candidates qualify; the {MAX_CONTENDERS} best ranked are refitted "
                         f"({', '.join(cut)} are not)")
        chosen = chosen[:MAX_CONTENDERS]
    # a family whose located shape's scan qualifies is refitted whatever its smooth shape's rank (not counted
    # against MAX_CONTENDERS: at most one per family with located shapes)
    chosen += [(c, "") for c in ranking.candidates if c.name in located and c.name not in named]
    contenders = []
    for c, why in chosen:
        shape, peak = located.get(c.name, ("", None))
        if peak is not None:
            where = "-".join(f"{w:.4g}" for w in peak.where)
            scan_why = (f"its located shape {shape}'s scan predicts a fall of J of {peak.predicted_drop:.4g} "
                        f"at {where} (p {peak.p_value(len(ranking.candidates)):.2g} over {peak.tested} locations)")
            why = f"{why}; {scan_why}" if why else scan_why
        effect = ranking.effect(c.name)
        contenders.append(Contender(effect, why, _start(c, effect, vehicle, fit.spec), shape))
    if located:
        notes.append("refitted for their located shapes' scans (ranked out as constant shapes): "
                     + ", ".join(f"{c} ({shape})" for c, (shape, _) in located.items()))
    return Screen(ranking, tuple(contenders), tuple(notes), scans=scans)


def _located(fit: EstimationResult, ranking: CandidateRanking, candidates, vehicle: Vehicle, level: float,
             lead: float, scans: dict) -> dict[str, tuple[str, ScanPeak]]:
    """Of ``candidates`` (the ones the screen left out), those whose located shapes' scans qualify
    them (module notes): candidate name -> (the located shape, its scan's peak), the best-scoring shape of each
    family. ``scans`` collects the profiles made. (Scanning only these keeps the scans' cost -- a sensitivity
    solve of a 32-copy bank each, and its code generation on a new model -- off clean data and off families
    the screen refits anyway.)"""
    out: dict[str, tuple[str, ScanPeak]] = {}
    n = len(ranking.candidates)
    for c in candidates:
        try:
            shapes = [v for v in ranking.effect(c.name).refinements(vehicle) if v.scan is not None]
        except (RocketidError, ValueError):
            continue
        for v in shapes:
            bank = v.scan.bank
            if bank.name not in scans:
                scans[bank.name] = scan_profile(fit, bank)
            peak = scan_peak(v.scan, scans[bank.name])
            if peak is None or peak.p_value(n) >= level or peak.predicted_drop < lead / WITHIN:
                continue
            if c.name not in out or peak.statistic > out[c.name][1].statistic:
                out[c.name] = (v.name, peak)
    return out
