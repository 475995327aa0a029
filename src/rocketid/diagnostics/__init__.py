"""Diagnostics: compare the model with the measurements, find where it fails, learn which
physical effect is missing, add it and watch the error fall (``docs/effects.md``).

Before anything is judged, the data's wild points (isolated samples no model can follow) and their
errors' correlation in time:

``wild``       :func:`find_wild_points` -> :class:`WildPoints` (on the base fit's residuals; dropped by default)
``correlated`` :func:`find_correlated_noise` -> :class:`CorrelatedNoise` (on the base fit's residuals; a
               correlated channel thinned to its independent samples by default)

Part A -- candidate effects, their ranking by the score test, confirmation by refit, model history:

``effects``  :class:`Effect`, :data:`CATALOGUE`, :func:`with_effects`, :func:`custom_effect`
``score``    :func:`rank_candidates` -> :class:`CandidateRanking` (score / Lagrange-multiplier test at the base fit)
``refit``    :func:`confirm` -> :class:`Confirmation` (likelihood ratio, AIC/BIC, whiteness, hold-out)
``history``  :class:`ModelHistory` (each revision's fit statistics and the test against the previous one)

The discovery (issue 8), one module per step, each handing the next an immutable value::

    screen -> refit -> accept -> step -> free shape -> report

``screen``   :func:`screen` -> :class:`Screen` (the ranking and the contenders to refit)
``refit``    :func:`refit_all` -> tuple of :class:`Refit` (every contender, forked workers, time guard)
``accept``   :func:`accept` -> :class:`Acceptance` (does a refit explain the data)
``step``     :func:`discover` -> :class:`Discovery` (forward selection, refinement, backward check, verdict)
``freeshape`` :func:`free_shape_check` -> :class:`FreeShape` (when the search ends above the noise: the free
             shape the verdict names, fitted -- of what kind the missing physics is, and its trace)
``variant``  :func:`mach_variant` (the Mach-indexed variant of a time-knot drag model)
``api``      :func:`diagnose` -> :class:`DiagnosisReport` with :class:`FinalModel` (the composition)

Several flights, after each flight's diagnosis:

``flights``  :func:`~rocketid.diagnostics.flights.joint_final` -> :class:`~rocketid.diagnostics.flights.JointFinal`
             (all flights at once with the effects each found; a vehicle effect found in several shared when
             a likelihood-ratio test says they agree; one found in some flights only carried to the others when
             they agree on its value, :class:`~rocketid.diagnostics.flights.Carried`)
"""

from .effects import (CATALOGUE, KINDS, Effect, Vehicle, apply_effect, back_pressure_effect, custom_effect,
                      density_effect, density_profile_effect, drag_mach_effect, earth_rotation_effect, is_present,
                      sensor_lag_effect,
                      liftoff_fade, mass_jettison_effect, misalignment_onset_effect, resolve_effects, throttle_step_effect, throttle_window_effect, drag_bump_effect, thrust_profile_effect, throttle_effect, wind_effect,
                      wind_profile_effect, with_effects, temperature_effect,
                      burn_rate_effect, base_drag_mach_effect, earth_rotation_site_effect)
from .history import ModelHistory, Revision
from .refit import Confirmation, confirm, ljung_box
from .score import AugmentedModel, CandidateRanking, CandidateScore, augment, rank_candidates

__all__ = [
    # part A: effects, ranking, confirmation, history
    "Effect", "CATALOGUE", "KINDS", "custom_effect", "with_effects", "apply_effect", "resolve_effects",
    "is_present", "wind_effect", "density_effect", "earth_rotation_effect", "sensor_lag_effect", "liftoff_fade", "Vehicle",
    "back_pressure_effect", "thrust_profile_effect", "throttle_effect", "wind_profile_effect", "density_profile_effect",
    "drag_mach_effect", "misalignment_onset_effect", "mass_jettison_effect", "throttle_step_effect", "throttle_window_effect", "drag_bump_effect",
    "temperature_effect", "burn_rate_effect", "base_drag_mach_effect", "earth_rotation_site_effect", "rank_candidates", "CandidateRanking", "CandidateScore", "augment", "AugmentedModel",
    "confirm", "Confirmation", "ljung_box",
    "ModelHistory", "Revision",
]

# ---------------------------------------------------------------------------
# Part B (compare, locate, plausibility, report): its imports and __all__
# entries go below this line.
# ---------------------------------------------------------------------------
from .compare import Comparison, compare
from .locate import Location, locate
from .plausibility import Plausibility, check_plausibility
from .api import DiagnosisReport, FinalModel, diagnose
from .screen import Screen, screen, vehicle_of
from .refit import Refit, refit_all
from .accept import Acceptance, NoiseBand, accept, noise_band
from .step import Discovery, Step, discover
from .freeshape import FreeShape, free_shape_check
from .variant import mach_variant
from .wild import WildPoint, WildPoints, find_wild_points
from .correlated import CorrelatedNoise, find_correlated_noise

__all__ += ["compare", "Comparison", "locate", "Location", "check_plausibility", "Plausibility",
            "diagnose", "DiagnosisReport", "FinalModel", "screen", "Screen", "vehicle_of", "refit_all", "Refit",
            "accept", "Acceptance", "NoiseBand", "noise_band", "discover", "Discovery", "Step", "mach_variant",
            "free_shape_check", "FreeShape",
            "find_wild_points", "WildPoints", "WildPoint", "find_correlated_noise", "CorrelatedNoise"]
