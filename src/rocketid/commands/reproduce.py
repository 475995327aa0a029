"""``rocketid reproduce``: the chapter's study (section 7.3) on RA-66, Tables 7.1-7.3.

::

    rocketid reproduce --out study                      # the chapter's setting: 10 runs, n_iter = 2000
    rocketid reproduce --out quick --runs 3 --n-iter 50  # a shorter study
    rocketid reproduce --out study --resume             # continue an interrupted study

Writes ``DIR/table_7_1.csv`` (columns ``index``, the parameter names, ``eta``;
index 0 = the initial guess with q2 fixed at V2^T p0, 1..R = the runs),
``DIR/table_7_2.csv`` (``index``, ``x``, ``h``, ``v``: mean |prediction -
truth| over the 6600 samples, prediction = high-accuracy simulation with the
estimates), ``DIR/table_7_3.csv`` (``case``, ``x0``, ``h0``, ``v0``,
``index``, ``x``, ``h``, ``v``: perturbed initial states, index 0 and the
least-eta run), ``tables.md`` (the tables beside the chapter's),
``summary.txt``, ``study.json``, ``predictions.png``, ``eta.png``, and
``checkpoints/run_<seed>.json`` after every batch of draws.

Exit codes: 0 success; 1 the study ran but a run (or the reference solve)
has no valid result; 2 bad input (including unfinished checkpoints in DIR
without ``--resume``, and DIR in use by another run: the folder is locked
while a study writes there); 130 interrupted (Ctrl-C; 143 on SIGTERM): the
checkpoints are kept, continue with ``--resume``. Worker processes end with
the command, however it ends.
"""

from __future__ import annotations

import click

from ..cli import EXIT_NOT_CONVERGED, status, verbose_option
from ..output import folder_lock

__all__ = ["command"]


@click.command("reproduce")
@click.option("--out", "out", required=True, type=click.Path(file_okay=False), metavar="DIR",
              help="Output directory (tables, plots, study.json, checkpoints/).")
@click.option("--runs", type=click.IntRange(1, 999), default=10, show_default=True,
              help="Runs of the sampling algorithm, each with its own seed.")
@click.option("--n-iter", "n_iter", type=click.IntRange(min=1), default=2000, show_default=True,
              help="Stop a run after this many draws in a row without improvement of eta.")
@click.option("--seed", type=click.IntRange(min=0), default=0, show_default=True,
              help="Base seed: run i uses seed 1000*SEED + i; Table 7.3's perturbations use it too.")
@click.option("--data-seed", "data_seed", type=click.IntRange(min=0), default=0, show_default=True,
              help="Noise seed of the measured data set.")
@click.option("--scaling", type=click.Choice(["nominal", "none"]), default="nominal", show_default=True,
              help="Parameter scaling of the estimability analysis (nominal: np = 5 like the chapter).")
@click.option("--threshold", type=float, default=3000.0, show_default=True,
              help="Modified E-optimal threshold on lambda_1/lambda_k.")
@click.option("--perturbations", "n_perturbations", type=click.IntRange(min=0), default=5, show_default=True,
              help="Perturbed initial states in Table 7.3.")
@click.option("--executor", type=click.Choice(["processes", "serial", "dask"]), default="processes",
              show_default=True, help="Where the draws are evaluated.")
@click.option("--workers", type=click.IntRange(min=1), default=None, metavar="N",
              help="Worker processes (default: the CPUs available).")
@click.option("--scheduler", "address", default=None, metavar="ADDRESS",
              help="dask.distributed scheduler address for --executor dask (e.g. tcp://host:8786).")
@click.option("--batch-size", "batch_size", type=click.IntRange(min=1), default=16, show_default=True,
              help="Draws per task and per checkpoint.")
@click.option("--max-draws", "max_draws", type=click.IntRange(min=1), default=None, metavar="N",
              help="Cap the draws of each run (default: no cap, the n_iter rule alone).")
@click.option("--resume", is_flag=True, help="Continue from DIR/checkpoints.")
@click.option("--no-plots", "no_plots", is_flag=True, help="Do not write the PNG plots.")
@click.option("-q", "--quiet", is_flag=True, help="No progress bars.")
@verbose_option
def command(out, runs, n_iter, seed, data_seed, scaling, threshold, n_perturbations, executor, workers, address,
            batch_size, max_draws, resume, no_plots, quiet):
    """The chapter's study on RA-66: Tables 7.1-7.3 as CSV and Markdown, with plots.

    One data set, RUNS runs of the statistic-criterion sampling algorithm
    (steps 1-10), and the prediction errors of each estimate against the
    noise-free truth. The full setting (10 runs, n_iter = 2000) takes minutes;
    interrupt it at any time and continue with --resume.
    """
    from ..errors import SettingsError
    from ..study import StudySettings, reproduce

    if executor == "dask" and address is None:
        raise SettingsError("--executor dask needs --scheduler ADDRESS (a running dask.distributed scheduler)")
    if address is not None and executor != "dask":
        raise SettingsError("--scheduler is for --executor dask")
    settings = StudySettings(runs=runs, n_iter=n_iter, seed=seed, data_seed=data_seed, scaling=scaling,
                             threshold=threshold, n_perturbations=n_perturbations, batch_size=batch_size,
                             max_draws=max_draws)
    with folder_lock(out):  # a second run into DIR is refused with this one's PID
        status(f"RA-66 study: {runs} runs, n_iter = {n_iter}, scaling {scaling}, executor {executor}; "
               f"writing to {out}")
        result = reproduce(out, settings=settings, executor=executor, workers=workers, address=address,
                           resume=resume, progress=False if quiet else None, plots=not no_plots)
    click.echo(result.summary().text())
    click.echo(f"\nwrote {out}/table_7_1.csv, table_7_2.csv, table_7_3.csv, tables.md, study.json"
               + ("" if no_plots else ", predictions.png, eta.png"))
    smp = result.sampling
    if not smp.reference.success or any(r.best is None for r in smp.runs):
        click.get_current_context().exit(EXIT_NOT_CONVERGED)
