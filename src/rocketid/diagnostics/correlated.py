"""Errors correlated in time: sensor noise that is not white, and the samples it leaves independent.

::

    fit -> wild points -> correlated errors -> compare -> locate -> plausibility -> discover ...

A GPS receiver's navigation filter, an air-data system's smoothing, a broadcast readout that stalls
and catches up: real telemetry's errors are often correlated from one sample to the next. The
diagnosis's tests assume they are not. Their whiteness check (Ljung-Box, 20 lags) then fails on a
model that is right, and every effect that can bend the trajectory a little "helps": measured on
RA-66M with its own truth and unit noise correlated 0.9 from one 10 ms sample to the next (a
first-order filter of 0.1 s), sigma stated, the base fit reached chi2/dof 0.98 inside its band, its
residuals were "not white" (p = 0), and the search added an altitude-bias drift, a 14-knot wind and
a 6-knot drag correction, "partly explained" -- three effects for a model that misses nothing. With
the noise estimated from the data it is worse: the differences the estimate rests on cancel most of
a correlated error (:func:`rocketid.data.difference_noise`), the noise comes out 4 times too small
and everything is significant.

The errors' correlation is measured on the base fit's normalized residuals, channel by channel, in
runs of steady sampling (:func:`stride_scatter`): the scatter of the fourth differences taken
``s`` samples apart,

``v(s) = mean((e_i - 4 e_{i+s} + 6 e_{i+2s} - 4 e_{i+3s} + e_{i+4s})^2) / 70``,

is the noise variance for white noise whatever ``s`` (the differences cancel the flight and any
misfit smooth at the scale of ``4 s`` samples), and for errors correlated over ``m`` samples it
rises with ``s`` until ``s`` passes ``m`` and then stays -- the variance-time idea of the Allan
variance, on differences that also cancel a curved trajectory. :func:`noise_correlation` steps ``s``
up by half each time (1, 2, 3, 4, 6, 9, ...; :func:`strides`) and fits the curve of errors correlated
``rho ** k`` at ``k`` samples (a first-order filter, the commonest sensor smoothing) to the measured
``v(s) / v(1)`` -- all strides at once, which is steadier than comparing any two -- leaving out the
strides from the first where ``log v`` rises against ``log s`` faster than filtered errors can
(:data:`GROWTH`: a second-order filter's cube) or faster than at the stride before (filtered errors
rise ever more slowly), with :data:`FLAT` sampling errors of slack: there a misfit's own curvature
enters. When the stride wanted lies beyond the strides tried, the level is the highest seen, not the
fit's extrapolation. The channel's errors are
**correlated** when the fitted variance exceeds ``v(1)`` by more than :data:`DETECT` sampling errors
(``sqrt(8 / n)`` relative, measured on white noise) and it rises at two samples' spacing in each
third of the flight (:data:`PARTS`: a misfit of a second's scale, a hybrid motor's thrust ripple, rises
only where it acts and only at longer spacings); samples ``s = log(RESIDUAL) / log(rho)`` apart then have errors
correlated :data:`RESIDUAL` at most. Errors of another shape (a moving average, a second-order filter,
a reading held over several frames) are matched by a longer first-order correlation, so they are
thinned more than they need: it costs samples, not correctness.

What is done (``diagnose(..., correlated_noise=...)``, ``--correlated-noise``): ``"thin"`` (the
default) keeps every ``s``-th sample of each such channel -- the samples whose errors are
independent, which hold almost all that the data say about effects that act over seconds -- takes
the noise where it is estimated at the errors' full size (the fitted level: the residuals'
fourth-difference scatter at the strides where it settled, the model having taken the flight's own
curvature out -- over a second or more the data's own differences would hold it), fits the base model
again and diagnoses that; the report says what was kept. ``"keep"`` only reports the correlation. Errors correlated over more
than :data:`MAX_SECONDS` cannot be told from a missing effect by any test on one flight: the channel
is thinned at that spacing and the note says so.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from ..data import Channel, Measurements, steady_runs
from ..errors import SettingsError
from ..solve import EstimationResult
from ..summary import Section, Summary, SummaryText, Table

__all__ = ["ChannelCorrelation", "CorrelatedNoise", "find_correlated_noise", "noise_correlation", "stride_scatter",
           "strides", "thin_channel", "DETECT", "RESIDUAL", "FLAT", "GROWTH", "PARTS", "MAX_SECONDS", "MIN_KEPT",
           "CORRELATED_NOISE_ACTIONS"]

DETECT = 4.0
"""Sampling errors (``sqrt(8 / n)`` of ``v(1)``, relative) by which the fitted level must exceed the one-sample
scatter for a channel's errors to be called correlated (measured: white noise never, in 2000 series each of 377 to
6600 samples; ``python benchmarks/wild_points_scan.py correlated``)."""

RESIDUAL = 0.03
"""Correlation of the errors of neighbouring samples kept: the stride is where the fitted first-order
correlation ``rho ** stride`` falls to this."""

FLAT = 3.0
"""Sampling errors of slack on the rise of ``log v`` against ``log s`` from one stride to the next (:data:`GROWTH`)."""

GROWTH = 3.0
"""The steepest rise of ``log v`` against ``log s`` that filtered errors make: 1 for a first-order filter, 3 for a
second-order one (a navigation filter's position), at the shortest strides, and ever less as the stride passes
their correlation. The strides from the first one that rises faster than that, or faster than the stride
before it, are left out of the fit: there a misfit's own curvature enters (up to the eighth power of the
stride; Wren-H's speed in its pad-hold case, under the hybrid motor's misfit thrust: a rise of 0.4 from 3 to 4
samples, then 3.4)."""

PARTS = 3
"""Consecutive parts of a channel's samples in each of which the scatter must rise at the second stride: a
sensor's correlated errors raise it at two samples' spacing throughout the flight; a misfit of a second's scale
(a hybrid motor's thrust ripple) raises it only at longer strides and only where it acts. Measured: the two
study data sets that pass the rise limit with a misfit (Wren-H's headwind and nose ballast) have a part at 0.73
and 0.74 there; errors through a navigation filter (Corvid-L, with drop-outs) 1.04-2.1 in every part, the two
real Falcon 9 flights' altitude 1.96-2.13."""

MAX_SECONDS = 2.0
"""Longest spacing, s, a channel is thinned to: errors correlated longer than this act on the time scales of the
flight's own events and cannot be told from a missing effect."""

MIN_KEPT = 40
"""Fewest samples of a channel thinning may leave."""

CORRELATED_NOISE_ACTIONS = ("thin", "keep")

_VAR4 = 70.0        # the sum of the squared coefficients of a fourth difference, 1 -4 6 -4 1


def stride_scatter(t: np.ndarray, e: np.ndarray, stride: int) -> tuple[float, int]:
    """``(v, n)``: the mean square of the fourth differences of ``e`` taken ``stride`` samples apart, over 70
    (the noise variance for white noise), inside runs of steady sampling of ``t``; ``n`` differences (NaN, 0
    when there are none)."""
    e = np.asarray(e, float)
    s = int(stride)
    total, n = 0.0, 0
    for run in steady_runs(np.asarray(t, float)):
        y = e[run]
        m = y.size - 4 * s
        if m <= 0:
            continue
        d = y[:m] - 4.0 * y[s:s + m] + 6.0 * y[2 * s:2 * s + m] - 4.0 * y[3 * s:3 * s + m] + y[4 * s:4 * s + m]
        total += float(d @ d)
        n += m
    return (total / n / _VAR4, n) if n else (math.nan, 0)


def strides(t: np.ndarray, *, max_seconds: float = MAX_SECONDS, min_kept: int = MIN_KEPT) -> list:
    """The strides tried on a channel sampled at ``t``: 1, then each half again larger (1, 2, 3, 4, 6, 9, 13,
    ...) while the spacing stays within ``max_seconds`` and thinning at it keeps ``min_kept`` samples."""
    t = np.asarray(t, float)
    dt = float(np.median(np.diff(t))) if t.size > 1 else math.inf
    out, s = [1], 1
    while True:
        s = max(s + 1, int(round(1.5 * s)))
        if not (s * dt <= max_seconds and t.size // s >= min_kept and t.size > 4 * s + 10):
            return out
        out.append(s)


@dataclass(frozen=True)
class ChannelCorrelation:
    """One channel's errors, from the base fit's normalized residuals (:func:`noise_correlation`).

    Attributes
    ----------
    channel : str
    stride : int
        Samples between the ones kept: where the fitted correlation falls to :data:`RESIDUAL` (1: white).
    seconds : float
        That spacing, s (the channel's median interval times the stride).
    ratio : float
        The errors' variance over ``v(1)`` -- the fitted level, or the highest ``v(s) / v(1)`` seen when the stride
        wanted lies beyond the strides tried: how much of it the one-sample differences miss.
    error : float
        The relative sampling error of ``v(1)``, ``sqrt(8 / n)``.
    correlated : bool
        ``ratio`` beyond :data:`DETECT` sampling errors above 1, and the scatter rising at the second stride in
        each of the :data:`PARTS` (``parts`` all above 1).
    settled : bool
        The stride is within the strides tried (False: correlated beyond :data:`MAX_SECONDS` or beyond what
        :data:`MIN_KEPT` samples allow; thinned at the largest).
    scatter : tuple of (int, float)
        ``(stride, v(stride) / v(1))`` of every stride tried.
    n_samples : int
    kept : int
        Samples thinning to ``stride`` keeps.
    rho : float
        The fitted correlation of neighbouring samples' errors (0 when they are not correlated).
    parts : tuple of float
        ``v(s) / v(1)`` at the second stride tried in each of :data:`PARTS` consecutive parts of the flight,
        when the whole channel's rose (empty otherwise): a sensor's errors are correlated throughout.
    v1 : float
        ``v(1)`` of the normalized residuals.
    """

    channel: str
    stride: int
    seconds: float
    ratio: float
    error: float
    correlated: bool
    settled: bool
    scatter: tuple
    n_samples: int
    kept: int
    rho: float
    parts: tuple = ()
    v1: float = 1.0

    @property
    def variance(self) -> float:
        """The errors' variance in units of the normalized residuals' (``ratio * v(1)``): the squared factor by
        which the sigma of the fit that measured it is to be scaled to the errors' full size."""
        return self.ratio * self.v1

    def text(self) -> str:
        return (f"{self.channel} over {self.seconds:.3g} s ({self.stride} samples; the one-sample differences see "
                f"{100 / self.ratio:.0f} % of the errors' variance)")

    def to_dict(self) -> dict:
        return {"channel": self.channel, "correlated": self.correlated, "stride": self.stride,
                "seconds": self.seconds, "ratio": self.ratio, "error": self.error, "settled": self.settled,
                "n_samples": self.n_samples, "kept": self.kept, "rho": self.rho, "parts": list(self.parts),
                "v1": self.v1, "scatter": [list(p) for p in self.scatter]}


def noise_correlation(name: str, t: np.ndarray, e: np.ndarray, *, max_seconds: float = MAX_SECONDS,
                      min_kept: int = MIN_KEPT) -> ChannelCorrelation:
    """The correlation of one channel's errors from its normalized residuals ``e`` at the times ``t`` (module
    notes): whether their fourth-difference scatter rises with the stride, and the stride at which neighbours'
    errors are independent."""
    t, e = np.asarray(t, float), np.asarray(e, float)
    dt = float(np.median(np.diff(t))) if t.size > 1 else math.nan
    v1, n1 = stride_scatter(t, e, 1)
    if not (n1 >= 10 and v1 > 0):
        return ChannelCorrelation(name, 1, dt, 1.0, math.inf, False, True, ((1, 1.0),), int(t.size), int(t.size),
                                  0.0, ())
    err = math.sqrt(8.0 / n1)
    tried = strides(t, max_seconds=max_seconds, min_kept=min_kept)
    v = {1: v1}
    for s in tried[1:]:
        v[s] = stride_scatter(t, e, s)[0]
    tried = [s for s in tried if math.isfinite(v[s])]
    used, slope = [1], GROWTH
    for s in tried[1:]:      # filtered errors rise ever more slowly; a misfit's curvature faster and faster
        step = math.log(s / used[-1])
        rise = math.log(v[s] / v[used[-1]]) / step
        if rise > min(GROWTH, slope) + FLAT * err * math.sqrt(2.0) / step:
            break
        used.append(s)
        slope = max(rise, 0.0)
    ss = np.array(used, float)
    vv = np.array([v[s] for s in used]) / v1
    rho, level = _fit_first_order(ss, vv)
    ratio = float(level)
    correlated = bool(ratio > 1.0 + DETECT * err and rho > 0.0)
    parts: tuple = ()
    if correlated:
        want = math.log(RESIDUAL) / math.log(rho)
        chosen = int(min(math.ceil(want), tried[-1]))
        settled = want <= tried[-1]
        if not settled:       # the fitted level is an extrapolation: the variance seen is a lower bound
            ratio = float(max(vv))
        parts = _parts(t, e, tried[1])
        correlated = all(r > 1.0 for r in parts)
    if not correlated:
        chosen, settled, rho = 1, True, 0.0
    seen = tuple((int(a), float(v[a] / v1)) for a in tried)
    return ChannelCorrelation(name, int(chosen), float(chosen * dt), float(ratio), float(err), correlated,
                              bool(settled), seen, int(t.size), int(_thin_index(t, chosen).size), float(rho),
                              parts, float(v1))


def _parts(t: np.ndarray, e: np.ndarray, stride: int) -> tuple:
    """``v(stride) / v(1)`` in each of :data:`PARTS` consecutive parts of the samples (NaN where a part has no
    difference at that stride)."""
    out = []
    for k in np.array_split(np.arange(t.size), PARTS):
        v1 = stride_scatter(t[k], e[k], 1)[0]
        vs, ns = stride_scatter(t[k], e[k], stride)
        out.append(float(vs / v1) if ns and v1 > 0 else math.nan)
    return tuple(out)


def _first_order(s: np.ndarray, rho: float) -> np.ndarray:
    """``v(s)`` over the noise variance for errors correlated ``rho ** k`` at ``k`` samples (a first-order
    filter of white noise)."""
    r = rho ** s
    return (_VAR4 - 112.0 * r + 56.0 * r ** 2 - 16.0 * r ** 3 + 2.0 * r ** 4) / _VAR4


def _fit_first_order(s: np.ndarray, ratios: np.ndarray) -> tuple[float, float]:
    """``(rho, level)``: the first-order correlation and the variance (relative to ``v(1)``) whose
    :func:`_first_order` curve is nearest the measured ``v(s) / v(1)`` in least squares (``rho`` on a grid of
    correlation times from 0 to 500 samples, the level in closed form at each)."""
    grid = np.concatenate([[0.0], np.exp(-1.0 / np.geomspace(0.05, 500.0, 400))])
    best = (math.inf, 0.0, 1.0)
    for rho in grid:
        g = _first_order(s, rho)
        level = float(np.sum(ratios * g) / np.sum(g * g))      # least squares for the level at this rho
        cost = float(np.sum((ratios - level * g) ** 2))
        if cost < best[0]:
            best = (cost, float(rho), level)
    return best[1], best[2]


def _thin_index(t: np.ndarray, stride: int) -> np.ndarray:
    """Every ``stride``-th sample of each run of steady sampling, from the run's first."""
    return np.concatenate([run[::int(stride)] for run in steady_runs(np.asarray(t, float))])


def thin_channel(channel: Channel, stride: int) -> Channel:
    """``channel`` with every ``stride``-th sample of each run of steady sampling kept (with its sigma)."""
    if int(stride) <= 1:
        return channel
    return channel.select(_thin_index(channel.times, stride))


@dataclass(frozen=True)
class CorrelatedNoise:
    """The correlation of one fit's errors, channel by channel (:func:`find_correlated_noise`).

    Attributes
    ----------
    channels : tuple of ChannelCorrelation
    action : str
        ``"thin"`` or ``"keep"``: what the caller does with correlated channels.
    chi2_before : float
        chi2/dof of the fit on every sample (NaN when nothing was thinned).
    """

    channels: tuple
    action: str = "thin"
    chi2_before: float = math.nan

    @property
    def correlated(self) -> tuple:
        """The channels whose errors are correlated."""
        return tuple(c for c in self.channels if c.correlated)

    def __bool__(self) -> bool:
        return bool(self.correlated)

    def thin(self, meas: Measurements) -> Measurements:
        """``meas`` with each correlated channel thinned to its stride (the others as they are)."""
        by = {c.channel: c.stride for c in self.correlated}
        return Measurements(tuple(thin_channel(c, by.get(c.name, 1)) for c in meas.channels))

    def note(self) -> str:
        """One sentence for the report (empty when no channel's errors are correlated)."""
        if not self:
            return ""
        listed = "; ".join(c.text() for c in self.correlated)
        if self.action == "thin":
            kept = ", ".join(f"{c.channel} {c.kept} of {c.n_samples}" for c in self.correlated)
            before = (f"; chi2/dof on every sample {self.chi2_before:.4g}" if math.isfinite(self.chi2_before) else "")
            done = (f"the diagnosis uses the samples that far apart ({kept}), whose errors are independent: on "
                    f"every sample the whiteness test would take the correlated errors for a missing effect{before}")
        else:
            done = ("kept (--correlated-noise keep): the whiteness test will find the residuals not white, and "
                    "effects may be added for the errors' slow wander")
        late = [c.channel for c in self.correlated if not c.settled]
        tail = (f". Errors of {', '.join(late)} are still correlated at that spacing: slower sensor errors cannot "
                "be told from a missing effect on one flight") if late else ""
        return f"errors correlated in time: {listed}; {done}{tail}"

    def table(self) -> Table:
        return Table(("channel", "correlated", "stride", "spacing (s)", "kept", "v(stride)/v(1)", "sampling error"),
                     [(c.channel, "yes" if c.correlated else "no", c.stride, c.seconds, f"{c.kept} of {c.n_samples}",
                       c.ratio, c.error) for c in self.channels], (None, None, "d", ".3g", None, ".3g", ".2g"))

    def summary(self) -> SummaryText:
        head = (f"Errors correlated in time: {len(self.correlated)} of {len(self.channels)} channel(s) "
                f"({self.action})")
        notes = [self.note()] if self else ["the errors of every channel are independent from sample to sample"]
        return SummaryText(Summary(head, (Section("Channels", (self.table(),)),), tuple(notes)))

    def to_dict(self) -> dict:
        return {"action": self.action, "chi2_per_dof_before": None if not math.isfinite(self.chi2_before)
                else self.chi2_before, "channels": [c.to_dict() for c in self.channels]}


def check_action(action: str) -> None:
    """A SettingsError unless ``action`` is one of :data:`CORRELATED_NOISE_ACTIONS`."""
    if action not in CORRELATED_NOISE_ACTIONS:
        raise SettingsError(f"correlated_noise must be one of {', '.join(CORRELATED_NOISE_ACTIONS)}, got {action!r}")


def find_correlated_noise(fit: EstimationResult, *, action: str = "thin") -> CorrelatedNoise:
    """The correlation in time of the errors of ``fit``'s data, from its normalized residuals (module notes).

    Parameters
    ----------
    fit : EstimationResult
        The base fit.
    action : {"thin", "keep"}
        Recorded on the result: what the caller does with correlated channels.

    Returns
    -------
    CorrelatedNoise
    """
    check_action(action)
    meas = fit.prepared.measurements
    norm = fit.normalized_residuals
    found = tuple(noise_correlation(c.name, c.times, norm[c.name]) for c in meas.channels)
    return CorrelatedNoise(found, action, float(fit.chi2_per_dof) if any(c.correlated for c in found) else math.nan)
