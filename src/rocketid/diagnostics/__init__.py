"""Diagnostics: compare the model with the measurements, find where it fails, learn which
physical effect is missing, add it and watch the error fall (``docs/effects.md``).

Part A -- candidate effects, their ranking by the score test, confirmation by refit, model history:

``effects``  :class:`Effect`, :data:`CATALOGUE`, :func:`with_effects`, :func:`custom_effect`
``score``    :func:`rank_candidates` -> :class:`CandidateRanking` (score / Lagrange-multiplier test at the base fit)
``refit``    :func:`confirm` -> :class:`Confirmation` (likelihood ratio, AIC/BIC, whiteness, hold-out)
``history``  :class:`ModelHistory` (each revision's fit statistics and the test against the previous one)
"""

from .effects import (CATALOGUE, KINDS, Effect, apply_effect, custom_effect, density_effect,
                      earth_rotation_effect, is_present, liftoff_fade, resolve_effects, wind_effect,
                      with_effects)
from .history import ModelHistory, Revision
from .refit import Confirmation, confirm, ljung_box
from .score import AugmentedModel, CandidateRanking, CandidateScore, augment, rank_candidates

__all__ = [
    # part A: effects, ranking, confirmation, history
    "Effect", "CATALOGUE", "KINDS", "custom_effect", "with_effects", "apply_effect", "resolve_effects",
    "is_present", "wind_effect", "density_effect", "earth_rotation_effect", "liftoff_fade",
    "rank_candidates", "CandidateRanking", "CandidateScore", "augment", "AugmentedModel",
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
from .api import DiagnosisReport, diagnose

__all__ += ["compare", "Comparison", "locate", "Location", "check_plausibility", "Plausibility",
            "diagnose", "DiagnosisReport"]
