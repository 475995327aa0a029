"""The statistic criterion eta (7.10).

For residuals ``eps_i = y_i - y_i_meas`` of all channels, each divided by its
own noise standard deviation and pooled (so that sigma = 1 below)::

    s1 = mean(e^3) / sigma^3          k1 = mean(e^4) / sigma^4     (moments about zero, known sigma)
    s2 = z3 / z2^1.5                  k2 = z4 / z2^2               (central sample moments)
    z_r = mean((e - mean(e))^r)
    eta = |s1 - 0| + |k1 - 3| + |s1 - s2| + |k1 - k2|

For residuals that are N(0, sigma^2) with the stated sigma, s1, s2 are near
0 and k1, k2 near 3, so eta is small (of order ``sqrt(96 / n)``); a bias, a
wrong spread, skewness or heavy tails all make it grow.

Notation
--------
=========  =================================================================
``e``      pooled normalized residuals, shape (n,)
``s1,k1``  skewness and kurtosis about zero with the known sigma
``s2,k2``  sample skewness and kurtosis (central moments, ``1/n``)
=========  =================================================================
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Mapping, Sequence

import numpy as np

from ..errors import DataError
from ..summary import Section, Summary

__all__ = ["StatisticCriterion", "statistic_criterion", "criterion_of", "TERM_NAMES"]

#: The four terms of (7.10), in order.
TERM_NAMES = ("|s1|", "|k1-3|", "|s1-s2|", "|k1-k2|")


@dataclass(frozen=True)
class StatisticCriterion:
    """eta (7.10) with its four terms and the moments behind them.

    Attributes
    ----------
    s1, k1 : float
        Skewness and kurtosis about zero with the known sigma.
    s2, k2 : float
        Sample skewness and kurtosis from central moments.
    n : int
        Number of pooled residuals.
    """

    s1: float
    k1: float
    s2: float
    k2: float
    n: int

    @property
    def terms(self) -> tuple[float, float, float, float]:
        """``(|s1|, |k1 - 3|, |s1 - s2|, |k1 - k2|)`` (see :data:`TERM_NAMES`)."""
        return (abs(self.s1), abs(self.k1 - 3.0), abs(self.s1 - self.s2), abs(self.k1 - self.k2))

    @property
    def eta(self) -> float:
        """The sum of the four terms (7.10); NaN when a moment is not finite."""
        return float(sum(self.terms))

    @property
    def finite(self) -> bool:
        return math.isfinite(self.eta)

    def as_dict(self) -> dict[str, float]:
        """``{"eta": ..., "|s1|": ..., ..., "s1": ..., "k1": ..., "s2": ..., "k2": ...}``."""
        out = {"eta": self.eta}
        out.update(zip(TERM_NAMES, self.terms))
        out.update(s1=self.s1, k1=self.k1, s2=self.s2, k2=self.k2)
        return out

    def summary(self) -> Summary:
        """eta, its four terms and the moments behind them."""
        rows = [("eta", f"{self.eta:.6g}")] + [(name, f"{v:.6g}") for name, v in zip(TERM_NAMES, self.terms)]
        rows.append(("moments", f"s1 {self.s1:.4g}, k1 {self.k1:.4g}, s2 {self.s2:.4g}, k2 {self.k2:.4g}"))
        return Summary(f"statistic criterion (7.10) over {self.n} normalized residuals", (Section("", rows),),
                       rule=False)


def statistic_criterion(residuals: Mapping[str, Sequence[float]] | Sequence[float] | np.ndarray,
                        sigma: Mapping[str, float] | float | None = None) -> StatisticCriterion:
    """eta (7.10) of residuals pooled over channels, each divided by its sigma.

    Parameters
    ----------
    residuals : mapping of str to array, or array
        ``{channel: model minus measurement}`` (e.g. ``EstimationResult.residuals``),
        or one array of residuals.
    sigma : mapping of str to float or array, or float, optional
        Noise standard deviation per channel (or one for all); a channel's may be an array,
        one per sample (per-sample sigma). Default 1 (the residuals are already normalized).

    Returns
    -------
    StatisticCriterion
        With NaN moments when a residual is not finite (the sampling loop
        counts that draw as failed).

    Raises
    ------
    DataError
        No residuals, a channel without a sigma, or a sigma that is not positive.
    """
    if isinstance(residuals, Mapping):
        parts = []
        for name, r in residuals.items():
            if sigma is None:
                s = 1.0
            elif isinstance(sigma, Mapping):
                if name not in sigma:
                    raise DataError(f"no sigma for channel {name!r}; pass sigma={{{name!r}: ...}} for every channel")
                s = np.asarray(sigma[name], dtype=float)
            else:
                s = np.asarray(float(sigma))
            r = np.asarray(r, dtype=float).ravel()
            if s.ndim and s.shape != r.shape:
                raise DataError(f"channel {name!r}: {s.size} per-sample sigmas for {r.size} residuals")
            if not np.all(s > 0):
                raise DataError(f"sigma of channel {name!r} must be positive, got {np.min(s):g}")
            parts.append(r / s)
        e = np.concatenate(parts) if parts else np.empty(0)
    else:
        if isinstance(sigma, Mapping):
            raise DataError("sigma is a mapping of channels but the residuals are one array")
        s = 1.0 if sigma is None else float(sigma)
        if not s > 0:
            raise DataError(f"sigma must be positive, got {s}")
        e = np.asarray(residuals, dtype=float).ravel() / s
    if e.size == 0:
        raise DataError("eta (7.10) needs at least one residual")
    with np.errstate(all="ignore"):
        e2 = e * e
        s1 = float(np.mean(e2 * e))
        k1 = float(np.mean(e2 * e2))
        d = e - np.mean(e)
        d2 = d * d
        z2 = float(np.mean(d2))
        z3 = float(np.mean(d2 * d))
        z4 = float(np.mean(d2 * d2))
        s2 = z3 / z2 ** 1.5 if z2 > 0 else math.nan
        k2 = z4 / z2 ** 2 if z2 > 0 else math.nan
    return StatisticCriterion(s1, k1, float(s2), float(k2), int(e.size))


def criterion_of(fit) -> StatisticCriterion:
    """eta (7.10) of an :class:`~rocketid.solve.EstimationResult`'s residuals, each
    channel divided by the sigma the NLP uses for it (at each sample: per-sample sigmas too)."""
    return statistic_criterion(fit.residuals, fit.nlp.channel_sigma_arrays())
