"""Distributions of ``p_trial`` for step 5 of the sampling algorithm.

A distribution is a function ``draw(rng, lower, upper, nominal) -> p`` of a
NumPy generator and the parameters' bounds and nominal values, returning one
full parameter vector inside the bounds. The registry names the built-in
ones; :func:`get_distribution` also accepts a callable with that signature.

==============  ================================================================
``uniform``     U(lower, upper) for each parameter (the chapter's choice, default)
``loguniform``  log-uniform between the bounds (positive bounds only)
==============  ================================================================
"""

from __future__ import annotations

from typing import Callable

import numpy as np

from ..errors import SettingsError

__all__ = ["DISTRIBUTIONS", "get_distribution", "uniform", "loguniform", "Distribution"]

Distribution = Callable[[np.random.Generator, np.ndarray, np.ndarray, np.ndarray], np.ndarray]


def _check_finite(lower: np.ndarray, upper: np.ndarray, name: str) -> None:
    if not (np.all(np.isfinite(lower)) and np.all(np.isfinite(upper))):
        raise SettingsError(f"the {name!r} distribution needs finite bounds on every parameter; give each "
                            "parameter bounds, or pass a distribution of your own")


def uniform(rng: np.random.Generator, lower: np.ndarray, upper: np.ndarray, nominal: np.ndarray) -> np.ndarray:
    """Each parameter uniform within its bounds."""
    _check_finite(lower, upper, "uniform")
    return rng.uniform(lower, upper)


def loguniform(rng: np.random.Generator, lower: np.ndarray, upper: np.ndarray, nominal: np.ndarray) -> np.ndarray:
    """Each parameter log-uniform within its (positive) bounds."""
    _check_finite(lower, upper, "loguniform")
    if np.any(lower <= 0):
        raise SettingsError("the 'loguniform' distribution needs positive lower bounds")
    return np.exp(rng.uniform(np.log(lower), np.log(upper)))


#: Built-in distributions by name.
DISTRIBUTIONS: dict[str, Distribution] = {"uniform": uniform, "loguniform": loguniform}


def get_distribution(value: str | Distribution) -> Distribution:
    """A distribution by name (see :data:`DISTRIBUTIONS`) or a callable
    ``draw(rng, lower, upper, nominal) -> p``.

    Raises
    ------
    SettingsError
        An unknown name (the valid ones are listed).
    """
    if callable(value):
        return value
    try:
        return DISTRIBUTIONS[str(value)]
    except KeyError:
        raise SettingsError(f"unknown sampling distribution {value!r}; choose one of "
                            f"{', '.join(DISTRIBUTIONS)} or pass a function draw(rng, lower, upper, nominal)") from None


def distribution_name(value: str | Distribution) -> str:
    """The registry name, or ``module.qualname`` of a callable (for reports)."""
    if isinstance(value, str):
        return value
    for name, fn in DISTRIBUTIONS.items():
        if fn is value:
            return name
    return f"{getattr(value, '__module__', '?')}.{getattr(value, '__qualname__', repr(value))}"
