"""``diagnose()``: the whole diagnosis loop on one data set, and its report.

::

    fit the model -> compare -> locate -> check plausibility
        -> rank candidate effects (score test) -> confirm the leaders by refitting
        -> history (base and refits) -> report.html, candidates.json

The model is the chapter's RA-66 parameterization by default (time-knot
CD(t), constant CL); ``"ra66m"`` selects the Mach-indexed one (CD(M),
CL = CL_alpha alpha), or pass a :class:`~rocketid.model.ModelSpec` or the
path of a model file defining ``build_model()``.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from ..cases.registry import BUILTIN_MODELS, resolve_model
from ..data import Measurements, read_csv
from ..errors import DataError, RocketidError, SettingsError
from ..model import Model, ModelSpec
from ..output import environment
from ..solve import EstimationResult, estimate
from .compare import Comparison, compare
from .locate import Location, locate
from .plausibility import Plausibility, check_plausibility

__all__ = ["diagnose", "DiagnosisReport", "FinalModel", "resolve_model", "BUILTIN_MODELS"]


def _read_data(data, spec: ModelSpec) -> tuple[Measurements, str]:
    if isinstance(data, Measurements):
        return data, "the given measurements"
    if isinstance(data, (str, Path)):
        return read_csv(data, spec.output_names), str(data)
    raise DataError(f"data must be Measurements or the path of a CSV file, got {type(data).__name__}")


@dataclass(frozen=True)
class FinalModel:
    """The model the diagnosis ends with.

    Attributes
    ----------
    effects : tuple of str
        The effects added, in the order added (empty: none).
    parameters : dict
        ``{name: (value, std)}`` of every estimated parameter (std NaN when not available).
    chi2_per_dof : float
    fits_to_noise : bool
        chi2/dof inside the noise band and residuals no less white than clean data.
    verdict : str
        ``"nothing missing"``, ``"explained"``, ``"partly explained"`` or
        ``"not explained by the catalogue"``.
    explanation : str
        One sentence: what was found, what remains and where, or what to try.
    fit : EstimationResult
    """

    effects: tuple
    parameters: dict
    chi2_per_dof: float
    fits_to_noise: bool
    verdict: str
    explanation: str
    fit: EstimationResult = field(repr=False)

    def to_dict(self) -> dict:
        return {"effects": list(self.effects),
                "parameters": {k: {"value": float(v), "std": None if not math.isfinite(s) else float(s)}
                               for k, (v, s) in self.parameters.items()},
                "chi2_per_dof": float(self.chi2_per_dof), "fits_to_noise": bool(self.fits_to_noise),
                "verdict": self.verdict, "explanation": self.explanation}


@dataclass(frozen=True)
class DiagnosisReport:
    """Everything the diagnosis found, with :meth:`summary` and :meth:`write`.

    Attributes
    ----------
    model : str
        What was asked for (``ra66``, ``ra66m``, a file, or the spec's name).
    data_label : str
    fit : EstimationResult
        The base fit.
    comparison : Comparison
    location : Location or None
        None when the data are too short for the windows (see :attr:`notes`).
    plausibility : Plausibility
    ranking : object or None
        :class:`rocketid.diagnostics.score.CandidateRanking` at the base fit (None when
        the ranking could not be made; see :attr:`notes`).
    confirmations : tuple
        :class:`rocketid.diagnostics.refit.Confirmation` of the final model's effects against
        the base model (with the hold-out check); empty when nothing was added.
    confirmed : tuple of str
        The effects of each confirmation (``"a + b"``), in the same order.
    refit_plausibility : tuple of Plausibility
        The plausibility checks of each confirmation's refit.
    after : Comparison or None
        The comparison of the final model.
    history : object or None
        :class:`rocketid.diagnostics.history.ModelHistory`: the base fit, then each step.
    level : float
    timings : dict
        Wall time of each step, s.
    notes : tuple of str
    discovery : Discovery or None
        The stepwise search (:mod:`rocketid.diagnostics.step`): every contender's refit and
        acceptance test, step by step.
    final : FinalModel or None
    variant : DiagnosisReport or None
        For a model with time-knot drag: the same discovery on its Mach-indexed variant.
    ranking_failed : str
        Why the score test could not be made at the base fit (empty when it was).
    noise_from_data : dict
        ``{channel: (sigma, number of differences)}`` of the channels whose noise was estimated from the
        data alone (``sigma="estimate"``; :func:`rocketid.data.difference_noise`); empty otherwise.
    wild_points : WildPoints or None
        The isolated samples no model can follow, found on the first base fit
        (:mod:`rocketid.diagnostics.wild`); dropped before the diagnosis unless
        ``wild_points="keep"``. None when the test was not made.
    correlated_noise : CorrelatedNoise or None
        The errors' correlation in time, channel by channel, found on the base fit
        (:mod:`rocketid.diagnostics.correlated`); a correlated channel is thinned to the samples whose
        errors are independent unless ``correlated_noise="keep"``. None when the test was not made.
    free_shape : FreeShape or None
        The free shape the verdict names, fitted to the user's model when the search ended above the
        noise (:mod:`rocketid.diagnostics.freeshape`): of what kind the missing physics is, and its shape.
        None when the search reached the noise, was cut short or named a tie, or the kind has none.
    """

    model: str
    data_label: str
    fit: EstimationResult
    comparison: Comparison
    location: Location | None
    plausibility: Plausibility
    ranking: Any
    confirmations: tuple
    confirmed: tuple
    refit_plausibility: tuple
    after: Comparison | None
    history: Any
    level: float
    timings: dict
    notes: tuple = ()
    discovery: Any = None
    final: FinalModel | None = None
    variant: Any = None
    ranking_failed: str = ""
    noise_from_data: dict = field(default_factory=dict)
    wild_points: Any = None
    correlated_noise: Any = None
    free_shape: Any = None

    # ---- verdicts
    @property
    def fails(self) -> bool:
        """The base model does not reach the noise, or its coefficients are implausible."""
        return (not self._base_fits()) or (not self.plausibility.passed)

    @property
    def steps(self) -> tuple:
        """The steps of the stepwise search (empty without one)."""
        return () if self.discovery is None else self.discovery.steps

    def effect_name(self, confirmation) -> str:
        """The candidate name a confirmation refitted."""
        for c, name in zip(self.confirmations, self.confirmed):
            if c is confirmation:
                return name
        return _effect_name(confirmation)

    @property
    def best(self):
        """The confirmation of the final model (None when nothing was added)."""
        return self.confirmations[-1] if self.confirmations else None

    @property
    def choice(self) -> str:
        """Why the final model's last effect was chosen."""
        chosen = [s for s in self.steps if s.chosen is not None]
        return chosen[-1].why if chosen else "nothing was chosen"

    def verdict(self) -> list[str]:
        """The diagnosis in a few sentences."""
        out = []
        c = self.comparison
        base_ok = self._base_fits()
        if self.wild_points:
            out.append(self.wild_points.note()[0].upper() + self.wild_points.note()[1:] + ".")
        if self.correlated_noise:
            text = self.correlated_noise.note()
            out.append(text[0].upper() + text[1:] + ".")
        if base_ok:
            measured = self.fit.prepared.measurements.names
            taken = [n for n in measured if n in self.noise_from_data]
            level = ("the noise taken from the data" if len(taken) == len(measured) else
                     f"the stated sigma, {', '.join(taken)} from the data" if taken else
                     "the stated sigma")
            out.append(f"The residuals of {self.fit.spec.name} are white noise at {level} "
                       f"(chi2/dof {c.chi2_per_dof:.3f}).")
        else:
            out.append(f"{self.fit.spec.name} does not fit to the noise: chi2/dof = {c.chi2_per_dof:.3g}"
                       + (f" (band <= {self.discovery.band.upper:.4g})" if self.discovery is not None else "")
                       + ", residuals not white." if not c.fits_to_noise else
                       f"{self.fit.spec.name} does not fit to the noise: chi2/dof = {c.chi2_per_dof:.3g}.")
        if self.location is not None and self.location.findings and not base_ok:
            f = self.location.findings[0]
            out.append(f"It fails most in: {f.text}.")
            e = self.location.earliest
            if e is not None and e is not f:
                out.append(f"It fails first in: {e.text}.")
        if not self.plausibility.passed:
            names = self.plausibility.flagged_parameters()
            out.append(f"The coefficients are implausible ({len(self.plausibility.flagged(severity='fail'))} failing "
                       f"check(s) on {', '.join(names[:6])}{'...' if len(names) > 6 else ''}): a flexible "
                       "parameterization may be absorbing a missing effect.")
        if self.ranking is not None and getattr(self.ranking, "candidates", None):
            top = self.ranking.candidates[0]
            sig = [k for k in self.ranking.candidates if getattr(k, "significant", False)]
            if sig:
                out.append(f"The score test ranks {top.name} ({top.title}) first (statistic {top.statistic:.4g}, "
                           f"corrected {_p(top.p_value_corrected)}); {len(sig)} candidate(s) significant at "
                           f"{self.level:g}.")
            else:
                out.append(f"No candidate effect is significant at {self.level:g} (best: {top.name}).")
        for s in self.steps:
            if s.acceptances:
                acc = sum(a.accepted for a in s.acceptances)
                out.append(f"Step {s.number}: {len(s.acceptances)} refit(s) ({', '.join(a.refit.name for a in s.acceptances)}); "
                           f"{acc} reach(es) the noise with plausible sizes; "
                           + (f"added {s.chosen.refit.name} (chi2/dof {s.chosen.refit.chi2_per_dof:.4g}; {s.why})."
                              if s.chosen is not None else f"none added ({s.why})."))
        b = self.best
        if b is not None:
            name = self.effect_name(b)
            est = "; ".join(f"{k} = {v[0]:.4g}" + (f" +- {v[1]:.2g}" if math.isfinite(v[1]) else "")
                            for k, v in b.effect_estimates.items())
            if any(not math.isfinite(v[1]) for v in b.effect_estimates.values()):
                why = next((n.split(": ", 1)[1] for n in b.notes if n.startswith("no uncertainty")), "")
                est += (" (no standard errors: the data at this fit do not determine every parameter"
                        + (f" -- {why}" if why else "") + "; these values are not estimates of known precision)")
            out.append(f"Refit with {name} ({'confirmed' if b.confirmed else 'NOT confirmed'}): chi2/dof "
                       f"{b.fit.chi2_per_dof:.4g} (was {self.fit.chi2_per_dof:.4g}), LR {_p(b.lr_p_value)}, "
                       f"BIC {b.bic[0]:.6g} -> {b.bic[1]:.6g}; {est}.")
        if self.final is not None:
            out.append(f"Verdict: {self.final.verdict}. {self.final.explanation}")
        if self.free_shape is not None:
            out.append(self.free_shape.text())
        if self.variant is not None and self.variant.final is not None:
            v = self.variant.final
            out.append(f"On the Mach-indexed variant ({self.variant.fit.spec.name}): {v.verdict}"
                       + (f" with {', '.join(v.effects)}" if v.effects else "")
                       + f" (chi2/dof {v.chi2_per_dof:.4g}).")
        return out

    @property
    def search_stopped(self) -> str:
        """Where the search's time budget ran out (the variant's search's, prefixed), empty when it did not."""
        own = _stopped(self.discovery)
        if own:
            return own
        var = _stopped(self.variant.discovery) if self.variant is not None else ""
        return f"the Mach-indexed variant's search: {var}" if var else ""

    def _base_fits(self) -> bool:
        if self.discovery is not None:
            from .accept import fits_to_noise
            return fits_to_noise(self.fit, self.discovery.band)[0]
        return self.comparison.fits_to_noise

    def summary(self) -> str:
        """Fixed sections (verdict, compare, locate, plausibility, candidates, steps,
        confirmations, history) and numbered notes: a :class:`~rocketid.summary.Summary`
        (as :class:`~rocketid.summary.SummaryText`, so it prints and joins as text)."""
        from ..summary import Section, Summary, SummaryText
        sections = [Section("Verdict", tuple(self.verdict()))]
        if self.wild_points:
            sections.append(Section("", (self.wild_points.summary(),)))
        if self.correlated_noise:
            sections.append(Section("", (self.correlated_noise.summary(),)))
        sections += [Section("", (self.comparison.summary(),)),
                    Section("", (self.location.summary() if self.location is not None
                                 else "Location: not available (see notes)",)),
                     Section("", (self.plausibility.summary(),))]
        if self.ranking is not None:
            sections.append(Section("", (self.ranking.summary(),)))
        if self.steps:
            lines = []
            for st in self.steps:
                lines.append(f"step {st.number}: {st.why}")
                for a in st.acceptances:
                    r = a.refit
                    lines.append(f"  {r.name:<22} chi2/dof {r.chi2_per_dof:>9.4g}  BIC {r.bic[1]:>12.6g}  "
                                 f"{'ACCEPTED' if a.accepted else ('admissible' if a.admissible else 'rejected')}"
                                 + ("" if a.accepted else f": {a.reason()}"))
            sections.append(Section("Stepwise search (every contender refitted; accepted = reaches the noise with "
                                    "plausible sizes and coefficients)", tuple(lines)))
        sections += [Section("", (c.summary(),)) for c in self.confirmations]
        if self.history is not None:
            try:
                sections.append(Section("History", (str(self.history.table()),)))
            except Exception as exc:  # noqa: BLE001 - a report must not fail on a table
                sections.append(Section("History", (f"not available ({exc})",)))
        return SummaryText(Summary(f"rocketid diagnosis: {self.fit.spec.name} on {self.data_label}", tuple(sections),
                                   tuple(self.notes)))

    def candidates_payload(self) -> dict:
        """``{"candidates": [...]}``, best first, each with ``name``, ``statistic``,
        ``p_value`` (corrected) and ``group`` (the content of candidates.json)."""
        if self.ranking is None:
            return {"candidates": [], "note": "no ranking: " + (self.ranking_failed or "the score test was not made")}
        payload = dict(self.ranking.to_dict())
        cands = list(payload.get("candidates", []))
        objs = list(getattr(self.ranking, "candidates", []))
        fixed = []
        for i, d in enumerate(cands):
            d = dict(d)
            o = objs[i] if i < len(objs) else None
            if o is not None:
                d.setdefault("name", o.name)
                d.setdefault("statistic", float(o.statistic))
                d.setdefault("p_value", float(o.p_value_corrected))
                d.setdefault("group", getattr(o, "group", None))
            fixed.append(d)
        payload["candidates"] = fixed
        return payload

    def to_dict(self) -> dict:
        out = {"model": self.model, "data": self.data_label, "fails": self.fails, "verdict": self.verdict(),
               "fit": self.fit.to_dict(), "comparison": self.comparison.to_dict(),
               "location": self.location.to_dict() if self.location is not None else None,
               "plausibility": self.plausibility.to_dict(), "candidates": self.candidates_payload()["candidates"],
               "confirmations": [_confirmation_dict(c, n) for c, n in zip(self.confirmations, self.confirmed)],
               "final": None if self.final is None else self.final.to_dict(),
               "steps": [s.to_dict() for s in self.steps],
               "noise_band": None if self.discovery is None else self.discovery.band.to_dict(),
               "search_stopped": self.search_stopped or None,
               "variant": None if self.variant is None else {
                   "model": self.variant.fit.spec.name,
                   "final": None if self.variant.final is None else self.variant.final.to_dict(),
                   "steps": [s.to_dict() for s in self.variant.steps]},
               "noise_from_data": {c: {"sigma": float(v), "differences": int(n)}
                                   for c, (v, n) in self.noise_from_data.items()},
               "wild_points": None if self.wild_points is None else self.wild_points.to_dict(),
               "correlated_noise": None if self.correlated_noise is None else self.correlated_noise.to_dict(),
               "free_shape": None if self.free_shape is None else self.free_shape.to_dict(),
               "timings": dict(self.timings), "notes": list(self.notes), "environment": environment()}
        return out

    def write(self, out: str | Path) -> Path:
        """Write ``out/report.html`` (self-contained), ``out/candidates.json``,
        ``out/diagnosis.json``, ``out/summary.txt`` and ``out/figures/*.png``;
        returns the path of report.html."""
        from .report import write_report
        return write_report(self, out)


def _p(p: float) -> str:
    return "p < 1e-300" if p == 0 else f"p = {p:.2g}"


def _effect_name(conf) -> str:
    effects = getattr(conf, "effects", None)
    if effects:
        return " + ".join(map(str, effects))
    est = getattr(conf, "effect_estimates", None) or {}
    return ", ".join(est) if est else "the effect"


def _prediction_check(disc, confs, notes: list):
    """The discovery, downgraded from "explained" to "partly explained" when the final model, fitted
    on the hold-out window, predicts the rest of the flight decisively worse than the base model
    (:attr:`rocketid.diagnostics.refit.Confirmation.predicts`): it reaches the noise by following
    the fitted data, not the physics."""
    if disc is None or disc.verdict != "explained" or not confs or confs[0].predicts:
        return disc
    why = confs[0].prediction_note
    notes.append(f"the final model ({' + '.join(disc.effect_names)}) reaches the noise but is not an explanation: {why}")
    return replace(disc, verdict="partly explained", not_an_explanation=why, notes=disc.notes + (notes[-1],))


def _confirmation_dict(c, name: str | None = None) -> dict:
    """:meth:`Confirmation.to_dict` with the candidate's name as ``effect``."""
    d = dict(c.to_dict())
    d["effect"] = name or _effect_name(c)
    return d


# ---------------------------------------------------------------------------
# the named steps of diagnose()
# ---------------------------------------------------------------------------


def _check_settings(level, confirm_top, max_effects, refit_timeout, budget=None) -> None:
    if not 0 < level < 1:
        raise SettingsError(f"level must be in (0, 1), got {level}")
    if isinstance(confirm_top, bool) or not isinstance(confirm_top, (int, np.integer)) or confirm_top < 0:
        raise SettingsError(f"confirm_top must be a non-negative integer, got {confirm_top!r}")
    if isinstance(max_effects, bool) or not isinstance(max_effects, (int, np.integer)) or max_effects < 1:
        raise SettingsError(f"max_effects must be a positive integer, got {max_effects!r}")
    if isinstance(refit_timeout, bool) or not isinstance(refit_timeout, (int, float)) or not refit_timeout > 0:
        raise SettingsError(f"refit_timeout must be a positive number of seconds, got {refit_timeout!r}")
    if budget is not None and (isinstance(budget, bool) or not isinstance(budget, (int, float, np.floating))
                               or not budget > 0 or not math.isfinite(budget)):
        raise SettingsError(f"budget must be a positive number of seconds (or None: no limit), got {budget!r}")


def _check_checkpoints(folder, resume: bool) -> None:
    """Refuse, before any work, a checkpoint folder that holds an unfinished diagnosis's refits without
    ``resume`` (they would be mixed with another search's)."""
    if folder is None:
        return
    kept = sorted(Path(folder).glob("*.pkl")) if Path(folder).is_dir() else []
    if kept and not resume:
        raise SettingsError(f"{folder} holds the refits of an unfinished diagnosis ({len(kept)}): continue it with "
                            "--resume (diagnose(resume=True)), or remove that folder to start afresh")


def _stopped(disc) -> str:
    return "" if disc is None else disc.stopped


def end_checkpoints(folder: Path, stopped: bool, notes: list, *, remove: bool = True) -> None:
    """Remove the refits kept in ``folder`` while a search ran, once it has ended (``remove``: the caller
    that set the folder up may keep them until its own work ends -- several flights, each resumed from
    its own); keep them, with a note, when it was stopped at its budget (a run with ``resume`` and a
    larger budget goes on from them)."""
    kept = sorted(folder.glob("*.pkl")) if folder.is_dir() else []
    if stopped:
        if kept:
            notes.append(f"checkpoints: the {len(kept)} refits made are kept in {folder}: run again with --resume "
                         "(diagnose(resume=True)) and a larger budget to go on from them")
        return
    if not remove:
        return
    for f in kept:
        f.unlink(missing_ok=True)
    try:
        folder.rmdir()
    except OSError:
        pass          # not empty (someone else's files) or already gone


def _noise_from_data(sigma, meas, notes: list, from_data: dict, known: Mapping | None = None) -> tuple:
    """The diagnosis's noise levels when some are to be estimated: from the data alone (the scatter of
    each channel's fourth differences, :func:`rocketid.data.difference_noise`), not from the base model's
    residuals -- those hold the misfit the diagnosis looks for, and a model judged against its own
    residuals always "reaches the noise". ``known`` gives ``{channel: (sigma, differences, how)}`` of
    channels whose level was measured otherwise (:func:`_noise_of_thinned`). Returns the ``sigma`` request
    with numbers in place of ``"estimate"`` and ``{channel: number of differences}`` of the channels
    estimated so."""
    from ..data import DIFFERENCE_ORDER, difference_noise, resolve_quantized, sigma_request

    if sigma is None:
        return None, {}
    sigma = resolve_quantized(sigma, meas)
    given, wanted = sigma_request(sigma, meas.names)
    if not wanted:
        return sigma, {}
    known = known or {}
    values, counts, how = dict(given), {}, {}
    for name in wanted:
        if name in known:
            values[name], counts[name], how[name] = known[name]
        else:
            values[name], counts[name] = difference_noise(meas[name])
            how[name] = f"{counts[name]} differences"
    from_data.update({n: (values[n], counts[n]) for n in wanted})
    notes.append(f"noise estimated from the data alone (the scatter of each channel's {DIFFERENCE_ORDER}th differences, "
                 "not the size of the model's residuals): " + ", ".join(f"{n} {values[n]:.4g} ({how[n]})"
                                                                       for n in wanted)
                 + "; the models are judged against it, and the noise band is widened for its uncertainty")
    return values, counts


def _noise_of_thinned(corr, fit) -> dict:
    """``{channel: (sigma, differences, how)}`` of the channels thinned for correlated errors, at the errors'
    full size: the sigma of ``fit`` (which measured the correlation) times ``sqrt(variance)``, the level the
    scatter of its normalized residuals' fourth differences settled at (:class:`~rocketid.diagnostics.correlated.
    ChannelCorrelation`), resting on the thinned channel's differences. The thinned data's own differences are
    not used: samples a second or more apart carry the flight's curvature into them (on Corvid-L's speed, 1.4 s
    apart, 2.6 m/s for 0.25)."""
    return {c.channel: (fit.sigma[c.channel] * math.sqrt(c.variance), max(1, c.kept - 4),
                        f"the errors' full size, from the base fit's residuals' differences up to {c.stride} samples "
                        "apart: one sample apart they see only part of correlated errors")
            for c in corr.correlated}


def base_fit(spec, meas, sigma=None, *, guess=None, mesh=None, options=None, notes: list | None = None,
             from_data: dict | None = None, wild_points: str = "drop", correlated_noise: str = "thin") -> tuple:
    """The diagnosis's base fit: the noise (from the data alone where it is to be estimated), the fit, the
    wild points on its residuals (:func:`~rocketid.diagnostics.wild.find_wild_points`) and, when they are
    dropped, the noise and the fit again without them; then the errors' correlation in time
    (:func:`~rocketid.diagnostics.correlated.find_correlated_noise`) and, where it is found and the channels
    are thinned, the noise and the fit again on the samples whose errors are independent.

    Returns
    -------
    fit : EstimationResult
    sigma
        The ``sigma`` request with numbers in place of ``"estimate"``.
    counts : dict
        ``{channel: number of differences}`` of the channels whose noise was estimated.
    wild : WildPoints
    correlated : CorrelatedNoise
    """
    from .correlated import check_action as check_correlated, find_correlated_noise
    from .wild import check_action, find_wild_points

    check_action(wild_points)          # before the first fit
    check_correlated(correlated_noise)
    notes = notes if notes is not None else []
    from_data = from_data if from_data is not None else {}
    first: list = []
    values, counts = _noise_from_data(sigma, meas, first, from_data)
    fit = _fit_base(spec, meas, guess, mesh, options, first, values)
    wild = find_wild_points(fit, action=wild_points)
    if wild and wild_points == "drop":
        first, meas = [], wild.without(meas)
        values, counts = _noise_from_data(sigma, meas, first, from_data)
        fit = _fit_base(spec, meas, fit.p, fit.prepared.transcription.mesh, options, first, values)
    corr = find_correlated_noise(fit, action=correlated_noise)
    if corr and correlated_noise == "thin":
        first, meas = [], corr.thin(meas)
        values, counts = _noise_from_data(sigma, meas, first, from_data, _noise_of_thinned(corr, fit))
        fit = _fit_base(spec, meas, fit.p, fit.prepared.transcription.mesh, options, first, values)
    notes.extend(first)
    if wild:
        notes.append(wild.note())
    if corr:
        notes.append(corr.note())
    return fit, values, counts, wild, corr


def _fit_base(spec, meas, guess, mesh, options, notes: list, sigma=None) -> EstimationResult:
    if mesh is None:
        # a short first element: effects that act from lift-off (misalignment, Earth
        # rotation) are otherwise blurred by the singular start (docs/effects.md); the
        # candidates' refits reuse this mesh
        from ..solve import default_mesh
        mesh = default_mesh(spec, refine_first=3)
    fit = estimate(spec, meas, guess=guess, mesh=mesh, options=options, sigma=sigma)
    if not fit.success:
        notes.append(f"the base fit did not converge ({fit.message}); the diagnosis describes its last iterate")
    return fit


def _describe(fit, level, window, notes: list) -> tuple:
    """compare -> locate -> plausibility of one fit."""
    comp = compare(fit, level=level)
    try:
        loc = locate(fit, comp, window=window, level=level)
    except DataError as exc:
        loc = None
        notes.append(f"no location: {exc}")
    return comp, loc, check_plausibility(fit, level=level)


def _oversized(refit, band) -> bool:
    from .accept import accept
    return accept(refit, band).oversized


def _stated(effects: list, sizes: dict, fit: EstimationResult, notes: list) -> list:
    """The candidates with the user's realistic sizes (:func:`~rocketid.diagnostics.effects.state_sizes`); an
    entry that names no parameter of them or of their refined shapes on this vehicle is refused."""
    if not sizes:
        return effects
    from .effects import state_sizes, stated_names
    from .screen import vehicle_of
    effects = state_sizes(effects, sizes)
    named = stated_names(effects, sizes, vehicle_of(fit))
    unused = [k for k, v in named.items() if not v]
    if unused:
        import difflib
        known = sorted({n for e in effects for n in e.realistic})
        close = difflib.get_close_matches(unused[0], known, n=3)
        raise SettingsError(f"sizes: {', '.join(map(repr, unused))} names no parameter of the candidate effects"
                            + (f"; did you mean {', '.join(close)}?" if close else "")
                            + f" (their parameters include {', '.join(known[:12])}{' ...' if len(known) > 12 else ''}; "
                            "a pattern such as 'eps_P*' names a profile's knots)")
    notes.append("realistic sizes stated by the user, in place of the catalogue's: "
                 + "; ".join(f"{k} {sizes[k]:g} ({', '.join(v[:4])}{' ...' if len(v) > 4 else ''})"
                             for k, v in named.items()))
    return effects


def _candidate_effects(candidates) -> list:
    from .effects import CATALOGUE, resolve_effects
    return resolve_effects(list(CATALOGUE.values()) if candidates is None else list(candidates))


def _confirm_final(fit, disc, holdout, level, timeout, options, notes: list) -> tuple:
    """The final model's effects confirmed against the base model (LR, BIC, hold-out), started
    from the final estimate; and the plausibility of its coefficients."""
    from .refit import confirm, effect_sizes
    if disc is None or not disc.effects:
        return (), (), ()
    spec_f = disc.fit.spec
    # IPOPT's relaxed bounds leave an estimate at a bound up to ~1e-8 outside it: start inside
    start = np.clip(np.asarray(disc.fit.p, float), spec_f.lower, spec_f.upper)
    guess = dict(zip(spec_f.parameter_names, (float(v) for v in start)))
    try:
        conf = confirm(fit, list(disc.effects), guess=guess, holdout=holdout, level=level, options=options,
                       timeout=timeout, fitted=disc.fit)
    except RocketidError as exc:
        notes.append(f"the final model could not be confirmed: {exc}")
        return (), (), ()
    sizes = effect_sizes(conf.fit.spec.parameter_names, fit.spec.parameter_names, disc.effects, disc.vehicle)
    try:
        pl = (check_plausibility(conf.fit, level=level, realistic=sizes),)
    except RocketidError as exc:
        notes.append(f"the plausibility of the final model could not be checked: {exc}")
        pl = ()
    return (conf,), (" + ".join(disc.effect_names),), pl


def _history(spec, fit, disc, notes: list):
    from .history import ModelHistory
    try:
        history = ModelHistory().add(f"{spec.name}", fit)
        for s in (disc.steps if disc is not None else ()):
            if s.fit is not None:
                history = history.add("+ " + " + ".join(s.effects), s.fit)
        return history
    except RocketidError as exc:
        notes.append(f"model history failed: {exc}")
        return None


def _lead(disc, ranking) -> tuple[str, str] | None:
    """``(kind, family)`` of what the missing physics most looks like: the search's first effect added of a kind
    that has a free shape (:data:`~rocketid.diagnostics.freeshape.FREE_SHAPE_KINDS`; its first effect when none
    has), else the screen's first candidate at the base fit; None when there is neither. (The screen alone
    misled: on Wren-H's cold tank it ranked a density profile first, leading a confounded group with the start
    mass and the thrust level, and the search's refits then took the burn rate. A first effect of another kind
    may be complete and right -- a warm tank on a shallow rail took the start angle first, then the burn rate.)"""
    leads = _leads(disc, ranking)
    return leads[0] if leads else None


def _leads(disc, ranking) -> list[tuple[str, str]]:
    """The ``(kind, family)`` of every kind of the search's effects, in the order added, those with a free shape
    first (one per free shape: a propulsion and a mass effect share the thrust's), then the screen's first
    candidate's, then the thrust's: the free shapes to try in turn
    (:func:`~rocketid.diagnostics.freeshape.free_shape_check`). The thrust's comes last whatever was found: a
    force in time over the burn, the term a motor outside the catalogue needs (Wren-H's grain 13 mm short with its
    GPS altitude 15 m low: the search took the altitude bias and two drag shapes, the screen ranked four sensor
    errors and the density first, and the thrust's free shape reaches the noise beside the bias alone, the drag
    shapes not needed)."""
    from .freeshape import FREE_SHAPE_KINDS
    from .step import _family
    effects = list(disc.effects) if disc is not None else []
    top = ranking.candidates[0] if ranking is not None and getattr(ranking, "candidates", None) else None
    pool = sorted(effects, key=lambda e: e.kind not in FREE_SHAPE_KINDS) + ([top] if top is not None else [])
    out, seen = [], set()
    for e in pool:
        fam = _family(e.name)
        key = "thrust" if e.kind in ("propulsion", "mass") else (e.kind, fam if e.kind == "environment" else "")
        if key not in seen and (e.kind in FREE_SHAPE_KINDS or not out):
            seen.add(key)
            out.append((e.kind, fam))
    if out and "thrust" not in seen:
        out.append(("propulsion", "thrust_level"))
    return out


def _suggest(lead: tuple[str, str] | None) -> str:
    """Which free-shape term to try, from the kind of what the missing physics looks like (:func:`_lead`)."""
    kind = lead[0] if lead is not None else ""
    if kind in ("propulsion", "mass"):
        return ("a thrust error in time (rocketid.diagnostics.thrust_profile_effect on the mesh's element boundaries over the burn), "
                "a throttle in time that scales thrust and mass flow together (throttle_effect on those knots: an "
                "engine or motor running at another operating point that changes through the burn), or your own "
                "propulsion term (custom_effect)")
    if kind == "environment":
        return ("a wind piecewise linear in altitude with a surface value on more knots "
                "(rocketid.diagnostics.wind_profile_effect) or a density deviation piecewise linear in altitude "
                "(density_profile_effect)")
    if kind == "aero":
        return ("a drag correction piecewise linear in Mach on more knots (rocketid.diagnostics.drag_mach_effect, "
                "or Model.table on the Mach role)")
    if kind == "sensor":
        return ("a sensor model of the failing channel: its own latency or lag (rocketid.diagnostics.sensor_lag_effect, "
                "passed as a candidate beside the catalogue), or custom_effect redefining that output")
    return "a term of your own written with custom_effect"


def _free_shape_kinds(disc, ranking) -> list[tuple[str, str]]:
    """The ``(kind, family)`` whose free shapes to fit, in turn (:func:`_leads`, those with a free shape); empty for
    a search of sensor effects only, whose suggestion is a sensor model (a lag in a speed sensor is no force)."""
    from .freeshape import FREE_SHAPE_KINDS
    leads = _leads(disc, ranking)
    if not leads or leads[0][0] == "sensor":
        return []
    return [k for k in leads if k[0] in FREE_SHAPE_KINDS]


def _free_shape(disc, ranking, settings: dict, budget, t_search: float, notes: list):
    """The free shape the verdict names (:func:`_lead`), fitted (:mod:`~rocketid.diagnostics.freeshape`), when the
    search ended above the noise ("partly explained" or "not explained by the catalogue", no tie named, not cut
    short by the time budget); None otherwise or when that kind has no free shape."""
    from .freeshape import free_shape_check
    kinds = _free_shape_kinds(disc, ranking)
    if (disc is None or not kinds or disc.fits_to_noise or disc.stopped or disc.ambiguous
            or disc.verdict not in ("partly explained", "not explained by the catalogue")):
        return None
    lead, then = kinds[0], kinds[1:]
    left = None if budget is None else budget - (time.perf_counter() - t_search)
    if left is not None and left <= 0:
        notes.append("the free shape was not fitted: the time budget had run out")
        return None
    timeout = settings["timeout"] if left is None else min(settings["timeout"], left)
    if settings.get("progress") is not None:
        settings["progress"](f"free shape: fitting the {lead[0]} term the verdict names")
    try:
        return free_shape_check(disc, lead[0], lead[1], timeout=timeout, options=settings["options"], then=then)
    except RocketidError as exc:
        notes.append(f"the free shape could not be fitted: {exc}")
        return None


def _blind_spots(ranking, exclude=()) -> str:
    """The candidates the base fit's coefficients absorb so far that, at a realistic size, they would go
    unseen (score test: expected statistic below ``DETECTABLE``), with what absorbs them; "" when none."""
    from .score import DETECTABLE
    out = []
    for c in (ranking.candidates if ranking is not None else ()):
        lam = c.realistic_statistic
        if c.name in exclude or not c.absorbed_by or lam is None or not lam < DETECTABLE:
            continue
        who = ", ".join(c.absorbed_by[:3]) + (" ..." if len(c.absorbed_by) > 3 else "")
        out.append(f"{c.name} (absorbed by {who}; at a realistic size it would raise the score statistic by only "
                   f"about {lam:.2g})")
    return "; ".join(out)


def _where(fit, level, window) -> str:
    try:
        loc = locate(fit, compare(fit, level=level), window=window, level=level)
    except RocketidError:
        return "(not located)"
    return loc.findings[0].text if loc.findings else "spread over the flight, no window stands out"


def _tried_lead(disc, ranking, free=None) -> tuple[str, str] | None:
    """What the verdict's "Try ..." names: the kind of the free shape that reached the noise, when one did (the
    check went on past the search's first kind: Wren-H's short web with its GPS altitude low led with the drag,
    whose free shape stays above the noise, and the thrust's reaches it); else :func:`_lead`."""
    if free is not None and free.reaches_noise:
        return (free.kind, "")
    return _lead(disc, ranking)


def _place_note(unit: str) -> str:
    """What a located shape's place is measured in, after its value: time after the start, or the unit."""
    return " s after the start" if unit == "s" else f" ({unit})"


def _size_lead(disc) -> str:
    """The refit of the search that reaches the noise with white residuals and fails the size check alone (the
    lowest chi2/dof of them), in words: where the data ask for a change of that kind, larger (or narrower) than
    the catalogue calls realistic -- not an explanation, a place to look. Empty when there is none, or when the
    final model reaches the noise. (Auk-B's boosters dropped 1.5 s late: the throttle window reached chi2/dof
    0.985, white, as a full cut over 40.59-40.81 s -- the same lost impulse as the 7 % of 3.2 t carried 1.5 s
    longer, on the ridge where depth and width trade off -- and the search ended on a drag correction.)"""
    if disc is None or disc.fits_to_noise:
        return ""
    best = None
    for step in disc.steps:
        for c, a in zip(step.screen.contenders, step.acceptances):
            r = a.refit
            if a.failed == ["size"] and r.success and (best is None or r.chi2_per_dof < best[1].refit.chi2_per_dof):
                best = (c.effect, a)
    if best is None:
        return ""
    effect, a = best
    r = a.refit
    sizes, places = effect.sizes(disc.vehicle), effect.locations
    parts = []
    for n in effect.parameter_names:
        if n not in r.parameter_names:
            continue
        v = r.estimate(n)[0]
        if n in places:
            parts.append(f"{n} {v:.4g}{_place_note(places[n])}")
        else:
            parts.append(f"{n} {v:.4g}" + (f" ({abs(v) / sizes[n]:.2g} times its realistic {sizes[n]:.3g})"
                                           if sizes.get(n) else ""))
    extra = [x for x in r.effects if x != effect.name]
    beside = f" beside {', '.join(extra)}" if extra else ""
    return (f" One refit reaches the noise with white residuals, but at an implausible size: {effect.name}{beside} "
            f"(chi2/dof {r.chi2_per_dof:.4g}; {'; '.join(parts)}) -- not an explanation, but where the data ask for a "
            f"change of that kind ({effect.title}) beyond its realistic size: compare it with the flight's events.")


def _final(disc, ranking, level, window, free=None) -> FinalModel | None:
    """The final model in the user's words (``free``: the free shape fitted, which the "Try ..." follows when it
    reached the noise)."""
    if disc is None:
        return None
    fit = disc.fit
    std = {}
    if disc.refit is not None and len(disc.refit.std) == len(disc.refit.parameter_names):
        std = dict(zip(disc.refit.parameter_names, (float(v) for v in disc.refit.std)))
    elif not disc.effects:
        try:
            from ..estimability import uncertainty
            std = dict(zip(fit.spec.parameter_names, (float(v) for v in uncertainty(fit).standard_errors)))
        except RocketidError:
            std = {}
    params = {n: (float(v), std.get(n, math.nan)) for n, v in zip(fit.spec.parameter_names, fit.p)}
    names = ", ".join(disc.effect_names)
    band = disc.band
    amb = f" {disc.ambiguous[0].upper()}{disc.ambiguous[1:]}." if disc.ambiguous else ""
    # what each added effect's estimates say in the field's terms (a launch site from an Earth rotation's)
    readings = "".join(f" That is {e.reading(params)}." for e in disc.effects
                       if e.reading is not None and all(n in params for n in e.parameter_names))
    if disc.verdict == "nothing missing":
        text = (f"{fit.spec.name} reaches the noise (chi2/dof {fit.chi2_per_dof:.4g}, band <= {band.upper:.4g}); "
                "no candidate effect is both significant and needed.")
        blind = _blind_spots(ranking)
        if blind:
            text += (f" These data cannot show whether these are present, as their coefficients take them up: {blind}.")
    elif disc.verdict == "explained":
        r = disc.refit
        base_names = set(disc.base_fit.spec.parameter_names)
        sizes, places = {}, {}
        for e in disc.effects:
            sizes.update(e.sizes(disc.vehicle))
            places.update(e.locations)                         # where, not how large

        def size_note(n):
            if n in places:
                return _place_note(places[n])
            return f" (realistic {sizes[n]:.3g})" if n in sizes else ""
        est = "; ".join(f"{n} = {v:.4g} +- {s:.2g}{size_note(n)}" for n, (v, s) in params.items()
                        if n not in base_names)
        text = f"the model with {names} reaches the noise (chi2/dof {fit.chi2_per_dof:.4g}): {est}." + readings
        if r is not None and r.identifiability:
            text += f" Caution: {r.identifiability}."
        if any(e.kind == "mass" or e.name == "thrust_level" or e.name.startswith("thrust_profile") for e in disc.effects):
            text += (" Note: x, h and v see the thrust and the mass only through their ratio (the acceleration): an "
                     "error of the vehicle's mass (its start mass or its consumption) would fit much alike, the drag "
                     "coefficients taking up the rest; a measured thrust or mass tells them apart.")
            text += _mass_reading(params, disc.vehicle)
        blind = _blind_spots(ranking, exclude=disc.effect_names)
        if blind:
            text += f" These data cannot show whether these are present too, as the coefficients take them up: {blind}."
        if disc.rivals:
            text += f" Rivals: {disc.rivals}."
    elif disc.ambiguous and not disc.effects:
        text = (f"the catalogue explains the misfit in more than one way and these data cannot say which: "
                f"{disc.ambiguous} (chi2/dof {fit.chi2_per_dof:.4g} without them, band <= {band.upper:.4g}); no effect "
                f"is added; the residual sits in: {_where(fit, level, window)}. Other data (another channel, a "
                "measured thrust or mass, an atmosphere sounding) would separate them.")
    elif disc.verdict == "partly explained":
        if disc.fits_to_noise:
            why = disc.not_an_explanation
            text = (f"the model with {names} reaches the noise (chi2/dof {fit.chi2_per_dof:.4g}, band <= "
                    f"{band.upper:.4g}) but is not an explanation{': ' + why if why else ''}.{readings}{amb}")
            if disc.refit is not None and _oversized(disc.refit, band):
                text += (" The data find it at that size: check the vehicle's stated numbers, or, if they are that "
                         "uncertain, state it (--size NAME=VALUE, diagnose(sizes={...})) and the same fit is judged "
                         "against it.")
        else:
            text = (f"the model with {names} does not reach the noise ({disc.noise_detail}); the residual is "
                    f"located in: {_where(fit, level, window)}.{readings}{amb}" + ("" if disc.stopped else f" Try {_suggest(_tried_lead(disc, ranking, free))}.")
                    + _size_lead(disc))
    elif disc.stopped:
        text = (f"no effect was added before the search was cut short (chi2/dof {fit.chi2_per_dof:.4g}, band <= "
                f"{band.upper:.4g}); not every candidate was tried, so this does not say the catalogue cannot explain "
                f"it; the residual sits in: {_where(fit, level, window)}.")
    else:
        text = (f"no catalogue effect explains the misfit (chi2/dof {fit.chi2_per_dof:.4g}, band <= {band.upper:.4g}); "
                f"the residual sits in: {_where(fit, level, window)}. Try {_suggest(_tried_lead(disc, ranking, free))}."
                + _size_lead(disc))
    if disc.stopped:
        text += (f" The search was cut short: {disc.stopped}. A larger budget (--budget, diagnose(budget=)) lets it "
                 "go on; with --resume (diagnose(resume=True)) from the refits it made (kept with an output folder) "
                 "and the models already built (the code cache).")
    return FinalModel(disc.effect_names, params, float(fit.chi2_per_dof), bool(disc.fits_to_noise), disc.verdict,
                      text[0].upper() + text[1:], fit)


def _mass_reading(params: Mapping, vehicle) -> str:
    """The mass error that a found thrust level ``eps_thrust`` is the same as, in words (empty without one).

    In the point-mass equations thrust, drag and lift act through force / mass and gravity does not
    depend on the mass: a thrust ``(1 + eps) P`` gives the same flight as the mass ``m / (1 + eps)``
    throughout (start mass and consumption scaled alike) with every aerodynamic coefficient scaled by
    ``1 / (1 + eps)`` -- exactly, when the model estimates those coefficients."""
    value = params.get("eps_thrust")
    m0 = getattr(vehicle, "mass", math.nan)
    if value is None or not (math.isfinite(m0) and m0 > 0) or not -1.0 < value[0] < 1.0:
        return ""
    k = 1.0 / (1.0 + value[0]) - 1.0
    return (f" Read as a mass error, the thrust {100 * value[0]:+.2g} % is the mass {100 * k:+.2g} % throughout "
            f"({m0 * k:+.3g} kg at the start, the consumption scaled alike) with the drag coefficients "
            f"{100 * k:+.2g} %: the same flight exactly, when every aerodynamic coefficient is estimated.")


def _variant(fit, meas, effects, settings: dict, notes: list):
    """For time-knot drag: the discovery on the Mach-indexed variant, and the user's model with its effects."""
    from .effects import with_effects
    from .variant import mach_variant, time_knot_drag
    if not time_knot_drag(fit.spec):
        return None
    try:
        spec_v = mach_variant(fit)
    except RocketidError as exc:
        notes.append(f"no Mach-indexed variant of the time-knot drag: {exc}")
        return None
    rep = diagnose(meas, spec_v, candidates=effects, variant=False, holdout=None, **settings)
    if rep.final is not None and rep.final.effects:
        try:
            spec_u = with_effects(fit.spec, [e for e in effects if e.name in rep.final.effects])
            mine = estimate(spec_u, meas, mesh=fit.prepared.transcription.mesh, options=settings.get("options"))
            notes.append(f"the time-knot drag absorbs most force effects; the Mach-indexed variant finds "
                         f"{', '.join(rep.final.effects)} ({rep.final.verdict}, chi2/dof {rep.final.chi2_per_dof:.4g}); "
                         f"{fit.spec.name} with them fits at chi2/dof {mine.chi2_per_dof:.4g} (without: "
                         f"{fit.chi2_per_dof:.4g})")
        except RocketidError as exc:
            notes.append(f"the variant's effects could not be added to {fit.spec.name}: {exc}")
    else:
        notes.append(f"the Mach-indexed variant of the time-knot drag: {rep.final.verdict if rep.final else 'no verdict'}"
                     f" (chi2/dof {rep.fit.chi2_per_dof:.4g})")
    return rep


def _timed(timings: dict, key: str, fn, *args, **kw):
    """``fn(*args, **kw)``, its wall time kept in ``timings[key]`` (the report's timings)."""
    t0 = time.perf_counter()
    value = fn(*args, **kw)
    timings[key] = time.perf_counter() - t0
    return value


def _setup(model, holdout, variant, sizes, checkpoints, out, resume) -> tuple:
    """Every setting refused before any work: the model resolved, the hold-out window, the variant, the stated
    sizes and the checkpoint folder (``out/checkpoints`` when none is given and a report is written -- then it
    is the diagnosis's own, removed when the search ends). Returns ``(spec, label, sizes, checkpoints, owned)``."""
    from .effects import check_sizes
    from .refit import holdout_window
    sizes = check_sizes(sizes)
    if variant not in (True, False, "auto"):
        raise SettingsError(f"variant must be 'auto', True or False, got {variant!r}")
    spec, label = resolve_model(model)
    holdout_window(spec, holdout)
    owned = checkpoints is None and out is not None
    if owned:
        checkpoints = Path(out) / "checkpoints"
    _check_checkpoints(checkpoints, resume)
    return spec, label, sizes, checkpoints, owned


def _windowed(spec, meas, flight_window, guess, mesh, notes: list) -> tuple:
    """The model and the data cut to ``flight_window`` (:func:`rocketid.start.apply_window`), with the guess
    carried over; unchanged without a window. Returns ``(spec, meas, guess)``."""
    if flight_window is None:
        return spec, meas, guess
    from ..start import apply_window, window_guess
    if mesh is not None:
        raise SettingsError("flight_window cuts the model: give no mesh (the default mesh of the window is used)")
    p_full = spec.parameter_vector(guess)
    spec_w, meas, wnotes = apply_window(spec, meas, flight_window, p_full)
    notes.extend(wnotes)
    return spec_w, meas, window_guess(spec, spec_w, p_full)


def _searched(fit, effects, counts, confirm_top: int, search: dict, timings: dict, notes: list) -> tuple:
    """The search for missing effects (:func:`~rocketid.diagnostics.step.discover`, its noise band widened
    for noise estimated from the data), or with ``confirm_top`` 0 the screen's ranking alone.
    Returns ``(discovery or None, ranking, why the ranking failed)``."""
    from .step import discover
    if confirm_top <= 0:
        from .screen import screen
        scr = _timed(timings, "rank_s", screen, fit, effects, level=search["level"])
        disc, ranking, failed = None, scr.ranking, scr.failed
    else:
        disc, ranking, failed = None, None, ""
        try:
            from .accept import noise_band
            band = noise_band(fit, estimated=counts) if counts else None
            disc = _timed(timings, "discover_s", discover, fit, effects, band=band, **search)
        except RocketidError as exc:
            notes.append(f"the discovery failed: {exc}")
        if disc is not None:
            notes.extend(disc.notes)
            timings.update({k: v for k, v in disc.timings.items() if k.startswith("search_")})
            ranking = disc.steps[0].screen.ranking if disc.steps else None
            failed = disc.ranking_failed
    if failed:
        notes.append(f"the candidate ranking failed: {failed}")
    return disc, ranking, failed


def _variant_search(fit, meas, effects, settings: dict, budget, t_search: float, progress, timings: dict,
                    notes: list):
    """The Mach-indexed variant's search (:func:`_variant`) with what is left of the ``budget``, or a note
    that it ran out first."""
    left = None if budget is None else budget - (time.perf_counter() - t_search)
    if left is not None and left <= 0:
        notes.append("the Mach-indexed variant of the time-knot drag was not searched: the time budget had run out")
        return None
    said = None if progress is None else (lambda m: progress(f"Mach-indexed variant: {m}"))
    return _timed(timings, "variant_s", _variant, fit, meas, effects, dict(settings, budget=left, progress=said), notes)


def diagnose(data: Measurements | str | Path, model: str | Path | ModelSpec | Model = "ra66", *,
             out: str | Path | None = None, candidates: Sequence | None = None, level: float = 0.05,
             confirm_top: int = 2, window: float | None = None, guess: Mapping | Sequence[float] | None = None,
             mesh=None, options: Mapping[str, Any] | None = None, holdout: tuple | str | None = "auto",
             max_effects: int = 3, workers: int | None = None, refit_timeout: float = 180.0,
             refine: bool = True, variant: bool | str = "auto",
             sigma: str | Mapping[str, float | str] | None = None,
             flight_window: Sequence[float] | None = None, wild_points: str = "drop",
             sizes: Mapping[str, float] | None = None, correlated_noise: str = "thin",
             budget: float | None = None, progress=None, checkpoints: str | Path | None = None,
             resume: bool = False, free_shape: bool = True) -> DiagnosisReport:
    """Fit ``model`` to ``data`` and find what it misses::

        fit -> compare -> locate -> plausibility
            -> discover (screen -> refit every contender -> accept -> step, to the noise)
            -> confirm the final model (LR, BIC, hold-out) -> history -> final verdict
            -> the free shape the verdict names, when the search ended above the noise -> report

    Parameters
    ----------
    data : Measurements or path
        The measurements (a CSV path is read with the model's output names).
    model : {"ra66", "ra66m"}, ModelSpec, Model or path
        ``"ra66"``: the chapter's time-knot CD(t) and constant CL (default);
        ``"ra66m"``: Mach-indexed CD(M), CL = CL_alpha alpha; or a model /
        model file (``build_model()``).
    out : path, optional
        Write the report there (:meth:`DiagnosisReport.write`).
    candidates : sequence of Effect or str, optional
        Candidate effects (default: the whole catalogue); ``custom_effect`` values are
        refitted like catalogue ones.
    level : float
        Significance level of every test and of the ranking.
    confirm_top : int
        0: rank only, refit nothing. Any other value: every contender is refitted
        (:mod:`rocketid.diagnostics.screen`: every significant candidate that leads its
        confounded group or whose predicted fall is within 10x of the leader's).
    window : float, optional
        Window length of :func:`~rocketid.diagnostics.locate.locate`, s.
    guess, mesh, options
        Passed to :func:`rocketid.estimate`.
    holdout : "auto", (float, float) or None
        Fit window of the final model's hold-out check: ``"auto"`` follows the
        model's horizon (the first 45/66 of it), None skips it.
    max_effects : int
        Cap of the stepwise search.
    workers : int, optional
        Parallel refit processes (default: up to 2).
    refit_timeout : float
        Seconds each refit and hold-out prediction may take before it is given up.
    refine : bool
        Try more flexible shapes of a chosen effect that leaves a residual.
    variant : "auto" or bool
        For a model with time-knot drag, also run the discovery on its Mach-indexed
        variant (``rocketid.diagnostics.variant``): ``"auto"`` does so unless the model
        itself is explained (the time-knot drag absorbs most force effects, so "nothing
        missing" or a partial answer on it needs the variant's word); True always.
    sigma : "estimate" or mapping, optional
        Noise levels (:func:`rocketid.estimate`'s ``sigma``: numbers, ``"quantized"``, ``"estimate"``).
        A channel to estimate gets its noise from the data alone -- the scatter of its fourth
        differences (:func:`rocketid.data.difference_noise`), not the base model's residuals,
        which hold the misfit the diagnosis looks for -- and it is then held: every fit, refit,
        score test and hold-out check uses it, and the noise band is widened for its
        uncertainty. Errors correlated from sample to sample are partly cancelled in the
        differences: give the sensor's sigma when it is known.
    flight_window : (float, float), optional
        Diagnose only the flight window ``(T0, T1)`` (s): the model and the data are cut to
        it (:func:`rocketid.start.apply_window`; a window that starts in flight estimates the
        initial states the data determine), and everything after works on the windowed model.
    wild_points : {"drop", "keep"}
        Isolated samples no model of the flight can follow (a GPS multipath jump, a radar wild
        point; :mod:`rocketid.diagnostics.wild`) are found on the base fit's residuals. ``"drop"``
        removes them, takes the noise from the data again when it is estimated, and fits the base
        model again before anything is judged; ``"keep"`` only lists them. Either way the report
        names every one.
    correlated_noise : {"thin", "keep"}
        Errors correlated from sample to sample (a navigation filter, a smoothed readout;
        :mod:`rocketid.diagnostics.correlated`) are measured on the base fit's residuals, channel by
        channel. ``"thin"`` keeps, in each such channel, the samples far enough apart for their errors
        to be independent, takes an estimated noise at the errors' full size (the one-sample differences
        see only part of correlated errors), and fits the base model again before anything is judged --
        on every sample the whiteness test takes correlated errors for a missing effect; ``"keep"`` only
        reports the correlation.
    sizes : mapping of str to float, optional
        Realistic sizes the user states for effect parameters, by name or ``fnmatch`` pattern
        (``{"eps_thrust": 0.10, "eps_P*": 0.10}``), in place of the catalogue's
        (:func:`~rocketid.diagnostics.effects.state_sizes`): an effect is implausible beyond 5 times
        its realistic size, so a vehicle whose numbers are less certain than the catalogue assumes
        says so here. An entry that names no parameter of the candidates is refused.
    budget : float, optional
        Seconds the search for missing effects may take, the Mach-indexed variant's search
        included (None: no limit). When they run out the step under way is not completed and the
        steps before it stand; the report says where the search stopped
        (:attr:`~rocketid.diagnostics.step.Discovery.stopped`), and its verdict is that of the
        model reached. The base fit, the comparison and the report are not counted.
    progress : callable, optional
        Called with one line of text at each stage of the search (the contenders refitted at
        each step, the effect taken, the second path, the variant's search); ``rocketid
        diagnose`` prints them on a terminal or with ``--verbose``.
    checkpoints : path, optional
        Folder where the search keeps every refit it completes, as it completes it (default:
        ``out/checkpoints`` when ``out`` is given, else none). It is removed when the search ends;
        kept when it was interrupted or stopped at its ``budget``, and then a folder holding refits
        is refused unless ``resume``.
    resume : bool
        Take the refits kept in ``checkpoints`` instead of running them again: the same inputs give
        the same search, which goes through what was done in no time and on from there (with a
        larger ``budget``, past where it stopped). The files are Python pickles: resume only from
        checkpoints you wrote.
    free_shape : bool
        When the search ends above the noise ("partly explained", "not explained by the catalogue"), fit
        the free shape the verdict names -- of the kind of the search's first effect added that has one (the
        screen's first candidate when none was): a thrust error on the mesh's element boundaries over the
        burn for a propulsion or mass effect, a wind or density profile in altitude, a drag correction in
        Mach; the other kinds in turn, the thrust's last, until one reaches the noise -- to the user's model (:mod:`~rocketid.diagnostics.freeshape`):
        :attr:`DiagnosisReport.free_shape` says whether what is missing is of that kind, and its shape.
        Never an explanation; it does not change the verdict. It runs within the ``budget``.

    Returns
    -------
    DiagnosisReport
        :attr:`~DiagnosisReport.final` holds the final model and the verdict.
    """
    _check_settings(level, confirm_top, max_effects, refit_timeout, budget)
    spec, label, sizes, checkpoints, owned = _setup(model, holdout, variant, sizes, checkpoints, out, resume)
    notes: list[str] = []
    meas, data_label = _read_data(data, spec)
    spec, meas, guess = _windowed(spec, meas, flight_window, guess, mesh, notes)
    timings: dict = {}
    from_data: dict = {}
    fit, _, counts, wild, corr = _timed(timings, "fit_s", base_fit, spec, meas, sigma, guess=guess, mesh=mesh,
                                        options=options, notes=notes, from_data=from_data,
                                        wild_points=wild_points, correlated_noise=correlated_noise)
    meas = fit.prepared.measurements  # with the sigmas of the fit (without the wild points dropped, thinned)
    comp, loc, plaus = _timed(timings, "describe_s", _describe, fit, level, window, notes)
    effects = _stated(_candidate_effects(candidates), sizes, fit, notes)
    search = dict(level=level, max_effects=int(max_effects), workers=workers, timeout=float(refit_timeout),
                  options=options, refine=refine, holdout=holdout, budget=budget, progress=progress)
    if not refine and confirm_top > 0:
        notes.append("the refined shapes were not tried (refine=False, --no-refine): every family stayed at its "
                     "catalogue shape, and a snug choice's near rivals were not given their fuller shapes -- a "
                     "first look; run with them before taking the verdict as the answer")
    t_search = time.perf_counter()
    from .refit import refit_checkpoints
    with refit_checkpoints(checkpoints):
        disc, ranking, failed = _searched(fit, effects, counts, confirm_top, search, timings, notes)
        confs, names, pls = _timed(timings, "confirm_s", _confirm_final, fit, disc, holdout, level, refit_timeout,
                                   options, notes)
        disc = _prediction_check(disc, confs, notes)
        history = _history(spec, fit, disc, notes)
        after = compare(disc.fit, level=level) if disc is not None and disc.effects else None
        free = (_timed(timings, "free_shape_s", _free_shape, disc, ranking, search, budget, t_search, notes)
                if free_shape and confirm_top > 0 else None)
        final = _final(disc, ranking, level, window, free)
        var = None
        if confirm_top > 0 and (variant is True or (variant == "auto"
                                                    and (final is None or final.verdict != "explained"))):
            settings = dict(level=level, confirm_top=confirm_top, window=window, options=options,
                            max_effects=max_effects, workers=workers, refit_timeout=refit_timeout, refine=refine,
                            sigma=sigma if counts else None,     # the same data, the same noise (and a widened band)
                            free_shape=False)
            var = _variant_search(fit, meas, effects, settings, budget, t_search, progress, timings, notes)
    if checkpoints is not None:
        stopped = bool(_stopped(disc) or (var is not None and _stopped(var.discovery)))
        end_checkpoints(Path(checkpoints), stopped, notes, remove=owned)
    report = DiagnosisReport(model=label, data_label=data_label, fit=fit, comparison=comp, location=loc,
                             plausibility=plaus, ranking=ranking, confirmations=confs, confirmed=names,
                             refit_plausibility=pls, after=after, history=history, level=float(level),
                             timings=timings, notes=tuple(notes), discovery=disc, final=final, variant=var,
                             ranking_failed=failed, noise_from_data=from_data, wild_points=wild,
                             correlated_noise=corr, free_shape=free)
    if out is not None:
        report.write(out)
    return report
