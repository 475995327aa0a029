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

__all__ = ["PointTemplate", "OutputTemplate", "SymbolicModel", "derive", "derive_hessian", "derivative"]


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
    """The templates of a model, ready for code generation (``hessian`` False: the point
    template's Hessian was not derived)."""

    fingerprint: str
    point: PointTemplate
    outputs: tuple
    hessian: bool = True


def _diff(expr: sp.Expr, var: sp.Symbol) -> sp.Expr:
    """``d expr / d var`` with Dirac deltas (from kinks such as Max or Abs) dropped:
    they live on a set of measure zero and have no value a solver could use."""
    d = derivative(expr, var)
    if d.has(sp.DiracDelta):
        d = d.replace(sp.DiracDelta, lambda *args: sp.S.Zero)
    return d


# ---------------------------------------------------------------------------
# Differentiation: SymPy's rules, without SymPy's per-node overhead
# ---------------------------------------------------------------------------
#
# ``sympy.diff`` builds a ``Derivative`` for every node it visits, and each one walks
# its whole subtree for its free symbols and for unevaluated derivatives: on the deep
# expressions of an ascent model (a layered atmosphere inside Mach inside a drag table)
# that is quadratic in the depth, and most of a model's code-generation time.
# :func:`derivative` applies the same rules as SymPy (the same constructor calls on the
# same arguments, so the result is the same expression, to the node) with the free symbols
# of every node computed once, and remembers each ``(node, variable)`` derivative: the
# Hessian differentiates the Jacobian's entries, which share subtrees, and a model
# extended by an effect shares most of its subtrees with the model it extends, so a
# diagnosis that generates ten extended models derives the shared part once. A node
# type without a known rule is differentiated by SymPy itself.

_MEMO_MAX = 400_000
_FREE: dict = {}
_DERIV: dict = {}
_RULES: dict = {}


def _owner(cls: type, name: str):
    for k in cls.__mro__:
        if name in k.__dict__:
            return k
    return None


def _rule(cls: type) -> str:
    """Which of SymPy's differentiation rules a node class uses ("" = let SymPy do it)."""
    rule = _RULES.get(cls)
    if rule is None:
        from sympy.functions.elementary.miscellaneous import MinMaxBase
        ev, evn = _owner(cls, "_eval_derivative"), _owner(cls, "_eval_derivative_n_times")
        if cls is sp.Add:
            rule = "add"
        elif cls is sp.Mul:
            rule = "mul"
        elif cls is sp.Pow:
            rule = "pow"
        elif cls is sp.Piecewise:
            rule = "piecewise"
        elif ev in (sp.Function, MinMaxBase) and evn is sp.Basic:
            rule = "chain"
        else:
            rule = ""
        _RULES[cls] = rule
    return rule


def _free(e) -> frozenset:
    """``e.free_symbols``, computed once per node."""
    if e.is_Symbol:
        return frozenset((e,))
    if not e.args:
        return frozenset(e.free_symbols)
    hit = _FREE.get(e)
    if hit is None:
        if _owner(type(e), "free_symbols") is sp.Basic:
            hit = frozenset().union(*map(_free, e.args))
        else:
            hit = frozenset(e.free_symbols)
        if len(_FREE) >= _MEMO_MAX:
            _FREE.clear()
        _FREE[e] = hit
    return hit


def derivative(expr: sp.Expr, var: sp.Symbol) -> sp.Expr:
    """``sympy.diff(expr, var)`` for a symbol ``var``: the same expression, computed once per
    ``(node, var)`` in this process (see the notes above)."""
    if var not in _free(expr):
        return sp.S.Zero
    if expr == var:
        return sp.S.One
    key = (expr, var)
    hit = _DERIV.get(key)
    if hit is not None:
        return hit
    rule = _rule(type(expr))
    args = expr.args
    if rule == "add":
        out = sp.Add(*[derivative(a, var) for a in args])
    elif rule == "mul":
        # Mul._eval_derivative_n_times at n = 1: the Leibniz rule, one factor differentiated per term
        out = sp.Add(*[sp.Mul(*args[:i], derivative(a, var), *args[i + 1:]) for i, a in enumerate(args)])
    elif rule == "pow":
        base, ex = args
        dbase, dexp = derivative(base, var), derivative(ex, var)
        out = expr * (dexp * sp.log(base) + dbase * ex / base)
    elif rule == "piecewise":
        out = sp.Piecewise(*[(derivative(e, var), c) for e, c in args])
    elif rule == "chain":
        from sympy.core.function import ArgumentIndexError
        terms = []
        try:
            for i, a in enumerate(args, 1):
                da = derivative(a, var)
                if da.is_zero:
                    continue
                terms.append(expr.fdiff(i) * da)
            out = sp.Add(*terms)
        except ArgumentIndexError:
            out = sp.diff(expr, var)
    else:
        out = sp.diff(expr, var)
    if len(_DERIV) >= _MEMO_MAX:
        _DERIV.clear()
    _DERIV[key] = out
    return out


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


def _point_jacobian(spec: ModelSpec) -> tuple:
    """``(z, d, lam, residuals, rows)``: ``rows[k]`` maps the z index of each structural non-zero
    of ``dF_k/dz`` to its expression."""
    z, d = point_variables(spec)
    lam = tuple(sp.Symbol(f"lam_{s}") for s in spec.state_symbols)
    residuals = spec.expanded_equations
    rows = []
    for F in residuals:
        row = {}
        for j, zj in enumerate(z):
            dF = _diff(F, zj)
            if _nonzero(dF):
                row[j] = dF
        rows.append(row)
    return z, d, lam, residuals, rows


def _point_hessian(z: tuple, lam: tuple, rows: list) -> tuple:
    """``(hess_rows, hess_cols, hess_exprs)``: the lower triangle of ``d2(sum_k lam_k F_k)/dz2``."""
    hess: dict[tuple[int, int], sp.Expr] = {}
    for k, row in enumerate(rows):
        cols = sorted(row)
        for a in cols:
            for b in cols:
                if b > a:
                    continue
                d2 = _diff(row[b], z[a])
                if _nonzero(d2):
                    hess[(a, b)] = hess.get((a, b), sp.S.Zero) + lam[k] * d2
    keys = sorted(hess)
    return tuple(a for a, _ in keys), tuple(b for _, b in keys), tuple(hess[k] for k in keys)


def derive_hessian(spec: ModelSpec) -> PointTemplate:
    """The point template of ``spec`` with its Hessian (the part :func:`derive` leaves out with
    ``hessian=False``; the first derivatives it repeats come from the memo of :func:`derivative`)."""
    return derive(spec, hessian=True, outputs=False).point


def derive(spec: ModelSpec, *, hessian: bool = True, outputs: bool = True) -> SymbolicModel:
    """Derive the residual and output templates of ``spec`` with their exact
    first and second derivatives.

    Parameters
    ----------
    spec : ModelSpec
    hessian : bool
        Also the point template's Hessian (False: its ``hess_*`` fields are empty; an
        analysis that needs only first derivatives, such as the score test, skips the
        costliest part).
    outputs : bool
        Also the output templates (False: none).

    Returns
    -------
    SymbolicModel
    """
    z, d, lam, residuals, rows = _point_jacobian(spec)
    jac_rows = [k for k, row in enumerate(rows) for _ in sorted(row)]
    jac_cols = [j for row in rows for j in sorted(row)]
    jac_exprs = [row[j] for row in rows for j in sorted(row)]
    hess_rows, hess_cols, hess_exprs = _point_hessian(z, lam, rows) if hessian else ((), (), ())
    point = PointTemplate(
        z=z, d=d, lam=lam, residuals=residuals,
        jac_rows=tuple(jac_rows), jac_cols=tuple(jac_cols), jac_exprs=tuple(jac_exprs),
        hess_rows=hess_rows, hess_cols=hess_cols, hess_exprs=hess_exprs,
    )
    if not outputs:
        return SymbolicModel(fingerprint=spec.fingerprint(), point=point, outputs=(), hessian=hessian)

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
    return SymbolicModel(fingerprint=spec.fingerprint(), point=point, outputs=tuple(outputs), hessian=hessian)
