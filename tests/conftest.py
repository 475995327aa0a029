"""Shared RA-66 fixtures (docs/reference-cases.md), built once per test session.

``ra66_spec``       the reference model (CD0..CD6, CL)
``ra66_p_true``     the true parameter vector, shape (8,)
``ra66_clean``      noise-free x, h, v at the 6600 sample times, from the high-accuracy simulator
``ra66_noisy``      the same plus N(0, 1) noise, seed 0
``ra66_noisy_fit``  the estimate from the noisy data, from p0, on the default mesh

Everything here is immutable (frozen specs, read-only arrays): tests must not modify it.
"""

from __future__ import annotations

import pytest

import rocketid as ri


@pytest.fixture(scope="session")
def ra66_spec():
    return ri.ra66()


@pytest.fixture(scope="session")
def ra66_p_true(ra66_spec):
    p = ri.ra66_truth(ra66_spec)
    p.flags.writeable = False
    return p


@pytest.fixture(scope="session")
def ra66_clean(ra66_spec, ra66_p_true):
    return ri.simulate_measurements(ra66_spec, ra66_p_true, ri.ra66_times(), noise=False)


@pytest.fixture(scope="session")
def ra66_noisy(ra66_spec, ra66_p_true):
    return ri.simulate_measurements(ra66_spec, ra66_p_true, ri.ra66_times(), seed=0)


@pytest.fixture(scope="session")
def ra66_noisy_fit(ra66_spec, ra66_noisy):
    return ri.estimate(ra66_spec, ra66_noisy)
