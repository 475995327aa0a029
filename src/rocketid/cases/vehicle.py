"""A launch vehicle as data: its mass history, thrust and reference area.

RA-66 and RA-66M fly the same vehicle (:data:`RA66_VEHICLE`); a case declares it
on its model with :meth:`Vehicle.declare` instead of repeating the numbers.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import sympy as sp

from ..errors import ModelError
from ..model import Model

__all__ = ["Vehicle", "VehicleTerms", "RA66_VEHICLE"]


@dataclass(frozen=True)
class VehicleTerms:
    """The vehicle's terms on a model: expressions and constant symbols for the dynamics."""

    mass: sp.Expr
    thrust: sp.Symbol
    area: sp.Symbol


@dataclass(frozen=True)
class Vehicle:
    """A vehicle with a constant mass flow and thrust.

    Parameters
    ----------
    name : str
    mass0 : float
        Mass at ``t = 0`` (kg).
    mass_flow : float
        Propellant mass flow (kg/s): ``m(t) = mass0 - mass_flow t``.
    thrust : float
        Thrust (N).
    reference_area : float
        Aerodynamic reference area ``Sm`` (m^2).
    """

    name: str
    mass0: float
    mass_flow: float
    thrust: float
    reference_area: float

    def __post_init__(self):
        for field in ("mass0", "thrust", "reference_area"):
            v = float(getattr(self, field))
            if not v > 0:
                raise ModelError(f"vehicle {self.name!r}: {field} must be positive, got {v}")
        if not float(self.mass_flow) >= 0:
            raise ModelError(f"vehicle {self.name!r}: mass_flow must be >= 0, got {self.mass_flow}")

    def burnout_time(self) -> float:
        """The time at which the mass would reach zero (``inf`` without mass flow)."""
        return self.mass0 / self.mass_flow if self.mass_flow > 0 else math.inf

    def declare(self, m: Model) -> VehicleTerms:
        """Declare the constants ``m0``, ``mdot``, ``Pe``, ``Sm`` on ``m``.

        Returns
        -------
        VehicleTerms
            ``mass = m0 - mdot t``, ``thrust = Pe``, ``area = Sm``.
        """
        m0 = m.constant("m0", float(self.mass0))
        mdot = m.constant("mdot", float(self.mass_flow))
        Pe = m.constant("Pe", float(self.thrust))
        Sm = m.constant("Sm", float(self.reference_area))
        return VehicleTerms(m0 - mdot * m.t, Pe, Sm)


#: rocketid's RA-66 vehicle (the chapter gives no vehicle data): 20 t at lift-off, 100 kg/s,
#: 400 kN, a 1 m radius body.
RA66_VEHICLE = Vehicle("RA-66", mass0=20000.0, mass_flow=100.0, thrust=400000.0, reference_area=math.pi * 1.0 ** 2)
