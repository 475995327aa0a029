"""RA-66M: RA-66's vehicle with physically structured aerodynamics, for finding missing effects.

The chapter's time-knot CD(t), CL(t) absorb most force-like modelling errors
into unphysical coefficient histories (``docs/time-knot-trap.md``). RA-66M
keeps RA-66's vehicle, atmosphere, gravity and pitch-over, and changes only
the aerodynamics and the excitation:

==============  ===============================================================
drag            CD(M), piecewise linear in Mach number (speed of sound from the
                1976 standard) on knots M = 0, 0.6, 0.9, 1.1, 1.3, 2.0, 2.8;
                truth 0.30, 0.30, 0.40, 0.55, 0.52, 0.42, 0.36 (a transonic rise)
lift            CL = CL_alpha * alpha, CL_alpha constant (truth 2.5 /rad) or
                Mach-indexed (``cl_alpha="mach"``)
input           RA-66's pitch-over (-8 deg, 4-24 s), then an attack-angle
                excitation alpha = 1.5 deg sin(2 pi (t - 24) / 14) for 24-66 s,
                so that CL_alpha is identifiable
parameters      CD_M_0..CD_M_6, CL_alpha (8, like RA-66)
guess           CD 0.4 at every knot, CL_alpha 2.0; bounds CD [0.01, 2],
                CL_alpha [0, 10]
measurements    as RA-66: x, h, v at 100 Hz, sigma 1
==============  ===============================================================

Numbers beside RA-66's are in ``docs/reference-cases.md``.
"""

from __future__ import annotations

import numpy as np
import sympy as sp

from ..model import Model, ModelSpec
from .ra66 import ra66_alpha, ra66_vehicle_model

__all__ = ["ra66m", "ra66m_truth", "RA66M_MACH_KNOTS", "RA66M_CD_TRUTH", "RA66M_CL_ALPHA_TRUTH"]

RA66M_MACH_KNOTS = (0.0, 0.6, 0.9, 1.1, 1.3, 2.0, 2.8)
RA66M_CD_TRUTH = (0.30, 0.30, 0.40, 0.55, 0.52, 0.42, 0.36)
RA66M_CL_ALPHA_TRUTH = 2.5
EXCITATION_DEG = 1.5
EXCITATION_PERIOD = 14.0


def ra66m_alpha(t: sp.Symbol) -> sp.Expr:
    """Pitch-over, then the attack-angle excitation (rad)."""
    exc = EXCITATION_DEG * sp.pi / 180 * sp.sin(2 * sp.pi * (t - 24) / EXCITATION_PERIOD)
    return sp.Piecewise((ra66_alpha(t), t <= 24), (exc, True))


def ra66m(*, cl_alpha: str = "constant", atmosphere: str = "yang1983", sigma: float = 1.0,
          build: bool = True) -> ModelSpec | Model:
    """The RA-66M model (Mach-indexed drag, CL = CL_alpha * alpha).

    Parameters
    ----------
    cl_alpha : {"constant", "mach"}
        CL_alpha as one constant, or piecewise linear in Mach on the drag knots.
    build : bool
        Return the frozen ModelSpec (default) or the editable Model.
    """
    from ..errors import ModelError
    if cl_alpha not in ("constant", "mach"):
        raise ModelError(f"cl_alpha must be 'constant' or 'mach', got {cl_alpha!r}")
    def mach_coefficients(m, fc, alpha):
        cd = m.table("CD_M", fc.mach, RA66M_MACH_KNOTS, 0.4, bounds=(0.01, 2.0), nominal=0.4)
        if cl_alpha == "constant":
            cla = m.parameter("CL_alpha", 2.0, bounds=(0.0, 10.0), nominal=2.5)
        else:
            cla = m.table("CL_alpha", fc.mach, RA66M_MACH_KNOTS, 2.0, bounds=(0.0, 10.0), nominal=2.5)
        return cd, cla * alpha

    m = ra66_vehicle_model("RA-66M", "RA-66 vehicle, CD(Mach), CL = CL_alpha alpha, alpha excitation", ra66m_alpha,
                           mach_coefficients, atmosphere=atmosphere, sigma=sigma)
    return m.freeze() if build else m


def ra66m_truth(spec: ModelSpec) -> np.ndarray:
    """The true parameter vector of an RA-66M model (extra effect parameters at 0)."""
    vals = {}
    for p in spec.parameters:
        name = str(p.symbol)
        if name.startswith("CD_M_"):
            vals[p.symbol] = RA66M_CD_TRUTH[int(name.rsplit("_", 1)[1])]
        elif name.startswith("CL_alpha"):
            vals[p.symbol] = RA66M_CL_ALPHA_TRUTH
    return spec.parameter_vector(vals)
