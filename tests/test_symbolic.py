"""``rocketid.symbolic.derivative`` against ``sympy.diff`` (unit tier).

The code generator differentiates with its own walk over the expression (SymPy's rules,
each node's free symbols computed once, every ``(node, variable)`` derivative remembered).
The truth here is SymPy's ``diff`` itself: the two must give the *same expression*, node
for node, so the generated code is unchanged. Checked on the expanded residuals and
outputs of RA-66M with the catalogue's wind and back-pressure effects (Piecewise, Max,
exp, cos, sin, powers) and on a small model using every other kind of node a user's model
may bring (Abs, atan2, tanh, Min, Heaviside, sqrt, log, a user-defined function with its
own ``fdiff``, one without), first and second derivatives.
"""

from __future__ import annotations

import pytest
import sympy as sp

import rocketid as ri
from rocketid import symbolic
from rocketid.cases import ra66m
from rocketid.diagnostics import with_effects


class _Bump(sp.Function):
    """A user function with its own derivative rule."""

    def fdiff(self, argindex=1):
        return -2 * self.args[0] * _Bump(self.args[0])


class _Opaque(sp.Function):
    """A user function SymPy can only differentiate as an unevaluated Derivative."""


def _exotic_exprs():
    x, y, z = sp.symbols("x y z")
    return (x, y, z), [
        sp.Abs(x - 2 * y) * sp.atan2(y, x + 3) + sp.tanh(z * x),
        sp.Min(x, y ** 2, z) + sp.Heaviside(x - 1) * sp.sqrt(1 + y ** 2),
        sp.log(1 + x ** 2) / (z + 4) + _Bump(x * y) + _Opaque(x + z),
        sp.Piecewise((x ** 3, x < y), (sp.exp(-y) * z, True)) * sp.Max(z - 0.5, 0) ** 2,
        x ** y + sp.cos(x) ** sp.sin(z),
    ]


def _model_exprs():
    spec = with_effects(ra66m(), ["wind", "back_pressure"])
    z = (*spec.state_symbols, *spec.derivative_symbols, *spec.local_symbols)
    exprs = [spec.expand(e) for e in spec.equations] + [spec.expand(o.expr) for o in spec.outputs]
    return z, exprs


@pytest.mark.parametrize("case", ["exotic", "ra66m_wind_back_pressure"])
def test_derivative_is_sympys_diff_node_for_node(case):
    vars_, exprs = _exotic_exprs() if case == "exotic" else _model_exprs()
    n_checked = 0
    for e in exprs:
        for v in vars_:
            d = symbolic.derivative(e, v)
            assert d == sp.diff(e, v), f"d/d{v} of {e}"
            n_checked += 1
            if d != 0:
                for w in vars_[:6]:
                    assert symbolic.derivative(d, w) == sp.diff(d, w), f"d2/d{v}d{w} of {e}"
    assert n_checked >= 15


def test_derive_gives_the_templates_of_sympys_diff(monkeypatch):
    """The whole point template (residuals, Jacobian, Hessian and their sparsity) is the same
    with SymPy's ``diff`` in place of the fast one, and a second derivation (from the memo) too."""
    spec = with_effects(ri.ra66(), ["thrust_level", "density"])
    fast = symbolic.derive(spec)
    again = symbolic.derive(spec)
    monkeypatch.setattr(symbolic, "derivative", sp.diff)
    reference = symbolic.derive(spec)
    assert fast == reference
    assert again == reference
    assert len(reference.point.hess_exprs) > 10


def test_the_point_hessian_is_generated_on_first_use(tmp_path, monkeypatch):
    """The main module has no point Hessian; its first use generates the companion module, whose
    functions are those of the single module made from the full derivation."""
    import importlib.util

    import numpy as np

    from rocketid import codegen
    monkeypatch.setenv("ROCKETID_CACHE_DIR", str(tmp_path))
    spec = with_effects(ri.ra66(), ["thrust_level"])
    gen = codegen.generate(spec)
    assert "def hessian" not in gen.source and "def jacobian" in gen.source
    assert not gen.hessian_path.exists()
    full = tmp_path / "full" / "rocketid_full_module.py"
    full.parent.mkdir()
    full.write_text(codegen.generate_source(symbolic.derive(spec), spec.name))
    mspec = importlib.util.spec_from_file_location("rocketid_full_module", full)
    ref = importlib.util.module_from_spec(mspec)
    mspec.loader.exec_module(ref)
    assert gen.HESS_ROWS == ref.HESS_ROWS and gen.HESS_COLS == ref.HESS_COLS and len(ref.HESS_ROWS) > 5
    assert gen.hessian_path.exists()
    rng = np.random.default_rng(3)
    n = 7
    Z = rng.uniform(0.1, 2.0, (n, len(gen.Z_NAMES)))
    Z[:, 1] *= 1e4                                  # altitudes in the atmosphere's range
    D = rng.uniform(0.1, 2.0, (n, len(gen.D_NAMES)))
    L = rng.standard_normal((n, gen.N_RESIDUALS))
    np.testing.assert_array_equal(gen.hessian(Z, D, L), ref.hessian(Z, D, L))
    np.testing.assert_array_equal(gen.jacobian(Z, D), ref.jacobian(Z, D))
    again = codegen.generate(spec)                  # both files from the cache
    assert again.cached and again.hessian_source == gen.hessian_source


def test_the_score_test_does_not_generate_the_augmented_models_hessian(tmp_path, monkeypatch):
    from rocketid.diagnostics import rank_candidates
    monkeypatch.setenv("ROCKETID_CACHE_DIR", str(tmp_path))
    spec = ri.ra66()
    data = ri.simulate_measurements(spec, ri.ra66_truth(spec), ri.ra66_times(), seed=0)
    fit = ri.estimate(spec, data, mesh=ri.default_mesh(spec, refine_first=3))
    ranking = rank_candidates(fit, ["thrust_level", "bias_h", "wind"])
    assert ranking.candidates
    mains = sorted(p for p in tmp_path.glob("rocketid_gen_*.py") if not p.stem.endswith("_hessian"))
    companions = sorted(tmp_path.glob("rocketid_gen_*_hessian.py"))
    assert len(mains) == 2 and len(companions) == 1    # the base model's (its fit solved with it)
