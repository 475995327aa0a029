"""Shared RA-66 fixtures (docs/reference-cases.md), built once per test session.

``ra66_spec``       the reference model (CD0..CD6, CL)
``ra66_p_true``     the true parameter vector, shape (8,)
``ra66_clean``      noise-free x, h, v at the 6600 sample times, from the high-accuracy simulator
``ra66_noisy``      the same plus N(0, 1) noise, seed 0
``ra66_noisy_fit``  the estimate from the noisy data, from p0, on the default mesh
``ra66_noisy_prepared``, ``ra66_clean_prepared``  the model collocated against those data
                    (default mesh; no solve: for tests that only need the NLP)
``ra66m_spec``      the RA-66M model (Mach-indexed drag)

Tiers: every test carries a marker of its tier, from its module (``TIERS`` below): ``unit``
(small models, no full RA-66 solve, seconds), ``golden`` (numbers against independent truths:
exactly solvable fits, standard tables, finite differences, the peer) and ``e2e`` (the
commands, the study, sampling and the diagnostics on RA-66/RA-66M). Run one with
``pytest -m unit``; a module not listed counts as ``e2e``.

Everything here is immutable (frozen specs, read-only arrays): tests must not modify it.
"""

from __future__ import annotations

import pytest

#: The studies' per-case check (``study_harness.Study.check_case``) asserts as a test does: rewritten likewise.
pytest.register_assert_rewrite("study_harness")

import rocketid as ri  # noqa: E402


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


@pytest.fixture(scope="session")
def ra66_noisy_prepared(ra66_spec, ra66_noisy):
    return ri.prepare(ra66_spec, ra66_noisy)


@pytest.fixture(scope="session")
def ra66_clean_prepared(ra66_spec, ra66_clean):
    return ri.prepare(ra66_spec, ra66_clean)


@pytest.fixture(scope="session")
def ra66m_spec():
    from rocketid.cases import ra66m
    return ra66m()


TIERS = {
    "unit": ("test_architecture", "test_summary", "test_scheduler", "test_nlp", "test_cases", "test_model",
             "test_derivatives", "test_bad_input", "test_accept", "test_plots", "test_output"),
    "golden": ("test_estimation", "test_sensitivity", "test_estimability", "test_uncertainty", "test_collocation",
               "test_atmosphere", "test_peer_casadi"),
}


def pytest_collection_modifyitems(config, items):
    tier_of = {module: tier for tier, modules in TIERS.items() for module in modules}
    for item in items:
        module = item.module.__name__.rsplit(".", 1)[-1] if getattr(item, "module", None) else ""
        item.add_marker(getattr(pytest.mark, tier_of.get(module, "e2e")))

