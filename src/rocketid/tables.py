"""Tabulated functions of one argument, as SymPy functions that generate compact code.

A sampled curve (a static firing's thrust every 0.1 s, a consumed-propellant table) evaluated at an
expression -- a motor's clock ``t_i + k (t - t_i)`` that depends on an estimated parameter -- cannot be a
known input (those are sampled at fixed times). Written as a sum of ramps (``v_0 + sum_j s_j Max(x - x_j,
0)``) it is exact, but a 249-sample table becomes 249 terms in every expression that holds it, in their
derivatives 249 Heaviside steps, and common-subexpression elimination over the model's Jacobian and
Hessian took 70 % of a diagnosis (22 minutes for each of Wren-H's motor cases).

:func:`table_function` makes instead one SymPy function per table: ``T(x)`` is the linear interpolation
of the samples (held at the end values outside them, as :func:`numpy.interp`), its derivative the
table's slope ``T'(x)`` (piecewise constant, zero outside), and the slope's derivative zero -- the Dirac
deltas at the samples are dropped, as for every kink in the generated code. Both print as one call to a
function of the generated module, whose samples are literal arrays at its top (:mod:`rocketid.codegen`),
and evaluate numerically through ``_imp_`` (``lambdify``) and at numbers (``T(2.5)`` is a Float).

The function's name holds a hash of the samples, so two tables never share a name, the same table always
gets the same class (and the same generated code), and the model's fingerprint changes with the samples.
"""

from __future__ import annotations

import copyreg
import hashlib
from typing import Sequence

import numpy as np
import sympy as sp
from sympy.core.function import FunctionClass

from .errors import ModelError

__all__ = ["TableFunction", "TableSlope", "table_function"]


class _TableClass(FunctionClass):
    """Metaclass of the table functions: a table's class pickles as the call that makes it (a worker process
    rebuilds it from the samples)."""


def _reduce_class(cls):
    if not cls.samples[0]:                  # the base classes (no samples) pickle by name
        return cls.__qualname__
    x, y = cls.samples
    maker = table_function if not cls.is_slope else _slope_of
    return maker, (x, y, cls.label)


copyreg.pickle(_TableClass, _reduce_class)


class TableFunction(sp.Function, metaclass=_TableClass):
    """Linear interpolation of a table (a class per table, made by :func:`table_function`).

    Attributes (of each table's class)
    ----------------------------------
    samples : (tuple, tuple)
        The abscissae (increasing) and values.
    label : str
        The name the table was given (the class name adds the samples' hash).
    """

    nargs = 1
    is_slope = False
    samples: tuple = ((), ())
    label = "table"
    slope: type | None = None

    @classmethod
    def eval(cls, x):
        if x.is_Number:
            return sp.Float(float(cls._imp_(float(x))))
        return None

    def fdiff(self, argindex=1):
        return type(self).slope(self.args[0])

    def _eval_is_real(self):
        return self.args[0].is_real


class TableSlope(TableFunction):
    """The slope of a table (piecewise constant, zero outside the samples); its own derivative is zero."""

    is_slope = True

    def fdiff(self, argindex=1):
        return sp.S.Zero


_CLASSES: dict = {}


def _digest(x: tuple, y: tuple) -> str:
    h = hashlib.sha256()
    h.update(np.asarray(x, float).tobytes())
    h.update(np.asarray(y, float).tobytes())
    return h.hexdigest()[:12]


def _interp(x: tuple, y: tuple):
    xa, ya = np.asarray(x, float), np.asarray(y, float)
    return lambda u: np.interp(u, xa, ya)


def _slope_values(x: tuple, y: tuple) -> np.ndarray:
    return np.diff(np.asarray(y, float)) / np.diff(np.asarray(x, float))


def _step(x: tuple, y: tuple):
    xa, s = np.asarray(x, float), _slope_values(x, y)

    def slope(u):
        u = np.asarray(u, float)
        i = np.searchsorted(xa, u, side="right") - 1
        inside = (i >= 0) & (i < s.size)
        return np.where(inside, s[np.clip(i, 0, s.size - 1)], 0.0)
    return slope


def table_function(x: Sequence[float], y: Sequence[float], label: str = "table") -> type:
    """The SymPy function of the table ``(x, y)``: ``table_function(times, thrust, "thrust")(clock)``.

    Parameters
    ----------
    x : sequence of float
        Abscissae, strictly increasing, at least two.
    y : sequence of float
        Values, finite, one per abscissa.
    label : str
        A name for the generated code (an identifier); the class is ``<label>_<hash of the samples>``.

    Returns
    -------
    type
        A :class:`TableFunction` subclass; call it on an expression.

    Raises
    ------
    ModelError
        Abscissae not increasing, fewer than two samples, lengths that differ, values not finite.
    """
    xs = tuple(float(v) for v in x)
    ys = tuple(float(v) for v in y)
    if len(xs) != len(ys) or len(xs) < 2:
        raise ModelError(f"table {label!r}: {len(xs)} abscissae and {len(ys)} values; give at least two of each, "
                         "as many values as abscissae")
    if not all(b > a for a, b in zip(xs, xs[1:])):
        raise ModelError(f"table {label!r}: the abscissae must increase strictly")
    if not np.all(np.isfinite(xs + ys)):
        raise ModelError(f"table {label!r}: the samples must be finite numbers")
    if not label.isidentifier():
        raise ModelError(f"table label {label!r} must be an identifier")
    key = (xs, ys, label)
    hit = _CLASSES.get(key)
    if hit is None:
        name = f"{label}_{_digest(xs, ys)}"
        slope = _slope_of(xs, ys, label)
        hit = _TableClass(name, (TableFunction,), {"samples": (xs, ys), "label": label, "slope": slope,
                                                     "_imp_": staticmethod(_interp(xs, ys)),
                                                     "__module__": __name__})
        _CLASSES[key] = hit
    return hit


def _slope_of(xs: tuple, ys: tuple, label: str) -> type:
    key = ("slope", xs, ys, label)
    hit = _CLASSES.get(key)
    if hit is None:
        hit = _TableClass(f"{label}_slope_{_digest(xs, ys)}", (TableSlope,),
                          {"samples": (xs, ys), "label": label, "_imp_": staticmethod(_step(xs, ys)),
                           "__module__": __name__})
        _CLASSES[key] = hit
    return hit
