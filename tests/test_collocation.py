"""Collocation: Radau tables, Lagrange bases, generated code, and the discretization error.

Golden numbers are the published Radau IIA values (Hairer and Wanner, *Solving Ordinary
Differential Equations II*, section IV.5; Butcher's Radau IIA tableaux), hard-coded, not
recomputed: nodes c_j for K = 1..5 and the coefficient matrices A for K = 1, 2, 3.

The differentiation matrix D of ``rocketid.collocation`` (``ds/dtau`` at the K points
from the values at ``0, c_1..c_K``) and the Runge-Kutta matrix A of the same collocation
method are inverse to each other: ``s_j = s_0 + sum_l A_jl s'_l`` gives
``D[:, 1:] A = I`` and ``D[:, 0] = -D[:, 1:] 1``.
"""

from __future__ import annotations

import inspect
import math
import os
import subprocess
import sys
import textwrap

import numpy as np
import pytest
import sympy as sp

import rocketid as ri
from rocketid import codegen
from rocketid.collocation import (differentiation_matrix, element_nodes, graded_mesh, lagrange_basis,
                                  radau_points, uniform_mesh)
from rocketid.errors import SettingsError
from rocketid.nlp import ParameterTransform
from rocketid.solve import solve_nlp
from rocketid.symbolic import derive

S6 = math.sqrt(6.0)

# Radau IIA collocation nodes on [0, 1] (published values)
RADAU_NODES = {
    1: [1.0],
    2: [1.0 / 3.0, 1.0],
    3: [(4.0 - S6) / 10.0, (4.0 + S6) / 10.0, 1.0],
    4: [0.088587959512703947, 0.409466864440735, 0.787659461760847, 1.0],
    5: [0.057104196114517683, 0.276843013638124, 0.583590432368917, 0.860240135656219, 1.0],
}

# Radau IIA Runge-Kutta matrices A (published tableaux)
RADAU_A = {
    1: [[1.0]],
    2: [[5.0 / 12.0, -1.0 / 12.0],
        [3.0 / 4.0, 1.0 / 4.0]],
    3: [[(88.0 - 7.0 * S6) / 360.0, (296.0 - 169.0 * S6) / 1800.0, (-2.0 + 3.0 * S6) / 225.0],
        [(296.0 + 169.0 * S6) / 1800.0, (88.0 + 7.0 * S6) / 360.0, (-2.0 - 3.0 * S6) / 225.0],
        [(16.0 - S6) / 36.0, (16.0 + S6) / 36.0, 1.0 / 9.0]],
}

# The K = 2 differentiation matrix worked by hand from the nodes 0, 1/3, 1
D_K2 = [[-2.0, 1.5, 0.5],
        [2.0, -4.5, 2.5]]


# ---------------------------------------------------------------------------
# Radau points, differentiation matrices, Lagrange bases
# ---------------------------------------------------------------------------


@pytest.mark.parametrize("K", [1, 2, 3, 4, 5])
def test_radau_points_match_published_values(K):
    np.testing.assert_allclose(radau_points(K), RADAU_NODES[K], rtol=0, atol=5e-15)


@pytest.mark.parametrize("K", [1, 2, 3])
def test_differentiation_matrix_inverts_the_radau_iia_tableau(K):
    D = differentiation_matrix(K)
    assert D.shape == (K, K + 1)
    A = np.array(RADAU_A[K])
    np.testing.assert_allclose(D[:, 1:] @ A, np.eye(K), atol=1e-13)
    np.testing.assert_allclose(D[:, 0], -D[:, 1:].sum(axis=1), atol=1e-12)


def test_differentiation_matrix_k2_by_hand():
    np.testing.assert_allclose(differentiation_matrix(2), D_K2, atol=1e-14)


@pytest.mark.parametrize("K", [1, 2, 3, 4, 5])
def test_differentiation_matrix_is_exact_for_polynomials(K):
    """D differentiates every polynomial of degree <= K exactly at the published nodes."""
    D = differentiation_matrix(K)
    nodes = np.concatenate([[0.0], RADAU_NODES[K]])
    c = np.array(RADAU_NODES[K])
    for degree in range(K + 1):
        expected = degree * c ** (degree - 1) if degree else np.zeros(K)
        np.testing.assert_allclose(D @ nodes ** degree, expected, atol=1e-11, err_msg=f"degree {degree}")


@pytest.mark.parametrize("K", [1, 2, 3, 4, 5])
def test_lagrange_basis_partition_of_unity(K):
    nodes = element_nodes(K)
    tau = np.random.default_rng(K).uniform(-0.2, 1.2, 50)
    values, derivatives = lagrange_basis(nodes, tau)
    np.testing.assert_allclose(values.sum(axis=1), 1.0, atol=1e-12)
    np.testing.assert_allclose(derivatives.sum(axis=1), 0.0, atol=1e-10)
    # cardinal at the nodes, and reproduces the identity polynomial tau
    at_nodes, _ = lagrange_basis(nodes, nodes)
    np.testing.assert_allclose(at_nodes, np.eye(K + 1), atol=1e-13)
    np.testing.assert_allclose(values @ nodes, tau, atol=1e-12)


@pytest.mark.parametrize("K", [0, 6, 2.5, "3"])
def test_radau_points_reject_unsupported_k(K):
    with pytest.raises(SettingsError, match="K"):
        radau_points(K)


def test_meshes(ra66_spec):
    m = uniform_mesh(0.0, 66.0, 66, 4)
    assert m.n_elements == 66 and m.K == 4
    np.testing.assert_allclose(m.lengths, 1.0)
    assert m.node_times.size == 66 * 4 + 1
    g = graded_mesh(0.0, 66.0, 66, 3, refine_first=2)
    # the first 1 s element split geometrically 1 : 4 : 16, the rest untouched
    np.testing.assert_allclose(g.boundaries[:4], [0.0, 1 / 21, 5 / 21, 1.0])
    np.testing.assert_allclose(g.boundaries[3:], np.arange(1.0, 67.0))
    default = ri.default_mesh(ra66_spec)
    assert (default.n_elements, default.K) == (66, 4)
    np.testing.assert_array_equal(default.boundaries, ri.ra66_mesh().boundaries)



def test_the_default_mesh_puts_a_thrust_tables_sharp_corners_on_boundaries():
    """A thrust table sampled every 0.25 s with a tail-off starting at 7.75 s and ending at 10.25 s: those
    corners become element boundaries; the gentle corners of the burn and of an attitude program sampled
    every 0.5 s do not (the mesh is not made as fine as the samples)."""
    m = ri.Model("corners", 0.0, 20.0)
    y = m.state("y", 0.0)
    times = np.arange(0.0, 12.01, 0.25)
    thrust = np.interp(times, [0.0, 0.25, 4.0, 7.75, 10.25, 12.0], [0.0, 88.0, 114.0, 98.0, 0.0, 0.0])
    u = m.input("thrust", times=times, values=thrust)
    tt = np.arange(0.0, 20.01, 0.5)
    phi = m.input("phi", times=tt, values=np.radians(80 - 2 * np.sin(tt / 3)))
    m.ode({y: u + phi})
    m.output("y", y, sigma=1.0)
    from rocketid.solve import _sharp_corners
    bounds = ri.default_mesh(m.freeze()).boundaries
    assert {0.25, 7.75, 10.25} <= set(np.round(bounds, 9))
    assert not {0.5, 1.5, 4.25, 11.5} & set(np.round(bounds, 9))
    assert sorted(_sharp_corners(m.freeze(), 1.0)) == [0.25, 7.75, 10.25]   # not 4.0, a gentle corner (9.8 %)
    assert np.diff(bounds).max() <= 1.0 and bounds.size - 1 == 22          # 1 + 8 + 3 + 10 elements


# ---------------------------------------------------------------------------
# Generated code: deterministic, inspectable, cached
# ---------------------------------------------------------------------------


def _small_spec(name="osc", power=2):
    m = ri.Model(name, 0.0, 2.0)
    y = m.state("y", 1.0)
    z = m.state("z", 0.0, free=True)
    u = m.input("u", sp.cos(m.t))
    a = m.piecewise_linear("a", [0.0, 1.0, 2.0], [0.5, 0.4, 0.4], ties=[(1, 2)])
    k = m.parameter("k", 2.0)
    m.ode({y: z, z: -k * sp.sin(y) - a * z * y ** power + u})
    m.output("y", y, sigma=0.1)
    m.output("zs", (1 + k / 10) * z, sigma=0.1)
    return m.freeze()


def test_generated_source_is_deterministic_within_a_process():
    first = codegen.generate_source(derive(_small_spec()), "osc")
    second = codegen.generate_source(derive(_small_spec()), "osc")  # freshly built spec
    assert first == second


_SUBPROCESS = textwrap.dedent("""
    import hashlib, rocketid as ri
    from rocketid import codegen
    from rocketid.symbolic import derive
    src = codegen.generate_source(derive(ri.ra66()), "RA-66")
    print(hashlib.sha256(src.encode()).hexdigest())
""")


def test_generated_source_is_byte_identical_across_hash_seeds():
    """SymPy's set iteration order changes with PYTHONHASHSEED; the source must not."""
    digests = []
    for seed in ("1", "2"):
        env = dict(os.environ, PYTHONHASHSEED=seed)
        out = subprocess.run([sys.executable, "-c", _SUBPROCESS], env=env, capture_output=True, text=True,
                             check=True)
        digests.append(out.stdout.strip())
    assert len(digests[0]) == 64 and digests[0] == digests[1]


def test_generated_module_is_inspectable(tmp_path, monkeypatch):
    monkeypatch.setenv("ROCKETID_CACHE_DIR", str(tmp_path))
    gen = codegen.generate(_small_spec("inspectable"))
    src = inspect.getsource(gen.module.jacobian)
    assert src.startswith("def jacobian(Z, D):")
    assert inspect.getsource(gen.module) == gen.source == gen.path.read_text()
    assert gen.path.parent == tmp_path
    # the header documents the argument order
    assert "Z : (n, " in gen.source and "FINGERPRINT" in gen.source
    written = gen.write(tmp_path / "out")
    assert written.read_text() == gen.source


def test_cache_hit_skips_derivation(tmp_path, monkeypatch):
    monkeypatch.setenv("ROCKETID_CACHE_DIR", str(tmp_path))
    spec = _small_spec("cached")
    first = codegen.generate(spec)
    assert first.cached is False
    assert list(tmp_path.glob("rocketid_gen_*.py")) == [first.path]

    def no_derivation(*args, **kwargs):
        raise AssertionError("derive() ran although the generated module was cached")

    monkeypatch.setattr(codegen, "derive", no_derivation)
    second = codegen.generate(_small_spec("cached"))  # a fresh, equal spec
    assert second.cached is True
    assert second.source == first.source
    Z = np.random.default_rng(0).standard_normal((5, len(second.Z_NAMES)))
    D = np.random.default_rng(1).standard_normal((5, len(second.D_NAMES)))
    np.testing.assert_array_equal(second.residual(Z, D), first.residual(Z, D))
    # a different model (another equation) is not served from the cache
    with pytest.raises(AssertionError, match="derive"):
        codegen.generate(_small_spec("cached", power=3))


# ---------------------------------------------------------------------------
# Discretization error of RA-66 at the true parameters: within 0.01 m, m, m/s, 1 % of the noise
# (docs/design.md, 'Default mesh'; measured in docs/accuracy.md)
# ---------------------------------------------------------------------------


def _collocation_error(spec, clean, p_true, mesh):
    """Max |collocation - simulation| per channel, all parameters fixed at the truth."""
    pr = ri.prepare(spec, clean, mesh=mesh)
    nlp = pr.nlp.with_transform(ParameterTransform(np.zeros((len(p_true), 0)), np.asarray(p_true), ()))
    S, _ = pr.initial_states(p_true)
    sol = solve_nlp(nlp, nlp.initial_x(S, p_true))
    assert sol.success, sol.message
    assert nlp.n == nlp.m_ic + nlp.m_col  # square: the states are determined
    return {name: float(np.abs(y - clean[name].values).max())
            for name, y in zip(nlp.channel_names, nlp.outputs(sol.x))}


def test_default_discretization_is_within_one_percent_of_the_noise(ra66_spec, ra66_clean, ra66_p_true):
    mesh = ri.default_mesh(ra66_spec)
    assert (mesh.n_elements, mesh.K) == (66, 4)
    err = _collocation_error(ra66_spec, ra66_clean, ra66_p_true, mesh)
    assert set(err) == {"x", "h", "v"}
    assert max(err.values()) <= 0.01, err
    # measured 1.65e-3 m, 1.94e-3 m, 3.5e-4 m/s (docs/accuracy.md)
    assert err["x"] > 1e-4  # a sanity bound: the error is measured, not identically zero


def test_chapter_baseline_k3_is_not_within_one_percent(ra66_spec, ra66_clean, ra66_p_true):
    err = _collocation_error(ra66_spec, ra66_clean, ra66_p_true, ri.ra66_mesh(66, K=3))
    # 4.5e-2 m, all of it in the first element (docs/design.md 'Default mesh', docs/accuracy.md), also
    # measured by an independent implementation (benchmarks/peer_casadi.py)
    assert 0.03 < err["x"] < 0.06, err
    assert err["h"] > 0.01, err
