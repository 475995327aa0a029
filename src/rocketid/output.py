"""Output files: every write is atomic, every output location is checked first.

Every file rocketid writes (CSV, JSON, reports, tables, figures, checkpoints)
goes through this module. A write goes to a temporary file in the target's
folder (``.NAME.<pid>.tmp``), is flushed and fsynced, and then renamed over
the target with :func:`os.replace`, so an interrupted or failed command
leaves the previous file or none, never a partial one. A temporary file left
by a process that was killed (``SIGKILL`` gives it no chance to clean up) is
removed when the same target is next checked (:func:`check_file`) or written.

:func:`check_file` and :func:`check_folder` check an output location
(writable, not a file where a folder is needed and not a folder where a file
is needed) before any work starts; :func:`folder_lock` keeps two runs out of
one output folder.

JSON written here refuses NaN and infinity (they are not JSON): callers write
``null`` for a missing number and say why.

:func:`environment` names what made a result -- rocketid's version and the numerical stack's
(NumPy, SciPy, SymPy, cyipopt and the Ipopt it links): reports and study tables record it, as a
diagnosis can end elsewhere with another release of the stack (a refit's optimum moves with the
linear algebra's rounding).
"""

from __future__ import annotations

import contextlib
import csv
import io
import json
import math
import os
import re
from pathlib import Path
from typing import Any, Iterable, Iterator, Sequence

from .errors import SettingsError

__all__ = ["atomic_open", "write_text", "write_bytes", "write_json", "write_csv", "save_figure", "new_axes", "figure_of",
           "plot_target", "check_file",
           "check_folder", "folder_lock", "remove_stale_tree", "finite_or_none", "nulls_for_non_finite", "LOCK_NAME",
           "environment", "environment_line"]

#: The lock file :func:`folder_lock` keeps in a folder while a run writes there.
LOCK_NAME = ".rocketid.lock"


def environment() -> dict[str, str]:
    """The versions a result depends on: ``python``, ``machine``, ``rocketid``, ``numpy``, ``scipy``, ``sympy``,
    ``cyipopt`` (the distribution installed: ``cyipopt`` or ``cyipopt-wheels``) and ``ipopt`` (the Ipopt it
    links); ``"?"`` for one that cannot be read.

    Examples
    --------
    >>> env = environment()
    >>> sorted(env) == ["cyipopt", "ipopt", "machine", "numpy", "python", "rocketid", "scipy", "sympy"]
    True
    """
    import platform
    from importlib import metadata

    def version(*dists: str) -> str:
        for dist in dists:
            try:
                return metadata.version(dist)
            except metadata.PackageNotFoundError:
                continue
        return "?"

    try:
        import cyipopt
        ipopt = ".".join(str(v) for v in cyipopt.IPOPT_VERSION)
    except (ImportError, AttributeError, TypeError):
        ipopt = "?"
    return {"python": platform.python_version(), "machine": platform.machine(),
            "rocketid": version("rocketid"), "numpy": version("numpy"), "scipy": version("scipy"),
            "sympy": version("sympy"), "cyipopt": version("cyipopt-wheels", "cyipopt"), "ipopt": ipopt}


def environment_line(env: dict | None = None) -> str:
    """:func:`environment` (or ``env``, one stored with a result) in one line: ``numpy 2.4.6, scipy 1.17.1, ...``."""
    env = environment() if env is None else env
    keys = ("rocketid", "numpy", "scipy", "sympy", "cyipopt", "ipopt", "python", "machine")
    return ", ".join(f"{k} {env[k]}" for k in keys if k in env)


def _fail(path: Path, exc: OSError, what: str = "write") -> SettingsError:
    reason = exc.strerror or str(exc)
    return SettingsError(f"cannot {what} {str(path)!r}: {reason}; choose another output location")


def _pid_alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:  # pragma: no cover - another user's process
        return True
    return True


_TMP = re.compile(r"^\.(?P<name>.+)\.(?P<pid>\d+)\.tmp$")


def _remove_stale(path: Path) -> None:
    """Remove ``.NAME.<pid>.tmp`` files of ``path`` left by processes that no longer run."""
    try:
        entries = list(path.parent.iterdir())
    except OSError:
        return
    for entry in entries:
        m = _TMP.match(entry.name)
        if m and m["name"] == path.name:
            _unlink_if_dead(entry, int(m["pid"]))


def _unlink_if_dead(entry: Path, pid: int) -> None:
    if pid != os.getpid() and not _pid_alive(pid):
        with contextlib.suppress(OSError):
            entry.unlink()


def remove_stale_tree(folder: str | os.PathLike) -> None:
    """Remove every ``.NAME.<pid>.tmp`` under ``folder`` whose writer no longer runs.

    A process killed with ``SIGKILL`` (or a worker killed with its parent)
    can leave its temporary file; the next run that takes the folder's lock
    sweeps them, so a resumed run leaves a clean folder.
    """
    for entry in Path(folder).rglob(".*.tmp"):
        m = _TMP.match(entry.name)
        if m:
            _unlink_if_dead(entry, int(m["pid"]))


def _make_parent(path: Path) -> None:
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        check_file(path, "output")  # names the part of the path that is a file
        raise _fail(path, exc, "create the folder of") from None


@contextlib.contextmanager
def atomic_open(path: str | os.PathLike, mode: str = "w", **kwargs) -> Iterator[Any]:
    """Open a temporary file that replaces ``path`` when the block ends without error.

    Parameters
    ----------
    path : path-like
        The target; its folder is created if needed.
    mode : {"w", "wb"}
    **kwargs
        Passed to :func:`open` (``newline=""``, ``encoding=``).

    Raises
    ------
    SettingsError
        The folder cannot be created or the file cannot be written.
    """
    if mode not in ("w", "wb"):
        raise ValueError(f"atomic_open writes whole files: mode 'w' or 'wb', not {mode!r}")
    path = Path(path)
    _make_parent(path)
    _remove_stale(path)
    tmp = path.parent / f".{path.name}.{os.getpid()}.tmp"
    if mode == "w":
        kwargs.setdefault("encoding", "utf-8")
    try:
        fh = open(tmp, mode, **kwargs)
    except OSError as exc:
        raise _fail(path, exc) from None
    try:
        with fh:
            yield fh
            fh.flush()
            os.fsync(fh.fileno())
        os.replace(tmp, path)
    except BaseException as exc:
        with contextlib.suppress(OSError):
            os.unlink(tmp)
        if isinstance(exc, OSError) and not isinstance(exc, SettingsError):
            raise _fail(path, exc) from None
        raise


def write_bytes(path: str | os.PathLike, data: bytes) -> Path:
    """Write ``data`` to ``path`` atomically."""
    with atomic_open(path, "wb") as fh:
        fh.write(data)
    return Path(path)


def write_text(path: str | os.PathLike, text: str) -> Path:
    """Write ``text`` (UTF-8) to ``path`` atomically."""
    with atomic_open(path, "w") as fh:
        fh.write(text)
    return Path(path)


def _non_finite(obj: Any, where: str = "") -> str | None:
    """The key path of the first NaN or infinity in ``obj`` (None if there is none)."""
    if isinstance(obj, float):
        return None if math.isfinite(obj) else (where or "(top level)")
    if isinstance(obj, dict):
        for k, v in obj.items():
            found = _non_finite(v, f"{where}.{k}" if where else str(k))
            if found:
                return found
    elif isinstance(obj, (list, tuple)):
        for i, v in enumerate(obj):
            found = _non_finite(v, f"{where}[{i}]")
            if found:
                return found
    return None


def finite_or_none(value: float) -> float | None:
    """``float(value)``, or None (JSON ``null``) for NaN and infinity."""
    value = float(value)
    return value if math.isfinite(value) else None


def nulls_for_non_finite(obj: Any) -> Any:
    """``obj`` with every NaN or infinite float (NumPy's too) replaced by None, for
    payloads where ``null`` means "no value" (a failed run, an undefined ratio)."""
    if isinstance(obj, dict):
        return {k: nulls_for_non_finite(v) for k, v in obj.items()}
    if isinstance(obj, (list, tuple)):
        return [nulls_for_non_finite(v) for v in obj]
    if isinstance(obj, float) or type(obj).__name__.startswith("float"):
        try:
            return finite_or_none(obj)
        except (TypeError, ValueError):
            return obj
    return obj


def write_json(path: str | os.PathLike, payload: Any, *, indent: int | None = 2, default=None) -> Path:
    """Write ``payload`` as JSON atomically (with a final newline).

    Raises
    ------
    ValueError
        ``payload`` holds NaN or infinity (not JSON; the message names the key):
        write ``None`` (``finite_or_none``) and say why instead.
    """
    try:
        text = json.dumps(payload, indent=indent, allow_nan=False, default=default)
    except ValueError:
        where = _non_finite(json.loads(json.dumps(payload, default=default)))
        raise ValueError(f"refusing to write {str(path)!r}: the value at {where} is not finite (NaN or infinity is "
                         "not JSON)") from None
    return write_text(path, text + "\n")


def write_csv(path: str | os.PathLike, header: Sequence[str], rows: Iterable[Sequence[Any]]) -> Path:
    """Write a CSV file (a header row, then ``rows``) atomically."""
    with atomic_open(path, "w", newline="") as fh:
        w = csv.writer(fh)
        w.writerow(header)
        w.writerows(rows)
    return Path(path)


def save_figure(fig: Any, path: str | os.PathLike, **kwargs) -> Path:
    """``fig.savefig`` to ``path`` atomically (the format from the suffix unless given)."""
    path = Path(path)
    kwargs.setdefault("format", path.suffix.lstrip(".").lower() or "png")
    buf = io.BytesIO()
    fig.savefig(buf, **kwargs)
    return write_bytes(path, buf.getvalue())


def new_axes(figsize: tuple, *args, **kwargs):
    """The axes of a new figure that pyplot does not manage (no backend is chosen or switched):
    ``Figure(figsize=figsize).subplots(*args, **kwargs)``."""
    from matplotlib.figure import Figure
    return Figure(figsize=figsize).subplots(*args, **kwargs)


def figure_of(drawn: Any):
    """The figure of what a plot returned: a figure, an Axes, or an array of Axes (None for None)."""
    if drawn is None or hasattr(drawn, "savefig"):
        return drawn
    if hasattr(drawn, "figure"):
        return drawn.figure
    import numpy as np
    return np.asarray(drawn, dtype=object).flat[0].figure


def plot_target(ax: Any, path: Any) -> tuple:
    """``(ax, path)`` of a plot method called as ``plot(ax=None, *, path=None)``: a path given in the
    axes' place (the older ``plot("figure.png")``) is taken as the path."""
    if isinstance(ax, (str, os.PathLike)):
        if path is not None:
            raise SettingsError(f"a plot got two paths, {ax!r} and {path!r}; pass the axes first, or path= alone")
        return None, ax
    return ax, path


# ---------------------------------------------------------------------------
# Output locations, checked before the work
# ---------------------------------------------------------------------------


def _nearest_existing(path: Path, option: str) -> Path:
    """The nearest existing ancestor of ``path``; every existing ancestor must be a folder."""
    for parent in path.absolute().parents:
        if parent.exists():
            if not parent.is_dir():
                raise SettingsError(f"{option} {str(path)!r}: {str(parent)!r} is a file, not a folder; "
                                    "choose another location")
            return parent
    return Path(path.absolute().anchor)  # pragma: no cover - the root exists


def check_file(path: str | os.PathLike, option: str = "--out") -> Path:
    """Check that ``path`` can be written as a file (before any work starts).

    Temporary files of ``path`` left by writers that no longer run (a command
    killed with ``SIGKILL`` while it wrote ``path``) are removed.

    Raises
    ------
    SettingsError
        ``path`` is a folder, a part of its folder path is a file, or the
        folder (or the nearest one that exists) is not writable.
    """
    path = Path(path)
    if path.is_dir():
        raise SettingsError(f"{option} {str(path)!r} is a folder; give a file name")
    if path.exists() and not os.access(path, os.W_OK):
        raise SettingsError(f"{option} {str(path)!r} exists and is not writable; choose another file")
    folder = _nearest_existing(path, option)
    if not os.access(folder, os.W_OK | os.X_OK):
        raise SettingsError(f"{option} {str(path)!r}: the folder {str(folder)!r} is not writable; "
                            "choose another location")
    _remove_stale(path)  # a killed writer's .NAME.<pid>.tmp of this target goes now, not at the next write
    return path


def check_folder(path: str | os.PathLike, option: str = "--out") -> Path:
    """Check that ``path`` can be used as an output folder (before any work starts).

    Raises
    ------
    SettingsError
        ``path`` or a part of it is a file, or the folder (or the nearest one
        that exists) is not writable.
    """
    path = Path(path)
    if path.exists() and not path.is_dir():
        raise SettingsError(f"{option} {str(path)!r} is a file, not a folder; give a folder")
    folder = path if path.is_dir() else _nearest_existing(path, option)
    if not os.access(folder, os.W_OK | os.X_OK):
        raise SettingsError(f"{option} {str(path)!r}: the folder {str(folder)!r} is not writable; "
                            "choose another location")
    return path


@contextlib.contextmanager
def folder_lock(folder: str | os.PathLike, option: str = "--out") -> Iterator[Path]:
    """Hold ``FOLDER/.rocketid.lock`` while the block runs (the folder is created).

    The lock is an advisory ``flock`` on the file, which also holds this
    process's PID; the operating system releases it when the process ends,
    however it ends, so a killed run never leaves a folder locked. Once the
    lock is held, temporary files left in the folder by killed writers are
    removed (:func:`remove_stale_tree`).

    Raises
    ------
    SettingsError
        Another process holds the lock (the message gives its PID).
    """
    import fcntl

    folder = check_folder(folder, option)
    try:
        folder.mkdir(parents=True, exist_ok=True)
    except OSError as exc:
        raise _fail(folder, exc, "create the folder") from None
    path = folder / LOCK_NAME
    while True:
        try:
            fd = os.open(path, os.O_RDWR | os.O_CREAT, 0o644)
        except OSError as exc:
            raise _fail(path, exc, "create the lock file") from None
        try:
            fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except BlockingIOError:
            try:
                holder = os.read(fd, 64).decode(errors="replace").strip() or "unknown"
            finally:
                os.close(fd)
            raise SettingsError(f"{option} {str(folder)!r} is in use by another rocketid run (PID {holder}); wait "
                                "for it to finish or choose another output folder") from None
        # the holder before us may have removed the file between our open and our lock: lock the file on disk
        try:
            same = os.fstat(fd).st_ino == os.stat(path).st_ino
        except FileNotFoundError:
            same = False
        if same:
            break
        os.close(fd)
    try:
        os.ftruncate(fd, 0)
        os.write(fd, f"{os.getpid()}\n".encode())
        remove_stale_tree(folder)  # only now: no other run can be writing here
        yield folder
    finally:
        with contextlib.suppress(OSError):
            os.unlink(path)
        os.close(fd)
