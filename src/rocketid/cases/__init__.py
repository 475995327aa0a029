"""Reference cases shipped with rocketid."""

from .ra66 import RA66_P0, RA66_TRUTH_VALUES, ra66, ra66_mesh, ra66_times, ra66_truth

__all__ = ["ra66", "ra66_truth", "ra66_times", "ra66_mesh", "RA66_P0", "RA66_TRUTH_VALUES"]
