"""Reference cases shipped with rocketid."""

from .ra66m import RA66M_CD_TRUTH, RA66M_CL_ALPHA_TRUTH, RA66M_MACH_KNOTS, ra66m, ra66m_truth
from .ra66 import RA66_P0, RA66_TRUTH_VALUES, ra66, ra66_mesh, ra66_times, ra66_truth, ra66_vehicle_model
from .registry import BUILTIN_MODELS, BuiltinModel, ModelSource, load_model, resolve_model
from .vehicle import RA66_VEHICLE, Vehicle

__all__ = ["ra66m", "ra66m_truth", "RA66M_MACH_KNOTS", "RA66M_CD_TRUTH", "RA66M_CL_ALPHA_TRUTH",
           "ra66", "ra66_truth", "ra66_times", "ra66_mesh", "ra66_vehicle_model", "RA66_P0", "RA66_TRUTH_VALUES",
           "BUILTIN_MODELS", "BuiltinModel", "ModelSource", "load_model", "resolve_model", "Vehicle", "RA66_VEHICLE"]
