"""The NLP as a frozen value: one structure, a frozen transform, one owner of x (unit tier).

A small decay model with one linear and one nonlinear output; no IPOPT solve.
"""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest
import sympy as sp

import rocketid as ri
from rocketid.errors import SettingsError
from rocketid.nlp import ParameterTransform


@pytest.fixture(scope="module")
def decay():
    """``y' = -k y`` (y0 free) with y measured and the nonlinear output ``e = exp(-y)``."""
    m = ri.Model("decay_nlp", 0.0, 2.0)
    y = m.state("y", 1.0, free=True, bounds=(0.1, 10.0))
    k = m.parameter("k", 0.3, bounds=(0.0, 5.0))
    m.ode({y: -k * y})
    m.output("y", y, sigma=0.1)
    m.output("e", sp.exp(-y), sigma=0.05)
    spec = m.freeze()
    t = np.arange(1, 41) * 0.05
    truth = 1.3 * np.exp(-0.7 * t)
    data = ri.Measurements.from_arrays(t, {"y": truth, "e": np.exp(-truth)})
    return ri.prepare(spec, data, mesh=ri.uniform_mesh(0.0, 2.0, 8, 3))


def _point(prepared, p):
    S, _ = prepared.initial_states(p)
    return S


def test_the_nlp_is_a_frozen_value(decay):
    nlp = decay.nlp
    with pytest.raises(dataclasses.FrozenInstanceError):
        nlp.transform = None
    with pytest.raises(ValueError):
        nlp.transform.P[0, 0] = 2.0  # read-only
    # the Hessian's structure is built once per structure and shared by re-offset copies
    rows, cols = nlp.hessianstructure()
    assert rows.size > 0 and np.all(rows >= cols)
    other = nlp.with_offset(np.array([0.1, 0.0]))
    assert other.hessianstructure()[0] is rows and other.jacobianstructure()[0] is nlp.jacobianstructure()[0]


def test_output_functions_are_typed_and_carry_their_sparsity(decay):
    outs = decay.nlp.generated.outputs
    assert [o.name for o in outs] == ["y", "e"] and [o.linear for o in outs] == [True, False]
    e = outs[1]
    n_u = len(decay.nlp.generated.U_NAMES)
    U = np.random.default_rng(0).uniform(-1, 1, (2, n_u))  # the output variables at two samples
    U[:, e.grad_idx[0]] = [0.3, 1.2]
    D = np.zeros((2, 1))
    y, g, h = e.evaluate(U, D, order=2)
    # against the exact derivatives of exp(-u), written independently
    u = U[:, e.grad_idx[0]]
    np.testing.assert_allclose(y, np.exp(-u), rtol=1e-14)
    np.testing.assert_allclose(g[:, 0], -np.exp(-u), rtol=1e-14)
    np.testing.assert_allclose(h[:, 0], np.exp(-u), rtol=1e-14)
    assert e.hess_rows.tolist() == e.hess_cols.tolist() == [e.grad_idx[0]]


def test_the_layout_owns_x_and_the_rows(decay):
    nlp = decay.nlp
    lay = nlp.layout
    S = _point(decay, decay.spec.guess)
    x = nlp.initial_x(S, np.array([1.2, 0.6]))
    assert lay.n == nlp.n == x.size and lay.m == nlp.m
    np.testing.assert_array_equal(lay.states(x), S.ravel())
    np.testing.assert_array_equal(lay.parameters(x), [1.2, 0.6])
    np.testing.assert_array_equal(lay.pack(lay.states(x), lay.reduced(x)), x)
    # the rows partition the constraint vector: the initial condition, then the collocation rows
    c = nlp.constraints(x)
    assert c[lay.equality_rows].size == lay.n_ic + lay.n_collocation == c.size
    assert lay.collocation_rows.start == lay.n_ic == 1
    x2 = lay.with_parameters(x, np.array([2.0, 0.1]))
    np.testing.assert_array_equal(lay.states(x2), lay.states(x))
    np.testing.assert_allclose(lay.parameters(x2), [2.0, 0.1])


def test_with_offset_shares_the_structure_and_moves_only_the_offset(decay):
    nlp = decay.nlp
    P = np.array([[1.0], [0.5]])
    a = nlp.with_transform(ParameterTransform(P, np.array([0.2, 0.3]), ("r",)))
    b = a.with_offset(np.array([0.4, 0.4]))  # c moved along P: every p of a is reachable in b
    assert b.structure is a.structure and b.transform.P is not None
    assert np.array_equal(b.transform.P, a.transform.P) and b.transform.names == ("r",)
    np.testing.assert_array_equal(a.transform.c, [0.2, 0.3])  # a is unchanged
    # the same physical point p through either offset gives the same constraints, objective and residuals
    S = _point(decay, decay.spec.guess)
    r_a = 0.9
    p = P[:, 0] * r_a + np.array([0.2, 0.3])
    xa = a.layout.pack(S.ravel(), [r_a])
    xb = b.layout.with_parameters(xa, p)
    np.testing.assert_allclose(b.layout.parameters(xb), p, rtol=1e-14)
    np.testing.assert_allclose(b.constraints(xb)[b.layout.equality_rows], a.constraints(xa)[a.layout.equality_rows],
                               atol=1e-12)
    assert b.objective(xb) == pytest.approx(a.objective(xa), rel=1e-12)
    # the bounds of p are linear rows, shifted by the offset
    lo, hi = decay.spec.lower, decay.spec.upper
    np.testing.assert_allclose(b.c_lower[b.layout.linear_rows], lo - [0.4, 0.4])
    np.testing.assert_allclose(b.c_upper[b.layout.linear_rows], hi - [0.4, 0.4])
    with pytest.raises(SettingsError, match="offset has shape"):
        a.with_offset(np.zeros(3))


def test_a_transform_is_checked():
    with pytest.raises(SettingsError, match="offset has shape"):
        ParameterTransform(np.eye(2), np.zeros(3), ("a", "b"))
    with pytest.raises(SettingsError, match="1 names for 2 reduced parameters"):
        ParameterTransform(np.eye(2), np.zeros(2), ("a",))


def _tiny_spec():
    m = ri.Model("nocache_probe", 0.0, 1.0)
    y = m.state("y", 1.0)
    k = m.parameter("k", 0.5, bounds=(0.0, 2.0))
    m.ode({y: -k * y})
    m.output("y", y, sigma=1.0)
    return m.freeze()


def test_use_cache_false_neither_reads_nor_writes_the_cache(tmp_path, monkeypatch):
    from rocketid.codegen import generate
    monkeypatch.setenv("ROCKETID_CACHE_DIR", str(tmp_path / "cache"))
    spec = _tiny_spec()
    g = generate(spec, use_cache=False)
    assert not (tmp_path / "cache").exists() or not any((tmp_path / "cache").iterdir())
    assert not g.cached and g.path.is_file() and g.path.read_text() == g.source
    cached = generate(spec)  # now it is written, and the next call reads it
    assert cached.path.parent == tmp_path / "cache" and generate(spec).cached
    assert cached.source == g.source  # deterministic: the same model gives the same source
    assert not generate(spec, use_cache=False).cached


def test_use_cache_false_leaves_no_folder_behind(tmp_path, monkeypatch):
    import gc

    from rocketid.codegen import generate
    monkeypatch.setenv("ROCKETID_CACHE_DIR", str(tmp_path / "cache"))
    g = generate(_tiny_spec(), use_cache=False)
    folder = g.path.parent
    assert folder.is_dir() and g.hessian_source            # the Hessian is written beside it on first use
    del g
    gc.collect()
    assert not folder.exists()


def test_the_cache_key_follows_the_generator(monkeypatch, tmp_path):
    from rocketid import codegen
    monkeypatch.setenv("ROCKETID_CACHE_DIR", str(tmp_path))
    spec = _tiny_spec()
    before = codegen.generate(spec).path.name
    monkeypatch.setattr(codegen, "generator_fingerprint", lambda: "a-changed-generator")
    assert codegen.generate(spec).path.name != before


def test_unique_keys_is_numpy_unique_on_both_paths(monkeypatch):
    """The Hessian structure's duplicate entries are merged by marking a dense array over the key range, or by
    :func:`numpy.unique` beyond :data:`~rocketid.nlp.DENSE_KEYS`: both give numpy's unique keys and inverse."""
    from rocketid import nlp
    rng = np.random.default_rng(4)
    key = rng.integers(0, 5000, size=20000).astype(np.int64) * 7
    want_u, want_i = np.unique(key, return_inverse=True)
    for limit in (nlp.DENSE_KEYS, 100):          # dense, then the fallback (key range above the limit)
        monkeypatch.setattr(nlp, "DENSE_KEYS", limit)
        u, i = nlp._unique_keys(key)
        assert np.array_equal(u, want_u) and np.array_equal(i, want_i) and u.dtype == np.int64
