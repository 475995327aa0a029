"""rocketid: aerodynamic coefficient estimation for launch vehicles.

The pipeline, one module per stage (imports flow downstream only)::

    model -> symbolic -> codegen -> collocation -> nlp -> solve
          -> sensitivity -> estimability -> sampling -> diagnostics

Quick start::

    import rocketid as ri
    spec = ri.ra66()                       # the chapter's reference case
    data = ri.simulate_measurements(spec, ri.RA66_TRUTH, seed=0)
    fit = ri.estimate(spec, data)
    print(fit.summary())
"""

from .errors import (DataError, ModelError, RocketidError, SensitivityError, SettingsError,
                     SolverError)
from .model import Model, ModelSpec

__version__ = "0.1.0"

__all__ = [
    "Model", "ModelSpec",
    "RocketidError", "ModelError", "DataError", "SettingsError", "SolverError", "SensitivityError",
]
