"""Gravity models as SymPy expressions of geometric altitude."""

from __future__ import annotations

import sympy as sp

__all__ = ["G0", "EARTH_RADIUS", "inverse_square_gravity"]

G0 = 9.80665
"""Standard gravity, m/s^2."""

EARTH_RADIUS = 6_371_000.0
"""Mean Earth radius Re used by the chapter's model, m."""


def inverse_square_gravity(h, g0: float = G0, radius: float = EARTH_RADIUS):
    """``g(h) = g0 (Re / (Re + h))^2``.

    Parameters
    ----------
    h : sympy.Expr or float
        Geometric altitude, m.
    g0 : float
        Gravity at h = 0, m/s^2.
    radius : float
        Earth radius, m.
    """
    return g0 * (radius / (radius + sp.sympify(h))) ** 2
