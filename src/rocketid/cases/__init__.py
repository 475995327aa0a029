"""Reference cases shipped with rocketid."""

from .ra66m import RA66M_CD_TRUTH, RA66M_CL_ALPHA_TRUTH, RA66M_MACH_KNOTS, ra66m, ra66m_truth
from .ra66 import RA66_P0, RA66_TRUTH_VALUES, ra66, ra66_mesh, ra66_times, ra66_truth

__all__ = ["ra66m", "ra66m_truth", "RA66M_MACH_KNOTS", "RA66M_CD_TRUTH", "RA66M_CL_ALPHA_TRUTH",
           "ra66", "ra66_truth", "ra66_times", "ra66_mesh", "RA66_P0", "RA66_TRUTH_VALUES"]
