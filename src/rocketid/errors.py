"""The exception tree of rocketid.

Every error a user can meet at the package boundary is a :class:`RocketidError`;
its message names the offending input and says how to fix it.
"""

from __future__ import annotations

__all__ = [
    "RocketidError",
    "ModelError",
    "DataError",
    "SettingsError",
    "SolverError",
    "SensitivityError",
]


class RocketidError(Exception):
    """Base class of every error raised by rocketid."""


class ModelError(RocketidError, ValueError):
    """A model declaration is inconsistent (unknown symbol, missing equation, ...)."""


class DataError(RocketidError, ValueError):
    """Measurement data are unusable (NaN, unsorted times, missing columns, ...)."""


class SettingsError(RocketidError, ValueError):
    """A setting or option is unknown or out of its range."""


class SolverError(RocketidError, RuntimeError):
    """The NLP solver could not be run (not: it ran and did not converge)."""


class SensitivityError(RocketidError, ValueError):
    """Sensitivities cannot be formed at the given point (singular Jacobian, ...)."""
