"""Tabulated functions (rocketid.tables): a sampled curve evaluated at an expression of the parameters, as one
SymPy function whose generated code is one ``numpy.interp`` call -- checked against numpy's own interpolation
and against finite differences of it, in the generated code of a model that uses one."""

from __future__ import annotations

import pickle

import numpy as np
import pytest
import sympy as sp

import rocketid as ri
from rocketid.codegen import generate
from rocketid.errors import ModelError
from rocketid.tables import TableFunction, table_function

X = (0.0, 0.5, 1.0, 2.5, 4.0)
Y = (0.0, 900.0, 1000.0, 600.0, 0.0)


def test_a_table_is_numpys_interpolation_and_its_slope():
    T = table_function(X, Y, "thrust")
    assert issubclass(T, TableFunction) and T is table_function(X, Y, "thrust")        # one class per table
    assert T is not table_function(X, Y[:-1] + (1.0,), "thrust")
    assert float(T.slope(0.5)) == 200.0                     # at a sample: the slope of the segment after it
    for u in (-1.0, 0.25, 0.6, 1.7, 3.9, 5.0):
        assert float(T(u)) == pytest.approx(np.interp(u, X, Y), abs=1e-12)
        h = 1e-6
        fd = (np.interp(u + h, X, Y) - np.interp(u - h, X, Y)) / (2 * h)
        assert float(T.slope(u)) == pytest.approx(fd, abs=1e-6), u
    x, k = sp.symbols("x k")
    e = T(k * x)
    assert sp.diff(e, k) == x * T.slope(k * x) and sp.diff(e, k, 2) == 0      # kinks: no Dirac deltas
    f = sp.lambdify([x, k], [e, sp.diff(e, k)], "numpy")
    got = f(np.array([0.3, 1.2, 3.0]), 1.1)
    assert np.allclose(got[0], np.interp(1.1 * np.array([0.3, 1.2, 3.0]), X, Y))
    assert pickle.loads(pickle.dumps(e)) == e
    # a class pickles as the call that makes it (its samples); the base classes by name
    from rocketid.tables import TableSlope
    for cls in (T, T.slope, TableFunction, TableSlope):
        assert pickle.loads(pickle.dumps(cls)) is cls


@pytest.mark.parametrize("x, y, match", [((0.0,), (1.0,), "at least two"), ((0.0, 0.0), (1.0, 2.0), "increase"),
                                         ((0.0, 1.0), (1.0, np.nan), "finite"), ((0.0, 1.0), (1.0,), "as many")])
def test_a_bad_table_is_refused(x, y, match):
    with pytest.raises(ModelError, match=match):
        table_function(x, y, "thrust")


def test_generated_code_holds_the_table_once_and_evaluates_it(tmp_path, monkeypatch):
    """A body pushed by a tabulated force on a clock ``k t`` (k estimated): v' = T(k t). The generated module
    holds the samples as literal arrays and one function; the residual and its Jacobian in k (t T'(k t)) are
    numpy's interpolation and the table's slope."""
    monkeypatch.setenv("ROCKETID_CACHE_DIR", str(tmp_path))
    m = ri.Model("pushed", 0.0, 4.0)
    v = m.state("v", 0.0)
    k = m.parameter("k", 1.0, bounds=(0.5, 2.0))
    m.ode({v: table_function(X, Y, "force")(k * m.t)})
    m.output("v", v, 1.0)
    spec = m.freeze()
    gen = generate(spec, use_cache=False)
    source = gen.source if hasattr(gen, "source") else open(gen.module.__file__).read()
    assert source.count("numpy.interp(x, _X_force_") == 1 and "_X_force_" in source
    assert "Max(" not in source and "Heaviside" not in source
    mod = gen.module
    names = list(mod.Z_NAMES)
    t = np.array([0.3, 1.2, 3.0])
    Z = np.zeros((t.size, len(names)))
    D = np.zeros((t.size, len(mod.D_NAMES)))
    D[:, 0] = t
    for j, n in enumerate(names):
        if n == "k":
            Z[:, j] = 1.1
    res = mod.residual(Z, D)
    jac = mod.jacobian(Z, D)
    jk = [i for i, c in enumerate(mod.JAC_COLS) if names[c] == "k"]
    assert np.allclose(np.abs(res[:, 0]), np.interp(1.1 * t, X, Y))
    slope = np.array([float(table_function(X, Y, "force").slope(1.1 * u)) for u in t])
    assert np.allclose(np.abs(jac[:, jk[0]]), np.abs(t * slope))


def test_the_point_hessian_holds_the_tables_slope(tmp_path, monkeypatch):
    """v' = k T(k t): d2F/dk2 = 2 t T'(k t) (T'' is zero between samples), in the Hessian's companion module
    (made on first use) as a call of the slope's function, equal to numpy's slope of the samples."""
    monkeypatch.setenv("ROCKETID_CACHE_DIR", str(tmp_path))
    m = ri.Model("pushed", 0.0, 4.0)
    v = m.state("v", 0.0)
    k = m.parameter("k", 1.0, bounds=(0.5, 2.0))
    T = table_function(X, Y, "force")
    m.ode({v: k * T(k * m.t)})
    m.output("v", v, 1.0)
    gen = generate(m.freeze(), use_cache=False)
    assert f"def _{T.slope.__name__}(x):" in gen.hessian_source
    names = list(gen.module.Z_NAMES)
    t = np.array([0.3, 1.2, 3.0])
    Z = np.zeros((t.size, len(names)))
    Z[:, names.index("k")] = 1.1
    D = np.zeros((t.size, len(gen.module.D_NAMES)))
    D[:, 0] = t
    H = gen.hessian(Z, D, np.ones((t.size, 1)))
    (j,) = [i for i, (r, c) in enumerate(zip(gen.HESS_ROWS, gen.HESS_COLS)) if names[r] == names[c] == "k"]
    slope = np.array([float(T.slope(1.1 * u)) for u in t])
    assert np.allclose(np.abs(H[:, j]), np.abs(2 * t * slope))
