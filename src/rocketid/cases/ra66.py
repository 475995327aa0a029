"""RA-66: the chapter's study as rocketid's reference case (docs/reference-cases.md).

The chapter gives no vehicle data; these are rocketid's:

============  ==================================================================
Earth         Re = 6 371 000 m, g = 9.80665 (Re/(Re+h))^2
vehicle       m(t) = 20 000 - 100 t kg; Pe = 400 000 N; Sm = pi * 1.0^2 m^2
input         alpha(t) = -8 deg sin^2(pi (t-4)/20) for 4 <= t <= 24 s, else 0
start         x = h = v = 0, theta = 90 deg; t in [0, 66] s
truth         CD = 0.5, CL = 0.1
measurements  x, h, v at t = 0.01 k s, k = 1..6600; noise N(0, 1)
parameters    CD0..CD6 (knots at 0, 11, ..., 66 s), CL (CL0 = CL1, one value)
p0            CD = 0.1, 0.6, 0.1, 0.6, 0.1, 0.6, 0.1; CL = 0.12
bounds        1e-4 <= p <= 1
============  ==================================================================
"""

from __future__ import annotations

from typing import Callable

import numpy as np
import sympy as sp

from ..collocation.transcription import Mesh, graded_mesh
from ..model import Model, ModelSpec
from ..physics.ascent import FlightConditions, ascent_dynamics, ascent_states, flight_conditions
from .vehicle import RA66_VEHICLE, Vehicle

__all__ = ["ra66", "ra66_truth", "ra66_times", "ra66_mesh", "ra66_vehicle_model", "RA66_P0", "RA66_TRUTH_VALUES"]

RA66_P0 = (0.1, 0.6, 0.1, 0.6, 0.1, 0.6, 0.1, 0.12)
RA66_TRUTH_VALUES = (0.5,) * 7 + (0.1,)
RA66_BOUNDS = (1e-4, 1.0)


def ra66_alpha(t: sp.Symbol) -> sp.Expr:
    """The pitch-over attack angle (rad)."""
    return sp.Piecewise((-8 * sp.pi / 180 * sp.sin(sp.pi * (t - 4) / 20) ** 2, (t >= 4) & (t <= 24)), (0, True))


def ra66_vehicle_model(name: str, description: str, alpha: Callable[[sp.Symbol], sp.Expr],
                       aerodynamics: Callable[[Model, FlightConditions, sp.Symbol], tuple], *,
                       atmosphere: str = "yang1983", sigma: float = 1.0, vehicle: Vehicle = RA66_VEHICLE) -> Model:
    """A model of the RA-66 flight: the vehicle, the ascent from rest on [0, 66] s, x, h, v measured.

    The reference cases differ only in their aerodynamics and attack-angle program.

    Parameters
    ----------
    name, description : str
    alpha : callable
        ``alpha(t)``: the attack-angle program (rad), with kinks at 4 and 24 s.
    aerodynamics : callable
        ``aerodynamics(m, fc, alpha) -> (cd, cl)``: declares the coefficients' parameters on
        ``m`` (in the order they should have) and returns the drag and lift coefficients.
    atmosphere : {"yang1983", "us76"}
    sigma : float
        Noise standard deviation of x, h, v.
    vehicle : Vehicle
        Default :data:`~rocketid.cases.vehicle.RA66_VEHICLE`.

    Returns
    -------
    Model
        Not frozen (the caller may add to it).
    """
    m = Model(name, 0.0, 66.0, description=description)
    st = ascent_states(m)
    fc = flight_conditions(m, st, atmosphere=atmosphere)
    a = m.input("alpha", alpha(m.t), breakpoints=(4.0, 24.0))
    terms = vehicle.declare(m)
    cd, cl = aerodynamics(m, fc, a)
    ascent_dynamics(m, st, fc, thrust=terms.thrust, mass=terms.mass, area=terms.area, cd=cd, cl=cl, alpha=a)
    for s in (st.x, st.h, st.v):
        m.output(str(s), s, sigma=sigma)
    return m


def ra66(*, n_cd_segments: int = 6, atmosphere: str = "yang1983", sigma: float = 1.0) -> ModelSpec:
    """The RA-66 model with the chapter's parameterization.

    Parameters
    ----------
    n_cd_segments : int
        Segments of the time-knot drag coefficient (the chapter: 6).
    atmosphere : {"yang1983", "us76"}
    sigma : float
        Noise standard deviation of x, h, v.

    Returns
    -------
    ModelSpec
    """
    def time_knot_coefficients(m, fc, alpha):
        bp = np.linspace(0.0, 66.0, n_cd_segments + 1)
        cd_guess = list(RA66_P0[:7]) if n_cd_segments == 6 else [0.5] * (n_cd_segments + 1)
        CD = m.piecewise_linear("CD", bp, cd_guess, bounds=RA66_BOUNDS, nominal=0.5)
        CL = m.piecewise_linear("CL", [0.0, 66.0], RA66_P0[7], bounds=RA66_BOUNDS, ties=[(0, 1)], nominal=0.1)
        return CD, CL

    return ra66_vehicle_model("RA-66", "the chapter's study (docs/reference-cases.md)", ra66_alpha,
                              time_knot_coefficients, atmosphere=atmosphere, sigma=sigma).freeze()


def ra66_truth(spec: ModelSpec) -> np.ndarray:
    """The true parameter vector of RA-66 (CD = 0.5 at every knot, CL = 0.1)."""
    vals = {}
    for p in spec.parameters:
        vals[p.symbol] = 0.1 if str(p.symbol) == "CL" else 0.5
    return spec.parameter_vector(vals)


def ra66_times() -> np.ndarray:
    """The 6600 sample times t = 0.01 k, k = 1..6600."""
    return np.arange(1, 6601) * 0.01


def ra66_mesh(n_elements: int = 66, K: int = 4, refine_first: int = 0) -> Mesh:
    """RA-66 meshes: by default rocketid's (66 elements of 1 s, K = 4); the
    chapter-like baseline is ``ra66_mesh(K=3)``."""
    return graded_mesh(0.0, 66.0, n_elements, K, refine_first=refine_first)
