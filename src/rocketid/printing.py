"""NumPy printing of model expressions, shared by the generated code and the simulator.

SymPy's NumPy printer writes a ``Piecewise`` as ``numpy.select``, which needs every condition to be a
boolean array; a condition that is itself piecewise (the Mach number through a layered speed of sound)
or a scalar (a condition on a constant) breaks it. :class:`WherePrinter` writes nested ``numpy.where``
instead, which keeps boolean results boolean and broadcasts scalars.
"""

from __future__ import annotations

from sympy.printing.numpy import NumPyPrinter

__all__ = ["WherePrinter"]


class WherePrinter(NumPyPrinter):
    """NumPy printer with ``Piecewise`` as nested ``numpy.where`` (module notes)."""

    def _print_Piecewise(self, expr):
        args = list(expr.args)
        if args[-1].cond == True:  # noqa: E712 (SymPy's true)
            out = self._print(args.pop().expr)
        else:
            out = "numpy.nan"
        for e, c in reversed(args):
            out = f"numpy.where({self._print(c)}, {self._print(e)}, {out})"
        return out
