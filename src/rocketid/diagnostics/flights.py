"""Several flights: the joint model with the effects each flight's diagnosis found.

Each flight's diagnosis (:func:`rocketid.diagnostics.diagnose`) ends with its own model: the base
model and the effects it added. This step fits all flights at once with those models and says,
for an effect found in several flights, whether it is one property of the vehicle (one value for
every flight) or differs between them.

Which effects may be shared is a matter of physics, decided by the effect's kind:

- **the flight's own** (always one value per flight): sensors (``sensor``: biases, scale factors,
  time tags), the day's air (``environment``: wind, density, temperature), the start and the site
  (``kinematics``), the loading (``start_mass`` and its rail-exit form), and events at a time of
  that flight (an effect with an onset time: a jettison, a throttle step or window, a late
  misalignment) or a flight's throttle programme (``throttle`` effects);
- **the vehicle's** (shared when the flights agree): the motor (``propulsion``: thrust level and
  profile, back-pressure, burn rate, misalignment), the mass flow, the aerodynamics (``aero``),
  and user effects (``custom``).

A vehicle effect found in two or more flights is first fitted with a value per flight (every
effect its own: the fit "each flight its own effects"), then with one value shared by the flights
that found it; the likelihood-ratio statistic ``2 (J_shared - J_own)`` is a chi-square with
``k (F_e - 1)`` degrees of freedom (``k`` parameters, ``F_e`` flights) when the flights agree. The
effect is shared when its p-value is at least the diagnosis's level; otherwise it is kept per flight
and said to differ. The final joint fit shares every effect that passed; each flight's chi2/dof in
it is judged against that flight's own noise band (:class:`~rocketid.diagnostics.accept.NoiseBand`).

A vehicle effect found in some flights but not in the others (their searches stopped at the noise
without it, or took a rival that fits their flight alike) is then **carried** to the others: the
joint fit with it in every flight and one value for all is tested against the fit with a value per
flight (``2 (J_one - J_each)`` against chi2 with ``k (F - 1)`` degrees of freedom); when the flights
agree it is carried, and each flight it was carried to is checked backward: an effect of its own that
no longer lowers the joint BIC is dropped (two flights that both fly 2 % above the stated thrust,
one of whose searches took a start-mass error for it, end with one thrust error). A vehicle property
is one value for every flight of that vehicle; a flight whose data reject the value keeps its own
model, and the report says so.

A flight's own effect found in two or more flights but not in all (the same loading error, the same sensor
fault on several days) is then **tried** in each of the others, with a value of its own: it is added to that
flight when the likelihood-ratio test of adding it (``2 (J_before - J_with)`` against chi2 with its
parameters' count) is significant at the level and the joint BIC falls. Without it, a flight whose own
search stopped between rivals keeps its misfit in the joint model, and the shared coefficients take it up
(:func:`_try_own`).

The flights' data are those their diagnoses fitted (wild points dropped, correlated channels
thinned, noise levels taken from the data held fixed), so the joint fits' objectives are
comparable with each other.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from typing import Any, Mapping, Sequence

import numpy as np
from scipy import stats

from ..errors import RocketidError, SensitivityError
from ..output import finite_or_none
from ..summary import Section, Table

__all__ = ["FLIGHT_KINDS", "SharingTest", "Carried", "JointFinal", "effect_nature", "sharing_plan", "joint_final"]

#: Effect kinds that are a property of one flight, never shared.
FLIGHT_KINDS = ("sensor", "environment", "kinematics")

SMALL_SPREAD = 0.1
"""Flights whose own values of an effect parameter lie within this share of its realistic size of each other
differ little in engineering terms; when the likelihood-ratio test still says they differ (long flights at
low noise resolve differences far below any tolerance), the report says so beside the verdict."""


def effect_nature(effect) -> str:
    """``"flight"`` for an effect that belongs to one flight (its sensors, its air, its start, its
    loading, an event at a time of its own, its throttle programme), ``"vehicle"`` for one that may be
    a property of the vehicle (motor, mass flow, aerodynamics, user effects)."""
    name = str(effect.name)
    if effect.kind in FLIGHT_KINDS or name.startswith("start_mass") or name.startswith("throttle"):
        return "flight"
    if effect.event_time is not None:
        return "flight"
    return "vehicle"


@dataclass(frozen=True)
class SharingTest:
    """Whether one vehicle effect found in several flights has one value for all of them.

    Attributes
    ----------
    effect : str
    flights : tuple of str
        The flights whose diagnosis found it.
    parameters : tuple of str
    own : dict
        ``{flight: {parameter: (value, std)}}`` in the fit where each flight has its own value.
    statistic : float
        ``2 (J_shared - J_own)`` (NaN when a fit failed).
    dof : int
        ``len(parameters) * (len(flights) - 1)``.
    p_value : float
    shared : bool
        The flights agree (``p_value >= level``): the effect is shared in the final joint fit.
    note : str
        Why the test could not be made (empty when it was).
    sizes : dict
        ``{parameter: realistic size}`` (the effect's, for the vehicle): the yardstick of the spread
        between the flights' own values, in engineering terms beside the test's.
    """

    effect: str
    flights: tuple
    parameters: tuple
    own: dict
    statistic: float
    dof: int
    p_value: float
    shared: bool
    note: str = ""
    sizes: dict = field(default_factory=dict)

    def spread(self) -> dict:
        """``{parameter: (max - min of the flights' own values, that as a share of its realistic size)}`` (the
        share NaN without a size)."""
        out = {}
        for n in self.parameters:
            vals = [d[n][0] for d in self.own.values() if n in d and math.isfinite(d[n][0])]
            if len(vals) > 1:
                width = max(vals) - min(vals)
                size = self.sizes.get(n, math.nan)
                out[n] = (width, width / size if size and math.isfinite(size) and size > 0 else math.nan)
        return out

    def sentence(self) -> str:
        values = "; ".join(f"{l}: " + ", ".join(f"{n} {v:.4g} +- {s:.2g}" for n, (v, s) in d.items())
                           for l, d in self.own.items())
        if self.note:
            return f"{self.effect}: kept per flight ({self.note}" + (f"; {values})" if values else ")")
        cost = f"sharing costs 2 dJ = {self.statistic:.4g} for {self.dof} degree(s) of freedom, p = {self.p_value:.2g}"
        if self.shared:
            return (f"{self.effect}: one value for flights {', '.join(self.flights)} ({cost}; with a value per "
                    f"flight in the joint fit {values})")
        apart = "; ".join(f"{n} {w:.3g} apart" + (f" ({100 * r:.2g} % of its realistic size)" if math.isfinite(r) else "")
                          for n, (w, r) in self.spread().items())
        small = [n for n, (_, r) in self.spread().items() if math.isfinite(r) and r < SMALL_SPREAD]
        return (f"{self.effect}: differs between flights {', '.join(self.flights)} ({values}; {cost}"
                + (f"; {apart}" if apart else "") + "): not one property of the vehicle, kept per flight"
                + (f" -- though {', '.join(small)} differ by less than {100 * SMALL_SPREAD:g} % of a realistic "
                   "size: a difference the data resolve, small in engineering terms" if small else ""))

    def to_dict(self) -> dict:
        return {"effect": self.effect, "flights": list(self.flights), "parameters": list(self.parameters),
                "own": {l: {n: {"value": finite_or_none(v), "std": finite_or_none(s)} for n, (v, s) in d.items()}
                        for l, d in self.own.items()},
                "statistic": finite_or_none(self.statistic), "dof": int(self.dof),
                "p_value": finite_or_none(self.p_value), "shared": bool(self.shared), "note": self.note,
                "spread": {n: {"width": finite_or_none(w), "of_realistic_size": finite_or_none(r)}
                           for n, (w, r) in self.spread().items()}}


@dataclass(frozen=True)
class Carried:
    """A vehicle effect found in some flights, tried in the others (module notes).

    Attributes
    ----------
    effect : str
    found_in : tuple of str
        The flights whose diagnosis found it.
    to : tuple of str
        The flights it was tried in.
    statistic : float
        ``2 (J_one - J_each)``: one value for every flight against one per flight (NaN when a fit failed).
    dof : int
    p_value : float
    carried : bool
        The flights agree on one value: the effect is in every flight's model, shared.
    dropped : dict
        ``{flight: (effect, ...)}``: the flight's own effects the backward check dropped once it was carried.
    fall : float
        ``2 (J_before - J_one)``: what carrying it changed in the joint fit (same number of parameters).
    note : str
        Why it could not be tried (empty when it was).
    own : bool
        A flight's own effect (:data:`FLIGHT_KINDS`, a loading) found in two or more flights, tried in one
        other flight (``to``) with a value of its own: ``statistic`` is then ``2 (J_before - J_with)``, the
        likelihood-ratio test of adding it, on ``dof`` = its parameters, and ``carried`` says it was added
        (p below the level and the joint BIC lower).
    """

    effect: str
    found_in: tuple
    to: tuple
    statistic: float
    dof: int
    p_value: float
    carried: bool
    dropped: dict = field(default_factory=dict)
    fall: float = math.nan
    note: str = ""
    own: bool = False

    def sentence(self) -> str:
        where = f"found in {', '.join(self.found_in)}, tried in {', '.join(self.to)}"
        if self.note:
            return f"{self.effect} ({where}): not carried ({self.note})"
        if self.own:
            test = f"2 dJ = {self.statistic:.4g} for {self.dof} degree(s) of freedom, p = {self.p_value:.2g}"
            return (f"{self.effect} ({where} with a value of its own): " +
                    (f"added there ({test}, the joint BIC lower)" if self.carried else
                     f"not added ({test}: not significant or the joint BIC not lower)"))
        test = f"one value for every flight costs 2 dJ = {self.statistic:.4g} for {self.dof} degree(s) of freedom, " \
               f"p = {self.p_value:.2g}"
        if not self.carried:
            return f"{self.effect} ({where}): the flights do not agree on one value ({test}): kept where it was found"
        out = f"{self.effect} ({where}): carried to every flight, one value ({test}; the joint J falls by " \
              f"{self.fall / 2:.4g})"
        drops = "; ".join(f"{l} drops {', '.join(d)}" for l, d in self.dropped.items() if d)
        return out + (f"; no longer needed with it: {drops}" if drops else "")

    def to_dict(self) -> dict:
        return {"effect": self.effect, "found_in": list(self.found_in), "to": list(self.to),
                "statistic": finite_or_none(self.statistic), "dof": int(self.dof),
                "p_value": finite_or_none(self.p_value), "carried": bool(self.carried),
                "dropped": {l: list(d) for l, d in self.dropped.items()}, "fall": finite_or_none(self.fall),
                "note": self.note, "own": bool(self.own)}


@dataclass(frozen=True)
class JointFinal:
    """All flights fitted at once with the effects their diagnoses found.

    Attributes
    ----------
    effects : dict
        ``{flight: (effect, ...)}``: each flight's final effects, in the order its diagnosis added them.
    nature : dict
        ``{effect: "vehicle" or "flight"}`` (:func:`effect_nature`).
    shared : tuple of str
        The effects fitted with one value for the flights that found them.
    tests : tuple of SharingTest
        One per vehicle effect found in two or more flights.
    carried : tuple of Carried
        One per vehicle effect found in some flights but not all, tried in the others.
    result : JointResult or None
        The final joint fit (None when it failed: :attr:`failed`).
    base_chi2_per_dof : float
        The joint fit of the base model (every flight), for the fall.
    bands : dict
        ``{flight: chi2/dof a correct model reaches}`` (each flight's noise band's upper edge).
    failed : str
    notes : tuple of str
    parameters_of : dict
        ``{(flight, effect): parameter names}``: what each flight's effect adds to the base model.
    """

    effects: dict
    nature: dict
    shared: tuple
    tests: tuple
    result: Any
    base_chi2_per_dof: float
    bands: dict
    failed: str = ""
    notes: tuple = ()
    parameters_of: dict = field(default_factory=dict, repr=False, compare=False)
    carried: tuple = ()

    @property
    def chi2_per_dof(self) -> float:
        return math.nan if self.result is None else float(self.result.chi2_per_dof)

    def per_flight(self) -> dict:
        """``{flight: (chi2/dof in the final joint fit, its band, reaches the noise)}``."""
        if self.result is None:
            return {}
        out = {}
        for label, r in zip(self.result.labels, self.result.flights):
            band = self.bands.get(label, math.nan)
            out[label] = (float(r.chi2_per_dof), band, bool(math.isfinite(band) and r.chi2_per_dof <= band))
        return out

    @property
    def fits_to_noise(self) -> bool:
        """Every flight's chi2/dof in the final joint fit is inside its noise band."""
        rows = self.per_flight()
        return bool(rows) and bool(self.result.success) and all(ok for _, _, ok in rows.values())

    def _values(self) -> list:
        """``(joint name, value, std)`` of every effect parameter of the final joint fit."""
        res = self.result
        try:
            se = res.standard_errors
        except SensitivityError:
            se = np.full(len(res.names), np.nan)
        names = set()
        for label, spec_effects in self.effects.items():
            for e in spec_effects:
                names.update(self.parameters_of.get((label, e), ()))
        out = []
        for i, n in enumerate(res.names):
            base = n.split("[")[0]
            if base in names:
                out.append((n, float(res.theta[i]), float(se[i])))
        return out

    def sentences(self) -> list[str]:
        """What the joint model says, in a few sentences."""
        if self.result is None:
            return [f"The joint fit with each flight's effects could not be made: {self.failed}"]
        out = [f"Joint fit with each flight's effects: chi2/dof {_chi2(self.base_chi2_per_dof)} (base model) -> "
               f"{_chi2(self.chi2_per_dof)}" + ("" if self.result.success else " (did not converge)") + "."]
        out += [t.sentence() + "." for t in self.tests]     # effect names keep their case
        out += [c.sentence() + "." for c in self.carried]
        rows = self.per_flight()
        over = [f"{l} {c:.4g} (band {b:.4g})" for l, (c, b, ok) in rows.items() if not ok]
        if self.fits_to_noise:
            out.append("Every flight reaches its noise in the joint model.")
        elif over:
            out.append("Above the noise in the joint model: " + ", ".join(over) + ".")
        return out

    def section(self) -> Section:
        """The summary's section "Joint model with the effects found"."""
        if self.result is None:
            return Section("Joint model with the effects found", (("status", f"not made ({self.failed})"),))
        rows = [(l, ", ".join(self.effects.get(l, ())) or "-", c, b, "yes" if ok else "no")
                for l, (c, b, ok) in self.per_flight().items()]
        items: list = [("chi2 / dof", f"{_chi2(self.base_chi2_per_dof)} (base model) -> {_chi2(self.chi2_per_dof)}"),
                       ("status", "converged" if self.result.success else f"FAILED ({self.result.message})"),
                       ("shared", ", ".join(self.shared) or "none"),
                       ("carried", ", ".join(f"{c.effect} to {', '.join(c.to)}" for c in self.carried if c.carried)
                        or "none"),
                       Table(("flight", "effects", "chi2/dof joint", "band", "at the noise"), rows,
                             (None, None, ".4g", ".4g", None))]
        values = self._values()
        if values:
            items.append(Table(("parameter", "estimate", "std error"), values, (None, ".6g", ".3g")))
        return Section("Joint model with the effects found", tuple(items))

    def to_dict(self) -> dict:
        d: dict = {"effects": {l: list(e) for l, e in self.effects.items()}, "nature": dict(self.nature),
                   "shared": list(self.shared), "tests": [t.to_dict() for t in self.tests],
                   "carried": [c.to_dict() for c in self.carried],
                   "base_chi2_per_dof": finite_or_none(self.base_chi2_per_dof), "failed": self.failed,
                   "notes": list(self.notes)}
        if self.result is not None:
            d.update({"success": bool(self.result.success), "chi2_per_dof": finite_or_none(self.chi2_per_dof),
                      "fits_to_noise": self.fits_to_noise,
                      "per_flight": {l: {"chi2_per_dof": finite_or_none(c), "band": finite_or_none(b),
                                         "fits_to_noise": ok} for l, (c, b, ok) in self.per_flight().items()},
                      "parameters": {n: {"value": finite_or_none(v), "std": finite_or_none(s)}
                                     for n, v, s in self._values()}})
        return d


def sharing_plan(declared: Mapping[str, Sequence[tuple]]) -> tuple[dict, set]:
    """Which effect parameters may be shared between flights, and which stay each flight's own.

    Parameters
    ----------
    declared : mapping
        ``{flight: [(effect, nature, parameter names), ...]}``: each flight's final effects, their
        :func:`effect_nature` and the parameters each adds.

    Returns
    -------
    (dict, set)
        ``{effect: (flights, parameters)}`` of the vehicle effects found in two or more flights whose
        parameters may take one value (a parameter is shareable only when no other effect, in any flight,
        declares a parameter of the same name: two drag tables on other knots both name ``dCD_M0``), and
        the set of effect parameters that are always per flight.
    """
    owner = _owners(declared)
    found: dict = {}
    for flight, items in declared.items():
        for effect, nature, ps in items:
            if nature == "vehicle":
                found.setdefault(effect, [])
                if flight not in found[effect]:
                    found[effect].append(flight)
    shareable = {}
    for effect, flights in found.items():
        ps = tuple(dict.fromkeys(n for f in flights for e, _, pp in declared[f] if e == effect for n in pp
                                 if owner[n] == {effect}))
        if len(flights) > 1 and ps:
            shareable[effect] = (tuple(flights), ps)
    sharing = {n for _, ps in shareable.values() for n in ps}
    return shareable, set(owner) - sharing


def _owners(declared: Mapping[str, Sequence[tuple]]) -> dict:
    """``{parameter: {effects that declare it}}`` over every flight's final effects (:func:`sharing_plan`'s
    ``declared``)."""
    owner: dict = {}
    for items in declared.values():
        for effect, _, ps in items:
            for n in ps:
                owner.setdefault(n, set()).add(effect)
    return owner


def _effect_parameters(base_spec, effect) -> tuple:
    """The names of the parameters ``effect`` adds to ``base_spec``."""
    from .effects import with_effects
    try:
        added = with_effects(base_spec, [effect]).parameter_names
    except RocketidError:
        return tuple(effect.parameter_names)
    known = set(base_spec.parameter_names)
    return tuple(n for n in added if n not in known)


def _guess(layout, values: Sequence[dict]) -> dict:
    """Joint guesses from each flight's own fit: a flight's own parameter its value, a shared one the mean of
    the flights that have it."""
    guess = {}
    for name, owner in zip(layout.names, layout.owner):
        if owner is None:
            vals = [v[name] for v in values if name in v]
            if vals:
                guess[name] = float(np.mean(vals))
        else:
            base = name[:name.rindex("[")]
            if base in values[owner]:
                guess[name] = float(values[owner][base])
    return guess


def joint_final(flights: Sequence, reports: Sequence, base_chi2_per_dof: float, *, level: float = 0.05,
                sigma=None, options=None, per_flight: Sequence[str] = ()) -> JointFinal | None:
    """Fit all flights at once with the effects their diagnoses found; test which vehicle effects are shared.

    Parameters
    ----------
    flights : sequence of Flight
        Each flight's base model and its data as its diagnosis fitted them (:class:`rocketid.joint.Flight`).
    reports : sequence of DiagnosisReport
        Each flight's diagnosis, in the same order.
    base_chi2_per_dof : float
        chi2/dof of the joint fit of the base model.
    level : float
        A vehicle effect is shared when the likelihood-ratio test of one value against one per flight
        has a p-value at least this.
    sigma : optional
        The noise request of the base model's joint fit (:func:`rocketid.joint.joint_estimate`), the same
        for every fit here.
    options : mapping, optional
        IPOPT options.
    per_flight : sequence of str
        Base-model parameters each flight keeps for itself in every joint fit (as in the base model's).

    Returns
    -------
    JointFinal or None
        None when some flight's diagnosis did not search for effects (``confirm_top=0``) or none added one.
    """
    from ..joint import joint_estimate, joint_prepare
    from .effects import with_effects

    finals = [r.discovery for r in reports]
    if any(d is None for d in finals):
        return None
    labels = [fl.label for fl in flights]
    effects = {l: tuple(e.name for e in d.effects) for l, d in zip(labels, finals)}
    nature: dict = {}
    params: dict = {}              # (flight, effect) -> parameter names
    declared: dict = {l: [] for l in labels}
    for l, d in zip(labels, finals):
        for e in d.effects:
            nature[e.name] = effect_nature(e)
            params[(l, e.name)] = _effect_parameters(d.base_fit.spec, e)
            declared[l].append((e.name, nature[e.name], params[(l, e.name)]))
    bands = {l: float(d.band.upper) for l, d in zip(labels, finals)}
    if not any(effects.values()):
        return None
    shareable, always_own = sharing_plan(declared)
    fl_final = [replace(fl, spec=d.fit.spec) for fl, d in zip(flights, finals)]
    values = [dict(zip(d.fit.spec.parameter_names, map(float, d.fit.p))) for d in finals]
    notes: list = []

    base_own = set(per_flight)
    fits: dict = {}
    found_cfg = {l: tuple(d.effects) for l, d in zip(labels, finals)}

    def fit(own: set, cfg: Mapping | None = None):
        # one fit per model of each flight and choice of per-flight parameters: the final fit is often one of
        # the tests' (every effect kept per flight, or the one shared effect's)
        cfg = found_cfg if cfg is None else cfg
        fls = [fl if cfg[fl.label] == found_cfg[fl.label] else
               replace(fl, spec=with_effects(d.base_fit.spec, list(cfg[fl.label])))
               for fl, d in zip(fl_final, finals)]
        key = (frozenset((own | base_own) & _names(fls)), tuple(tuple(e.name for e in cfg[l]) for l in labels))
        if key not in fits:
            prepared = joint_prepare(fls, per_flight=sorted(key[0]))
            fits[key] = joint_estimate(fls, prepared=prepared, guess=_guess(prepared.layout, _carry_values(
                values, labels, cfg, found_cfg)), sigma=sigma, options=options)
        return fits[key]

    tests = []
    shared: list = []
    if shareable:
        own_all = always_own | {n for _, ps in shareable.values() for n in ps}
        try:
            own = fit(own_all)
        except RocketidError as exc:
            own = None
            notes.append(f"the joint fit with every effect per flight failed: {exc}")
        for e, (fs, ps) in shareable.items():
            own_vals = _own_values(own, fs, ps)
            if own is None or not own.success:
                tests.append(SharingTest(e, tuple(fs), ps, own_vals, math.nan, 0, math.nan, False,
                                         "the fit with one value per flight did not converge"))
                continue
            try:
                one = fit(own_all - set(ps))
            except RocketidError as exc:
                tests.append(SharingTest(e, tuple(fs), ps, own_vals, math.nan, 0, math.nan, False,
                                         f"the fit with one value failed: {exc}"))
                continue
            if not one.success:
                tests.append(SharingTest(e, tuple(fs), ps, own_vals, math.nan, 0, math.nan, False,
                                         "the fit with one value did not converge"))
                continue
            stat = max(0.0, 2.0 * (one.objective - own.objective))
            dof = len(ps) * (len(fs) - 1)
            p = float(stats.chi2.sf(stat, dof))
            tests.append(SharingTest(e, tuple(fs), ps, own_vals, stat, dof, p, p >= level,
                                     sizes=_sizes_of(finals, labels, fs, e)))
            if p >= level:
                shared.append(e)
    kept_own = always_own | {n for t in tests if not t.shared for n in t.parameters}
    try:
        result = fit(kept_own)
        failed = ""
    except RocketidError as exc:
        result, failed = None, str(exc)
    carried: list = []
    if result is not None and result.success:
        owner = _owners(declared)
        differ = {t.effect for t in tests if not t.shared}
        cfg, own = dict(found_cfg), set(kept_own)
        for e, finders, effect, ps in _to_carry(labels, finals, nature, params, owner, differ):
            lacking = tuple(l for l in labels if l not in finders)
            step = _carry(fit, cfg, own, effect, ps, finders, lacking, result, level, notes)
            carried.append(step[0])
            if step[0].carried:
                _, cfg, own, result = step
                if e not in shared:
                    shared.append(e)
                for l in lacking:
                    params[(l, e)] = ps
        for e, finders, effect, ps in _to_try_own(labels, finals, nature, params, owner):
            for l in (m for m in labels if m not in finders):      # each flight on its own: its own value
                step = _try_own(fit, cfg, own, effect, ps, finders, (l,), result, level)
                carried.append(step[0])
                if step[0].carried:
                    _, cfg, result = step
                    params[(l, e)] = ps
        effects = {l: tuple(x.name for x in cfg[l]) for l in labels}
    return JointFinal(effects, nature, tuple(shared), tuple(tests), result, float(base_chi2_per_dof), bands,
                      failed, tuple(notes), parameters_of=params, carried=tuple(carried))


def _to_carry(labels, finals, nature: dict, params: dict, owner: dict, differ: set) -> list:
    """``[(effect name, finders, Effect, parameters)]``: the vehicle effects found in some flights but not all,
    whose parameters no other effect declares and on whose value the finders do not differ."""
    return _found_in_some(labels, finals, params, owner, lambda n: nature.get(n) == "vehicle" and n not in differ)


def _found_in_some(labels, finals, params: dict, owner: dict, wanted) -> list:
    """``[(effect name, finders, Effect, parameters)]`` of the effects ``wanted(name)`` found in some flights but
    not all, whose parameters no other effect declares."""
    out, seen = [], set()
    for l, d in zip(labels, finals):
        for e in d.effects:
            if e.name in seen or not wanted(e.name):
                continue
            seen.add(e.name)
            finders = tuple(m for m, dm in zip(labels, finals) if e.name in {x.name for x in dm.effects})
            ps = params[(l, e.name)]
            if len(finders) < len(labels) and ps and all(owner.get(n) == {e.name} for n in ps):
                out.append((e.name, finders, e, ps))
    return out


def _carry(fit, cfg: dict, own: set, effect, ps: tuple, finders: tuple, lacking: tuple, before, level: float,
           notes: list) -> tuple:
    """Try ``effect`` in the flights ``lacking`` it (module notes). Returns ``(Carried, cfg, own, result)``: the
    models of each flight, the per-flight parameters and the joint fit after it (those given when not carried)."""
    ext = {l: cfg[l] + ((effect,) if l in lacking else ()) for l in cfg}
    n_f = len(finders) + len(lacking)
    dof = len(ps) * (n_f - 1)
    try:
        each, one = fit(own | set(ps), ext), fit(own - set(ps), ext)
    except RocketidError as exc:
        return Carried(effect.name, finders, lacking, math.nan, dof, math.nan, False, note=str(exc)), cfg, own, before
    if not (each.success and one.success):
        return (Carried(effect.name, finders, lacking, math.nan, dof, math.nan, False,
                        note="a joint fit with it in every flight did not converge"), cfg, own, before)
    stat = max(0.0, 2.0 * (one.objective - each.objective))
    p = float(stats.chi2.sf(stat, dof))
    fall = 2.0 * (before.objective - one.objective)
    if p < level:
        return Carried(effect.name, finders, lacking, stat, dof, p, False, fall=fall), cfg, own, before
    cfg, own, result = ext, own - set(ps), one
    dropped: dict = {}
    for l in lacking:
        for x in reversed(cfg[l][:-1]):             # the flight's own effects, the latest first
            fewer = {m: tuple(y for y in cfg[m] if not (m == l and y is x)) for m in cfg}
            try:
                r = fit(own, fewer)
            except RocketidError as exc:
                notes.append(f"the joint fit of {l} without {x.name} failed: {exc}")
                continue
            if r.success and _bic(r) < _bic(result):
                cfg, result = fewer, r
                dropped.setdefault(l, []).append(x.name)
    return (Carried(effect.name, finders, lacking, stat, dof, p, True, {l: tuple(d) for l, d in dropped.items()},
                    fall), cfg, own, result)


def _to_try_own(labels, finals, nature: dict, params: dict, owner: dict) -> list:
    """``[(effect name, finders, Effect, parameters)]``: the flights' own effects (not the vehicle's) found in two
    or more flights but not all, whose parameters no other effect declares."""
    return [x for x in _found_in_some(labels, finals, params, owner, lambda n: nature.get(n) != "vehicle")
            if len(x[1]) >= 2]


def _try_own(fit, cfg: dict, own: set, effect, ps: tuple, finders: tuple, lacking: tuple, before,
             level: float) -> tuple:
    """Try a flight's own ``effect``, found in the flights ``finders``, in the flights ``lacking`` it, with a value
    of its own in each (module notes). Returns ``(Carried, cfg, result)``: the models of each flight and the joint
    fit after it (those given when it is not added).

    A flight's own effect (its loading, its sensor, its day) is never one value for the campaign, but one found
    in several flights is a pattern the others may share and their own searches may have missed: measured on
    three Petrel-V flights that each carried a 40 kg adapter nobody declared, two found ``start_mass`` (40.4 and
    40.1 kg), the third's search met ``start_mass`` and a thrust profile at the noise alike and added nothing;
    without the start mass in the third flight the joint model put the shared drag on its misfit (CD_0 1.38) and
    the other two flights' start masses at 0.08 kg."""
    ext = {l: cfg[l] + ((effect,) if l in lacking else ()) for l in cfg}
    dof = len(ps) * len(lacking)
    try:
        r = fit(own | set(ps), ext)
    except RocketidError as exc:
        return Carried(effect.name, finders, lacking, math.nan, dof, math.nan, False, note=str(exc), own=True), \
            cfg, before
    if not r.success:
        return (Carried(effect.name, finders, lacking, math.nan, dof, math.nan, False,
                        note="the joint fit with it did not converge", own=True), cfg, before)
    stat = max(0.0, 2.0 * (before.objective - r.objective))
    p = float(stats.chi2.sf(stat, dof))
    added = p < level and _bic(r) < _bic(before)
    return (Carried(effect.name, finders, lacking, stat, dof, p, added, fall=stat, own=True),
            ext if added else cfg, r if added else before)


def _sizes_of(finals, labels, flights, name: str) -> dict:
    """The realistic sizes of effect ``name``'s parameters for the vehicle of the first flight that found it."""
    for l, d in zip(labels, finals):
        vehicle = getattr(d, "vehicle", None)
        if l in flights and vehicle is not None:
            for e in d.effects:
                if e.name == name:
                    return {k: float(v) for k, v in e.sizes(vehicle).items()}
    return {}


def _bic(res) -> float:
    """The joint fit's BIC, ``2 J + k ln n`` (``k`` joint parameters, ``n`` data)."""
    return 2.0 * float(res.objective) + res.layout.n * math.log(max(1, res.n_data))


def _carry_values(values: Sequence[dict], labels: Sequence[str], cfg: Mapping, found: Mapping) -> list:
    """Each flight's guesses, with an effect carried to it started from the mean of the flights that found it."""
    out = [dict(v) for v in values]
    for i, l in enumerate(labels):
        for e in cfg[l]:
            if e in found[l]:
                continue
            for n in e.parameter_names:
                vals = [values[j][n] for j, m in enumerate(labels) if n in values[j] and e in found[m]]
                if vals and n not in out[i]:
                    out[i][n] = float(np.mean(vals))
    return out


def _chi2(value: float) -> str:
    """chi2/dof as the summaries print it: four decimals near the noise, four digits far from it."""
    return f"{value:.4f}" if abs(value) < 100 else f"{value:.4g}"


def _names(flights) -> set:
    return {n for fl in flights for n in fl.spec.parameter_names}


def _own_values(res, flights: Sequence[str], parameters: Sequence[str]) -> dict:
    """``{flight: {parameter: (value, std)}}`` of a fit where each flight has its own values."""
    if res is None:
        return {}
    try:
        se = res.standard_errors
    except SensitivityError:
        se = np.full(len(res.names), np.nan)
    out = {}
    for l in flights:
        d = {}
        for n in parameters:
            key = f"{n}[{l}]"
            if key in res.names:
                i = res.names.index(key)
                d[n] = (float(res.theta[i]), float(se[i]))
        out[l] = d
    return out
