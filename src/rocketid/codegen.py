"""Code generation: the symbolic templates become vectorized NumPy functions.

Each template function takes the variables of many points at once, one row a
point, and returns one column per structural non-zero, in the order of the
sparsity pattern stored beside it. The generated module is plain Python you
can read: a header lists the argument order and shapes, common
subexpressions are shared, and the source is deterministic (same model, same
bytes), so it is cached by content hash and imported from a file (which makes
``inspect.getsource`` work on every generated function).

Generated functions
-------------------
``residual(Z, D)``              -> (n, n_states)
``jacobian(Z, D)``              -> (n, len(JAC_ROWS))
``hessian(Z, D, L)``            -> (n, len(HESS_ROWS)), of sum_k L[:, k] F_k (in the
                                   companion module ``<name>_hessian.py``, made on first use)
``output_<k>(U, D)``            -> (n,)
``output_<k>_grad(U, D)``       -> (n, len(OUTPUT_GRAD_IDX[k]))
``output_<k>_hess(U, D)``       -> (n, len(OUTPUT_HESS_ROWS[k]))

with ``Z`` (n, nz) point variables, ``D`` (n, nd) point data, ``L`` (n,
n_states) multipliers, ``U`` (n, nu) output variables.
"""

from __future__ import annotations

import functools
import hashlib
import importlib.util
import keyword
import os
import shutil
import sys
import tempfile
import weakref
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Callable

import numpy as np
import sympy as sp

from .model import ModelSpec
from .output import write_text
from .printing import WherePrinter
from .symbolic import SymbolicModel, derive
from .tables import TableFunction

__all__ = ["GeneratedModel", "OutputFunction", "generate", "generate_source", "generate_hessian_source",
           "cache_dir", "cache_path"]

CODEGEN_VERSION = "3"


@functools.lru_cache(maxsize=None)
def generator_fingerprint() -> str:
    """A hash of the code generator's own source (this module, :mod:`rocketid.symbolic`, the printer
    :mod:`rocketid.printing` and the tables :mod:`rocketid.tables`), part of every cache key: a change to
    the generator never reuses a stale module."""
    here = Path(__file__).resolve().parent
    h = hashlib.sha256()
    for name in ("codegen.py", "symbolic.py", "printing.py", "tables.py"):
        h.update((here / name).read_bytes())
    return h.hexdigest()[:16]


def cache_dir() -> Path:
    """Where generated modules are cached: ``$ROCKETID_CACHE_DIR``, else
    ``$XDG_CACHE_HOME/rocketid``, else ``~/.cache/rocketid``."""
    env = os.environ.get("ROCKETID_CACHE_DIR")
    if env:
        return Path(env)
    base = os.environ.get("XDG_CACHE_HOME") or os.path.join(os.path.expanduser("~"), ".cache")
    return Path(base) / "rocketid"


def _safe_name(sym: sp.Symbol, taken: set[str]) -> str:
    name = str(sym)
    if not name.isidentifier() or keyword.iskeyword(name) or name.startswith("_") or name in {"numpy", "n"}:
        name = "v_" + "".join(c if c.isalnum() else "_" for c in name)
    while name in taken:
        name += "_"
    taken.add(name)
    return name


class _Printer(WherePrinter):
    """NumPy printer with Piecewise as nested ``numpy.where`` (:class:`~rocketid.printing.WherePrinter`),
    model symbols under their safe names and tables as calls of the module's functions."""

    def __init__(self, names: dict | None = None):
        super().__init__({"fully_qualified_modules": True, "inline": True, "allow_unknown_functions": False})
        self._names = names or {}
        self.tables: dict = {}            # the tables printed, by class name (rocketid.tables)

    def _print_Symbol(self, expr):
        # model symbols print under their safe names (no xreplace: rebuilding
        # large Piecewise trees is slow in SymPy)
        return self._names.get(expr) or super()._print_Symbol(expr)

    def _print_Function(self, expr):
        # a table (rocketid.tables) is a call of a function of the module, its samples at the module's top
        if isinstance(expr, TableFunction):
            cls = type(expr)
            self.tables.setdefault(cls.__name__, cls)
            return f"_{cls.__name__}({self._print(expr.args[0])})"
        return super()._print_Function(expr)


def _table_lines(printer: _Printer) -> list[str]:
    """The module-level samples and functions of the tables ``printer`` printed (rocketid.tables), by name."""
    lines = []
    for name in sorted(printer.tables):
        cls = printer.tables[name]
        x, y = cls.samples
        lines += [f"_X_{name} = numpy.array({list(x)!r})", f"_Y_{name} = numpy.array({list(y)!r})"]
        if cls.is_slope:
            lines += [f"_S_{name} = numpy.diff(_Y_{name}) / numpy.diff(_X_{name})", "", "",
                      f"def _{name}(x):",
                      f'    """The slope of table {cls.label!r} at x (piecewise constant, 0 outside its samples)."""',
                      f"    i = numpy.searchsorted(_X_{name}, x, side='right') - 1",
                      f"    return numpy.where((i >= 0) & (i < _S_{name}.size), "
                      f"_S_{name}[numpy.clip(i, 0, _S_{name}.size - 1)], 0.0)", "", ""]
        else:
            lines += ["", "", f"def _{name}(x):",
                      f'    """Table {cls.label!r} at x, interpolated linearly (its end values outside)."""',
                      f"    return numpy.interp(x, _X_{name}, _Y_{name})", "", ""]
    return lines



def _emit_block(lines: list[str], exprs, targets, printer: _Printer, indent: str) -> None:
    """CSE ``exprs`` and emit assignments ``targets[i] = expr_i``."""
    if not exprs:
        return
    reps, reduced = sp.cse(list(exprs), symbols=sp.numbered_symbols("_c"), order="canonical")
    for sym, val in reps:
        lines.append(f"{indent}{sym} = {printer.doprint(val)}")
    for tgt, val in zip(targets, reduced):
        lines.append(f"{indent}{tgt} = {printer.doprint(val)}")


def _unpack(lines, names, arg, indent):
    for j, nm in enumerate(names):
        lines.append(f"{indent}{nm} = {arg}[:, {j}]")


def _names(sym: SymbolicModel) -> dict:
    """The Python name of every symbol of the templates (the point variables, data and
    multipliers first, so that a Hessian module made alone uses the same names)."""
    pt = sym.point
    taken: set[str] = set()
    names = {s: _safe_name(s, taken) for s in (*pt.z, *pt.d, *pt.lam)}
    for o in sym.outputs:
        for s in o.u:
            if s not in names:
                names[s] = _safe_name(s, taken)
    return names


I = "        "


def _function(printer: _Printer, fname, args, doc, exprs, ncols, unpack, single=False) -> list[str]:
    lines = ["", f"def {fname}({', '.join(args)}):", f'    """{doc}"""',
             f"    n = {args[0]}.shape[0]",
             "    with numpy.errstate(all='ignore'):"]
    for arg, nms in unpack:
        _unpack(lines, nms, arg, I)
    exprs = [sp.sympify(e) for e in exprs]
    if single:
        lines.append(f"{I}_out = numpy.empty(n)")
        _emit_block(lines, exprs, ["_out[:]"], printer, I)
    else:
        lines.append(f"{I}_out = numpy.empty((n, {ncols}))")
        _emit_block(lines, exprs, [f"_out[:, {j}]" for j in range(ncols)], printer, I)
    lines.append("    return _out")
    return lines


def _hessian_function(sym: SymbolicModel, names: dict, printer: _Printer) -> list[str]:
    pt = sym.point
    return _function(printer, "hessian", ["Z", "D", "L"],
                     "d2(sum_k L_k F_k)/dz2 at (HESS_ROWS, HESS_COLS), lower triangle.",
                     pt.hess_exprs, len(pt.hess_exprs),
                     [("Z", [names[s] for s in pt.z]), ("D", [names[s] for s in pt.d]),
                      ("L", [names[s] for s in pt.lam])])


def generate_hessian_source(sym: SymbolicModel, spec_name: str = "") -> str:
    """The Python source of the point Hessian alone (``HESS_ROWS``, ``HESS_COLS``, ``hessian``):
    the companion module :func:`generate` makes on first use of the Hessian."""
    pt = sym.point
    names = _names(sym)
    out = [f'"""Generated by rocketid.codegen (version {CODEGEN_VERSION}) for model {spec_name!r}: the point Hessian.',
           "",
           f"Model fingerprint: {sym.fingerprint}",
           "Do not edit: regenerate from the model. The residuals, their Jacobian and the outputs are in",
           "the module of the same name without the _hessian suffix; the argument order is the same.",
           '"""', "", "import functools", "", "import numpy", "",
           f"FINGERPRINT = {sym.fingerprint!r}",
           f"HESS_ROWS = {pt.hess_rows!r}",
           f"HESS_COLS = {pt.hess_cols!r}",
           ""]
    printer = _Printer(names)
    body = _hessian_function(sym, names, printer)
    return "\n".join(out + _table_lines(printer) + body) + "\n"


def generate_source(sym: SymbolicModel, spec_name: str = "") -> str:
    """The Python source of the generated module for ``sym`` (without the point Hessian when
    ``sym`` was derived without it: :func:`generate_hessian_source` makes that part)."""
    pt = sym.point
    names = _names(sym)
    printer = _Printer(names)

    out = [
        f'"""Generated by rocketid.codegen (version {CODEGEN_VERSION}) for model {spec_name!r}.',
        "",
        f"Model fingerprint: {sym.fingerprint}",
        "Do not edit: regenerate from the model.",
        "",
        "Arguments (one row per point or sample):",
        f"    Z : (n, {len(pt.z)}) point variables  {', '.join(names[s] for s in pt.z)}",
        f"    D : (n, {len(pt.d)}) point data       {', '.join(names[s] for s in pt.d)}",
        f"    L : (n, {len(pt.lam)}) multipliers     {', '.join(names[s] for s in pt.lam)}",
    ]
    if sym.outputs:
        out.append(f"    U : (n, {len(sym.outputs[0].u)}) output variables {', '.join(names[s] for s in sym.outputs[0].u)}")
    out += ['"""', "", "import functools", "", "import numpy", "",
            f"FINGERPRINT = {sym.fingerprint!r}",
            f"Z_NAMES = {tuple(names[s] for s in pt.z)!r}",
            f"D_NAMES = {tuple(names[s] for s in pt.d)!r}",
            f"N_RESIDUALS = {len(pt.residuals)}",
            f"JAC_ROWS = {pt.jac_rows!r}",
            f"JAC_COLS = {pt.jac_cols!r}",
            *([f"HESS_ROWS = {pt.hess_rows!r}", f"HESS_COLS = {pt.hess_cols!r}"] if sym.hessian else []),
            f"OUTPUT_NAMES = {tuple(o.name for o in sym.outputs)!r}",
            f"U_NAMES = {tuple(names[s] for s in sym.outputs[0].u) if sym.outputs else ()!r}",
            f"OUTPUT_LINEAR = {tuple(o.linear for o in sym.outputs)!r}",
            f"OUTPUT_GRAD_IDX = {tuple(o.grad_idx for o in sym.outputs)!r}",
            f"OUTPUT_HESS_ROWS = {tuple(o.hess_rows for o in sym.outputs)!r}",
            f"OUTPUT_HESS_COLS = {tuple(o.hess_cols for o in sym.outputs)!r}",
            ""]
    tables_at = len(out)

    def function(fname, args, doc, exprs, ncols, unpack, single=False):
        return _function(printer, fname, args, doc, exprs, ncols, unpack, single)

    zn = [names[s] for s in pt.z]
    dn = [names[s] for s in pt.d]
    out += function("residual", ["Z", "D"], "Residuals F(z, d), shape (n, N_RESIDUALS).",
                    pt.residuals, len(pt.residuals), [("Z", zn), ("D", dn)])
    out += function("jacobian", ["Z", "D"], "dF/dz at (JAC_ROWS, JAC_COLS), shape (n, len(JAC_ROWS)).",
                    pt.jac_exprs, len(pt.jac_exprs), [("Z", zn), ("D", dn)])
    if sym.hessian:
        out += _hessian_function(sym, names, printer)
    for k, o in enumerate(sym.outputs):
        un = [names[s] for s in o.u]
        out += function(f"output_{k}", ["U", "D"], f"Output {o.name!r}, shape (n,).", [o.expr], 1,
                        [("U", un), ("D", dn[:1])], single=True)
        out += function(f"output_{k}_grad", ["U", "D"], f"d {o.name}/du at OUTPUT_GRAD_IDX[{k}].",
                        o.grad_exprs, len(o.grad_exprs), [("U", un), ("D", dn[:1])])
        out += function(f"output_{k}_hess", ["U", "D"], f"d2 {o.name}/du2 at OUTPUT_HESS_ROWS/COLS[{k}].",
                        o.hess_exprs, len(o.hess_exprs), [("U", un), ("D", dn[:1])])
    out[tables_at:tables_at] = _table_lines(printer)
    return "\n".join(out) + "\n"


@dataclass(frozen=True)
class OutputFunction:
    """One generated output template ``y = h(u, d)`` per sample, with its sparsity.

    Attributes
    ----------
    index : int
        Position among the model's outputs (``output_<index>`` in the module).
    name : str
    linear : bool
        ``h`` is affine in ``u`` with constant coefficients.
    grad_idx : ndarray of int, shape (n_g,)
        Columns of ``U`` the gradient is taken at.
    hess_rows, hess_cols : ndarray of int, shape (n_h,)
        Lower-triangle entries of the Hessian in ``U``'s columns.
    value, gradient, hessian : callable
        ``f(U, D)`` with ``U`` (n, n_u) and ``D`` (n, 1); shapes (n,), (n, n_g), (n, n_h).
    """

    index: int
    name: str
    linear: bool
    grad_idx: np.ndarray
    hess_rows: np.ndarray
    hess_cols: np.ndarray
    value: Callable
    gradient: Callable
    hessian: Callable

    def evaluate(self, U: np.ndarray, D: np.ndarray, order: int = 0) -> tuple:
        """``(y,)``, ``(y, dy/du)`` or ``(y, dy/du, d2y/du2)`` at the samples, for ``order`` 0, 1, 2."""
        out = (self.value(U, D),)
        if order >= 1:
            out += (self.gradient(U, D),)
        if order >= 2:
            out += (self.hessian(U, D),)
        return out


def _index_array(values) -> np.ndarray:
    a = np.asarray(values, dtype=np.int64)
    a.flags.writeable = False
    return a


_HESSIAN_NAMES = frozenset({"hessian", "HESS_ROWS", "HESS_COLS"})


@dataclass(frozen=True)
class GeneratedModel:
    """A loaded generated module with its source and sparsity patterns.

    The point Hessian (``hessian``, ``HESS_ROWS``, ``HESS_COLS``) lives in a companion module
    (``<path stem>_hessian.py``), generated or loaded on its first use: a solve needs it, the
    analyses that need only first derivatives (sensitivities, the score test's augmented
    model) never derive it -- on an ascent model it is most of the code generation.

    Attributes
    ----------
    source : str
        The module's Python source (without the point Hessian; :attr:`hessian_source`).
    path : pathlib.Path
        The cached file it was imported from.
    module : module
        The imported module (``residual``, ``jacobian``, outputs; ``hessian`` through this
        object).
    cached : bool
        True when the module came from the cache (no SymPy derivation ran).
    """

    source: str
    path: Path
    module: ModuleType
    cached: bool
    outputs: tuple = field(init=False, repr=False, compare=False)
    spec: ModelSpec | None = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        m = self.module
        object.__setattr__(self, "outputs", tuple(
            OutputFunction(k, name, bool(m.OUTPUT_LINEAR[k]), _index_array(m.OUTPUT_GRAD_IDX[k]),
                           _index_array(m.OUTPUT_HESS_ROWS[k]), _index_array(m.OUTPUT_HESS_COLS[k]),
                           getattr(m, f"output_{k}"), getattr(m, f"output_{k}_grad"), getattr(m, f"output_{k}_hess"))
            for k, name in enumerate(m.OUTPUT_NAMES)))

    def __getattr__(self, name):
        module = self.__dict__["module"]
        if name in _HESSIAN_NAMES and not hasattr(module, name):
            return getattr(self.hessian_module, name)
        return getattr(module, name)

    @property
    def hessian_path(self) -> Path:
        """The companion module's file."""
        return self.path.with_name(f"{self.path.stem}_hessian.py")

    @property
    def hessian_module(self) -> ModuleType:
        """The module of the point Hessian (generated, or loaded from the cache, on first use)."""
        hm = self.__dict__.get("_hessian_module")
        if hm is None:
            if hasattr(self.module, "hessian"):
                hm = self.module
            else:
                hm = _hessian_module(self)
            object.__setattr__(self, "_hessian_module", hm)
        return hm

    @property
    def hessian_source(self) -> str:
        """The Python source of the point Hessian."""
        hm = self.hessian_module
        return self.source if hm is self.module else self.hessian_path.read_text()

    def write(self, folder: str | os.PathLike) -> Path:
        """Write the generated source into ``folder`` (with the Hessian's companion module);
        returns the main file's path."""
        if self.hessian_module is not self.module:
            write_text(Path(folder) / self.hessian_path.name, self.hessian_source)
        return write_text(Path(folder) / self.path.name, self.source)

    def print(self) -> None:
        """Print the generated source (and the Hessian's)."""
        print(self.source)
        if self.hessian_module is not self.module:
            print(self.hessian_source)


def _load(path: Path, name: str) -> ModuleType:
    spec = importlib.util.spec_from_file_location(name, path)
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module  # so that inspect.getsource finds it
    spec.loader.exec_module(module)
    return module


def _hessian_module(gen: GeneratedModel) -> ModuleType:
    path = gen.hessian_path
    modname = path.stem
    if path.exists():
        return sys.modules.get(modname) or _load(path, modname)
    if gen.spec is None:
        raise RuntimeError(f"the generated module {gen.path.name} has no Hessian and no model to derive it from")
    sym = derive(gen.spec, hessian=True, outputs=False)
    write_text(path, generate_hessian_source(sym, gen.spec.name))  # atomic, like the main module
    return _load(path, modname)


def cache_path(spec: ModelSpec) -> Path:
    """Where :func:`generate` caches the module of ``spec`` (named by the hash of the model's
    content and of the generator); ``cache_path(spec).exists()`` says whether generating it
    will be a load (fast) or a derivation and printing (seconds to a minute)."""
    key = hashlib.sha256(f"{CODEGEN_VERSION}:{generator_fingerprint()}:{spec.fingerprint()}".encode()
                         ).hexdigest()[:20]
    return cache_dir() / f"rocketid_gen_{key}.py"


def generate(spec: ModelSpec, *, use_cache: bool = True) -> GeneratedModel:
    """Generate (or load from the cache) the NumPy functions of ``spec``.

    The point Hessian is generated (or loaded) on first use (:class:`GeneratedModel`).

    Parameters
    ----------
    spec : ModelSpec
    use_cache : bool
        Look up and store the generated module by content hash. False: generate afresh into a
        private temporary folder; the cache is neither read nor written, and the folder is removed
        when the returned model is garbage-collected (or at exit).

    Returns
    -------
    GeneratedModel
    """
    path = cache_path(spec)
    folder, modname = path.parent, path.stem
    if use_cache and path.exists():
        source = path.read_text()
        module = sys.modules.get(modname) or _load(path, modname)
        return GeneratedModel(source, path, module, True, spec=spec)
    source = generate_source(derive(spec, hessian=False), spec.name)
    if not use_cache:
        # a private folder outside the cache: the module still has a file (inspect.getsource works)
        folder = Path(tempfile.mkdtemp(prefix="rocketid_gen_"))
        modname = f"{modname}_{folder.name}"
        path = folder / f"{modname}.py"
    write_text(path, source)  # atomic: concurrent processes never read half a file
    module = _load(path, modname)
    gen = GeneratedModel(source, path, module, False, spec=spec)
    if not use_cache:
        # the private folder lives as long as the generated model (its Hessian is written there on
        # first use) and is removed with it, or at exit
        weakref.finalize(gen, shutil.rmtree, folder, ignore_errors=True)
    return gen
