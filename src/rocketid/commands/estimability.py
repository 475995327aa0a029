"""``rocketid estimability``: the estimability report of a model and a data set.

::

    rocketid estimability ra66.csv --scaling nominal --out est.json --plot est.png

Forms the reduced Hessian (7.6) at the model's guess p0 (the chapter's step 2;
``--at fit`` forms it at the full fit's estimate instead), decomposes it (7.7),
selects ``np`` with the modified E-optimal criterion against ``--threshold``,
prints :meth:`rocketid.estimability.Estimability.summary` and writes the JSON
(``eigenvalues``, ``ratios``, ``np``, ``scaling``, ``threshold``,
``evaluated_at``, ``directions``, ``notes``, plus the model, data file, point
and mesh). Exit codes as every rocketid command: 0 success, 1 the full fit of
``--at fit`` did not converge (nothing is written), 2 bad input.
"""

from __future__ import annotations

import time
from dataclasses import replace

import click

from ..cli import (EXIT_NOT_CONVERGED, NameValue, data_options, fit_inputs, flight_window, ipopt_options, load_model,
                   model_option, prepare_verbosely, sigma_argument, status, verbose_option, windowed_inputs,
                   write_json)
from ..errors import SettingsError
from ..output import check_file

__all__ = ["command"]


@click.command("estimability")
@click.argument("data_files", metavar="DATA.csv...", nargs=-1, required=True, type=click.Path(dir_okay=False))
@model_option
@click.option("--scaling", type=click.Choice(["none", "nominal"]), default="none", show_default=True,
              help="Decompose H_r in physical units, or with each parameter divided by its nominal value.")
@click.option("--threshold", type=float, default=3000.0, show_default=True,
              help="Modified E-optimal criterion: np = largest k with lambda_1/lambda_k <= threshold (> 1).")
@click.option("--np", "n_estimated", type=int, default=None, metavar="N",
              help="Force the number of estimated directions (1 .. number of parameters).")
@click.option("--at", "at", type=click.Choice(["guess", "fit"]), default="guess", show_default=True,
              help="Form H_r at the guess p0 (the chapter's step 2) or at the full fit's estimate.")
@click.option("--guess", "guesses", multiple=True, type=NameValue(float), metavar="NAME=VALUE",
              help="Change a parameter of the guess (repeatable; default: the model's p0).")
@data_options
@click.option("--per-flight", "per_flight", multiple=True, metavar="NAME",
              help="With several data files: a parameter each flight has for itself (repeatable).")
@click.option("--ipopt", "ipopt", multiple=True, type=NameValue(str, "value"), metavar="NAME=VALUE",
              help="IPOPT option for the full fit of --at fit (repeatable).")
@click.option("--out", "out", required=True, type=click.Path(dir_okay=False), metavar="EST.json",
              help="Write the report as JSON.")
@click.option("--plot", "plot", type=click.Path(dir_okay=False), default=None, metavar="EST.png",
              help="Plot the eigenvalue spectrum and the directions' composition.")
@verbose_option
def command(data_files, model, scaling, threshold, n_estimated, at, guesses, columns, time_column, sigmas,
            sigma_columns, unmeasured, window_text, n_elements, K, per_flight, ipopt, out, plot):
    """Estimability report: eigenvalues of the reduced Hessian, ratios, np, directions.

    Prints the report; writes EST.json (and EST.png with --plot).

    Several files are several flights of one vehicle: the report gives the eigenvalues of the
    information on the shared parameters for each flight alone and jointly, and each flight's
    share of every joint direction (which directions each flight adds).
    """
    from ..estimability import analyze, select_np
    from ..sensitivity import sensitivity_at, sensitivity_of
    from ..solve import estimate

    # every setting is checked before any work is done
    try:
        select_np([1.0], threshold)
    except SettingsError as exc:
        raise SettingsError(f"--threshold: {exc}") from None
    options = ipopt_options(ipopt)
    check_file(out, "--out")
    if plot is not None:
        check_file(plot, "--plot")
    src = load_model(model)
    spec = src.spec
    n_p = len(spec.parameters)
    if n_estimated is not None and not 1 <= n_estimated <= n_p:
        raise SettingsError(f"--np must be from 1 to {n_p} (the number of parameters of {spec.name}), "
                            f"got {n_estimated}")
    sigma = sigma_argument(sigmas, spec)
    if sigma is not None and at == "guess" and any(v == "estimate" for v in
                                                   (sigma.values() if isinstance(sigma, dict) else [sigma])):
        raise SettingsError("--sigma estimate needs a fit to estimate the noise from: add --at fit (or give the "
                            "sigma as a number)")
    window = flight_window(window_text)
    if len(data_files) > 1:
        _joint(spec, data_files, scaling=scaling, at=at, guesses=guesses, columns=columns, time_column=time_column,
               sigmas=sigmas, n_elements=n_elements, K=K, per_flight=per_flight, options=options, out=out,
               unmeasured=unmeasured, window=window, sigma_columns=sigma_columns, sigma=sigma)
        return
    if per_flight:
        raise SettingsError("--per-flight needs several data files (one per flight)")
    data_file = data_files[0]
    guess, mesh, data = fit_inputs(spec, data_file, guesses=guesses, columns=columns, time_column=time_column,
                                   sigmas=sigmas, n_elements=n_elements, K=K, unmeasured=unmeasured,
                                   sigma_columns=sigma_columns)
    spec, data, guess, mesh, window_notes = windowed_inputs(spec, data, guess, window, n_elements, K)
    n_p = len(spec.parameters)
    if n_estimated is not None and not 1 <= n_estimated <= n_p:
        raise SettingsError(f"--np must be from 1 to {n_p} (the number of parameters of {spec.name} in the window), "
                            f"got {n_estimated}")
    status(f"read {data.n_samples} values of {', '.join(data.names)} from {data_file}; collocating on "
           f"{mesh.describe()}")
    t0 = time.perf_counter()
    prepared = prepare_verbosely(spec, data, mesh)
    extra_notes = list(window_notes)
    fit_info = None
    if at == "fit":
        fit = estimate(spec, data, guess=guess, prepared=prepared, options=options, sigma=sigma)
        fit_info = {"success": bool(fit.success), "iterations": int(fit.iterations),
                    "objective": float(fit.objective), "chi2_per_dof": float(fit.chi2_per_dof),
                    "sigma": fit.sigma, "sigma_estimated": list(fit.sigma_estimated)}
        prepared = fit.prepared  # the estimated sigmas weight H_r
        if not fit.success:
            click.echo(f"Error: the full fit did not converge ({fit.message}); the reduced Hessian is not formed "
                       "at a point that is not an estimate (use --at guess, or --ipopt to help the fit)", err=True)
            click.get_current_context().exit(EXIT_NOT_CONVERGED)
        for s, side in fit.active_bounds():
            extra_notes.append(f"{s} is at its {side} bound in the full fit where H_r was formed")
        sens = sensitivity_of(fit)
        point = fit.p
    else:
        point = guess
        sens = sensitivity_at(prepared, point)
    est = analyze(prepared, point, threshold=threshold, scaling=scaling, n_estimated=n_estimated,
                  sensitivity=sens)
    if extra_notes:
        est = replace(est, notes=est.notes + tuple(extra_notes))
    status(f"formed H_r in {sens.formed_s:.3f} s ({time.perf_counter() - t0:.2f} s in all)")
    click.echo(est.summary().text())
    payload = est.to_dict()
    payload.update({
        "model": spec.name,
        "data": str(data_file),
        "at": at,
        "mesh": {"n_elements": int(mesh.n_elements), "K": int(mesh.K)},
        "formed_s": float(sens.formed_s),
    })
    if fit_info is not None:
        payload["fit"] = fit_info
    path = write_json(out, payload)
    status(f"wrote {path}")
    if plot is not None:
        import matplotlib.pyplot as plt

        fig = est.plot(plot)
        plt.close(fig)
        status(f"wrote {plot}")


def _joint(spec, data_files, *, scaling, at, guesses, columns, time_column, sigmas, n_elements, K, per_flight,
           unmeasured=(), window=None, sigma_columns=(), sigma=None,
           options, out):
    """The joint estimability report of several flights (``rocketid.joint.joint_estimability``)."""
    from ..cli import assignments, read_flights
    from ..joint import joint_estimability, joint_estimate, joint_prepare
    from ..sensitivity import sensitivity_at

    flights = read_flights(data_files, spec, columns=columns, time_column=time_column, sigmas=sigmas,
                           unmeasured=unmeasured, window=window, sigma_columns=sigma_columns,
                           n_elements=n_elements, K=K)
    guess = assignments(guesses, "--guess")
    prep = joint_prepare(flights, per_flight=per_flight)
    lay = prep.layout
    payload = {"model": spec.name, "data": [str(p) for p in data_files], "at": at}
    if at == "fit":
        joint = joint_estimate(flights, per_flight=per_flight, guess=guess, options=options, prepared=prep,
                               sigma=sigma)
        payload["fit"] = {"success": bool(joint.success), "iterations": int(joint.iterations),
                          "chi2_per_dof": float(joint.chi2_per_dof), "sigma": joint.sigma,
                          "sigma_estimated": {l: list(c) for l, c in joint.sigma_estimated.items()}}
        if not joint.success:
            click.echo(f"Error: the joint fit did not converge ({joint.message}); use --at guess or --ipopt",
                       err=True)
            click.get_current_context().exit(EXIT_NOT_CONVERGED)
        est = joint.estimability(scaling=scaling)
    else:
        theta = lay.guess.copy()
        for name, value in guess.items():
            if name not in lay.names:
                raise SettingsError(f"--guess {name}: not a joint parameter; they are {', '.join(lay.names)}")
            theta[lay.names.index(name)] = value
        infos = [sensitivity_at(pr, lay.flight_parameters(theta, f)).H_data for f, pr in enumerate(prep.prepared)]
        est = joint_estimability(lay, infos, scaling=scaling)
    click.echo(est.summary().text())
    payload.update(est.to_dict())
    write_json(out, payload)
