"""The ``rocketid`` command line.

::

    rocketid simulate --out ra66.csv                 # RA-66 synthetic measurements
    rocketid estimate ra66.csv --out fit.json        # fit, print the summary, write JSON

Exit codes: 0 success; 1 the command ran but its result is not valid (IPOPT
did not converge: the JSON is still written); 2 bad input (a missing file or
column, a malformed ``NAME=VALUE``, an unknown option, an output location
that cannot be written: checked before any work); 130 interrupted (Ctrl-C;
"continue with --resume" where a command resumes), 143 terminated (SIGTERM).
Every file is written atomically (:mod:`rocketid.output`). Every
:class:`~rocketid.errors.RocketidError` and every usage error is reported as
one ``Error: ...`` line on stderr; ``--verbose`` shows the traceback instead.

Adding a command
----------------
A command lives in its own module ``rocketid/cli_<name>.py`` (``-`` in the
command name becomes ``_``) that defines ``command``, a :class:`click.Command`.
The group finds such modules by name, without importing them, and imports one
only when its command runs or ``--help`` lists it; nothing in this file needs
to change. Use the shared helpers below so that every command reads models,
``NAME=VALUE`` options and errors the same way::

    # rocketid/cli_reproduce.py
    import click
    from rocketid.cli import model_option, verbose_option, load_model

    @click.command("reproduce")
    @model_option
    @verbose_option
    def command(model):
        src = load_model(model)
        ...

Shared helpers: :func:`load_model` / :func:`model_option` (``ra66`` or a model
file), :class:`NameValue` / :func:`assignments` / :func:`parameter_values`
(``NAME=VALUE`` options), :func:`ipopt_options`, :func:`read_data`, :func:`make_mesh`,
:func:`write_json`, :func:`status` and :func:`progress` (stderr progress),
:func:`verbose_option`.
"""

from __future__ import annotations

import difflib
import importlib
import math
import os
import pkgutil
import signal
import sys
import threading
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Any, Callable, Iterable, Mapping, Sequence

import click
import numpy as np

from . import output
from .cases.registry import BUILTIN_MODELS, ModelSource, load_model
from .collocation.radau import MAX_DEGREE
from .data import Measurements, read_csv
from .errors import RocketidError, SettingsError
from .model import ModelSpec, check_guess
from .summary import Section, Summary, Table

__all__ = [
    "main", "simulate_command", "estimate_command",
    "ModelSource", "BUILTIN_MODELS", "load_model", "model_option", "data_options", "fit_inputs", "verbose_option",
    "NameValue", "SigmaValue", "sigma_argument", "given_sigmas", "flight_window", "windowed_inputs", "assignments", "parameter_values", "ipopt_options", "read_data", "make_mesh", "write_json",
    "status", "progress", "LAZY_COMMANDS",
]

EXIT_OK, EXIT_NOT_CONVERGED, EXIT_BAD_INPUT = 0, 1, 2
_VERBOSE = "rocketid.verbose"
_COMMAND = "rocketid.command"
_GUARD = "rocketid.interrupt_guard"
EXIT_INTERRUPTED = 130  # 128 + SIGINT; SIGTERM gives 143


# ---------------------------------------------------------------------------
# NAME=VALUE options
# ---------------------------------------------------------------------------


class NameValue(click.ParamType):
    """A ``NAME=VALUE`` option value, parsed to ``(name, value)``.

    Parameters
    ----------
    value_type : callable
        Converts the value text (``float`` or ``str``).
    what : str
        What the value is, for messages ("number", "CSV column").
    """

    name = "NAME=VALUE"

    def __init__(self, value_type: Callable[[str], Any] = float, what: str = "number"):
        self.value_type = value_type
        self.what = what

    def convert(self, value, param, ctx):
        if isinstance(value, tuple):
            return value
        text = str(value)
        name, sep, raw = text.partition("=")
        name, raw = name.strip(), raw.strip()
        if not sep or not name or not raw:
            self.fail(f"{text!r} is not NAME=VALUE (for example CD0=0.5)", param, ctx)
        try:
            converted = self.value_type(raw)
        except ValueError:
            self.fail(f"in {text!r}, {raw!r} is not a {self.what}", param, ctx)
        if isinstance(converted, float) and not math.isfinite(converted):
            self.fail(f"in {text!r}, the value must be finite", param, ctx)
        return name, converted


class SigmaValue(click.ParamType):
    """A ``--sigma`` value: ``NAME=VALUE`` (a number), ``NAME=estimate``, or ``estimate``
    (every channel), parsed to ``(name, value)`` with name ``"*"`` for every channel."""

    name = "NAME=VALUE|NAME=estimate|estimate"

    def convert(self, value, param, ctx):
        if isinstance(value, tuple):
            return value
        text = str(value).strip()
        if text.lower() == "estimate":
            return "*", "estimate"
        name, sep, raw = text.partition("=")
        name, raw = name.strip(), raw.strip()
        if not sep or not name or not raw:
            self.fail(f"{text!r} is not NAME=VALUE, NAME=estimate or estimate (for example h=2.5)", param, ctx)
        if raw.lower() == "estimate":
            return name, "estimate"
        if raw.lower().startswith("quantized"):
            return name, raw.lower()
        try:
            v = float(raw)
        except ValueError:
            self.fail(f"in {text!r}, {raw!r} is not a number or 'estimate'", param, ctx)
        if not math.isfinite(v):
            self.fail(f"in {text!r}, the value must be finite", param, ctx)
        return name, v


def sigma_argument(pairs: Iterable[tuple[str, Any]], spec: ModelSpec, option: str = "--sigma"):
    """The ``sigma=`` argument of :func:`rocketid.estimate` from ``--sigma`` values:
    None, ``"estimate"`` (every channel) or ``{output: value or "estimate"}``.

    Raises
    ------
    SettingsError
        A name given twice, an output the model does not have, or ``estimate`` for every
        channel together with a value for one.
    """
    raw = assignments(pairs, option)
    if "*" in raw:
        if len(raw) > 1:
            others = ", ".join(k for k in raw if k != "*")
            raise SettingsError(f"{option} estimate (every channel) cannot be combined with {option} for {others}; "
                                f"name the channels to estimate instead ({option} NAME=estimate)")
        return "estimate"
    outputs = spec.output_names
    for name, value in raw.items():
        if name not in outputs:
            raise SettingsError(f"{option} {name}={value:g}: {name!r} is not one of {', '.join(outputs)} (model "
                                f"{spec.name!r} has no output {name!r})" if not isinstance(value, str) else
                                f"{option} {name}={value}: {name!r} is not one of {', '.join(outputs)} (model "
                                f"{spec.name!r} has no output {name!r})")
    return raw or None


def given_sigmas(sigma) -> dict[str, float]:
    """The numeric values of a ``sigma=`` argument (the ones not to be estimated nor taken from
    a quantization step)."""
    if not isinstance(sigma, Mapping):
        return {}
    return {k: v for k, v in sigma.items() if not isinstance(v, str)}


def assignments(pairs: Iterable[tuple[str, Any]], option: str, allowed: Sequence[str] | None = None) -> dict[str, Any]:
    """``(name, value)`` pairs of a repeated ``NAME=VALUE`` option as a dict.

    Raises
    ------
    SettingsError
        A name given twice, or (with ``allowed``) a name not in ``allowed``.
    """
    out: dict[str, Any] = {}
    for name, value in pairs:
        if name in out:
            raise SettingsError(f"{option} {name} is given twice")
        if allowed is not None and name not in allowed:
            raise SettingsError(f"{option} {name}={value}: {name!r} is not one of {', '.join(allowed)}")
        out[name] = value
    return out


def parameter_values(spec: ModelSpec, values: Mapping[str, float], option: str,
                     base: Sequence[float] | None = None) -> np.ndarray:
    """A full parameter vector: ``base`` (default: the model's p0) with ``values``
    (``{name: value}`` from a ``NAME=VALUE`` option) replacing entries.

    Raises
    ------
    SettingsError
        A name that is not an estimated parameter of ``spec``.
    """
    p = np.array(spec.guess if base is None else base, dtype=float)
    names = spec.parameter_names
    for name, value in values.items():
        if name not in names:
            close = difflib.get_close_matches(name, names, n=3)
            hint = f"; did you mean {', '.join(close)}?" if close else f"; its parameters are {', '.join(names)}"
            raise SettingsError(f"{option} {name}={value:g}: {name!r} is not a parameter of model {spec.name!r}{hint}")
        p[names.index(name)] = value
    return p


def ipopt_options(pairs: Iterable[tuple[str, str]]) -> dict[str, Any]:
    """``--ipopt NAME=VALUE`` pairs, checked and typed by
    :func:`rocketid.solve.check_ipopt_options` (before any work is done)."""
    from .solve import check_ipopt_options

    raw = assignments(pairs, "--ipopt")
    try:
        return check_ipopt_options(raw)
    except SettingsError as exc:
        raise SettingsError(f"--ipopt: {exc}") from None


# ---------------------------------------------------------------------------
# Data, mesh, output
# ---------------------------------------------------------------------------


def _names_channel_files(text: str) -> bool:
    """Whether a data argument is ``NAME=FILE[,NAME=FILE...]`` rather than a CSV path."""
    return "=" in text and not Path(text).exists()


def channel_files(path: str | os.PathLike, outputs: Sequence[str]) -> dict[str, str] | None:
    """``{output: CSV}`` when a data argument is one flight given as one file per channel,
    ``NAME=FILE[,NAME=FILE...]`` (``h=alt.csv,v=speed.csv``); None for an ordinary CSV path."""
    text = str(path)
    if not _names_channel_files(text):
        return None
    files: dict[str, str] = {}
    for part in text.split(","):
        name, sep, file = part.partition("=")
        name, file = name.strip(), file.strip()
        if not sep or not name or not file:
            raise SettingsError(f"data argument {text!r}: one file per channel is written NAME=FILE[,NAME=FILE...] "
                                f"(e.g. {outputs[0]}=channel.csv); {part!r} is not NAME=FILE")
        if name not in outputs:
            raise SettingsError(f"data argument {text!r}: the model has no output {name!r}; its outputs are "
                                f"{', '.join(outputs)}")
        if name in files:
            raise SettingsError(f"data argument {text!r}: output {name!r} is given two files; give each once")
        files[name] = file
    return files


def read_data(path: str | os.PathLike, spec: ModelSpec, *, time_column: str = "t",
              columns: Mapping[str, str] | None = None, sigma: Mapping[str, float] | None = None,
              unmeasured: Sequence[str] = (), window: tuple[float, float] | None = None,
              sigma_columns: Mapping[str, str] | None = None) -> Measurements:
    """Read a CSV with one column per model output (see :func:`rocketid.data.read_csv`), or one
    file per channel (``NAME=FILE[,NAME=FILE...]``, :func:`channel_files`, read by
    :func:`rocketid.data.read_channels`: each with its own sample times; an output without a
    file is predicted, not fitted); ``columns``, ``sigma`` and ``sigma_columns`` (per-sample
    sigma columns, ``--sigma-column``) are keyed by output name, checked against the model.

    An output without a column is left out (predicted, not fitted) when it is named in
    ``unmeasured`` or when the file has no column that goes unread; an empty cell means
    "not measured then". ``window`` keeps the samples in ``[t0, t1]``.
    """
    outputs = spec.output_names
    for option, names in (("--column", columns), ("--sigma", sigma), ("--sigma-column", sigma_columns),
                          ("--unmeasured", unmeasured)):
        for name in names or {}:
            if name not in outputs:
                raise SettingsError(f"{option} {name}: model {spec.name!r} has no output {name!r}; "
                                    f"its outputs are {', '.join(outputs)}")
    wanted = [o for o in outputs if o not in set(unmeasured)]
    if not wanted:
        raise SettingsError(f"--unmeasured names every output of model {spec.name!r}: nothing is left to fit")
    skipped = [k for k in (sigma_columns or {}) if k not in wanted]
    if skipped:
        raise SettingsError(f"--sigma-column {skipped[0]}={sigma_columns[skipped[0]]}: {skipped[0]!r} is named by "
                            "--unmeasured (not fitted); drop one of the two")
    files = channel_files(path, outputs)
    if files is not None:
        from .data import read_channels

        given = {k: v for k, v in files.items() if k in wanted}
        if not given:
            raise SettingsError(f"data argument {str(path)!r}: every output it gives a file is named by --unmeasured: "
                                "nothing is left to fit")
        data = read_channels(given, time_column=time_column,
                             column_map={k: v for k, v in (columns or {}).items() if k in given},
                             sigma={k: v for k, v in (sigma or {}).items() if k in given},
                             sigma_columns=sigma_columns)
    else:
        data = read_csv(path, wanted, time_column=time_column, column_map=columns,
                        sigma={k: v for k, v in (sigma or {}).items() if k in wanted}, missing="auto",
                        sigma_columns=sigma_columns)
    if window is not None:
        data = data.window(*window)
    return data


def make_mesh(spec: ModelSpec, n_elements: int | None = None, K: int = 4):
    """The estimation mesh: :func:`rocketid.solve.default_mesh` (elements of about
    1 s), or about ``n_elements`` equal elements, split so that every breakpoint
    of a parameter family falls on an element boundary."""
    from .solve import default_mesh

    if n_elements is None:
        return default_mesh(spec, K=K)
    if n_elements < 1:
        raise SettingsError(f"--elements must be a positive integer, got {n_elements}")
    return default_mesh(spec, K=K, element_length=(spec.tf - spec.t0) / n_elements)


def write_json(path: str | os.PathLike, payload: Mapping) -> Path:
    """Write ``payload`` as indented JSON atomically, creating parent folders
    (:func:`rocketid.output.write_json`: NaN and infinity are refused)."""
    return output.write_json(path, payload)


# ---------------------------------------------------------------------------
# Progress and verbosity
# ---------------------------------------------------------------------------


def _verbose(ctx: click.Context | None = None) -> bool:
    ctx = ctx or click.get_current_context(silent=True)
    return bool(ctx is not None and ctx.meta.get(_VERBOSE))


def _interactive() -> bool:
    try:
        return sys.stderr.isatty()
    except (AttributeError, ValueError):
        return False


def status(message: str) -> None:
    """A progress line on stderr, shown on a terminal or with ``--verbose``
    (so that stderr carries only the error line when a script runs rocketid)."""
    if _interactive() or _verbose():
        click.echo(message, err=True)


def progress(iterable: Iterable, *, desc: str, total: int | None = None):
    """A tqdm progress bar on stderr for long loops (hidden unless on a terminal
    or ``--verbose``)."""
    from tqdm import tqdm

    return tqdm(iterable, desc=desc, total=total, file=sys.stderr, disable=not (_interactive() or _verbose()),
                leave=False)


def _set_verbose(ctx: click.Context, param, value):
    if value:
        ctx.meta[_VERBOSE] = True
    return value


def verbose_option(f):
    """``-v/--verbose``: tracebacks instead of one-line errors, and progress lines."""
    return click.option("-v", "--verbose", is_flag=True, expose_value=False, is_eager=True, callback=_set_verbose,
                        help="Show progress and full tracebacks.")(f)


def sigma_option_decl():
    """The ``--sigma`` option: a value, ``NAME=estimate`` or ``estimate``."""
    return click.option("--sigma", "sigmas", multiple=True, type=SigmaValue(), metavar="NAME=VALUE|NAME=estimate|estimate",
                        help="Noise standard deviation of an output (repeatable; default: the model's); "
                             "NAME=estimate estimates it with the parameters, 'estimate' every output's; "
                             "NAME=quantized (or quantized:STEP) sets it to the rounding error STEP/sqrt(12).")


def sigma_column_option_decl():
    """The ``--sigma-column NAME=COLUMN`` option: a column of per-sample sigmas of output NAME."""
    return click.option("--sigma-column", "sigma_columns", multiple=True, type=NameValue(str, "CSV column name"),
                        metavar="NAME=CSVCOL",
                        help="Read the noise standard deviation of output NAME at each sample from column CSVCOL "
                             "(per-sample sigma, repeatable); each sample's residual is weighted by 1/sigma^2.")


def window_option_decl(name: str = "--window"):
    """The flight-window option ``--window T0:T1``."""
    return click.option(name, "window_text", default=None, metavar="T0:T1",
                        help="Fit only the flight window T0:T1 (s; '20:' to the end). A window that starts in "
                             "flight estimates the initial states the data determine (guesses from the data).")


def unmeasured_option_decl():
    """``--unmeasured NAME``: a model output the data do not measure (predicted, not fitted)."""
    return click.option("--unmeasured", "unmeasured", multiple=True, metavar="NAME",
                        help="A model output the data do not measure: predicted, not fitted (repeatable). An "
                             "output without a column is taken as unmeasured anyway when every column of the "
                             "file is read.")


def flight_window(text: str | None, option: str = "--window"):
    """``--window`` text -> ``(T0, T1)`` (NaN for an open end) or None."""
    from .start import parse_window

    if text is None:
        return None
    return parse_window(text, option)


def windowed_inputs(spec: ModelSpec, data: Measurements, guess, window, n_elements, K):
    """Cut the model and the data to ``window`` (:func:`rocketid.start.apply_window`):
    ``(spec, data, guess, mesh, notes)``, the guess extended by the initial states' guesses."""
    from .start import apply_window, window_guess

    if window is None:
        return spec, data, guess, make_mesh(spec, n_elements, K), []
    spec_w, data_w, notes = apply_window(spec, data, window, guess)
    guess_w = window_guess(spec, spec_w, guess)
    return spec_w, data_w, guess_w, make_mesh(spec_w, n_elements, K), notes


def data_options(f):
    """``--column``, ``--time-column``, ``--sigma``, ``--sigma-column``, ``--unmeasured``, ``--window`` (reading
    DATA.csv) and ``--elements``, ``--K`` (the mesh): the options of every command that fits a
    model to a data file."""
    for opt in reversed([
        click.option("--column", "columns", multiple=True, type=NameValue(str, "CSV column name"),
                     metavar="NAME=CSVCOL", help="Read output NAME from column CSVCOL (repeatable)."),
        click.option("--time-column", default="t", show_default=True, help="Name of the time column."),
        sigma_option_decl(),
        sigma_column_option_decl(),
        unmeasured_option_decl(),
        window_option_decl(),
        click.option("--elements", "n_elements", type=click.IntRange(min=1), default=None, metavar="N",
                     help="About N finite elements (default: elements of about 1 s)."),
        click.option("--K", "K", type=click.IntRange(1, MAX_DEGREE), default=4, show_default=True, metavar="K",
                     help=f"Radau collocation points per element (1-{MAX_DEGREE})."),
    ]):
        f = opt(f)
    return f


#: Memory of the built NLP per finite element at K = 4 (MB), and the process's base (MB): measured on
#: RA-66 with ``benchmarks``-style runs of prepare() (272 MB at 5000 elements, 613 MB at 20000).
NLP_MB_PER_ELEMENT, BASE_MB = 0.025, 120.0


def expected_memory_mb(mesh) -> float:
    """Rough memory (MB) of the process once the NLP is built on ``mesh`` (IPOPT needs more)."""
    return BASE_MB + NLP_MB_PER_ELEMENT * mesh.n_elements * (mesh.K + 1) / 5


def mesh_size_warning(spec: ModelSpec, mesh, data: Measurements) -> str | None:
    """A warning when ``mesh`` is far finer than the data resolve: more collocation points
    than distinct sample times and over ten times the default mesh's elements."""
    from .solve import default_mesh

    points = mesh.n_elements * mesh.K
    n_times = np.unique(np.concatenate([c.times for c in data.channels])).size
    default = default_mesh(spec, K=mesh.K).n_elements
    if points <= n_times or mesh.n_elements <= 10 * default:
        return None
    return (f"Warning: {mesh.n_elements} elements x K = {mesh.K} give {points} collocation points for {n_times} "
            f"sample times, far finer than the data resolve (the default mesh has {default} elements). Expect "
            f"about {expected_memory_mb(mesh):.0f} MB to build the NLP, several times that while IPOPT factorizes, "
            "and a long solve; use fewer --elements")


def prepare_verbosely(spec: ModelSpec, data: Measurements, mesh):
    """:func:`rocketid.solve.prepare` with progress lines (code generation, NLP size) and
    :func:`mesh_size_warning` (always shown) before the work."""
    from .codegen import cache_path, generate
    from .solve import prepare

    warning = mesh_size_warning(spec, mesh, data)
    if warning:
        click.echo(warning, err=True)
    if not cache_path(spec).exists():
        status(f"generating the code of model {spec.name!r} (SymPy derivatives printed as NumPy; first use only, "
               "then cached)")
        t0 = time.perf_counter()
        generate(spec)
        status(f"generated the code in {time.perf_counter() - t0:.1f} s")
    status(f"building the NLP on {mesh.describe()} (about {expected_memory_mb(mesh):.0f} MB; the model's code is "
           "generated on first use and cached)")
    t0 = time.perf_counter()
    prepared = prepare(spec, data, mesh=mesh)
    status(f"built the NLP in {time.perf_counter() - t0:.2f} s ({prepared.nlp.n} variables, code "
           f"{'from the cache' if prepared.codegen_cached else 'generated'})")
    return prepared


def fit_inputs(spec: ModelSpec, data_file, *, guesses, columns, time_column, sigmas, n_elements, K,
               unmeasured=(), sigma_columns=()):
    """``(guess, mesh, data)`` from the options of a command that fits ``spec`` to DATA.csv
    (``--guess`` checked against the bounds, :func:`data_options`; the window is applied by
    :func:`windowed_inputs`)."""
    guess = parameter_values(spec, assignments(guesses, "--guess"), "--guess")
    check_guess(spec, guess, where="--guess", error=SettingsError)
    mesh = make_mesh(spec, n_elements, K)
    sigma = sigma_argument(sigmas, spec)
    data = read_data(data_file, spec, time_column=time_column, columns=assignments(columns, "--column"),
                     sigma=given_sigmas(sigma), unmeasured=tuple(unmeasured),
                     sigma_columns=assignments(sigma_columns, "--sigma-column"))
    if isinstance(sigma, Mapping):
        from .data import resolve_quantized
        quantized = {k: v for k, v in sigma.items() if isinstance(v, str) and v.startswith("quantized")}
        if quantized:
            data = data.with_sigma(resolve_quantized(quantized, data))
    return guess, mesh, data


def model_option(f):
    """``--model ra66|ra66m|PATH.py`` (passed to the command as the string ``model``)."""
    return click.option("--model", "model", default="ra66", show_default=True,
                        metavar="|".join(sorted(BUILTIN_MODELS)) + "|PATH.py",
                        help="; ".join(f"{b.name}: {b.description}" for b in BUILTIN_MODELS.values())
                        + "; or a Python file defining build_model().")(f)


# ---------------------------------------------------------------------------
# The group: lazy commands, one-line errors
# ---------------------------------------------------------------------------

#: Extra commands by name -> ``"module:attribute"`` (imported when used).
#: Modules ``rocketid/cli_<name>.py`` defining ``command`` are found without an entry here.
LAZY_COMMANDS: dict[str, str] = {"estimability": "rocketid.commands.estimability:command",
                                  "diagnose": "rocketid.commands.diagnose:command",
                                  "reproduce": "rocketid.commands.reproduce:command"}


def _one_line(text: str) -> str:
    return " ".join(str(text).split())


class Interrupted(KeyboardInterrupt):
    """SIGTERM, raised like Ctrl-C so that the same clean-up runs (exit code 128 + 15)."""

    signum = signal.SIGTERM


#: After the first Ctrl-C (or SIGTERM) a command whose main thread cannot act on it (a long
#: IPOPT factorization holds the interpreter) is ended after this long (s) ...
INTERRUPT_GRACE_S = 5.0
#: ... and one that acts on it (its clean-up runs) after this long.
INTERRUPT_CLEANUP_S = 30.0

# The watchdog process (see _InterruptGuard): argv parent pid, grace, clean-up grace, wake-up fd; the
# message to print on stdin (the last line); signal numbers (0: the main thread acted) on the fd.
_WATCHDOG = r"""
import os, select, signal, sys, time
parent, grace, cleanup, wake = int(sys.argv[1]), float(sys.argv[2]), float(sys.argv[3]), int(sys.argv[4])
signal.signal(signal.SIGINT, signal.SIG_IGN)
signal.signal(signal.SIGTERM, signal.SIG_IGN)
try:
    import ctypes
    ctypes.CDLL(None).prctl(1, 9, 0, 0, 0)
except Exception:
    pass
if os.getppid() != parent:
    sys.exit(0)
message, buf, first, start, acted = "interrupted", b"", None, None, False
inp = sys.stdin.fileno()
while True:
    if first is None:
        timeout = 1.0
    else:
        timeout = max(0.0, start + (cleanup if acted else grace) - time.monotonic())
    ready, _, _ = select.select([inp, wake], [], [], timeout)
    if os.getppid() != parent:
        sys.exit(0)
    if first is not None and not ready and time.monotonic() >= start + (cleanup if acted else grace):
        try:
            os.write(2, ("\nError: " + message + "\n").encode())
            os.kill(parent, first)
            time.sleep(2.0)
            os.kill(parent, signal.SIGKILL)
        except OSError:
            pass
        sys.exit(0)
    if inp in ready:
        data = os.read(inp, 4096)
        if not data:
            sys.exit(0)
        buf += data
        lines = buf.split(b"\n")
        buf = lines[-1]
        if len(lines) > 1 and lines[-2]:
            message = lines[-2].decode()
    if wake in ready:
        for signum in os.read(wake, 64):
            if signum == 0:
                acted = True
            elif signum in (signal.SIGINT, signal.SIGTERM) and first is None:
                first, start = signum, time.monotonic()
"""


def _reset_on_delivery(*signums: int) -> bool:
    """Add ``SA_RESETHAND`` to the handlers of ``signums`` (Linux, glibc's ``struct sigaction``):
    the first delivery resets the signal to its default action, so that a second one ends the
    process even when no Python code can run. False when it cannot be done here."""
    import platform
    if not sys.platform.startswith("linux") or platform.machine() not in ("x86_64", "aarch64"):
        return False
    try:
        import ctypes

        class SigAction(ctypes.Structure):
            _fields_ = [("handler", ctypes.c_void_p), ("mask", ctypes.c_ulong * 16), ("flags", ctypes.c_int),
                        ("restorer", ctypes.c_void_p)]
        libc = ctypes.CDLL(None, use_errno=True)
        for signum in signums:
            act = SigAction()
            if libc.sigaction(signum, None, ctypes.byref(act)) != 0:
                return False
            act.flags |= 0x80000000  # SA_RESETHAND
            if libc.sigaction(signum, ctypes.byref(act), None) != 0:
                return False
        return True
    except (OSError, AttributeError):  # pragma: no cover - no libc sigaction
        return False


class _InterruptGuard:
    """Ctrl-C and SIGTERM while a command runs.

    The first signal raises :class:`KeyboardInterrupt` (SIGTERM: :class:`Interrupted`) in the
    main thread, so that worker pools are shut down and temporary files removed. A signal only
    reaches Python code between bytecodes, and no Python thread runs while a C call holds the
    interpreter (cyipopt holds it through IPOPT, a MUMPS factorization can take minutes). So:

    - the handlers are reset to the default action on their first delivery (``SA_RESETHAND``):
      a second Ctrl-C ends the process at once, as killed by SIGINT (the shell's code 130);
    - a small watchdog process reads the signal wake-up file descriptor (the C-level handler
      writes each signal's number there whatever the main thread does) and, when the command
      has not ended :data:`INTERRUPT_GRACE_S` seconds after the first signal (or
      :data:`INTERRUPT_CLEANUP_S` once its clean-up started), prints the interrupted message
      and sends the signal again, which now ends the process.

    That is safe because every write is atomic (:mod:`rocketid.output`): a temporary file left
    behind is removed by the next write of its target, and worker processes die with their
    parent.
    """

    def __init__(self):
        self.owner = os.getpid()
        self._watchdog = None
        self._read = self._write = -1

    def handler(self, signum, frame):
        if os.getpid() != self.owner:  # a forked worker before it reset its handlers: the parent decides
            if signum == signal.SIGTERM:
                os._exit(128 + int(signum))
            return
        if self._write >= 0:
            try:
                os.write(self._write, b"\0")  # the watchdog: the clean-up runs
            except OSError:
                pass
        raise KeyboardInterrupt() if signum == signal.SIGINT else Interrupted()

    def tell(self, message: str) -> None:
        """The message the watchdog prints if it ends the command."""
        if self._watchdog is not None:
            try:
                self._watchdog.stdin.write(" ".join(message.split()) + "\n")
                self._watchdog.stdin.flush()
            except (OSError, ValueError):  # pragma: no cover - the watchdog ended
                pass

    def _start_watchdog(self) -> None:
        import subprocess
        self._read, self._write = os.pipe()
        os.set_blocking(self._write, False)
        try:
            self._watchdog = subprocess.Popen(
                [sys.executable, "-S", "-E", "-c", _WATCHDOG, str(os.getpid()), str(INTERRUPT_GRACE_S),
                 str(INTERRUPT_CLEANUP_S), str(self._read)], stdin=subprocess.PIPE, pass_fds=(self._read,),
                text=True)
        except OSError:  # pragma: no cover - cannot start a process: Ctrl-C works as before
            self._watchdog = None
        os.close(self._read)
        self._read = -1

    @contextmanager
    def installed(self):
        previous = {s: signal.signal(s, self.handler) for s in (signal.SIGINT, signal.SIGTERM)}
        wakeup = None
        if _reset_on_delivery(signal.SIGINT, signal.SIGTERM):
            self._start_watchdog()
            try:
                wakeup = signal.set_wakeup_fd(self._write, warn_on_full_buffer=False)
            except ValueError:  # pragma: no cover - not the main thread
                wakeup = None
        try:
            yield self
        finally:
            for s, h in previous.items():
                signal.signal(s, h)
            if wakeup is not None:
                signal.set_wakeup_fd(wakeup)
            if self._watchdog is not None:
                try:
                    self._watchdog.stdin.close()  # the watchdog ends
                except OSError:  # pragma: no cover
                    pass
                try:
                    self._watchdog.wait(5.0)
                except Exception:  # pragma: no cover - it will die with this process
                    pass
            if self._write >= 0:
                os.close(self._write)
                self._write = -1


@contextmanager
def _terminate_as_interrupt():
    """While a command runs, SIGTERM raises :class:`Interrupted` in the main thread (worker
    pools are shut down and temporary files removed as on Ctrl-C), and a command that cannot
    act on the signal is ended (see :class:`_InterruptGuard`). Yields the guard (None in a thread)."""
    if threading.current_thread() is not threading.main_thread():
        yield None
        return
    with _InterruptGuard().installed() as guard:
        yield guard


class RocketidGroup(click.Group):
    """A click group that loads commands lazily and turns errors into one line."""

    def _discovered(self) -> dict[str, str]:
        found = {}
        for info in pkgutil.iter_modules(sys.modules[__package__].__path__):
            if info.name.startswith("cli_"):
                found[info.name[4:].replace("_", "-")] = f"{__package__}.{info.name}:command"
        return found

    def list_commands(self, ctx):
        return sorted(set(super().list_commands(ctx)) | set(LAZY_COMMANDS) | set(self._discovered()))

    def get_command(self, ctx, cmd_name):
        cmd = super().get_command(ctx, cmd_name)
        if cmd is not None:
            return cmd
        target = LAZY_COMMANDS.get(cmd_name) or self._discovered().get(cmd_name)
        if target is None:
            return None
        module_name, _, attr = target.partition(":")
        module = importlib.import_module(module_name)
        cmd = getattr(module, attr or "command", None)
        if not isinstance(cmd, click.Command):
            raise click.ClickException(f"{module_name} does not define a click command {attr or 'command'!r}")
        return cmd

    def resolve_command(self, ctx, args):
        name, cmd, rest = super().resolve_command(ctx, args)
        ctx.meta[_COMMAND] = cmd
        guard = ctx.meta.get(_GUARD)
        if guard is not None:
            guard.tell(self._interrupted_message(ctx))
        return name, cmd, rest

    def _interrupted_message(self, ctx) -> str:
        cmd = ctx.meta.get(_COMMAND)
        resumable = cmd is not None and any(p.name == "resume" for p in cmd.params)
        return "interrupted" + ("; continue with --resume" if resumable else "; nothing was written in part")

    def invoke(self, ctx):
        try:
            with _terminate_as_interrupt() as guard:
                ctx.meta[_GUARD] = guard
                return super().invoke(ctx)
        except KeyboardInterrupt as exc:
            self._exit_interrupted(ctx, exc)
        except RocketidError as exc:
            if _verbose(ctx):
                raise
            click.echo(f"Error: {_one_line(exc)}", err=True)
            ctx.exit(EXIT_BAD_INPUT)
        except OSError as exc:  # unreadable or unwritable files named by the user
            if _verbose(ctx):
                raise
            where = f": {exc.filename}" if exc.filename else ""
            click.echo(f"Error: {_one_line(exc.strerror or exc)}{where}", err=True)
            ctx.exit(EXIT_BAD_INPUT)
        except click.UsageError as exc:
            if _verbose(ctx):
                raise
            where = exc.ctx.command_path if exc.ctx is not None else ctx.command_path
            click.echo(f"Error: {_one_line(exc.format_message())} (see '{where} --help')", err=True)
            ctx.exit(exc.exit_code)
        except RuntimeError as exc:
            # an interrupt that arrived inside a class body being created comes back wrapped (Python 3.11
            # re-raises an error of ``__set_name__`` as RuntimeError: a Ctrl-C during matplotlib's import)
            cause = _interrupt_in(exc)
            if cause is None:
                raise
            self._exit_interrupted(ctx, cause)

    def _exit_interrupted(self, ctx, exc: KeyboardInterrupt) -> None:
        signum = getattr(exc, "signum", signal.SIGINT)
        click.echo(f"\nError: {self._interrupted_message(ctx)}", err=True)
        ctx.exit(128 + int(signum))


def _interrupt_in(exc: BaseException) -> KeyboardInterrupt | None:
    """The interrupt in ``exc``'s chain of causes, or None."""
    seen = set()
    while exc is not None and id(exc) not in seen:
        if isinstance(exc, KeyboardInterrupt):
            return exc
        seen.add(id(exc))
        exc = exc.__cause__ or exc.__context__
    return None


@click.group(cls=RocketidGroup, context_settings={"help_option_names": ["-h", "--help"]})
@click.version_option(package_name="rocketid")
@verbose_option
def main():
    """rocketid: aerodynamic coefficients of launch vehicles from trajectory data.

    Run `rocketid COMMAND --help` for a command's options. Exit codes: 0 success,
    1 the solver did not converge (results still written), 2 bad input,
    130 interrupted (Ctrl-C), 143 terminated (SIGTERM).
    """


# ---------------------------------------------------------------------------
# rocketid simulate
# ---------------------------------------------------------------------------


@main.command("simulate")
@click.option("--out", "out", required=True, type=click.Path(dir_okay=False), metavar="DATA.csv",
              help="CSV file to write (columns t and one per output).")
@model_option
@click.option("--seed", default=0, show_default=True, type=click.IntRange(min=0),
              help="Seed of the measurement noise (a non-negative integer).")
@click.option("--no-noise", is_flag=True, help="Write the noise-free outputs.")
@click.option("--param", "params", multiple=True, type=NameValue(float), metavar="NAME=VALUE",
              help="Override a true parameter value (repeatable), e.g. --param CL=0.12.")
@verbose_option
def simulate_command(out, model, seed, no_noise, params):
    """Synthetic measurements of a model at its true parameters.

    RA-66 (the default) is integrated at CD = 0.5, CL = 0.1 and sampled at
    t = 0.01 k s, k = 1..6600, with N(0, 1) noise on x, h and v.
    """
    from .simulate import simulate_measurements

    output.check_file(out, "--out")
    src = load_model(model)
    spec = src.spec
    overrides = assignments(params, "--param")
    p = parameter_values(spec, overrides, "--param", base=src.truth)
    for name, value in overrides.items():  # a truth the estimate could never reach is a mistake
        i = spec.parameter_names.index(name)
        lo, hi = spec.lower[i], spec.upper[i]
        if not (np.isfinite(value) and lo <= value <= hi):
            raise SettingsError(f"--param {name}={value:g} lies outside the bounds of {name} in model "
                                f"{spec.name!r}, [{lo:g}, {hi:g}]; give a value within them")
    t0 = time.perf_counter()
    data = simulate_measurements(spec, p, src.times, seed=seed, noise=not no_noise)
    status(f"simulated {spec.name} in {time.perf_counter() - t0:.2f} s")
    path = data.to_csv(out)  # atomic: an interrupted write leaves the previous file or none
    noise = "noise-free" if no_noise else f"noise seed {seed}"
    click.echo(f"wrote {data.channels[0].times.size} samples of {', '.join(data.names)} ({noise}) to {path}")


# ---------------------------------------------------------------------------
# rocketid estimate
# ---------------------------------------------------------------------------


def flight_labels(paths: Sequence[str]) -> list[str]:
    """Labels of several data files: their names without the extension (made unique; a flight
    given one file per channel, ``NAME=FILE,...``, by its first file)."""
    stems = [Path(str(p).split(",")[0].partition("=")[2] if _names_channel_files(str(p)) else p).stem or "flight"
             for p in paths]
    return [s if stems.count(s) == 1 else f"{s}_{i + 1}" for i, s in enumerate(stems)]


def read_flights(paths: Sequence[str], spec: ModelSpec, *, columns, time_column, sigmas, n_elements, K,
                 unmeasured=(), window=None, sigma_columns=()):
    """:class:`rocketid.joint.Flight` values for several data files fitted with one model
    (each cut to ``window`` with its own initial states, :func:`windowed_inputs`)."""
    from .joint import Flight
    from .solve import check_determined

    flights = []
    for label, path in zip(flight_labels(paths), paths):
        data = read_data(path, spec, time_column=time_column, columns=assignments(columns, "--column"),
                         sigma=given_sigmas(sigma_argument(sigmas, spec)), unmeasured=tuple(unmeasured),
                         sigma_columns=assignments(sigma_columns, "--sigma-column"))
        spec_f, data, _, mesh, _ = windowed_inputs(spec, data, spec.guess, window, n_elements, K)
        check_determined(spec_f, data)
        flights.append(Flight(label, spec_f, data, mesh))
    return flights


@main.command("estimate")
@click.argument("data_files", metavar="DATA.csv...", nargs=-1, required=True, type=click.Path(dir_okay=False))
@model_option
@data_options
@click.option("--guess", "guesses", multiple=True, type=NameValue(float), metavar="NAME=VALUE",
              help="Initial guess of a parameter (repeatable; default: the model's p0).")
@click.option("--per-flight", "per_flight", multiple=True, metavar="NAME",
              help="With several data files: a parameter each flight estimates for itself (repeatable; the others "
                   "are shared, free initial states are per flight always).")
@click.option("--ipopt", "ipopt", multiple=True, type=NameValue(str, "value"), metavar="NAME=VALUE",
              help="IPOPT option (repeatable), e.g. --ipopt max_iter=200.")
@click.option("--errors", "errors", type=click.Choice(["white", "coloured"]), default="white", show_default=True,
              help="Standard errors for white residuals, or corrected for residuals correlated in time "
                   "(telemetry whose errors last longer than a sample: a broadcast readout, a filtered sensor).")
@click.option("--out", "out", type=click.Path(dir_okay=False), default=None, metavar="FIT.json",
              help="Write the result as JSON.")
@verbose_option
def estimate_command(data_files, model, columns, time_column, sigmas, sigma_columns, unmeasured, window_text,
                     n_elements, K, guesses, per_flight, ipopt, errors, out):
    """Estimate the model's parameters from measurements in DATA.csv.

    DATA.csv has a time column and one column per measured output (an empty cell: not
    measured then). A flight measured in one file per channel is one argument
    NAME=FILE[,NAME=FILE...], e.g. h=altimeter.csv,v=speed.csv.

    Prints the summary; with --out writes FIT.json (success, parameters,
    objective, iterations, timings, ...). Exit code 1 when IPOPT did not
    converge (the JSON is still written).

    Several files are several flights of one vehicle fitted jointly: the
    parameters are shared except those named by --per-flight (and free initial
    states), which FIT.json names NAME[flight], the flight being the file's name.
    With --sigma estimate each flight's noise levels are estimated separately.
    """
    from dataclasses import replace

    from .solve import check_determined, estimate

    options = ipopt_options(ipopt)
    window = flight_window(window_text)
    if out is not None:
        output.check_file(out, "--out")
    src = load_model(model)
    spec = src.spec
    sigma = sigma_argument(sigmas, spec)
    if len(data_files) > 1:
        from .joint import joint_estimate

        guess = assignments(guesses, "--guess")
        flights = read_flights(data_files, spec, columns=columns, time_column=time_column, sigmas=sigmas,
                               n_elements=n_elements, K=K, unmeasured=unmeasured, window=window,
                               sigma_columns=sigma_columns)
        status(f"fitting {len(flights)} flights jointly")
        result = joint_estimate(flights, per_flight=per_flight, guess=guess, options=options, sigma=sigma)
        click.echo(result.summary().text())
        payload = result.to_dict()
        if errors == "coloured" and result.success:
            payload["standard_errors_coloured"] = _print_joint_coloured(result)
        if result.success:
            payload["wild_points"] = {fl.label: _print_wild_points(fit, fl.label)
                                      for fl, fit in zip(flights, result.flights)}
            payload["correlated_noise"] = {fl.label: _print_correlated(fit, errors, fl.label)
                                           for fl, fit in zip(flights, result.flights)}
        payload["std_err_residuals"] = errors
        if out is not None:
            write_json(out, payload)
        if not result.success:
            click.get_current_context().exit(EXIT_NOT_CONVERGED)
        return
    if per_flight:
        raise SettingsError("--per-flight needs several data files (one per flight)")
    data_file = data_files[0]
    guess, mesh, data = fit_inputs(spec, data_file, guesses=guesses, columns=columns, time_column=time_column,
                                   sigmas=sigmas, n_elements=n_elements, K=K, unmeasured=unmeasured,
                                   sigma_columns=sigma_columns)
    status(f"read {data.n_samples} values of {', '.join(data.names)} from {data_file}")
    spec, data, guess, mesh, wnotes = windowed_inputs(spec, data, guess, window, n_elements, K)
    check_determined(spec, data)
    prepared = prepare_verbosely(spec, data, mesh)
    status("solving with IPOPT")
    result = estimate(spec, data, guess=guess, prepared=prepared, options=options, sigma=sigma)
    if wnotes:
        result = replace(result, notes=tuple(wnotes) + result.notes)
    click.echo(result.summary().text())
    payload = result.to_dict()
    if result.success:
        payload["std_err"] = _print_standard_errors(result, coloured=errors == "coloured")
        payload["std_err_residuals"] = errors
        payload["wild_points"] = _print_wild_points(result)
        payload["correlated_noise"] = _print_correlated(result, errors)
    if out is not None:
        path = write_json(out, payload)
        status(f"wrote {path}")
    if not result.success or result.sanity:
        click.get_current_context().exit(EXIT_NOT_CONVERGED)


def _print_wild_points(result, flight: str = "") -> list:
    """Warn of samples the fit cannot follow (:mod:`rocketid.diagnostics.wild`); the fit keeps them. Returns
    them for FIT.json (empty when there are none). ``flight`` names the flight of a joint fit."""
    from .diagnostics.wild import find_wild_points

    wild = find_wild_points(result, action="keep")
    if wild:
        click.echo(f"\nWarning: {f'flight {flight}: ' if flight else ''}{len(wild)} sample(s) look like wild points, "
                   f"isolated and more than {wild.threshold:.2f} robust standard deviations off their neighbours: "
                   f"{wild.listed()}. The fit keeps them; `rocketid diagnose` drops them, or remove those rows to "
                   "fit without them.")
    return [p.to_dict() for p in wild.points]


def _print_correlated(result, errors: str, flight: str = "") -> dict:
    """Warn of channels whose errors look correlated in time (:mod:`rocketid.diagnostics.correlated`) when the
    standard errors printed assume they are not. Returns the measurement for FIT.json."""
    from .diagnostics.correlated import find_correlated_noise

    corr = find_correlated_noise(result, action="keep")
    if corr and errors != "coloured":
        listed = "; ".join(c.text() for c in corr.correlated)
        click.echo(f"\nWarning: {f'flight {flight}: ' if flight else ''}the errors look correlated in time: {listed}. "
                   "The standard errors above assume independent errors and are too small; --errors coloured "
                   "corrects them ([Residuals correlated in time] in the telemetry guide).")
    return corr.to_dict()


def _print_joint_coloured(result) -> dict:
    """Print a joint fit's standard errors corrected for coloured residuals beside the white ones;
    ``{name: std err}`` for FIT.json (empty, with the reason printed, when they cannot be formed)."""
    try:
        white, col = result.standard_errors, result.coloured_standard_errors
    except RocketidError as exc:
        click.echo(f"\nCorrected standard errors: not available ({_one_line(exc)})")
        return {}
    rows = [(n, float(v), float(w), float(c)) for n, v, w, c in zip(result.names, result.theta, white, col)]
    table = Table(("name", "estimate", "std error (white)", "std error (coloured)"), rows, (None, ".6g", ".3g", ".3g"))
    click.echo("")
    click.echo(Summary("Standard errors corrected for coloured residuals (sandwich H^-1 B H^-1, each flight's "
                       "score with Bartlett weights over its channels' lags; flights independent)",
                       (Section("", (table,)),), (), rule=False).text())
    return {str(n): output.finite_or_none(float(c)) for n, c in zip(result.names, col)}


def _print_standard_errors(result, coloured: bool = False) -> dict:
    """Print the estimates' standard errors and 95 % intervals (from the reduced Hessian at the
    estimate, with the sigmas of the fit; ``coloured``: corrected for residuals correlated in time);
    ``{name: std err}`` for FIT.json, empty when they cannot be formed (the reason is printed)."""
    from .estimability import uncertainty

    try:
        unc = uncertainty(result, coloured=coloured)
    except RocketidError as exc:
        click.echo(f"\nStandard errors: not available ({_one_line(exc)})")
        return {}
    click.echo("")
    click.echo(unc.summary().text())
    return {str(n): output.finite_or_none(float(s)) for n, s in zip(unc.parameter_names, unc.standard_errors)}


if __name__ == "__main__":  # pragma: no cover
    main()
