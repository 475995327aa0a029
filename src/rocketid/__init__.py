"""rocketid: aerodynamic coefficient estimation for launch vehicles.

The pipeline, one module per stage (imports flow downstream only)::

    model -> symbolic -> codegen -> collocation -> nlp -> solve
          -> sensitivity -> estimability -> sampling -> diagnostics

Quick start::

    import rocketid as ri
    spec = ri.ra66()                                   # the chapter's reference case
    data = ri.simulate_measurements(spec, ri.ra66_truth(spec), ri.ra66_times(), seed=0)
    fit = ri.estimate(spec, data)
    print(fit.summary())
"""

from .cases import RA66_P0, RA66_TRUTH_VALUES, ra66, ra66_mesh, ra66_times, ra66_truth
from .codegen import generate
from .collocation import Mesh, graded_mesh, radau_points, transcribe, uniform_mesh
from .data import Channel, Measurements, read_channels, read_csv
from .errors import (DataError, ModelError, RocketidError, SensitivityError, SettingsError,
                     SolverError)
from .model import Model, ModelSpec
from .simulate import Trajectory, simulate, simulate_measurements
from .solve import EstimationResult, default_mesh, estimate, prepare

__version__ = "0.1.0"

__all__ = [
    "Model", "ModelSpec", "Measurements", "Channel", "read_csv", "read_channels",
    "generate", "Mesh", "uniform_mesh", "graded_mesh", "radau_points", "transcribe", "default_mesh",
    "prepare", "estimate", "EstimationResult", "simulate", "simulate_measurements", "Trajectory",
    "ra66", "ra66_truth", "ra66_times", "ra66_mesh", "RA66_P0", "RA66_TRUTH_VALUES",
    "RocketidError", "ModelError", "DataError", "SettingsError", "SolverError", "SensitivityError",
]
