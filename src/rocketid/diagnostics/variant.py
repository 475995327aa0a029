"""The Mach-indexed variant of a model whose drag is a time-knot family.

The chapter's CD(t) absorbs most force-like effects into unphysical coefficient
histories (``docs/time-knot-trap.md``): the discovery cannot see them. For such
a model, :func:`mach_variant` builds a physically structured variant from the
model's own drag-coefficient definition: the time family is replaced by a table
piecewise linear in Mach number over the Mach range flown (:data:`KNOTS` knots,
started from the time-knot estimate at each Mach number). ``diagnose`` runs the
same discovery on it and reports what it finds.
"""

from __future__ import annotations

import numpy as np

from ..errors import ModelError
from ..model import ModelSpec
from ..solve import EstimationResult
from .screen import _evaluate

__all__ = ["time_knot_drag", "mach_variant", "KNOTS"]

KNOTS = 7
"""Knots of the variant's drag table in Mach."""


def time_knot_drag(spec: ModelSpec) -> list:
    """The time families the drag coefficient (role ``drag_coefficient``) is made of (empty: none,
    or the model declares no drag-coefficient role)."""
    cd = spec.role("drag_coefficient")
    if cd is None:
        return []
    syms = spec.expand(cd).free_symbols
    return [f for f in spec.families if f.symbol in syms]


def mach_variant(fit: EstimationResult) -> ModelSpec:
    """``fit``'s model with its time-knot drag replaced by CD(Mach), piecewise linear over the
    Mach range flown, each knot started from the time-knot estimate at that Mach number.

    Raises
    ------
    ModelError
        The model has no time-knot drag, or no Mach role (the variant needs the Mach number).
    """
    spec = fit.spec
    fams = time_knot_drag(spec)
    if not fams:
        raise ModelError(f"model {spec.name!r} has no time-knot drag coefficient (role 'drag_coefficient')")
    mach = spec.require_role("mach", "the Mach-indexed variant of a time-knot drag model")
    cd_sym = spec.role("drag_coefficient")
    M = _evaluate(fit, mach)
    CD = _evaluate(fit, cd_sym)
    lo, hi = float(np.min(M)), float(np.max(M))
    if not hi > lo:
        raise ModelError(f"the flight of model {spec.name!r} spans no Mach range; no Mach-indexed variant")
    knots = np.linspace(max(0.0, lo), hi, KNOTS)
    order = np.argsort(M)
    guess = np.interp(knots, M[order], CD[order])
    lower = min(p.lower for p in spec.parameters if p.family in {f.symbol for f in fams})
    upper = max(p.upper for p in spec.parameters if p.family in {f.symbol for f in fams})
    guess = np.clip(guess, lower, upper)
    m = spec.to_model()
    m.name = f"{spec.name} (CD(Mach) variant)"
    table = m.table("CD_Mach", mach, knots, guess, bounds=(lower, upper), nominal=float(np.mean(np.abs(guess))) or 1.0)
    old = m.definition(cd_sym)
    new = old
    for f in fams:
        new = new.xreplace({f.symbol: table})
    if new == old:
        raise ModelError(f"the drag coefficient {cd_sym} of model {spec.name!r} uses its time family only through "
                         "other definitions; no Mach-indexed variant")
    m.redefine(cd_sym, new)
    for f in fams:
        m.remove_family(f.symbol)
    return m.freeze()
