"""The state of one run of the sampling algorithm, and its checkpoint file.

After every processed batch the coordinator writes the run's state to
``DIR/checkpoints/run_<seed>.json`` atomically (a temporary file in the same
folder, flushed and fsynced, then ``os.replace``), so a run killed at any
moment leaves either the previous or the new checkpoint, never a torn one.
Because a draw's outcome is a pure function of ``(seed, draw)`` and the
problem, a resumed run continues at the first unprocessed draw and ends
exactly where an uninterrupted run would.

File format (JSON, version 1)::

    {"version": 1, "token": <problem hash>, "settings": {...}, "n_iter": ...,
     "seed": s, "draws": <processed>, "since": <draws since the last improvement>,
     "stopped_by": null | "n_iter" | "max_draws",
     "best": <DrawOutcome> | null, "failures": [[draw, status, message], ...],
     "history": [eta of draw 1, 2, ... (null: failed)], "improvements": [draw, ...],
     "solve_s": <summed draw wall time>, "n_retried": ..., "iterations": <summed IPOPT iterations>}
"""

from __future__ import annotations

import json
import math
import os
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from ..errors import SettingsError
from ..output import write_json
from .worker import DrawOutcome

__all__ = ["RunState", "checkpoint_path", "write_checkpoint", "read_checkpoint", "checkpoint_problem",
           "CHECKPOINT_VERSION"]

CHECKPOINT_VERSION = 1


@dataclass
class RunState:
    """Mutable state of one run inside the coordinator (the result types are frozen).

    Attributes
    ----------
    seed : int
    draws : int
        Draws processed, in order (draws 1 .. ``draws``).
    since : int
        Draws in a row, up to now, that did not improve eta (failed ones included).
    best : DrawOutcome or None
    failures : list of (draw, status, message)
    history : list of float
        eta of every processed draw (NaN: failed).
    improvements : list of int
        Draws that improved eta.
    stopped_by : str or None
        ``"n_iter"`` (the rule) or ``"max_draws"`` (the cap).
    solve_s : float
    n_retried : int
    iterations : int
        IPOPT iterations summed over the processed draws.
    resumed_from : int
        Draws loaded from a checkpoint (0 for a fresh run).
    """

    seed: int
    draws: int = 0
    since: int = 0
    best: DrawOutcome | None = None
    failures: list = field(default_factory=list)
    history: list = field(default_factory=list)
    improvements: list = field(default_factory=list)
    stopped_by: str | None = None
    solve_s: float = 0.0
    n_retried: int = 0
    iterations: int = 0
    resumed_from: int = 0

    @property
    def next_draw(self) -> int:
        return self.draws + 1

    def process(self, outcome: DrawOutcome, n_iter: int, max_draws: int | None) -> None:
        """Steps 7-10 for the next draw, in order."""
        if outcome.draw != self.next_draw or outcome.seed != self.seed:
            raise RuntimeError(f"internal error: run {self.seed} expected draw {self.next_draw}, got "
                               f"{outcome.seed}/{outcome.draw}")
        self.draws += 1
        self.solve_s += outcome.solve_s
        self.n_retried += int(outcome.retried)
        self.iterations += int(outcome.iterations)
        if not outcome.success:
            self.failures.append((outcome.draw, outcome.status, outcome.message))
            self.history.append(math.nan)
            self.since += 1
        else:
            self.history.append(outcome.eta)
            if self.best is None or outcome.eta < self.best.eta:
                self.best = outcome
                self.improvements.append(outcome.draw)
                self.since = 0
            else:
                self.since += 1
        if self.since >= n_iter:
            self.stopped_by = "n_iter"
        elif max_draws is not None and self.draws >= max_draws:
            self.stopped_by = "max_draws"

    def certain_end(self, n_iter: int, max_draws: int | None) -> int:
        """One past the last draw that is certainly needed: with no improvement
        from now on the run stops at draw ``draws + n_iter - since``."""
        end = self.draws + (n_iter - self.since) + 1
        if max_draws is not None:
            end = min(end, max_draws + 1)
        return end

    def to_dict(self) -> dict:
        return {"seed": self.seed, "draws": self.draws, "since": self.since, "stopped_by": self.stopped_by,
                "best": None if self.best is None else self.best.to_dict(),
                "failures": [list(f) for f in self.failures],
                "history": [v if math.isfinite(v) else None for v in self.history],
                "improvements": list(self.improvements), "solve_s": self.solve_s, "n_retried": self.n_retried,
                "iterations": self.iterations}

    @classmethod
    def from_dict(cls, d: dict) -> "RunState":
        return cls(seed=int(d["seed"]), draws=int(d["draws"]), since=int(d["since"]),
                   best=None if d["best"] is None else DrawOutcome.from_dict(d["best"]),
                   failures=[tuple(f) for f in d["failures"]],
                   history=[math.nan if v is None else float(v) for v in d["history"]],
                   improvements=[int(k) for k in d["improvements"]], stopped_by=d.get("stopped_by"),
                   solve_s=float(d.get("solve_s", 0.0)), n_retried=int(d.get("n_retried", 0)),
                   iterations=int(d.get("iterations", 0)), resumed_from=int(d["draws"]))

    def replay_max_since(self) -> int:
        """The longest stretch of non-improving draws in the history (to check
        that a smaller n_iter would not have stopped the run earlier)."""
        best, since, longest = math.inf, 0, 0
        for v in self.history:
            if math.isfinite(v) and v < best:
                best, since = v, 0
            else:
                since += 1
                longest = max(longest, since)
        return longest


def _is_int(v) -> bool:
    return isinstance(v, int) and not isinstance(v, bool)


def _is_num(v) -> bool:
    return isinstance(v, (int, float)) and not isinstance(v, bool) and math.isfinite(v)


def checkpoint_problem(d: object, seed: int) -> str | None:
    """What is wrong with a checkpoint's content as a whole (None: a consistent run state).

    Every field is checked for its type, and the fields against each other:
    the history has one entry per draw, failures are exactly its nulls,
    improvements are the draws where the running best fell, the best draw is
    the last of them with the history's least eta, and ``since`` counts the
    draws after it.
    """
    if not isinstance(d, dict):
        return "not a JSON object"
    need = {"n_iter": _is_int, "seed": _is_int, "draws": _is_int, "since": _is_int, "failures": list.__instancecheck__,
            "history": list.__instancecheck__, "improvements": list.__instancecheck__, "best": lambda v: True}
    for key, ok in need.items():
        if key not in d:
            return f"the field {key!r} is missing"
        if not ok(d[key]):
            return f"the field {key!r} has the wrong type ({type(d[key]).__name__})"
    for key, ok in (("solve_s", _is_num), ("n_retried", _is_int), ("iterations", _is_int)):
        if key in d and not ok(d[key]):
            return f"the field {key!r} has the wrong type ({type(d[key]).__name__})"
    if d.get("stopped_by") not in (None, "n_iter", "max_draws"):
        return f"stopped_by is {d.get('stopped_by')!r}"
    if d["seed"] != seed:
        return f"it holds run {d['seed']}, not {seed}"
    draws, history = d["draws"], d["history"]
    if d["n_iter"] < 1 or draws < 0 or not 0 <= d["since"] <= draws:
        return f"n_iter {d['n_iter']}, draws {draws} and since {d['since']} are out of range"
    if len(history) != draws:
        return f"{len(history)} history entries for {draws} draws"
    if any(v is not None and not _is_num(v) for v in history):
        return "the history holds values that are neither numbers nor null"
    failed = [k for k, v in enumerate(history, 1) if v is None]
    fails = d["failures"]
    if (any(not (isinstance(f, list) and len(f) == 3 and _is_int(f[0])) for f in fails)
            or [f[0] for f in fails] != failed):
        return "the failures do not match the failed (null) draws of the history"
    best_eta, improvements = math.inf, []
    for k, v in enumerate(history, 1):
        if v is not None and v < best_eta:
            best_eta = v
            improvements.append(k)
    if d["improvements"] != improvements:
        return "the improvements do not match the history"
    best = d["best"]
    if not improvements:
        if best is not None:
            return "a best draw in a run with no successful draw"
        since = draws
    else:
        if not isinstance(best, dict):
            return "the best draw is missing"
        try:
            outcome = DrawOutcome.from_dict(best)
        except (KeyError, TypeError, ValueError) as exc:
            return f"the best draw is malformed ({type(exc).__name__}: {exc})"
        if outcome.draw != improvements[-1] or outcome.seed != seed or outcome.eta != best_eta:
            return "the best draw is not the history's least eta"
        if not (outcome.success and len(outcome.moments) == 4 and len(outcome.p) == len(outcome.p_trial) > 0
                and all(v is not None for v in outcome.p) and np.all(np.isfinite(np.array(outcome.p, float)))):
            return "the best draw has no valid estimate"
        since = draws - improvements[-1]
    if d["since"] != since:
        return f"since is {d['since']}, the history gives {since}"
    if d.get("stopped_by") == "n_iter" and since < d["n_iter"]:
        return "stopped by n_iter before n_iter draws without improvement"
    return None


def checkpoint_path(directory: str | os.PathLike, seed: int) -> Path:
    """``DIR/checkpoints/run_<seed>.json``."""
    return Path(directory) / "checkpoints" / f"run_{int(seed)}.json"


def write_checkpoint(directory: str | os.PathLike, state: RunState, *, token: str, settings_key: dict,
                     n_iter: int) -> Path:
    """Write ``state`` atomically (tmp file + ``os.replace``)."""
    path = checkpoint_path(directory, state.seed)
    payload = {"version": CHECKPOINT_VERSION, "token": token, "settings": settings_key, "n_iter": n_iter}
    payload.update(state.to_dict())
    return write_json(path, payload, indent=None)


def read_checkpoint(directory: str | os.PathLike, seed: int, *, token: str, settings_key: dict,
                    n_iter: int) -> RunState | None:
    """The saved state of run ``seed`` (None when there is no checkpoint).

    Raises
    ------
    SettingsError
        The checkpoint belongs to another problem or settings, or a smaller
        ``n_iter`` would already have stopped the saved run earlier.
    """
    path = checkpoint_path(directory, seed)
    if not path.is_file():
        return None
    try:
        d = json.loads(path.read_text())
    except (OSError, ValueError) as exc:
        raise SettingsError(f"cannot read checkpoint {str(path)!r}: {exc}; remove it to start run {seed} afresh") from None
    if d.get("version") != CHECKPOINT_VERSION:
        raise SettingsError(f"checkpoint {str(path)!r} has format version {d.get('version')!r}, this rocketid "
                            f"writes {CHECKPOINT_VERSION}; remove it or use another output directory")
    if d.get("token") != token:
        raise SettingsError(
            f"checkpoint {str(path)!r} was written for another problem (the data, model, mesh, p0, sampling "
            "settings, the reference solution or rocketid's code differ); resume with the same settings and the "
            "same rocketid on the same machine, or use another output directory")
    if d.get("settings") != settings_key:
        raise SettingsError(f"checkpoint {str(path)!r} was written with settings {d.get('settings')}, not "
                            f"{settings_key}; use the same settings or another output directory")
    problem = checkpoint_problem(d, seed)
    if problem:
        raise SettingsError(f"checkpoint {str(path)!r} is not a consistent run state ({problem}); it was edited or "
                            f"damaged: remove it to start run {seed} afresh")
    state = RunState.from_dict(d)
    old_n_iter = int(d["n_iter"])
    if n_iter != old_n_iter:
        if n_iter < old_n_iter and state.replay_max_since() >= n_iter:
            raise SettingsError(f"checkpoint {str(path)!r} was written with n_iter = {old_n_iter}; with n_iter = "
                                f"{n_iter} its run would have stopped earlier. Resume with n_iter >= "
                                f"{state.replay_max_since() + 1} or use another output directory")
        # the saved run is exactly the start of a run with the new n_iter: re-apply the rule
        state.stopped_by = None
        if state.since >= n_iter:
            state.stopped_by = "n_iter"
    elif state.stopped_by == "max_draws":
        state.stopped_by = None  # the cap is re-checked by the caller with its own max_draws
    return state
