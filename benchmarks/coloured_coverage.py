"""Coverage of the 95 % intervals with residuals correlated in time (docs/telemetry.md).

RA-66 at its true parameters, x, h and v at 100 Hz with unit-variance AR(1) noise
``e_i = rho e_{i-1} + sqrt(1 - rho^2) w_i`` (so the stated sigma of 1 is right and chi2/dof is near 1),
fitted once per data set; the share of the white-noise intervals (``uncertainty(fit)``) and of the
coloured-residual ones (``uncertainty(fit, coloured=True)``) that hold the truth, and the ratio of their
standard errors.

Run: ``python3 benchmarks/coloured_coverage.py [RHO] [N_SETS]`` (default 0.9 and 30; about 1 s a set).
"""

from __future__ import annotations

import sys

import numpy as np

import rocketid as ri
from rocketid.cases.ra66 import ra66, ra66_times, ra66_truth
from rocketid.estimability import uncertainty
from rocketid.simulate import simulate


def ar1(rng: np.random.Generator, n: int, rho: float) -> np.ndarray:
    """Stationary unit-variance AR(1) noise by SciPy's linear filter (the first value is the first draw)."""
    from scipy.signal import lfilter
    w = rng.normal(size=n)
    c = np.sqrt(1 - rho ** 2)
    w[0] /= c
    return lfilter([c], [1.0, -rho], w)


def main(rho: float = 0.9, sets: int = 30) -> None:
    spec = ra66()
    truth = ra66_truth(spec)
    t = ra66_times()
    clean = simulate(spec, truth, times=t).outputs()
    hit_white = hit_col = total = 0
    ratios = []
    for seed in range(sets):
        rng = np.random.default_rng(seed)
        data = ri.Measurements(tuple(ri.Channel(c, t, np.asarray(clean[c]) + ar1(rng, t.size, rho), 1.0)
                                     for c in ("x", "h", "v")))
        fit = ri.estimate(spec, data)
        white, col = uncertainty(fit), uncertainty(fit, coloured=True)
        err = np.abs(fit.p - truth)
        hit_white += int(np.sum(err <= 1.96 * white.standard_errors))
        hit_col += int(np.sum(err <= 1.96 * col.standard_errors))
        total += err.size
        ratios.append(col.standard_errors / white.standard_errors)
    r = np.concatenate(ratios)
    print(f"rho {rho:g}, {sets} data sets, {total} intervals: white coverage {hit_white / total:.3f}, coloured "
          f"{hit_col / total:.3f}; coloured / white standard errors {r.min():.2f}-{r.max():.2f} (median "
          f"{np.median(r):.2f}; theory sqrt((1 + rho) / (1 - rho)) = {np.sqrt((1 + rho) / (1 - rho)):.2f})")


if __name__ == "__main__":
    main(*(float(a) if i == 0 else int(a) for i, a in enumerate(sys.argv[1:3])))
