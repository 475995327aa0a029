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
import warnings
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Mapping, Sequence

import numpy as np

from ..cases.registry import BUILTIN_MODELS, resolve_model
from ..data import Measurements, read_csv
from ..errors import DataError, RocketidError, SettingsError
from ..model import Model, ModelSpec
from ..solve import EstimationResult, estimate
from .compare import Comparison, compare
from .locate import Location, locate
from .plausibility import Plausibility, check_plausibility

__all__ = ["diagnose", "DiagnosisReport", "resolve_model", "BUILTIN_MODELS"]


def _read_data(data, spec: ModelSpec) -> tuple[Measurements, str]:
    if isinstance(data, Measurements):
        return data, "the given measurements"
    if isinstance(data, (str, Path)):
        return read_csv(data, spec.output_names), str(data)
    raise DataError(f"data must be Measurements or the path of a CSV file, got {type(data).__name__}")


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
        :class:`rocketid.diagnostics.score.CandidateRanking` (None when the
        ranking could not be made; see :attr:`notes`).
    confirmations : tuple
        :class:`rocketid.diagnostics.refit.Confirmation` of the leading candidates.
    confirmed : tuple of str
        The candidates' names, in the order of :attr:`confirmations`.
    refit_plausibility : tuple of Plausibility
        The plausibility checks of each refit, in the same order.
    after : Comparison or None
        The comparison of the best confirmed refit (the lowest BIC).
    history : object or None
        :class:`rocketid.diagnostics.history.ModelHistory`: the base fit, then the
        best refit (:attr:`best`).
    level : float
    timings : dict
        Wall time of each step, s.
    notes : tuple of str
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

    # ---- verdicts
    @property
    def fails(self) -> bool:
        """The residuals are not white noise, or the coefficients are implausible."""
        return (not self.comparison.fits_to_noise) or (not self.plausibility.passed)

    def effect_name(self, confirmation) -> str:
        """The candidate name a confirmation refitted."""
        for c, name in zip(self.confirmations, self.confirmed):
            if c is confirmation:
                return name
        return _effect_name(confirmation)

    @property
    def best(self):
        """The best refit (None without a converged one): among those within
        :data:`BIC_TIE` of the lowest BIC, the one with plausible coefficients and
        then the best hold-out prediction (:attr:`choice`)."""
        i, _ = self._choice()
        return None if i is None else self.confirmations[i]

    def _choice(self):
        pl = [p.passed for p in self.refit_plausibility] if len(self.refit_plausibility) == len(self.confirmations) \
            else None
        return _choose(self.confirmations, pl)

    @property
    def choice(self) -> str:
        """Why :attr:`best` was chosen."""
        return self._choice()[1]

    def verdict(self) -> list[str]:
        """The diagnosis in a few sentences."""
        out = []
        c = self.comparison
        if c.fits_to_noise:
            out.append(f"The residuals of {self.fit.spec.name} are white noise at the stated sigma "
                       f"(chi2/dof {c.chi2_per_dof:.3f}).")
        else:
            out.append(f"{self.fit.spec.name} does not fit to the noise: chi2/dof = {c.chi2_per_dof:.3g}, "
                       f"residuals not white.")
        if self.location is not None and self.location.findings:
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
        b = self.best
        if b is not None:
            name = self.effect_name(b)
            est = "; ".join(f"{k} = {v[0]:.4g} +- {v[1]:.2g}" for k, v in b.effect_estimates.items())
            if len(self.confirmations) > 1:
                out.append(f"Best refit: {name} ({self.choice}).")
            out.append(f"Refit with {name} ({'confirmed' if b.confirmed else 'NOT confirmed'}): chi2/dof "
                       f"{b.fit.chi2_per_dof:.4g} (was {self.fit.chi2_per_dof:.4g}), LR {_p(b.lr_p_value)}, "
                       f"BIC {b.bic[0]:.6g} -> {b.bic[1]:.6g}; {est}.")
        return out

    def summary(self) -> str:
        """Fixed sections (verdict, compare, locate, plausibility, candidates,
        confirmations) and numbered notes."""
        lines = [f"rocketid diagnosis: {self.fit.spec.name} on {self.data_label}", "=" * 60, "Verdict"]
        lines += [f"  {s}" for s in self.verdict()]
        lines += ["", self.comparison.summary()]
        lines += ["", self.location.summary() if self.location is not None else "Location: not available (see notes)"]
        lines += ["", self.plausibility.summary()]
        if self.ranking is not None:
            lines += ["", self.ranking.summary()]
        for c in self.confirmations:
            lines += ["", c.summary()]
        if self.history is not None:
            try:
                lines += ["", "History", str(self.history.table())]
            except Exception as exc:  # noqa: BLE001 - a report must not fail on a table
                lines += ["", f"History: not available ({exc})"]
        if self.notes:
            lines += ["", "Notes"] + [f"  [{i}] {n}" for i, n in enumerate(self.notes, 1)]
        return "\n".join(lines)

    def candidates_payload(self) -> dict:
        """``{"candidates": [...]}``, best first, each with ``name``, ``statistic``,
        ``p_value`` (corrected) and ``group`` (the content of candidates.json)."""
        if self.ranking is None:
            return {"candidates": [], "note": "no ranking: " + "; ".join(n for n in self.notes if "rank" in n)}
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
               "timings": dict(self.timings), "notes": list(self.notes)}
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


#: Refits whose BIC lie within this of the lowest are not told apart by BIC (Kass and Raftery's
#: "very strong" evidence starts at 10); the hold-out prediction decides between them.
BIC_TIE = 10.0


def _holdout_score(c) -> float:
    """Mean over channels of (hold-out prediction RMS of the new model / sigma)^2; inf without one."""
    if not c.holdout_rms:
        return math.inf
    sig = dict(zip(c.fit.nlp.channel_names, (float(s) for s in c.fit.nlp.channel_sigmas)))
    return float(np.mean([(b / sig.get(k, 1.0)) ** 2 for k, (_, b) in c.holdout_rms.items()]))


def _choose(confirmations, plausible=None) -> tuple:
    """The index of the best refit and why: among converged refits, those within :data:`BIC_TIE`
    of the lowest BIC, preferring plausible coefficients, then the best hold-out prediction."""
    ok = [i for i, c in enumerate(confirmations) if c.fit.success]
    if not ok:
        return None, "no refit converged"
    lo = min(confirmations[i].bic[1] for i in ok)
    near = [i for i in ok if confirmations[i].bic[1] <= lo + BIC_TIE]
    why = []
    if plausible is not None and len(near) > 1:
        good = [i for i in near if plausible[i]]
        if good and len(good) < len(near):
            why.append("plausible coefficients")
            near = good
    if len(near) == 1:
        why.insert(0, "the lowest BIC" if confirmations[near[0]].bic[1] == lo else f"BIC within {BIC_TIE:g} of the lowest")
        return near[0], ", ".join(why)
    score = {i: _holdout_score(confirmations[i]) for i in near}
    if all(math.isfinite(v) for v in score.values()):
        best = min(near, key=lambda i: score[i])
        why.insert(0, f"BIC within {BIC_TIE:g} of each other; the best hold-out prediction")
        return best, ", ".join(why)
    best = min(near, key=lambda i: confirmations[i].bic[1])
    why.insert(0, "the lowest BIC")
    return best, ", ".join(why)




def _confirmation_dict(c, name: str | None = None) -> dict:
    """:meth:`Confirmation.to_dict` with the candidate's name as ``effect``."""
    d = dict(c.to_dict())
    d["effect"] = name or _effect_name(c)
    return d


def diagnose(data: Measurements | str | Path, model: str | Path | ModelSpec | Model = "ra66", *,
             out: str | Path | None = None, candidates: Sequence | None = None, level: float = 0.05,
             confirm_top: int = 2, window: float | None = None, guess: Mapping | Sequence[float] | None = None,
             mesh=None, options: Mapping[str, Any] | None = None) -> DiagnosisReport:
    """Fit ``model`` to ``data`` and diagnose what it misses.

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
        Candidate effects to rank (default: part A's catalogue).
    level : float
        Significance level of every test and of the ranking.
    confirm_top : int
        Refit the model with each of this many leading significant candidates.
    window : float, optional
        Window length of :func:`~rocketid.diagnostics.locate.locate`, s.
    guess, mesh, options
        Passed to :func:`rocketid.estimate`.

    Returns
    -------
    DiagnosisReport
    """
    if not 0 < level < 1:
        raise SettingsError(f"level must be in (0, 1), got {level}")
    if isinstance(confirm_top, bool) or not isinstance(confirm_top, (int, np.integer)) or confirm_top < 0:
        raise SettingsError(f"confirm_top must be a non-negative integer, got {confirm_top!r}")
    spec, label = resolve_model(model)
    meas, data_label = _read_data(data, spec)
    notes: list[str] = []
    timings = {}
    t0 = time.perf_counter()
    if mesh is None:
        # a short first element: effects that act from lift-off (misalignment, Earth
        # rotation) are otherwise blurred by the singular start (docs/effects.md); the
        # candidates' refits reuse this mesh
        from ..solve import default_mesh
        mesh = default_mesh(spec, refine_first=3)
    fit = estimate(spec, meas, guess=guess, mesh=mesh, options=options)
    timings["fit_s"] = time.perf_counter() - t0
    if not fit.success:
        notes.append(f"the base fit did not converge ({fit.message}); the diagnosis describes its last iterate")
    t0 = time.perf_counter()
    comp = compare(fit, level=level)
    timings["compare_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    try:
        loc = locate(fit, comp, window=window, level=level)
    except DataError as exc:
        loc = None
        notes.append(f"no location: {exc}")
    timings["locate_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    plaus = check_plausibility(fit, level=level)
    timings["plausibility_s"] = time.perf_counter() - t0
    ranking, confirmations, confirmed, history, after = None, [], [], None, None
    t0 = time.perf_counter()
    try:
        from .score import rank_candidates
    except ImportError as exc:
        rank_candidates = None
        notes.append(f"candidate ranking is not available ({exc})")
    if rank_candidates is not None:
        try:
            ranking = rank_candidates(fit, candidates, level=level)
        except RocketidError as exc:
            notes.append(f"the candidate ranking failed: {exc}")
    timings["rank_s"] = time.perf_counter() - t0
    t0 = time.perf_counter()
    if ranking is not None and confirm_top > 0:
        sig = [c for c in ranking.candidates if getattr(c, "significant", False)]
        chosen = sig[:confirm_top]
        if not chosen and ranking.candidates and (not comp.fits_to_noise or not plaus.passed):
            chosen = list(ranking.candidates[:1])
            notes.append(f"no candidate is significant at {level:g}; the best-ranked one ({chosen[0].name}) was "
                         "refitted anyway because the base model fails")
        try:
            from .refit import confirm
        except ImportError as exc:
            confirm = None
            notes.append(f"refit confirmation is not available ({exc})")
        if confirm is not None:
            for c in chosen:
                try:
                    with warnings.catch_warnings():
                        warnings.simplefilter("ignore", RuntimeWarning)
                        confirmations.append(confirm(fit, c.name))
                        confirmed.append(c.name)
                except RocketidError as exc:
                    notes.append(f"refitting with {c.name} failed: {exc}")
    refit_pl = []
    for c in confirmations:
        try:
            refit_pl.append(check_plausibility(c.fit, level=level))
        except RocketidError as exc:
            notes.append(f"the plausibility of the refit with {confirmed[len(refit_pl)]} could not be checked: {exc}")
            refit_pl = []
            break
    best_i, _ = _choose(confirmations, [p.passed for p in refit_pl] if refit_pl else None)
    timings["confirm_s"] = time.perf_counter() - t0
    try:
        from .history import ModelHistory
        history = ModelHistory().add(f"{spec.name}", fit)
        if best_i is not None:
            history = history.add(f"+ {confirmed[best_i]}", confirmations[best_i].fit)
    except ImportError as exc:
        history = None
        notes.append(f"model history is not available ({exc})")
    except RocketidError as exc:
        notes.append(f"model history failed: {exc}")
    if best_i is not None:
        try:
            after = compare(confirmations[best_i].fit, level=level)
        except RocketidError as exc:
            notes.append(f"the best refit could not be compared: {exc}")
    report = DiagnosisReport(model=label, data_label=data_label, fit=fit, comparison=comp, location=loc,
                             plausibility=plaus, ranking=ranking, confirmations=tuple(confirmations),
                             confirmed=tuple(confirmed), refit_plausibility=tuple(refit_pl), after=after,
                             history=history, level=float(level), timings=timings, notes=tuple(notes))
    if out is not None:
        report.write(out)
    return report
