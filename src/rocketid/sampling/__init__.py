"""Statistic-criterion sampling: eta (7.10) and the algorithm of steps 1-10.

The fixed transformed parameters ``q2`` of (7.9) are chosen by sampling:
draw ``p_trial``, fix ``q2 = V2^T p_trial``, estimate ``q1``, and keep the
draw whose residuals look most like the stated Gaussian noise (least eta).

Modules, in pipeline order::

    criterion      eta (7.10) and its four terms
    distributions  how p_trial is drawn (uniform within the bounds by default)
    settings       SamplingSettings
    worker         one draw (steps 5-7), as a pure function of (seed, draw)
    checkpoint     a run's state on disk (atomic JSON)
    executors      serial, process pool, dask.distributed
    runner         steps 1-10 for several runs: prepare_sampling, sample

Example::

    import rocketid as ri
    from rocketid.sampling import SamplingSettings, sample

    spec = ri.ra66()
    data = ri.simulate_measurements(spec, ri.ra66_truth(spec), ri.ra66_times(), seed=0)
    result = sample(ri.prepare(spec, data), seeds=[1, 2], settings=SamplingSettings(n_iter=20))
    print(result.summary())
"""

from .criterion import TERM_NAMES, StatisticCriterion, criterion_of, statistic_criterion
from .distributions import DISTRIBUTIONS, get_distribution
from .executors import EXECUTORS, default_workers
from .runner import RunResult, SamplingProblem, SamplingResult, prepare_sampling, sample
from .settings import SamplingSettings
from .worker import DrawOutcome, Recipe

__all__ = [
    "statistic_criterion", "criterion_of", "StatisticCriterion", "TERM_NAMES",
    "DISTRIBUTIONS", "get_distribution", "EXECUTORS", "default_workers",
    "SamplingSettings", "prepare_sampling", "sample", "SamplingProblem", "SamplingResult", "RunResult",
    "DrawOutcome", "Recipe",
]
