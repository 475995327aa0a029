"""Symbolic derivatives: one point's residual template and one sample's output template.

The collocated NLP is built by replicating two small templates, never by
writing one expression per point:

* the *point template* evaluates the model residuals ``F(z; d)`` at one
  collocation point, with ``z = (s, ds/dt, l)`` the point variables (states,
  their derivatives, local parameter values) and ``d = (t, u)`` the point's
  data (time, inputs). Its exact Jacobian ``dF/dz`` and the Hessian of
  ``sum_k lambda_k F_k`` with respect to ``z`` (lower triangle) are derived
  here;
* one *output template* per measured channel evaluates ``g(u; t)`` at one
  sample with ``u = (s, ds/dt, scalar parameters)``, with its gradient and
  Hessian.

Sparsity patterns are computed once, symbolically: an entry is structural
when its derivative is not identically zero. Everything is ordered by the
model's declaration order, so the same model gives the same templates.

Notation
--------
=======  ============================================================
``z``    point variables ``(s_1..s_n, ds_1..ds_n, l_1..l_m)``
``d``    point data ``(t, u_1..u_r)``
``F``    residuals, one per state
``lam``  multipliers of the residuals at the point
``u``    output variables ``(s_1..s_n, ds_1..ds_n, p_1..p_q)``
=======  ============================================================
"""

from __future__ import annotations

from dataclasses import dataclass

import sympy as sp

from .model import ModelSpec

__all__ = ["PointTemplate", "OutputTemplate", "SymbolicModel", "derive"]


@dataclass(frozen=True)
class PointTemplate:
    """Residuals at one collocation point and their exact derivatives.

    Attributes
    ----------
    z : tuple of sympy.Symbol
        Point variables, length ``nz``.
    d : tuple of sympy.Symbol
        Point data, length ``nd``.
    lam : tuple of sympy.Symbol
        Multipliers, one per residual.
    residuals : tuple of sympy.Expr
        ``F_k(z, d)``, one per state.
    jac_rows, jac_cols : tuple of int
        Structural non-zeros of ``dF/dz`` (residual index, z index).
    jac_exprs : tuple of sympy.Expr
    hess_rows, hess_cols : tuple of int
        Lower triangle (``row >= col``) of ``d2(sum lam_k F_k)/dz2``.
    hess_exprs : tuple of sympy.Expr
    """

    z: tuple
    d: tuple
    lam: tuple
    residuals: tuple
    jac_rows: tuple
    jac_cols: tuple
    jac_exprs: tuple
    hess_rows: tuple
    hess_cols: tuple
    hess_exprs: tuple


@dataclass(frozen=True)
class OutputTemplate:
    """One measured channel ``g(u; t)`` and its exact derivatives.

    Attributes
    ----------
    name : str
    u : tuple of sympy.Symbol
        Output variables (shared by all channels).
    expr : sympy.Expr
    grad_idx : tuple of int
        Structural non-zeros of ``dg/du``.
    grad_exprs : tuple of sympy.Expr
    hess_rows, hess_cols : tuple of int
        Lower triangle of ``d2 g/du2``.
    hess_exprs : tuple of sympy.Expr
    linear : bool
        True when ``g`` is affine in ``u`` with constant coefficients (then the
        objective's Hessian is constant and is formed once).
    """

    name: str
    u: tuple
    expr: sp.Expr
    grad_idx: tuple
    grad_exprs: tuple
    hess_rows: tuple
    hess_cols: tuple
    hess_exprs: tuple
    linear: bool


@dataclass(frozen=True)
class SymbolicModel:
    """The templates of a model, ready for code generation."""

    fingerprint: str
    point: PointTemplate
    outputs: tuple


def _diff(expr: sp.Expr, var: sp.Symbol) -> sp.Expr:
    """``d expr / d var`` with Dirac deltas (from kinks such as Max or Abs) dropped:
    they live on a set of measure zero and have no value a solver could use."""
    d = sp.diff(expr, var)
    if d.has(sp.DiracDelta):
        d = d.replace(sp.DiracDelta, lambda *args: sp.S.Zero)
    return d


def _nonzero(expr: sp.Expr) -> bool:
    return not (expr == 0 or expr.is_zero is True)


def point_variables(spec: ModelSpec) -> tuple[tuple, tuple]:
    """``(z, d)``: the point variables and data symbols of the residual template."""
    z = (*spec.state_symbols, *spec.derivative_symbols, *spec.local_symbols)
    d = (spec.t, *spec.input_symbols)
    return z, d


def output_variables(spec: ModelSpec) -> tuple:
    """``u``: the output template's variables (states, derivatives, scalar parameters)."""
    init = {s.initial_parameter for s in spec.states if s.free}
    scal = tuple(p.symbol for p in spec.parameters if p.family is None and p.symbol not in init)
    return (*spec.state_symbols, *spec.derivative_symbols, *scal)


def derive(spec: ModelSpec) -> SymbolicModel:
    """Derive the residual and output templates of ``spec`` with their exact
    first and second derivatives.

    Parameters
    ----------
    spec : ModelSpec

    Returns
    -------
    SymbolicModel
    """
    z, d = point_variables(spec)
    lam = tuple(sp.Symbol(f"lam_{s}") for s in spec.state_symbols)
    residuals = tuple(spec.expand(e) for e in spec.equations)

    jac_rows, jac_cols, jac_exprs = [], [], []
    hess: dict[tuple[int, int], sp.Expr] = {}
    for k, F in enumerate(residuals):
        row = {}
        for j, zj in enumerate(z):
            dF = _diff(F, zj)
            if _nonzero(dF):
                row[j] = dF
                jac_rows.append(k)
                jac_cols.append(j)
                jac_exprs.append(dF)
        cols = sorted(row)
        for a in cols:
            for b in cols:
                if b > a:
                    continue
                d2 = _diff(row[b], z[a])
                if _nonzero(d2):
                    hess[(a, b)] = hess.get((a, b), sp.S.Zero) + lam[k] * d2
    keys = sorted(hess)
    point = PointTemplate(
        z=z, d=d, lam=lam, residuals=residuals,
        jac_rows=tuple(jac_rows), jac_cols=tuple(jac_cols), jac_exprs=tuple(jac_exprs),
        hess_rows=tuple(a for a, _ in keys), hess_cols=tuple(b for _, b in keys),
        hess_exprs=tuple(hess[k] for k in keys),
    )

    u = output_variables(spec)
    outputs = []
    for o in spec.outputs:
        g = spec.expand(o.expr)
        grad = {j: _diff(g, uj) for j, uj in enumerate(u)}
        grad = {j: e for j, e in grad.items() if _nonzero(e)}
        hrows, hcols, hexprs = [], [], []
        for a in sorted(grad):
            for b in sorted(grad):
                if b > a:
                    continue
                d2 = _diff(grad[b], u[a])
                if _nonzero(d2):
                    hrows.append(a)
                    hcols.append(b)
                    hexprs.append(d2)
        const_grad = all(not (e.free_symbols) for e in grad.values())
        outputs.append(OutputTemplate(
            name=o.name, u=u, expr=g, grad_idx=tuple(sorted(grad)),
            grad_exprs=tuple(grad[j] for j in sorted(grad)),
            hess_rows=tuple(hrows), hess_cols=tuple(hcols), hess_exprs=tuple(hexprs),
            linear=(not hexprs) and const_grad and spec.t not in g.free_symbols,
        ))
    return SymbolicModel(fingerprint=spec.fingerprint(), point=point, outputs=tuple(outputs))
