"""``rocketid diagnose``: fit a model, find where it fails and which effect it misses.

::

    rocketid diagnose data.csv --out report/                 # the chapter's RA-66 parameterization
    rocketid diagnose data.csv --out report/ --model ra66m   # Mach-indexed CD(M), CL = CL_alpha alpha
    rocketid diagnose data.csv --out report/ --model my_model.py --holdout 0:40 --max-effects 2
    rocketid diagnose f1.csv f2.csv --out report/ --model ra66m   # several flights: each alone, then jointly

Runs :func:`rocketid.diagnostics.api.diagnose` (fit, compare, locate,
plausibility, candidate ranking, every contender refitted, the acceptance test,
effects added stepwise until the model reaches the noise) and writes
``DIR/report.html`` (self-contained: opens with no network),
``DIR/candidates.json`` (``{"candidates": [...]}``, best first, each with
``name``, ``statistic``, ``p_value`` (corrected) and ``group``),
``DIR/diagnosis.json`` (with ``"final"``: the effects added, every parameter's
value and std, chi2/dof, fits_to_noise and the verdict), ``DIR/summary.txt`` and
``DIR/figures/*.png``; prints the verdict. Exit codes as every rocketid command: 0 the report is written
(whatever it finds), 1 the base fit did not converge (the report is still
written), 2 bad input.

Several data files are several flights of one model
(:mod:`rocketid.commands.diagnose_flights`): each flight's report in
``DIR/<flight>/``, then ``DIR/diagnosis.json``, ``DIR/summary.txt`` and
``DIR/index.html``; exit 0 also when the flights disagree, 1 when a flight's base
fit or the joint fit did not converge, 2 bad input in any file (before any work).
"""

from __future__ import annotations

import time
from pathlib import Path

import click

from ..cli import (EXIT_NOT_CONVERGED, NameValue, assignments, flight_window, given_sigmas, model_option, read_data,
                   sigma_argument, sigma_column_option_decl, sigma_option_decl, status, unmeasured_option_decl,
                   verbose_option)
from ..errors import ModelError, RocketidError, SettingsError
from ..output import check_folder, folder_lock

__all__ = ["command"]


@click.command("diagnose")
@click.argument("data_files", metavar="DATA.csv...", nargs=-1, required=True, type=click.Path(dir_okay=False))
@click.option("--out", "out", required=True, type=click.Path(file_okay=False), metavar="DIR",
              help="Folder for report.html, candidates.json, diagnosis.json, summary.txt and figures/ (several "
                   "files: DIR/<flight>/ each, and DIR/diagnosis.json, summary.txt, index.html).")
@model_option
@click.option("--level", type=float, default=0.05, show_default=True,
              help="Significance level of the tests and of the candidate ranking (0 < level < 1).")
@click.option("--confirm", "confirm_top", type=click.IntRange(min=0), default=2, show_default=True, metavar="N",
              help="0: rank the candidates only. Otherwise every significant contender (each confounded group's "
                   "leader, every candidate whose predicted fall is within 10x of the leader's) is refitted.")
@click.option("--holdout", default="auto", show_default=True, metavar="auto|none|START:END",
              help="Hold-out check of the final model: 'auto' fits the first 45/66 of the fitted span (the model's "
                   "horizon, or the --window) and predicts the rest; START:END sets the fit window (s); 'none' "
                   "skips it.")
@click.option("--max-effects", type=click.IntRange(min=1), default=3, show_default=True, metavar="N",
              help="Add at most N effects (stepwise).")
@click.option("--workers", type=click.IntRange(min=1), default=None, metavar="N",
              help="Parallel refit processes (default: up to 2).")
@click.option("--refit-timeout", type=float, default=180.0, show_default=True, metavar="SECONDS",
              help="Give up a refit or hold-out prediction after this long (it is reported as given up).")
@click.option("--budget", type=float, default=None, metavar="SECONDS",
              help="Stop the search for missing effects after this long (each flight's, with several files): the "
                   "step under way is not completed, the steps before it stand, and the report says where it "
                   "stopped. Default: no limit. Continue with --resume and a larger budget.")
@click.option("--resume", is_flag=True,
              help="Continue a diagnosis interrupted or stopped at its --budget: the refits it made, kept in "
                   "DIR/checkpoints (DIR/<flight>/checkpoints), are taken instead of run again.")
@click.option("--free-shape/--no-free-shape", "free_shape", default=True, show_default=True,
              help="When the search ends above the noise, fit the free shape the verdict names (a thrust error on "
                   "the mesh over the burn, a wind or density profile, a drag correction in Mach) to the model: "
                   "the report says whether what is missing is of that kind, and its shape. Never an explanation.")
@click.option("--refine/--no-refine", "refine", default=True, show_default=True,
              help="Try the refined shapes of the families the search meets (more knots, a surface wind, event "
                   "times, the fuller shapes of a snug choice's near rivals). --no-refine is several times faster "
                   "on a clear case and keeps every family at its catalogue shape: a first look, not the answer.")
@click.option("--locate-window", "locate_window", type=float, default=None, metavar="SECONDS",
              help="Window length of the located statistics (default: the flight's span / 22).")
@click.option("--window", "window_text", default=None, metavar="T0:T1",
              help="Fit only the flight window T0:T1 (s; '20:' to the end); a window that starts in flight "
                   "estimates the initial states the data determine. (A plain number is the old meaning, "
                   "--locate-window.)")
@click.option("--column", "columns", multiple=True, type=NameValue(str, "CSV column name"),
              metavar="NAME=CSVCOL", help="Read output NAME from column CSVCOL (repeatable).")
@click.option("--time-column", default="t", show_default=True, help="Name of the time column.")
@click.option("--wild-points", "wild_points", type=click.Choice(["drop", "keep"]), default="drop", show_default=True,
              help="Isolated samples no model can follow (a GPS multipath jump, a radar wild point), found on the "
                   "base fit's residuals: 'drop' removes them before the diagnosis, 'keep' only lists them. The "
                   "report names every one.")
@click.option("--correlated-noise", "correlated_noise", type=click.Choice(["thin", "keep"]), default="thin",
              show_default=True,
              help="Errors correlated from sample to sample (a navigation filter, a smoothed readout), measured on "
                   "the base fit's residuals: 'thin' keeps the samples of such a channel far enough apart for "
                   "their errors to be independent before the diagnosis, 'keep' only reports the correlation. "
                   "On every sample the whiteness test would take correlated errors for a missing effect.")
@click.option("--size", "size_opts", multiple=True, type=NameValue(float), metavar="NAME=VALUE",
              help="Realistic size of an effect parameter (repeatable; a name or a pattern such as 'eps_P*'), in "
                   "place of the catalogue's: an effect beyond 5 times it is implausible. A model file's "
                   "realistic_sizes() states them too; the option wins.")
@click.option("--per-flight", "per_flight", multiple=True, metavar="NAME",
              help="With several data files: a model parameter (or a pattern such as 'alpha*') that each flight "
                   "estimates for itself in the joint fits (repeatable; the others are shared, free initial states "
                   "are per flight always): a flight's attitude program, its lift-off mass.")
@sigma_option_decl()
@sigma_column_option_decl()
@unmeasured_option_decl()
@verbose_option
def command(data_files, out, model, level, confirm_top, holdout, max_effects, workers, refit_timeout, budget,
            resume, free_shape, refine, locate_window,
            window_text, columns, time_column, wild_points, correlated_noise, size_opts, per_flight, sigmas,
            sigma_columns, unmeasured):
    """Fit a model to DATA.csv and diagnose what it misses; write DIR/report.html.

    The report compares each channel with the model, locates where the
    residuals fail (time, flight phase, Mach, dynamic pressure, altitude),
    checks the coefficients' plausibility, ranks candidate physical effects by
    the score test and confirms the leaders by refitting.

    Several files are several flights of one vehicle: each is diagnosed alone
    (DIR/<flight>/, the flight being the file's name), then the model is fitted
    to all jointly and each flight refitted alone; DIR/diagnosis.json and
    DIR/index.html say which effects are found in every flight and which in one
    flight only.
    """
    from ..diagnostics.api import diagnose, end_checkpoints, resolve_model

    if not 0 < level < 1:
        raise SettingsError(f"--level must be between 0 and 1, got {level:g}")
    window, window_option = locate_window, "--locate-window"
    flight = None
    if window_text is not None:
        try:
            legacy = float(window_text)
        except ValueError:
            flight = flight_window(window_text)
        else:
            window, window_option = legacy, "--window"
    if window is not None and not window > 0:
        raise SettingsError(f"{window_option} must be a positive number of seconds, got {window:g}")
    if window_option == "--window":
        click.echo(f"Warning: --window {window_text} (a length) is now --locate-window; --window takes a flight "
                   "window T0:T1", err=True)
    if not refit_timeout > 0:
        raise SettingsError(f"--refit-timeout must be a positive number of seconds, got {refit_timeout:g}")
    if budget is not None and not (budget > 0 and budget < float("inf")):
        raise SettingsError(f"--budget must be a positive number of seconds, got {budget:g}")
    holdout = _holdout(holdout)
    check_folder(out, "--out")  # before the work: a bad --out fails at once, not after the fits
    spec, label = resolve_model(model)
    candidates = _file_candidates(model)
    sizes = {**_file_sizes(model), **assignments(size_opts, "--size")}
    sigma = sigma_argument(sigmas, spec)
    if per_flight and len(data_files) < 2:
        raise SettingsError("--per-flight needs several data files (one per flight)")
    own = _per_flight_names(per_flight, spec)
    if len(data_files) > 1:
        _several(data_files, out, spec, label, sigma, flight, columns=columns, time_column=time_column,
                 sigma_columns=sigma_columns, unmeasured=unmeasured, per_flight=own,
                 settings=dict(level=level, confirm_top=confirm_top, window=window, holdout=holdout,
                               max_effects=max_effects, workers=workers, refit_timeout=refit_timeout,
                               candidates=candidates, wild_points=wild_points, sizes=sizes,
                               correlated_noise=correlated_noise, budget=budget, resume=resume,
                               free_shape=free_shape, refine=refine))
        return
    data_file = data_files[0]
    data = read_data(data_file, spec, time_column=time_column, columns=assignments(columns, "--column"),
                     sigma=given_sigmas(sigma), unmeasured=tuple(unmeasured),
                     sigma_columns=assignments(sigma_columns, "--sigma-column"))
    with folder_lock(out):
        status(f"read {data.n_samples} values of {', '.join(data.names)} from {data_file}; fitting {spec.name} and "
               "diagnosing")
        t0 = time.perf_counter()
        report = diagnose(data, spec, level=level, confirm_top=confirm_top, window=window, holdout=holdout,
                          max_effects=max_effects, workers=workers, refit_timeout=refit_timeout, sigma=sigma,
                          flight_window=flight, candidates=candidates, wild_points=wild_points, sizes=sizes,
                          correlated_noise=correlated_noise, budget=budget, progress=status,
                          checkpoints=Path(out) / "checkpoints", resume=resume, free_shape=free_shape,
                          refine=refine)
        report = _relabel(report, label, str(data_file))
        path = report.write(out)
        end_checkpoints(Path(out) / "checkpoints", bool(report.search_stopped), [])
    for line in report.verdict():
        click.echo(line)
    click.echo(f"wrote {path} and {path.parent / 'candidates.json'} ({time.perf_counter() - t0:.1f} s)")
    if not report.fit.success:
        click.get_current_context().exit(EXIT_NOT_CONVERGED)


def _per_flight_names(patterns, spec) -> tuple:
    """The model's parameters named by ``--per-flight`` (names or shell-style patterns, ``alpha*``); a
    SettingsError naming the parameters when one matches none."""
    from fnmatch import fnmatchcase

    names = tuple(spec.parameter_names)
    out: list = []
    for pat in patterns:
        hit = [n for n in names if fnmatchcase(n, pat)]
        if not hit:
            raise SettingsError(f"--per-flight {pat}: no parameter of {spec.name} matches; its parameters are "
                                f"{', '.join(names)}")
        out += [n for n in hit if n not in out]
    return tuple(out)


def _several(data_files, out, spec, model_label, sigma, flight, *, columns, time_column, sigma_columns, unmeasured,
             per_flight=(), settings):
    """Several flights: each diagnosed alone, then jointly (:mod:`rocketid.commands.diagnose_flights`)."""
    from ..cli import flight_labels
    from .diagnose_flights import diagnose_flights

    labels = flight_labels(data_files)
    datas = [read_data(f, spec, time_column=time_column, columns=assignments(columns, "--column"),
                       sigma=given_sigmas(sigma), unmeasured=tuple(unmeasured),
                       sigma_columns=assignments(sigma_columns, "--sigma-column")) for f in data_files]
    with folder_lock(out):
        t0 = time.perf_counter()

        def done(label, report):
            final = report.final
            status(f"flight {label}: " + ("no effects searched" if final is None else
                                          f"{final.verdict} ({', '.join(final.effects) or 'no effect added'})")
                   + f"; wrote {Path(out) / label / 'report.html'}")

        status(f"diagnosing {len(labels)} flights ({', '.join(labels)}) with {spec.name}, one at a time, then jointly")
        result = diagnose_flights(datas, labels, spec, files=[str(f) for f in data_files], model_label=model_label,
                                  flight_window=flight, sigma=sigma, out=out, on_flight=done, per_flight=per_flight,
                                  progress=status, **settings)
    click.echo(result.summary().text())
    click.echo(f"wrote {Path(out) / 'index.html'}, {Path(out) / 'diagnosis.json'} and each flight's report in "
               f"{Path(out)}/<flight>/ ({time.perf_counter() - t0:.1f} s)")
    if not result.success:
        click.get_current_context().exit(EXIT_NOT_CONVERGED)


def _file_sizes(model: str) -> dict:
    """The model file's ``realistic_sizes()``: ``{parameter name or pattern: size}`` the vehicle's engineers
    state for its effects (empty without one)::

        def realistic_sizes():
            return {"eps_thrust": 0.10, "eps_burn": 0.10}   # a hybrid: the N2O tank's temperature moves both
    """
    from ..cases.files import optional_hook
    if not str(model).endswith(".py"):
        return {}
    value = optional_hook(model, "realistic_sizes")
    if value is None:
        return {}
    if not isinstance(value, dict):
        raise ModelError(f"model file {model!r}: realistic_sizes() must return a dict {{parameter: size}}, got "
                         f"{type(value).__name__}")
    return dict(value)


def _file_candidates(model: str):
    """The model file's ``candidates()``: the effects ``diagnose`` tries (None: the whole catalogue).

    A vehicle launched elsewhere than RA-66's site states its own Earth rotation this way, and a user's
    ``custom_effect`` reaches the command line::

        def candidates():
            from rocketid.diagnostics import CATALOGUE, earth_rotation_effect
            return [e for n, e in CATALOGUE.items() if n != "earth_rotation"] + [earth_rotation_effect(37.84, 120.0)]
    """
    from ..cases.files import optional_hook
    from ..diagnostics.effects import resolve_effects
    if not str(model).endswith(".py"):
        return None
    value = optional_hook(model, "candidates")
    if value is None:
        return None
    try:
        out = resolve_effects(list(value))
    except (TypeError, RocketidError) as exc:
        raise ModelError(f"model file {model!r}: candidates() must return effects (rocketid.diagnostics.Effect) or "
                         f"catalogue names: {exc}") from None
    if not out:
        raise ModelError(f"model file {model!r}: candidates() returned no effect; return the effects to try, or "
                         "remove the function to try the whole catalogue")
    return out


def _holdout(text: str):
    """'auto', 'none' or 'START:END' -> the diagnose() argument."""
    t = text.strip().lower()
    if t == "auto":
        return "auto"
    if t == "none":
        return None
    try:
        a, b = (float(x) for x in t.split(":"))
    except ValueError:
        raise SettingsError(f"--holdout must be auto, none or START:END in seconds (e.g. 0:45), got {text!r}") from None
    if not b > a:
        raise SettingsError(f"--holdout START:END needs END > START, got {text!r}")
    return a, b


def _relabel(report, model_label: str, data_label: str):
    from dataclasses import replace
    return replace(report, model=model_label, data_label=data_label)
