"""``rocketid diagnose F1.csv F2.csv ...``: the diagnosis per flight and joint.

::

    rocketid diagnose f1.csv f2.csv --model ra66m --out diag/

Several data files are several flights of one vehicle (one model). Each flight is
diagnosed on its own (:func:`rocketid.diagnostics.diagnose`, its report written to
``DIR/<label>/``, the label being the file's name without extension as in the joint
estimate), then the base model is fitted to all flights jointly
(:func:`rocketid.joint.joint_estimate`) and each flight is refitted alone
(:meth:`rocketid.joint.JointResult.consistency`). The effects each flight's diagnosis
ends with are compared: found in every flight, in some, or in one flight only. Last, all
flights are fitted at once with the effects each found (:mod:`rocketid.diagnostics.flights`):
a vehicle effect (motor, mass flow, aerodynamics) found in several flights is shared when a
likelihood-ratio test says the flights agree on it, a flight's own effects (sensors, air,
start, loading, events) stay its own.

Written: ``DIR/<label>/`` (each flight's report.html, diagnosis.json, ...),
``DIR/diagnosis.json`` (``flights``, ``joint``, ``common``), ``DIR/summary.txt`` and
``DIR/index.html`` (linking each flight's report).
"""

from __future__ import annotations

import html
import math
import time
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Any, Sequence

from ..errors import RocketidError
from ..output import finite_or_none, write_json, write_text
from ..summary import Section, Summary, Table

__all__ = ["FlightsDiagnosis", "diagnose_flights", "common_effects"]


def common_effects(effects: dict[str, tuple | None]) -> dict:
    """Which final effects are found in every flight, in some, in one flight only.

    Parameters
    ----------
    effects : dict
        ``{flight label: effects its diagnosis added}`` (None: not searched, ``--confirm 0``).

    Returns
    -------
    dict
        ``in_every_flight`` (list), ``in_one_flight_only`` (``{effect: label}``),
        ``in_some_flights`` (``{effect: [labels]}``, more than one but not all),
        ``none_found`` (labels whose diagnosis added nothing), ``not_searched`` (labels)
        and ``statements`` (one sentence per effect, e.g. "bias_h: found in flight B only").
    """
    searched = [l for l, e in effects.items() if e is not None]
    found: dict[str, list[str]] = {}
    for label in searched:
        for e in effects[label]:
            found.setdefault(str(e), [])
            if label not in found[str(e)]:
                found[str(e)].append(label)
    every = [e for e, ls in found.items() if len(searched) > 1 and len(ls) == len(searched)]
    one = {e: ls[0] for e, ls in found.items() if len(ls) == 1 and e not in every}
    some = {e: ls for e, ls in found.items() if e not in every and e not in one}
    statements = []
    for e in every:
        statements.append(f"{e}: found in every flight ({', '.join(searched)})")
    for e, ls in some.items():
        missing = [l for l in searched if l not in ls]
        statements.append(f"{e}: found in flights {', '.join(ls)} (not in {', '.join(missing)})")
    for e, l in one.items():
        statements.append(f"{e}: found in flight {l} only")
    none_found = [l for l in searched if not effects[l]]
    if searched and not found:
        statements.append("no effect found in any flight")
    elif none_found:
        statements.append(f"no effect found in flight{'s' if len(none_found) > 1 else ''} {', '.join(none_found)}")
    return {"in_every_flight": every, "in_one_flight_only": one, "in_some_flights": some, "none_found": none_found,
            "not_searched": [l for l, e in effects.items() if e is None], "statements": statements}


@dataclass(frozen=True)
class FlightsDiagnosis:
    """The diagnosis of several flights of one vehicle: each alone, and the joint fit.

    Attributes
    ----------
    model : str
    labels : tuple of str
        The flights' labels (the data files' names).
    files : tuple of str
    reports : tuple of DiagnosisReport
        Each flight's own diagnosis, in the order of :attr:`labels`.
    joint : JointResult or None
        The base model fitted to all flights jointly (None when it failed: :attr:`joint_failed`).
    joint_failed : str
        Why the joint fit could not be made (empty when it was).
    timings : dict
        ``diagnose_s`` (all flights), ``joint_s`` (the joint fit and each flight refitted alone).
    joint_noise : dict
        ``{label: {channel: sigma}}``: the noise levels the joint fit held for the channels whose
        sigma was to be estimated -- each flight's from its data alone, as its diagnosis took them
        (:attr:`~rocketid.diagnostics.DiagnosisReport.noise_from_data`); empty when none was.
    final : JointFinal or None
        All flights fitted at once with the effects each flight's diagnosis found, vehicle effects found
        in several flights shared when the flights agree (:func:`rocketid.diagnostics.flights.joint_final`);
        None when no flight added an effect, a flight was not searched or the base joint fit failed.
    """

    model: str
    labels: tuple
    files: tuple
    reports: tuple
    joint: Any
    joint_failed: str = ""
    timings: Any = None
    joint_noise: dict = field(default_factory=dict)
    final: Any = None

    # ---- per flight
    def effects(self) -> dict[str, tuple | None]:
        """``{label: final effects}`` (None when the diagnosis searched none)."""
        return {l: (None if r.final is None else tuple(r.final.effects)) for l, r in zip(self.labels, self.reports)}

    def common(self) -> dict:
        """:func:`common_effects` of the flights' final effects."""
        return common_effects(self.effects())

    @property
    def success(self) -> bool:
        """Every flight's base fit and the joint fit converged."""
        return all(r.fit.success for r in self.reports) and self.joint is not None and bool(self.joint.success)

    def _flight_row(self, label, report) -> dict:
        final = report.final
        chi2 = report.fit.chi2_per_dof if final is None else final.chi2_per_dof
        return {"file": self.files[self.labels.index(label)],
                "verdict": None if final is None else final.verdict,
                "final_effects": None if final is None else list(final.effects),
                "chi2_per_dof": finite_or_none(float(chi2)),
                "base_chi2_per_dof": finite_or_none(float(report.fit.chi2_per_dof)),
                "fits_to_noise": None if final is None else bool(final.fits_to_noise),
                "converged": bool(report.fit.success),
                "report": f"{label}/report.html"}

    # ---- joint
    def _consistency_rows(self) -> dict:
        if self.joint is None:
            return {}
        return {l: {"chi2_per_dof_alone": finite_or_none(float(a.chi2_per_dof)),
                    "chi2_per_dof_joint": finite_or_none(float(j.chi2_per_dof)),
                    "objective_excess": finite_or_none(float(j.data_objective - a.data_objective))}
                for l, j, a in zip(self.joint.labels, self.joint.flights, self.joint.alone)}

    def _joint_notes(self) -> list[str]:
        if self.joint is None:
            return [f"the joint fit failed: {self.joint_failed}"]
        notes = list(self.joint.consistency().notes)
        if not self.joint.success:
            notes.insert(0, f"the joint fit did not converge: {self.joint.message}")
        if self.joint_noise:
            notes.append("the joint fit holds each flight's noise levels as its diagnosis took them from the data "
                         "alone (not from the base model's residuals, which hold the misfit): "
                         + "; ".join(f"{l}: " + ", ".join(f"{c} {v:.4g}" for c, v in d.items())
                                     for l, d in self.joint_noise.items()))
        return notes

    # ---- reports
    def verdict(self) -> list[str]:
        """The diagnosis of the flights in a few sentences."""
        out = []
        for label, r in zip(self.labels, self.reports):
            row = self._flight_row(label, r)
            if row["verdict"] is None:
                out.append(f"Flight {label}: no effects searched (chi2/dof {row['chi2_per_dof']:.4g}).")
            else:
                eff = ", ".join(row["final_effects"]) or "no effect added"
                out.append(f"Flight {label}: {row['verdict']} ({eff}; chi2/dof {row['chi2_per_dof']:.4g}).")
        out += [f"Effects: {s}." for s in self.common()["statements"]]   # effect names keep their case
        if self.joint is not None:
            out.append(f"Joint fit of {self.reports[0].fit.spec.name} to {len(self.labels)} flights: chi2/dof "
                       f"{self.joint.chi2_per_dof:.4g} ("
                       + ", ".join(f"{l} {r.chi2_per_dof:.4g}" for l, r in zip(self.joint.labels, self.joint.flights))
                       + ").")
        out += [n[0].upper() + n[1:] + ("" if n.endswith(".") else ".") for n in self._joint_notes()]
        if self.final is not None:
            out += self.final.sentences()
        return out

    def summary(self) -> Summary:
        """Fixed sections: flights, effects, joint fit; the joint notes."""
        flights = Table(("flight", "file", "verdict", "effects added", "chi2/dof base", "chi2/dof final"),
                        [(l, f, row["verdict"] or "not searched", ", ".join(row["final_effects"] or []) or "-",
                          float(r.fit.chi2_per_dof), row["chi2_per_dof"] if row["chi2_per_dof"] is not None else math.nan)
                         for l, f, r in zip(self.labels, self.files, self.reports)
                         for row in (self._flight_row(l, r),)],
                        (None, None, None, None, ".4g", ".4g"))
        effects = Section("Effects", tuple(self.common()["statements"])
                          or ("no flight's effects were searched (--confirm 0)",))
        if self.joint is not None:
            rows = self._consistency_rows()
            joint_items = (("chi2 / dof", f"{self.joint.chi2_per_dof:.4g} (all flights, base model)"),
                           ("status", "converged" if self.joint.success else f"FAILED ({self.joint.message})"),
                           Table(("flight", "chi2/dof alone", "chi2/dof joint", "J joint - J alone"),
                                 [(l, d["chi2_per_dof_alone"], d["chi2_per_dof_joint"], d["objective_excess"])
                                  for l, d in rows.items()], (None, ".4g", ".4g", ".4g")))
        else:
            joint_items = (("status", f"not made ({self.joint_failed})"),)
        sections = [Section("Flights", (flights,)), effects, Section("Joint fit", joint_items)]
        notes = self._joint_notes()
        if self.final is not None:
            sections.append(self.final.section())
            notes += ([t.sentence() for t in self.final.tests] + [c.sentence() for c in self.final.carried]
                      + list(self.final.notes))
        return Summary(f"rocketid diagnosis of {len(self.labels)} flights: {self.reports[0].fit.spec.name}",
                       tuple(sections), notes)

    def to_dict(self) -> dict:
        """The content of ``DIR/diagnosis.json``."""
        joint: dict = {"success": False, "failed": self.joint_failed}
        if self.joint is not None:
            fit = self.joint.to_dict()
            joint = {"success": bool(self.joint.success), "chi2_per_dof": finite_or_none(self.joint.chi2_per_dof),
                     "per_flight": fit["per_flight"], "parameters": fit["parameters"],
                     "standard_errors": fit["standard_errors"], "sigma": fit["sigma"],
                     "consistency": self._consistency_rows(), "notes": self._joint_notes(),
                     "noise_from_data": {l: dict(d) for l, d in self.joint_noise.items()}}
        return {"model": self.model, "flights": {l: self._flight_row(l, r) for l, r in zip(self.labels, self.reports)},
                "joint": joint, "joint_final": None if self.final is None else self.final.to_dict(),
                "common": self.common(), "verdict": self.verdict(),
                "timings": dict(self.timings or {})}

    def index_html(self) -> str:
        """A small page linking each flight's report, with the summary."""
        esc = html.escape
        rows = "".join(
            f"<tr><td><a href=\"{esc(row['report'])}\">{esc(l)}</a></td><td>{esc(row['file'])}</td>"
            f"<td>{esc(row['verdict'] or 'not searched')}</td><td>{esc(', '.join(row['final_effects'] or []) or '-')}"
            f"</td><td>{'-' if row['chi2_per_dof'] is None else format(row['chi2_per_dof'], '.4g')}</td></tr>"
            for l, r in zip(self.labels, self.reports) for row in (self._flight_row(l, r),))
        verdict = "".join(f"<li>{esc(s)}</li>" for s in self.verdict())
        title = esc(f"rocketid diagnosis of {len(self.labels)} flights: {self.reports[0].fit.spec.name}")
        return ("<!DOCTYPE html>\n<html lang=\"en\"><head><meta charset=\"utf-8\"><title>" + title + "</title>"
                "<style>body{font-family:sans-serif;max-width:60em;margin:2em auto}table{border-collapse:collapse}"
                "td,th{border:1px solid #ccc;padding:.2em .6em;text-align:left}</style></head><body>"
                f"<h1>{title}</h1><h2>Verdict</h2><ul>{verdict}</ul><h2>Flights</h2><table><tr><th>flight</th>"
                f"<th>file</th><th>verdict</th><th>effects added</th><th>chi2/dof</th></tr>{rows}</table>"
                f"<h2>Summary</h2>{self.summary().html()}"
                "<p>diagnosis.json holds the same; each flight's folder holds its full report.</p></body></html>\n")

    def write(self, out: str | Path) -> Path:
        """Write ``out/<label>/`` (each flight's report), ``out/diagnosis.json``,
        ``out/summary.txt`` and ``out/index.html``; returns index.html's path."""
        out = Path(out)
        for label, r in zip(self.labels, self.reports):
            r.write(out / label)
        return self.write_joint(out)

    def write_joint(self, out: str | Path) -> Path:
        """The joint files only (the flights' reports written already)."""
        out = Path(out)
        payload, text, page = self.to_dict(), self.summary().text() + "\n", self.index_html()
        write_json(out / "diagnosis.json", payload)
        write_text(out / "summary.txt", text)
        return write_text(out / "index.html", page)


def diagnose_flights(datas: Sequence, labels: Sequence[str], spec, *, files: Sequence[str] | None = None,
                     model_label: str | None = None, flight_window=None, sigma=None, out: str | Path | None = None,
                     on_flight=None, per_flight: Sequence[str] = (), progress=None, **settings) -> FlightsDiagnosis:
    """Diagnose each flight alone, then fit the base model to all flights jointly.

    Parameters
    ----------
    datas : sequence of Measurements
        One per flight, not cut to the window.
    labels : sequence of str
        The flights' labels (folder names of their reports).
    spec : ModelSpec
        The one model of every flight.
    files : sequence of str, optional
        The data files (for the reports); default the labels.
    flight_window : (float, float), optional
        Each flight's window (its model and data cut to it, initial states free).
    sigma : optional
        Noise levels, the same request for every flight (``"estimate"``: each flight's own).
    out : path, optional
        Write each flight's report to ``out/<label>/`` as soon as it is made, then the joint files.
    on_flight : callable, optional
        ``on_flight(label, report)`` after each flight's diagnosis (progress).
    progress : callable, optional
        Each flight's search's lines of progress (:func:`rocketid.diagnostics.diagnose`), prefixed with
        the flight's label.
    per_flight : sequence of str
        Model parameters each flight estimates for itself in the joint fits (its attitude program, its
        lift-off mass); the others are shared (:func:`rocketid.joint.joint_estimate`).
    **settings
        Passed to :func:`rocketid.diagnostics.diagnose` for each flight (``level``,
        ``confirm_top``, ``holdout``, ``max_effects``, ``workers``, ``refit_timeout``, ``window``,
        ``wild_points``, ``correlated_noise``, ``budget``: each flight's search its own, ``resume``: each
        flight's refits kept in ``out/<label>/checkpoints``). The joint fit sees each flight's data as its diagnosis
        did: without the wild points it dropped, thinned where its errors were correlated.
    """
    from ..cli import windowed_inputs
    from ..diagnostics import diagnose
    from ..diagnostics.api import end_checkpoints
    from ..diagnostics.flights import joint_final
    from ..joint import Flight, joint_estimate
    from ..solve import check_determined

    files = tuple(str(f) for f in (files or labels))
    labels = tuple(labels)
    # every flight's joint input is formed (and checked) before any work
    flights = []
    for label, data in zip(labels, datas):
        spec_f, data_f, _, mesh, _ = windowed_inputs(spec, data, spec.guess, flight_window, None, 4)
        check_determined(spec_f, data_f)
        flights.append(Flight(label, spec_f, data_f, mesh))
    t0 = time.perf_counter()
    reports = []
    for label, f, data in zip(labels, files, datas):
        said = None if progress is None else (lambda m, label=label: progress(f"flight {label}: {m}"))
        rep = diagnose(data, spec, sigma=sigma, flight_window=flight_window, progress=said,
                       checkpoints=None if out is None else Path(out) / label / "checkpoints", **settings)
        rep = replace(rep, model=model_label or spec.name, data_label=f)
        if out is not None:
            rep.write(Path(out) / label)
        if on_flight is not None:
            on_flight(label, rep)
        reports.append(rep)
    t1 = time.perf_counter()
    joint, failed = None, ""
    # the joint fit sees each flight's data as its diagnosis did: without the wild points it dropped,
    # thinned where its errors were correlated
    flights = [replace(fl, data=_as_diagnosed(fl.data, rep)) for fl, rep in zip(flights, reports)]
    flights, joint_sigma, noise = _noise_of_the_flights(flights, reports, sigma)
    try:
        joint = joint_estimate(flights, per_flight=per_flight, sigma=joint_sigma)
        joint.consistency()  # each flight refitted alone (cached)
    except RocketidError as exc:
        joint, failed = None, str(exc)
    t2 = time.perf_counter()
    final = None
    if joint is not None:
        final = joint_final(flights, reports, joint.chi2_per_dof, level=settings.get("level", 0.05),
                            sigma=joint_sigma, options=settings.get("options"), per_flight=per_flight)
    timings = {"diagnose_s": t1 - t0, "joint_s": t2 - t1, "joint_final_s": time.perf_counter() - t2}
    result = FlightsDiagnosis(model=model_label or spec.name, labels=labels, files=files, reports=tuple(reports),
                              joint=joint, joint_failed=failed, timings=timings, joint_noise=noise, final=final)
    if out is not None:
        result.write_joint(out)
        # every flight's refits were kept until the whole command had ended (a flight resumed after another's
        # interruption goes through its own in no time); a flight stopped at its budget keeps them
        for label, rep in zip(labels, reports):
            end_checkpoints(Path(out) / label / "checkpoints", bool(rep.search_stopped), [])
    return result


def _as_diagnosed(data, report):
    """A flight's data as its diagnosis saw them: without the wild points it dropped, each channel whose errors
    it found correlated thinned to the same stride."""
    if report.wild_points and report.wild_points.action == "drop":
        data = report.wild_points.without(data)
    corr = report.correlated_noise
    if corr and corr.action == "thin":
        data = corr.thin(data)
    return data


def _noise_of_the_flights(flights: list, reports: Sequence, sigma) -> tuple[list, Any, dict]:
    """The joint fit's flights and ``sigma`` request when some noise levels are to be estimated.

    Each flight's diagnosis took those from its data alone (:attr:`DiagnosisReport.noise_from_data`);
    the joint fit holds the same values, written into each flight's data with the ones the request
    gives, instead of estimating them again from the joint residuals of the base model (which hold
    the misfit the diagnosis looks for). Returns ``(flights, sigma for joint_estimate,
    {label: {channel: sigma}})``; unchanged when no report estimated any."""
    from ..data import resolve_quantized, sigma_request

    if not any(r.noise_from_data for r in reports):
        return flights, sigma, {}
    out, noise = [], {}
    for fl, rep in zip(flights, reports):
        given, _ = sigma_request(resolve_quantized(sigma, fl.data), fl.data.names)
        values = {**given, **{c: float(v) for c, (v, _) in rep.noise_from_data.items()}}
        noise[fl.label] = {c: float(v) for c, (v, _) in rep.noise_from_data.items()}
        out.append(replace(fl, data=fl.data.with_sigma(values)))
    return out, None, noise
