"""Orthogonal collocation on finite elements (7.2)-(7.4): mesh, variable layout, linear maps.

A :class:`Transcription` turns a :class:`~rocketid.model.ModelSpec` and the
measurement sample times into index arithmetic: which entries of the flat
decision vector ``w`` make up each collocation point's variables ``z`` and
each sample's output variables ``u``. All of these are *linear* maps, stored
as sparse matrices built once; the NLP applies the generated templates to
``z = Mz w`` and ``u = Mu w``.

Notation
--------
==============  =============================================================
``N, K``        number of elements, collocation points per element (Radau)
``t_e, h_e``    element ``e``'s start time and length
``tau``         local time in an element, ``t = t_e + h_e tau``
``q``           state node index, ``0 .. N K`` (``q = e K + j``, ``j = 0..K``;
                node ``e K`` is element e's start and element e-1's end)
``c``           collocation point index ``0 .. N K - 1`` (node ``q = c + 1``)
``w``           flat decision vector ``[S, p]``; ``S[q, i]`` is state ``i`` at
                node ``q`` (row-major), ``p`` the parameters
==============  =============================================================
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Sequence

import numpy as np
import scipy.sparse as sps
import sympy as sp

from ..data import Measurements
from ..errors import DataError, ModelError, SettingsError
from ..model import ModelSpec
from ..symbolic import output_variables, point_variables
from .radau import differentiation_matrix, element_nodes, lagrange_basis

__all__ = ["Mesh", "VariableLayout", "Transcription", "transcribe", "uniform_mesh", "graded_mesh"]


@dataclass(frozen=True)
class Mesh:
    """Finite elements ``t_0 < t_1 < ... < t_N`` and ``K`` Radau points each.

    Attributes
    ----------
    boundaries : ndarray, shape (N+1,)
    K : int
    """

    boundaries: np.ndarray
    K: int

    def __post_init__(self):
        b = np.asarray(self.boundaries, dtype=float).ravel()
        if b.size < 2 or np.any(np.diff(b) <= 0) or not np.all(np.isfinite(b)):
            raise SettingsError("mesh boundaries must be finite and strictly increasing (at least two)")
        b.flags.writeable = False
        object.__setattr__(self, "boundaries", b)
        element_nodes(self.K)  # validates K

    @property
    def n_elements(self) -> int:
        return self.boundaries.size - 1

    @property
    def lengths(self) -> np.ndarray:
        return np.diff(self.boundaries)

    @property
    def node_times(self) -> np.ndarray:
        """Times of the ``N K + 1`` state nodes."""
        tau = element_nodes(self.K)[1:]
        inner = (self.boundaries[:-1, None] + self.lengths[:, None] * tau[None, :]).ravel()
        return np.concatenate([[self.boundaries[0]], inner])

    def locate(self, t: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """Element index and local ``tau`` of times ``t`` (a time on a boundary
        belongs to the element it ends, ``tau = 1``, except ``t_0``)."""
        t = np.asarray(t, dtype=float)
        b = self.boundaries
        e = np.clip(np.searchsorted(b, t, side="left") - 1, 0, self.n_elements - 1)
        tau = (t - b[e]) / (b[e + 1] - b[e])
        return e, tau

    def refine_first(self, pieces: int, ratio: float = 4.0) -> "Mesh":
        """This mesh with its first element split geometrically into ``pieces + 1``
        elements, each ``ratio`` times longer than the previous one (a short first element
        resolves a singular start, such as a launch from rest).

        ``pieces = 0`` gives the mesh back.
        """
        if not isinstance(pieces, (int, np.integer)) or pieces < 0:
            raise SettingsError(f"refine_first must be a non-negative integer, got {pieces!r}")
        if not ratio > 0:
            raise SettingsError(f"the grading ratio must be positive, got {ratio!r}")
        if pieces == 0:
            return self
        b = self.boundaries
        w = float(ratio) ** np.arange(pieces + 1, dtype=float)
        cuts = b[0] + (b[1] - b[0]) * np.cumsum(w)[:-1] / w.sum()
        return Mesh(np.concatenate([[b[0]], cuts, b[1:]]), self.K)

    def describe(self) -> str:
        h = self.lengths
        kind = "uniform" if np.allclose(h, h[0]) else "graded"
        return f"{self.n_elements} elements ({kind}, {h.min():.3g}-{h.max():.3g} s), K = {self.K} Radau points"


def uniform_mesh(t0: float, tf: float, n_elements: int, K: int = 3) -> Mesh:
    """``n_elements`` equal elements on ``[t0, tf]``."""
    if not isinstance(n_elements, (int, np.integer)) or n_elements < 1:
        raise SettingsError(f"n_elements must be a positive integer, got {n_elements!r}")
    return Mesh(np.linspace(t0, tf, int(n_elements) + 1), K)


def graded_mesh(t0: float, tf: float, n_elements: int, K: int = 3, *, refine_first: int = 0,
                ratio: float = 4.0) -> Mesh:
    """Uniform elements, with the first element split geometrically into
    ``refine_first + 1`` pieces (each ``ratio`` times the previous; :meth:`Mesh.refine_first`)
    to resolve a singular start."""
    return uniform_mesh(t0, tf, n_elements, K).refine_first(refine_first, ratio)


@dataclass(frozen=True)
class VariableLayout:
    """Owner of the flat decision vector ``w = [S (n_nodes x n_states, row-major), p]``.

    Nobody else slices ``w``: use :meth:`pack`, :meth:`unpack`, :meth:`index_of`.
    """

    state_symbols: tuple
    parameter_symbols: tuple
    n_nodes: int

    @property
    def n_states(self) -> int:
        return len(self.state_symbols)

    @property
    def n_state_vars(self) -> int:
        return self.n_nodes * self.n_states

    @property
    def n(self) -> int:
        return self.n_state_vars + len(self.parameter_symbols)

    def state_index(self, node: np.ndarray | int, state: int) -> np.ndarray:
        """Index in ``w`` of state number ``state`` at node(s) ``node``."""
        return np.asarray(node) * self.n_states + state

    def parameter_index(self, j: int | np.ndarray) -> np.ndarray:
        """Index in ``w`` of parameter number ``j``."""
        return self.n_state_vars + np.asarray(j)

    def index_of(self, symbol: sp.Symbol) -> np.ndarray | int:
        """Indices of a state (all nodes) or the index of a parameter."""
        if symbol in self.state_symbols:
            return self.state_index(np.arange(self.n_nodes), self.state_symbols.index(symbol))
        if symbol in self.parameter_symbols:
            return int(self.parameter_index(self.parameter_symbols.index(symbol)))
        raise ModelError(f"{symbol} is neither a state nor a parameter of this transcription")

    def pack(self, states: np.ndarray, p: np.ndarray) -> np.ndarray:
        """``w`` from node states (n_nodes, n_states) and parameters (n_p,)."""
        states = np.asarray(states, dtype=float)
        if states.shape != (self.n_nodes, self.n_states):
            raise ValueError(f"states must have shape {(self.n_nodes, self.n_states)}, got {states.shape}")
        return np.concatenate([states.ravel(), np.asarray(p, dtype=float).ravel()])

    def unpack(self, w: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
        """``(states (n_nodes, n_states), p (n_p,))`` from ``w``."""
        w = np.asarray(w, dtype=float)
        return w[: self.n_state_vars].reshape(self.n_nodes, self.n_states), w[self.n_state_vars:]


@dataclass(frozen=True)
class OutputMap:
    """Linear map from ``w`` to one channel's output variables at its samples.

    ``U = (Mu @ w).reshape(n_samples, nu)``.
    """

    name: str
    times: np.ndarray
    Mu: sps.csr_matrix
    data: np.ndarray  # (n_samples, 1): time
    index: int = 0    # the output's position in ``spec.outputs`` (and the generated code's)


@dataclass(frozen=True)
class Transcription:
    """The collocated model: mesh, layout and the linear maps to template variables.

    Attributes
    ----------
    spec : ModelSpec
    mesh : Mesh
    layout : VariableLayout
    Mz : scipy.sparse.csr_matrix, shape (n_col * nz, n)
        ``Z = (Mz @ w).reshape(n_col, nz)``: point variables at collocation points.
    point_data : ndarray, shape (n_col, nd)
        ``(t, inputs)`` at collocation points.
    ic_matrix : scipy.sparse.csr_matrix, shape (n_states, n)
    ic_offset : ndarray, shape (n_states,)
        Initial-condition rows: ``ic_matrix @ w - ic_offset = 0``.
    outputs : tuple of OutputMap
    """

    spec: ModelSpec
    mesh: Mesh
    layout: VariableLayout
    Mz: sps.csr_matrix
    point_data: np.ndarray
    ic_matrix: sps.csr_matrix
    ic_offset: np.ndarray
    outputs: tuple
    nz: int = field(default=0)
    nu: int = field(default=0)

    @property
    def n_collocation(self) -> int:
        return self.mesh.n_elements * self.mesh.K

    @property
    def n_constraints(self) -> int:
        """Initial conditions plus one residual per state and collocation point."""
        return self.layout.n_states * (1 + self.n_collocation)

    def interpolation_matrix(self, times: np.ndarray, derivative: bool = False) -> sps.csr_matrix:
        """Sparse map from ``w`` to all states at ``times``: ``(M @ w).reshape(n, n_states)``."""
        return _interp_matrix(self.mesh, self.layout, np.asarray(times, dtype=float), derivative)

    def states_at(self, w: np.ndarray, times: np.ndarray) -> np.ndarray:
        """The collocation polynomial's states at ``times``, shape (n, n_states)."""
        times = np.asarray(times, dtype=float)
        return (self.interpolation_matrix(times) @ w).reshape(times.size, self.layout.n_states)


def _interp_matrix(mesh: Mesh, layout: VariableLayout, times: np.ndarray, derivative: bool) -> sps.csr_matrix:
    K, ns = mesh.K, layout.n_states
    e, tau = mesh.locate(times)
    vals, ders = lagrange_basis(element_nodes(K), tau)
    coef = ders / mesh.lengths[e][:, None] if derivative else vals
    n = times.size
    rows, cols, data = [], [], []
    for i in range(ns):
        for l in range(K + 1):
            rows.append(np.arange(n) * ns + i)
            cols.append(layout.state_index(e * K + l, i))
            data.append(coef[:, l])
    return sps.csr_matrix((np.concatenate(data), (np.concatenate(rows), np.concatenate(cols))),
                          shape=(n * ns, layout.n))


def _local_rows(spec: ModelSpec, layout: VariableLayout, times: np.ndarray, symbols: Sequence) -> list:
    """For each local symbol, (cols, coefs) arrays of shape (n, 2): its value at
    ``times`` as a combination of parameters."""
    pindex = {s: j for j, s in enumerate(spec.parameter_symbols)}
    fams = {f.symbol: f for f in spec.families}
    out = []
    n = times.size
    for sym in symbols:
        if sym in fams:
            f = fams[sym]
            left, right, wr = f.weights(times)
            kl = np.array([pindex[f.knots[i]] for i in left])
            kr = np.array([pindex[f.knots[i]] for i in right])
            cols = np.stack([layout.parameter_index(kl), layout.parameter_index(kr)], axis=1)
            out.append((cols, np.stack([1.0 - wr, wr], axis=1)))
        else:
            col = layout.parameter_index(pindex[sym])
            out.append((np.full((n, 1), col), np.ones((n, 1))))
    return out


def _check_mesh(spec: ModelSpec, mesh: Mesh) -> None:
    b = mesh.boundaries
    if abs(b[0] - spec.t0) > 1e-9 * max(1.0, abs(spec.tf)) or abs(b[-1] - spec.tf) > 1e-9 * max(1.0, abs(spec.tf)):
        raise SettingsError(f"the mesh spans [{b[0]:g}, {b[-1]:g}] but model {spec.name!r} spans "
                            f"[{spec.t0:g}, {spec.tf:g}]")
    for f in spec.families:
        for tb in f.breakpoints:
            if not spec.t0 < tb < spec.tf:
                continue  # the ends are checked above; a model cut to a window keeps breakpoints outside it
            if np.min(np.abs(b - tb)) > 1e-9 * max(1.0, abs(spec.tf)):
                raise SettingsError(
                    f"breakpoint t = {tb:g} of family {f.symbol} is not on an element boundary of the mesh "
                    f"({mesh.describe()}); choose a number of elements that puts every breakpoint on a "
                    "boundary or pass a mesh that includes them")


def transcribe(spec: ModelSpec, measurements: Measurements, mesh: Mesh) -> Transcription:
    """Collocate ``spec`` on ``mesh`` with outputs at the sample times of ``measurements``.

    Parameters
    ----------
    spec : ModelSpec
    measurements : Measurements
        Only the sample times are used here (values enter the NLP).
    mesh : Mesh

    Returns
    -------
    Transcription
    """
    _check_mesh(spec, mesh)
    K, N = mesh.K, mesh.n_elements
    ns = len(spec.states)
    layout = VariableLayout(spec.state_symbols, spec.parameter_symbols, N * K + 1)
    z, d = point_variables(spec)
    nz = len(z)
    n_col = N * K
    node_t = mesh.node_times
    col_nodes = np.arange(1, n_col + 1)
    col_t = node_t[col_nodes]
    col_e = np.repeat(np.arange(N), K)
    col_j = np.tile(np.arange(1, K + 1), N)
    D = differentiation_matrix(K)
    h = mesh.lengths

    rows, cols, data = [], [], []

    def add(zi, c_cols, c_coef):
        r = np.arange(n_col)[:, None] * nz + zi
        rows.append(np.broadcast_to(r, c_cols.shape).ravel())
        cols.append(c_cols.ravel())
        data.append(c_coef.ravel())

    for i in range(ns):
        add(i, layout.state_index(col_nodes, i)[:, None], np.ones((n_col, 1)))
        nodes = col_e[:, None] * K + np.arange(K + 1)[None, :]
        add(ns + i, layout.state_index(nodes, i), D[col_j - 1, :] / h[col_e][:, None])
    for m, (c_cols, c_coef) in enumerate(_local_rows(spec, layout, col_t, z[2 * ns:])):
        add(2 * ns + m, c_cols, c_coef)
    Mz = sps.csr_matrix((np.concatenate(data), (np.concatenate(rows), np.concatenate(cols))),
                        shape=(n_col * nz, layout.n))
    Mz.sum_duplicates()
    point_data = np.column_stack([col_t, spec.input_values(col_t)])

    # initial conditions: S[0, i] - s0_i = 0, or S[0, i] - p_init = 0 for free ones (= s0_i for an offset)
    pindex = {s: j for j, s in enumerate(spec.parameter_symbols)}
    ic_r, ic_c, ic_v = [], [], []
    ic_off = np.zeros(ns)
    for i, s in enumerate(spec.states):
        ic_r.append(i); ic_c.append(int(layout.state_index(0, i))); ic_v.append(1.0)
        if s.free:
            ic_r.append(i); ic_c.append(int(layout.parameter_index(pindex[s.initial_parameter]))); ic_v.append(-1.0)
        if not s.free or s.offset:
            ic_off[i] = s.initial          # S[0, i] - p_init = s0_i for an offset from the declared start
    ic = sps.csr_matrix((ic_v, (ic_r, ic_c)), shape=(ns, layout.n))

    # outputs at their own sample times: u = (states, derivatives, scalar params)
    u = output_variables(spec)
    nu = len(u)
    maps = []
    if not any(o.name in measurements.names for o in spec.outputs):
        raise DataError(f"the measurements have none of model {spec.name!r}'s outputs ({', '.join(spec.output_names)}); "
                        f"they have {', '.join(measurements.names)}: map the columns (CLI: --column NAME=COLUMN)")
    for index, o in enumerate(spec.outputs):
        if o.name not in measurements.names:
            continue  # an output the data do not measure: predicted, not fitted
        ch = measurements[o.name]
        ts = ch.times
        if ts[0] < spec.t0 - 1e-12 or ts[-1] > spec.tf + 1e-12:
            before = ts[ts < spec.t0 - 1e-12]
            after = ts[ts > spec.tf + 1e-12]
            where = []
            if before.size:
                where.append(f"{before.size} before t0 = {spec.t0:g} (from t = {before[0]:g})")
            if after.size:
                where.append(f"{after.size} after tf = {spec.tf:g} (from t = {after[0]:g})")
            raise DataError(f"channel {o.name!r}: {' and '.join(where)} of {ts.size} samples lie outside the "
                            f"model's horizon [{spec.t0:g}, {spec.tf:g}]; remove those rows or extend the horizon")
        n = ts.size
        S = _interp_matrix(mesh, layout, ts, False).tocoo()
        dS = _interp_matrix(mesh, layout, ts, True).tocoo()
        r = [S.row // ns * nu + S.row % ns, dS.row // ns * nu + ns + dS.row % ns]
        c = [S.col, dS.col]
        v = [S.data, dS.data]
        for m, (c_cols, c_coef) in enumerate(_local_rows(spec, layout, ts, u[2 * ns:])):
            r.append(np.repeat(np.arange(n) * nu + 2 * ns + m, c_cols.shape[1]))
            c.append(c_cols.ravel())
            v.append(c_coef.ravel())
        Mu = sps.csr_matrix((np.concatenate(v), (np.concatenate(r), np.concatenate(c))), shape=(n * nu, layout.n))
        maps.append(OutputMap(o.name, ts, Mu, ts[:, None].copy(), index))
    return Transcription(spec, mesh, layout, Mz, point_data, ic, ic_off, tuple(maps), nz=nz, nu=nu)
