"""Wild points: isolated samples no model of the flight can follow.

::

    fit -> wild points -> compare -> locate -> plausibility -> discover ...

A GPS fix thrown by multipath, a radar's wild point, a telemetry word with a flipped bit, a frame
of a broadcast read wrong: real logs hold single samples tens of sigma off the rest. Nothing in
the model explains them, and left in they do harm twice. With the noise stated, a single one can
carry the whole misfit: three wild points in a clean 1131-sample GPS log of Wren-H (a 40 m
altitude jump, a 15 m downrange jump, a 3 m/s speed glitch) took the base fit from chi2/dof 1.017
to 1.191, above its noise band of 1.13, and the diagnosis answered "not explained by the catalogue"
for a model that was right. With the noise estimated from the data they inflate it (sigma_v 0.282
for 0.244 measured on the same log) and blunt every later test.

The test, on the base fit's normalized residuals ``e_i`` (residual / sigma_i), channel by channel
in its own sample order (:func:`series_points`):

1. each sample's departure from the quadratic in time through its :data:`NEIGHBOURS` nearest
   samples, itself left out (:func:`departures`), fitted robustly (least squares, then Tukey's
   bisquare), in standard deviations of that difference for white noise. A misfit smooth at the
   scale of a few samples -- any missing effect, a sharp minimum of the residual, a trend up to
   the data's end, the kink of a motor's knee -- is followed; an isolated sample is not;
2. divided by a robust scale: ``1.4826 MAD`` of the departures over the channel or over the
   :data:`SCALE_WINDOW` samples around the sample, whichever is larger (:func:`scales`: a stretch
   of larger noise raises its own bar);
3. flagged beyond ``k``, the ``1 - level / (2 N)`` quantile over the ``N`` samples of all
   channels (Bonferroni), of Student's t for the scale's own uncertainty (:func:`threshold`).
   Measured on Gaussian noise: 0.6 % of 4000 data sets of 3 x 377 samples and 0.3 % of 300 of
   3 x 6600 have a point flagged, for a ``level`` of 1 %;
4. the worst sample beyond ``k`` is taken out and the test made again without it; at most
   :data:`MAX_RUN` adjacent samples are wild points, and each must stand off the line through the
   samples before it **and** the line through those after it: a longer run, or a sample beside a
   step (a receiver that jumps to another solution and stays), is a segment the location step
   describes, not a wild point -- the data cannot tell a sensor's glitch from the flight's there.

What is done with them (``diagnose(..., wild_points=...)``, ``--wild-points``): ``"drop"`` (the
default) removes them, estimates the noise again when it comes from the data, fits the base model
again and diagnoses that; the report lists every point dropped, with the chi2/dof with them.
``"keep"`` lists them and diagnoses the data as given.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from scipy import stats

from ..data import Measurements
from ..errors import SettingsError
from ..solve import EstimationResult
from ..summary import Section, Summary, SummaryText, Table

__all__ = ["WildPoint", "WildPoints", "find_wild_points", "series_points", "departures", "scales", "threshold", "NEIGHBOURS",
           "SCALE_WINDOW", "LEVEL", "MAX_RUN", "MAX_SHARE", "WILD_POINT_ACTIONS"]

NEIGHBOURS = 12
"""Samples a wild point is measured against: the quadratic through them (6 on each side inside a series)."""

SIDE_LIMIT = 3.0
"""A run taken out must be off the line through its neighbours on each side by more than this many robust
standard deviations (:func:`_stands_apart`)."""

MAX_RUN = 3
"""At most this many adjacent samples off together are wild points (a receiver's 0.3 s glitch at 10 Hz); a
longer run is a segment (:func:`_channel_points`)."""

SCALE_WINDOW = 51
"""Samples over which the local robust scale is taken (:func:`scales`)."""

MAX_SHARE = 0.01
"""At most this share of a channel's samples (and at least 5) is taken out as wild: beyond it the noise is not
Gaussian with wild points in it but heavier-tailed throughout, and the note says so."""

LEVEL = 0.01
"""Family-wise level of the test: the share of clean data sets that have a point flagged."""

WILD_POINT_ACTIONS = ("drop", "keep")

_MAD_TO_SIGMA = 1.4826


@dataclass(frozen=True)
class WildPoint:
    """One sample flagged as wild.

    Attributes
    ----------
    channel : str
    time : float
        Sample time, s.
    index : int
        Position in the channel's samples.
    value : float
        The measured value.
    residual : float
        Model minus measured, channel units.
    z : float
        Its departure from the running median of its neighbours, in robust standard deviations.
    """

    channel: str
    time: float
    index: int
    value: float
    residual: float
    z: float

    def text(self) -> str:
        return f"{self.channel} at t = {self.time:.6g} s ({self.z:+.1f} sigma, residual {self.residual:+.4g})"

    def to_dict(self) -> dict:
        return {"channel": self.channel, "t": self.time, "index": self.index, "value": self.value,
                "residual": self.residual, "z": self.z}


@dataclass(frozen=True)
class WildPoints:
    """The wild points of one fit's data (:func:`find_wild_points`).

    Attributes
    ----------
    points : tuple of WildPoint
        In channel order, then time.
    threshold : float
        ``k``: the flagging limit in robust standard deviations.
    level : float
    n_samples : int
        Samples tested, all channels.
    scales : dict
        Per channel: the robust standard deviation of the detrended normalized residuals.
    action : str
        ``"drop"`` or ``"keep"``: what the diagnosis did with them.
    chi2_with : float
        chi2/dof of the fit with them (NaN when none was found).
    capped : tuple of str
        Channels where the search stopped at :data:`MAX_SHARE` of the samples: their noise is heavier-tailed
        than Gaussian throughout, not a few wild points.
    """

    points: tuple
    threshold: float
    level: float
    n_samples: int
    scales: dict
    action: str = "drop"
    chi2_with: float = math.nan
    capped: tuple = ()

    def __len__(self) -> int:
        return len(self.points)

    def __bool__(self) -> bool:
        return bool(self.points)

    def by_channel(self) -> dict:
        """``{channel: sample times}`` of the points."""
        out: dict = {}
        for p in self.points:
            out.setdefault(p.channel, []).append(p.time)
        return out

    def without(self, meas: Measurements) -> Measurements:
        """``meas`` without the points, matched by channel and sample time (so also in the data before a
        flight window cut them); every other sample, and each channel's sigma, as they were."""
        drop = self.by_channel()
        chans = []
        for c in meas.channels:
            keep = ~np.isin(c.times, np.asarray(drop.get(c.name, []), float))
            chans.append(c if keep.all() else c.select(keep))
        return Measurements(tuple(chans))

    def listed(self, most: int = 6) -> str:
        """The first ``most`` points in words, and how many more."""
        return "; ".join(p.text() for p in self.points[:most]) + (
            f"; and {len(self.points) - most} more" if len(self.points) > most else "")

    def note(self) -> str:
        """One sentence for the report (empty when there are none)."""
        if not self.points:
            return ""
        shown = self.listed()
        done = ("dropped before the diagnosis" if self.action == "drop" else
                "kept (--wild-points keep): the diagnosis judges them with the rest")
        with_ = f" (chi2/dof with them {self.chi2_with:.4g})" if self.action == "drop" and \
            math.isfinite(self.chi2_with) else ""
        heavy = (f"; the search stopped at {100 * MAX_SHARE:g} % of the samples of {', '.join(self.capped)}: that "
                 "noise is heavier-tailed than Gaussian throughout (give per-sample sigmas, --sigma-column, where "
                 "it is known to be larger)") if self.capped else ""
        return (f"{len(self.points)} wild point(s), isolated samples more than {self.threshold:.2f} robust standard "
                f"deviations off the quadratic through their neighbours (level {self.level:g} over {self.n_samples} "
                f"samples), {done}{with_}: {shown}{heavy}")

    def table(self) -> Table:
        return Table(("channel", "t (s)", "measured", "residual", "z"),
                     [(p.channel, p.time, p.value, p.residual, p.z) for p in self.points],
                     (None, ".6g", ".6g", "+.4g", "+.1f"))

    def summary(self) -> SummaryText:
        head = (f"Wild points: {len(self.points)} at the limit {self.threshold:.2f} (level {self.level:g}, "
                f"{self.n_samples} samples; {self.action})")
        notes = [self.note()] if self.points else ["no wild point"]
        return SummaryText(Summary(head, (Section("Points", (self.table(),)),), tuple(notes)))

    def to_dict(self) -> dict:
        return {"action": self.action, "threshold": self.threshold, "level": self.level,
                "n_samples": self.n_samples, "scales": dict(self.scales),
                "chi2_per_dof_with": None if not math.isfinite(self.chi2_with) else self.chi2_with,
                "points": [p.to_dict() for p in self.points]}


MAD_EFFICIENCY = 0.37
"""Asymptotic efficiency of the MAD as a scale estimate for Gaussian noise: a scale from ``n`` samples is as
uncertain as a standard deviation from ``0.37 n``."""


def threshold(n_samples: int, level: float = LEVEL, n_scale: int | None = None) -> float:
    """The flagging limit ``k``: the ``1 - level / (2 N)`` quantile over ``N = n_samples`` (Bonferroni), of
    Student's t with ``MAD_EFFICIENCY * n_scale`` degrees of freedom -- the departures are divided by a scale
    estimated from ``n_scale`` of them, which fattens the tails -- or of the normal without ``n_scale``.
    Robust standard deviations."""
    q = level / (2.0 * max(1, int(n_samples)))
    if n_scale is None:
        return float(stats.norm.isf(q))
    return float(stats.t.isf(q, max(1.0, MAD_EFFICIENCY * int(n_scale))))


def _windows(n: int, size: int) -> np.ndarray:
    """``(n, size)`` sample indices: for each sample the ``size`` consecutive samples centred on it, shifted
    inside the series at its ends."""
    first = np.clip(np.arange(n) - size // 2, 0, n - size)
    return first[:, None] + np.arange(size)[None, :]


def departures(t: np.ndarray, e: np.ndarray) -> np.ndarray:
    """Each sample's departure from the quadratic through its :data:`NEIGHBOURS` nearest samples (itself left
    out), in standard deviations of that difference for white unit noise: ``(e_i - q_i(t_i)) / sqrt(1 + v_i)``,
    ``v_i`` the variance factor of the fitted value. A smooth residual, a minimum, a trend up to a series' end
    are followed; a sample off its neighbours is not. The quadratic is fitted robustly (least squares, then
    twice with Tukey's bisquare weights at 4.685 robust standard deviations), so that two or three wild
    samples side by side do not drag their neighbours' references along."""
    n, m = e.size, NEIGHBOURS
    win = _windows(n, m + 1)
    keep = win != np.arange(n)[:, None]
    nb = win[keep].reshape(n, m)
    step = float(np.median(np.diff(t))) if n > 1 else 1.0
    tau = (t[nb] - t[:, None]) / (step if step > 0 else 1.0)
    basis = np.stack([np.ones_like(tau), tau, tau * tau], axis=2)
    y = e[nb]
    w = np.ones_like(tau)
    for sweep in range(3):
        wb = basis * w[:, :, None]
        inv = np.linalg.inv(np.einsum("nmi,nmj->nij", wb, basis))
        coef = np.einsum("nij,nj->ni", inv, np.einsum("nmi,nm->ni", wb, y))
        if sweep == 2:
            break
        res = y - np.einsum("nmi,ni->nm", basis, coef)
        scale = _MAD_TO_SIGMA * float(np.median(np.abs(res)))
        if not scale > 0:
            break
        u = res / (4.685 * scale)
        w = np.where(np.abs(u) < 1.0, (1.0 - u * u) ** 2, 0.0)
        # a window left with fewer than 3 weighted samples keeps its least-squares fit
        w[np.count_nonzero(w, axis=1) < 3] = 1.0
    # the variance factor of the fitted value under the final weights (the least-squares one when every
    # neighbour counts: 0.21 inside a series for 12 neighbours, 1.07 at its first sample)
    second = np.einsum("nm,nmi,nmj->nij", w * w, basis, basis)
    var = np.einsum("ni,nij,nj->n", inv[:, 0, :], second, inv[:, 0, :])
    return (e - coef[:, 0]) / np.sqrt(1.0 + np.maximum(var, 0.0))


def scales(d: np.ndarray) -> np.ndarray:
    """Robust standard deviation of the departures at each sample: ``1.4826 MAD`` over the whole series or
    over the :data:`SCALE_WINDOW` samples around it, whichever is larger (a stretch of larger noise, an engine's
    vibration, raises its own bar; nowhere is the bar lowered below the series')."""
    whole = _MAD_TO_SIGMA * float(np.median(np.abs(d - np.median(d))))
    if d.size < 2 * SCALE_WINDOW:
        return np.full(d.size, whole)
    part = d[_windows(d.size, SCALE_WINDOW)]
    local = _MAD_TO_SIGMA * np.median(np.abs(part - np.median(part, axis=1, keepdims=True)), axis=1)
    return np.maximum(whole, local)


def _channel_points(t: np.ndarray, e: np.ndarray, k: float, cap: int) -> tuple[list, float]:
    """``[(index, z)]`` of one channel's wild points and the series' robust scale.

    The worst sample beyond ``k`` is taken out and the test made again without it, until none is left (at most
    ``cap``). A run of more than :data:`MAX_RUN` adjacent samples taken out is an edge walking along a step --
    a sensor switching, a GPS solution jumping and staying -- not wild points: they are put back, and no sample
    within :data:`NEIGHBOURS` of that run is taken out (the location step describes the segment). A run kept
    must stand apart from both sides (:func:`_stands_apart`)."""
    n = e.size
    active = np.ones(n, bool)
    barred = np.zeros(n, bool)
    found: dict = {}
    whole = math.nan
    while active.sum() > NEIGHBOURS + 1 and len(found) < cap:
        idx = np.flatnonzero(active)
        d = departures(t[idx], e[idx])
        sc = scales(d)
        whole = float(np.min(sc))
        if not whole > 0:
            break
        z = d / sc
        z[barred[idx]] = 0.0
        j = int(np.argmax(np.abs(z)))
        if not abs(z[j]) > k:
            break
        i = int(idx[j])
        found[i] = float(z[j])
        lo, hi = i, i
        while lo - 1 in found:
            lo -= 1
        while hi + 1 in found:
            hi += 1
        if hi - lo + 1 > MAX_RUN:
            for q in range(lo, hi + 1):
                del found[q]
            active[lo:hi + 1] = True
            barred[max(0, lo - NEIGHBOURS):hi + NEIGHBOURS + 1] = True
        else:
            active[i] = False
    for run in _runs(sorted(found)):
        if not _stands_apart(t, e, run, active, whole):
            for q in run:
                del found[q]
    return sorted(found.items()), whole


def _runs(indices: list) -> list:
    """Runs of adjacent indices."""
    out: list = []
    for i in indices:
        if out and i == out[-1][-1] + 1:
            out[-1].append(i)
        else:
            out.append([i])
    return out


def _stands_apart(t: np.ndarray, e: np.ndarray, run: list, active: np.ndarray, scale: float) -> bool:
    """Whether every sample of a run taken out is off the line through the :data:`NEIGHBOURS` samples before the
    run **and** off the line through those after it, the same way, each by more than :data:`SIDE_LIMIT` robust
    standard deviations and by at least half the other's offset (a spike; a sample beside a step agrees with
    one side). At a series' end the one side decides."""
    offsets = []
    for side in (-1, 1):
        pool = np.flatnonzero(active[:run[0]])[::-1] if side < 0 else np.flatnonzero(active[run[-1] + 1:]) + run[-1] + 1
        nb = np.sort(pool[:NEIGHBOURS])
        if nb.size < NEIGHBOURS // 2:
            continue
        line = np.polyfit(t[nb], e[nb], 1)
        offsets.append((e[run] - np.polyval(line, t[run])) / scale)
    if not offsets or not math.isfinite(scale) or not scale > 0:
        return False
    off = np.array(offsets)                                   # (sides, samples of the run)
    big = np.max(np.abs(off), axis=0)
    return bool(np.all((off * off[0] > 0) & (np.abs(off) > np.maximum(SIDE_LIMIT, 0.5 * big))))


def series_points(t, e, *, n_total: int | None = None, level: float = LEVEL) -> list:
    """The wild points of one series of normalized residuals: ``[(index, z)]`` (module notes).

    Parameters
    ----------
    t : array_like
        Sample times, increasing.
    e : array_like
        Normalized residuals (residual / sigma).
    n_total : int, optional
        Samples the family-wise level is spread over (default: this series').
    level : float
    """
    t, e = np.asarray(t, float), np.asarray(e, float)
    if t.shape != e.shape or t.ndim != 1:
        raise SettingsError(f"series_points needs times and residuals of one length, got {t.shape} and {e.shape}")
    return _series(t, e, n_total or e.size, level)[0]


def _series(t: np.ndarray, e: np.ndarray, n_total: int, level: float) -> tuple[list, float, bool]:
    """One series' ``(points, robust scale, capped)``: the limit for ``n_total`` samples, at most
    :data:`MAX_SHARE` of the series (and at least 5) taken out; nothing for a series too short to test."""
    if e.size <= NEIGHBOURS + 1:
        return [], math.nan, False
    cap = max(5, int(MAX_SHARE * e.size))
    found, scale = _channel_points(t, e, threshold(n_total, level, e.size), cap)
    return found, scale, len(found) >= cap


def check_action(action: str) -> None:
    """A SettingsError unless ``action`` is one of :data:`WILD_POINT_ACTIONS`."""
    if action not in WILD_POINT_ACTIONS:
        raise SettingsError(f"wild_points must be one of {', '.join(WILD_POINT_ACTIONS)}, got {action!r}")


def find_wild_points(fit: EstimationResult, *, level: float = LEVEL, action: str = "drop") -> WildPoints:
    """The isolated samples of ``fit``'s data that are off their neighbours by more than the noise can be
    (module notes).

    Parameters
    ----------
    fit : EstimationResult
        The base fit: its normalized residuals are tested.
    level : float
        Family-wise level over all samples (0 < level < 1).
    action : {"drop", "keep"}
        Recorded on the result: what the caller does with the points.

    Returns
    -------
    WildPoints
    """
    if not 0.0 < level < 1.0:
        raise SettingsError(f"wild-point level must be in (0, 1), got {level}")
    check_action(action)
    meas = fit.prepared.measurements
    norm, resid = fit.normalized_residuals, fit.residuals
    n = sum(np.asarray(norm[c.name]).size for c in meas.channels)
    k = min(threshold(n, level, np.asarray(norm[c.name]).size) for c in meas.channels)
    points, scale, capped = [], {}, []
    for c in meas.channels:
        e = np.asarray(norm[c.name], float)
        if e.size <= NEIGHBOURS + 1:
            continue
        found, scale[c.name], full = _series(np.asarray(c.times, float), e, n, level)
        if full:
            capped.append(c.name)
        r = np.asarray(resid[c.name], float)
        points += [WildPoint(c.name, float(c.times[i]), i, float(c.values[i]), float(r[i]), z)
                   for i, z in found]
    return WildPoints(tuple(points), k, float(level), int(n), scale, action,
                      float(fit.chi2_per_dof) if points else math.nan, tuple(capped))
