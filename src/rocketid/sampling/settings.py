"""Settings of the sampling algorithm (a typed, immutable dataclass)."""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Mapping

from ..errors import SettingsError
from ..estimability import DEFAULT_THRESHOLD, Scaling
from ..solve import check_ipopt_options
from .distributions import Distribution, distribution_name, get_distribution

__all__ = ["SamplingSettings"]


@dataclass(frozen=True)
class SamplingSettings:
    """How the statistic-criterion sampling algorithm (steps 1-10) runs.

    Attributes
    ----------
    n_iter : int
        Stop a run after this many draws in a row that did not improve eta
        (the chapter: 2000). Failed draws count as "no improvement".
    threshold : float
        Modified E-optimal threshold on ``lambda_1 / lambda_k`` (the chapter: 3000).
    scaling : {"nominal", "none"}
        Parameter scaling before the eigen-decomposition of H_r. ``"nominal"``
        divides each parameter by its nominal value (RA-66: np = 5 like the
        chapter); ``"none"`` decomposes in physical units (RA-66: np = 3).
    distribution : str or callable
        Of ``p_trial`` (step 5): ``"uniform"`` within the bounds (the default),
        ``"loguniform"``, or ``draw(rng, lower, upper, nominal) -> p`` (a
        module-level function, so that worker processes can import it).
    n_estimated : int, optional
        Force np instead of the criterion.
    batch_size : int
        Draws per task sent to a worker (and per checkpoint). Larger batches
        cost less overhead but waste more draws past a run's stopping point.
    max_draws : int, optional
        A cap on the draws of one run, beside the n_iter rule (default: none).
        A run stopped by the cap is reported as such.
    ipopt : mapping
        IPOPT options of every (7.9) solve (checked; stored as sorted pairs).
    """

    n_iter: int = 2000
    threshold: float = DEFAULT_THRESHOLD
    scaling: str = "nominal"
    distribution: Any = "uniform"
    n_estimated: int | None = None
    batch_size: int = 16
    max_draws: int | None = None
    ipopt: Any = field(default=())

    def __post_init__(self):
        if isinstance(self.n_iter, bool) or not isinstance(self.n_iter, int) or self.n_iter < 1:
            raise SettingsError(f"n_iter must be a positive integer (the chapter uses 2000), got {self.n_iter!r}")
        try:
            thr = float(self.threshold)
        except (TypeError, ValueError):
            raise SettingsError(f"threshold must be a number above 1, got {self.threshold!r}") from None
        if not thr > 1 or math.isnan(thr):
            raise SettingsError(f"threshold must be above 1 (the chapter uses 3000), got {self.threshold!r}")
        object.__setattr__(self, "threshold", thr)
        object.__setattr__(self, "scaling", Scaling.parse(self.scaling).value)
        get_distribution(self.distribution)
        if self.n_estimated is not None and (isinstance(self.n_estimated, bool) or not isinstance(self.n_estimated, int)
                                             or self.n_estimated < 1):
            raise SettingsError(f"n_estimated must be a positive integer or None, got {self.n_estimated!r}")
        if isinstance(self.batch_size, bool) or not isinstance(self.batch_size, int) or self.batch_size < 1:
            raise SettingsError(f"batch_size must be a positive integer, got {self.batch_size!r}")
        if self.max_draws is not None and (isinstance(self.max_draws, bool) or not isinstance(self.max_draws, int)
                                           or self.max_draws < 1):
            raise SettingsError(f"max_draws must be a positive integer or None, got {self.max_draws!r}")
        opts = dict(self.ipopt) if not isinstance(self.ipopt, Mapping) else dict(self.ipopt)
        object.__setattr__(self, "ipopt", tuple(sorted(check_ipopt_options(opts).items())))

    @property
    def ipopt_options(self) -> dict[str, Any]:
        return dict(self.ipopt)

    @property
    def draw(self) -> Distribution:
        """The distribution function."""
        return get_distribution(self.distribution)

    @property
    def distribution_name(self) -> str:
        return distribution_name(self.distribution)

    def to_dict(self) -> dict:
        return {"n_iter": self.n_iter, "threshold": self.threshold, "scaling": self.scaling,
                "distribution": self.distribution_name, "n_estimated": self.n_estimated,
                "batch_size": self.batch_size, "max_draws": self.max_draws, "ipopt": dict(self.ipopt)}

    def key(self) -> dict:
        """The settings a draw's outcome depends on (for checkpoint compatibility):
        everything except ``batch_size``, ``max_draws`` and ``n_iter``."""
        d = self.to_dict()
        for k in ("batch_size", "max_draws", "n_iter"):
            d.pop(k)
        return d
