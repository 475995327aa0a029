"""Reference cases as data: one vehicle for RA-66 and RA-66M, one graded mesh, one guess check (unit tier)."""

from __future__ import annotations

import math

import numpy as np
import pytest

import rocketid as ri
from rocketid.cases import RA66_VEHICLE, Vehicle, ra66m
from rocketid.collocation import Mesh, graded_mesh
from rocketid.errors import ModelError, SettingsError
from rocketid.model import check_guess


def _constants(spec) -> dict[str, float]:
    return {str(s): float(v) for s, v in spec.constants}


def test_both_cases_fly_the_declared_vehicle():
    # the vehicle the way a user would write it down: 20 t, 100 kg/s, 400 kN, a 1 m radius body
    expected = {"m0": 20000.0, "mdot": 100.0, "Pe": 400000.0, "Sm": math.pi}
    assert _constants(ri.ra66()) == expected
    assert _constants(ra66m()) == expected
    assert RA66_VEHICLE.burnout_time() == 200.0


def test_a_vehicle_is_checked():
    with pytest.raises(ModelError, match="vehicle 'v': thrust must be positive"):
        Vehicle("v", mass0=1.0, mass_flow=0.0, thrust=0.0, reference_area=1.0)
    with pytest.raises(ModelError, match="mass_flow must be >= 0"):
        Vehicle("v", mass0=1.0, mass_flow=-1.0, thrust=1.0, reference_area=1.0)


def test_refine_first_splits_the_first_element_geometrically():
    m = Mesh(np.array([0.0, 1.0, 3.0]), 3)
    # pieces in the ratio 1 : 4 : 16 of the first element (length 1): cuts at 1/21 and 5/21
    np.testing.assert_allclose(m.refine_first(2).boundaries, [0.0, 1 / 21, 5 / 21, 1.0, 3.0], rtol=0, atol=1e-15)
    np.testing.assert_allclose(m.refine_first(1, ratio=1.0).boundaries, [0.0, 0.5, 1.0, 3.0])
    assert m.refine_first(0) is m
    with pytest.raises(SettingsError, match="refine_first must be a non-negative integer"):
        m.refine_first(-1)
    # the graded mesh and the default mesh are that one refinement
    assert np.array_equal(graded_mesh(0.0, 66.0, 66, 4, refine_first=3).boundaries,
                          ri.uniform_mesh(0.0, 66.0, 66, 4).refine_first(3).boundaries)
    spec = ri.ra66()
    assert np.array_equal(ri.default_mesh(spec, refine_first=3).boundaries,
                          ri.default_mesh(spec).refine_first(3).boundaries)


def test_one_guess_check_names_the_parameter_and_the_fix():
    spec = ri.ra66()
    check_guess(spec)  # the model's own guesses are inside
    with pytest.raises(ModelError, match=r"the guess 2 of parameter CD3 lies outside its bounds \[0.0001, 1\]; "
                                         "move the guess inside"):
        check_guess(spec, [0.5, 0.5, 0.5, 2.0, 0.5, 0.5, 0.5, 0.1])
    with pytest.raises(SettingsError, match="^--guess: the guess -1 of parameter CL"):
        check_guess(spec, [0.5] * 7 + [-1.0], where="--guess", error=SettingsError)
