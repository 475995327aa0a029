"""The sparse NLP (7.5), and (7.9) with parameters transformed: exact derivatives by index arithmetic.

The collocated problem is

    min_x  J(x) = 1/2 sum_k sum_s ((g_k(u_ks) - y_ks) / sigma_ks)^2  [+ 1/2 sum_i ((p_i - mu_i) / s_i)^2]
    s.t.   c(x) = [ IC w - s0 ;  F(z_c) for every collocation point c ;  A_lin x ]
           cl <= c(x) <= cu,  xl <= x <= xu

(the bracket: Gaussian priors on parameters, when the model declares them; ``sigma_ks`` is
channel k's sigma, the same at every sample or one per sample), with the full
decision vector ``w = T x + w0`` (``T`` is the identity for the
plain estimation (7.5); for (7.9), ``p = V1 q1 + V2 q2`` with ``q2`` fixed,
so ``x = [S, q1]`` and the bounds on ``p`` become the linear rows ``A_lin``).

Point variables ``z = Mz w`` and output variables ``u = Mu w`` are linear in
``w``; the generated templates give ``dF/dz`` and ``d2(lam F)/dz2`` per
point. The Jacobian and the Lagrangian Hessian of the whole NLP are then
*linear* in those template values, ``jac_values = E_J @ template_values``, so
each evaluation is a template call plus one sparse mat-vec. The expansion
matrices ``E`` are built once, with the final sparsity structure.

Notation
--------
=========  ===============================================================
``x``      decision vector of the NLP (length ``n``)
``w``      full collocation vector ``[S, p]`` (``VariableLayout``)
``T, w0``  ``w = T x + w0``
``Mz``     ``Z = reshape(Mz_x x + z0)``, ``Mz_x = Mz T``, ``z0 = Mz w0``
``E_*``    expansion matrices from template values to non-zero values
=========  ===============================================================
"""

from __future__ import annotations

from dataclasses import dataclass, field, replace
from functools import cached_property

import numpy as np
import scipy.sparse as sps

from .codegen import GeneratedModel, OutputFunction
from .collocation.transcription import Transcription, VariableLayout
from .data import Measurements, equivalent_sigma
from .errors import SettingsError

__all__ = ["CollocationNLP", "NLPStructure", "HessianStructure", "ParameterTransform", "ReducedLayout", "build_nlp"]


@dataclass(frozen=True)
class ParameterTransform:
    """``p = P r + c``: the parameters as an affine function of the reduced ones.

    The identity (``P = I``, ``c = 0``) is the full estimation (7.5); for
    (7.9) ``P = V1`` and ``c = V2 q2``. A frozen value with read-only arrays.

    Attributes
    ----------
    P : ndarray, shape (n_p, n_r)
    c : ndarray, shape (n_p,)
    names : tuple of str
        Names of the reduced parameters.
    """

    P: np.ndarray
    c: np.ndarray
    names: tuple

    def __post_init__(self):
        P = np.array(self.P, dtype=float, ndmin=2)
        c = np.array(self.c, dtype=float).ravel()
        if c.shape != (P.shape[0],):
            raise SettingsError(f"offset has shape {c.shape}, expected {(P.shape[0],)}")
        if len(self.names) != P.shape[1]:
            raise SettingsError(f"{len(self.names)} names for {P.shape[1]} reduced parameters")
        P.flags.writeable = False
        c.flags.writeable = False
        object.__setattr__(self, "P", P)
        object.__setattr__(self, "c", c)
        object.__setattr__(self, "names", tuple(self.names))

    @classmethod
    def identity(cls, names) -> "ParameterTransform":
        n = len(names)
        return cls(np.eye(n), np.zeros(n), tuple(names))

    @property
    def is_identity(self) -> bool:
        return self.P.shape[0] == self.P.shape[1] and np.array_equal(self.P, np.eye(self.P.shape[0])) \
            and not np.any(self.c)

    @property
    def n_reduced(self) -> int:
        return self.P.shape[1]

    def with_offset(self, c) -> "ParameterTransform":
        """The same ``P`` with the offset ``c``."""
        return replace(self, c=c)

    def parameters(self, r: np.ndarray) -> np.ndarray:
        """``p = P r + c``."""
        return self.P @ r + self.c

    def reduced(self, p: np.ndarray) -> np.ndarray:
        """The ``r`` whose ``P r + c`` is nearest to ``p`` (least squares; exact when ``p`` is reachable)."""
        return np.linalg.lstsq(self.P, p - self.c, rcond=None)[0]


@dataclass(frozen=True)
class ReducedLayout:
    """Owner of the NLP's decision vector ``x`` and of its constraint rows.

    ==========  =====================================================================
    ``x``       ``[gamma, r]``: the node states (``VariableLayout`` order, length
                ``n_state_vars``), then the reduced parameters (length ``n_reduced``)
    ``p``       ``P r + c`` (the :class:`ParameterTransform`)
    ``w``       the collocation vector ``[gamma, p]`` of the transcription
    rows        ``[initial conditions (n_ic), collocation (n_collocation),
                linear bound rows of p (n_linear)]``
    ==========  =====================================================================

    Nobody else slices ``x`` or the constraint vector: use :meth:`states`,
    :meth:`reduced`, :meth:`parameters`, :meth:`pack`, :meth:`with_parameters` and the
    row slices.
    """

    layout: VariableLayout
    transform: ParameterTransform
    n_ic: int
    n_collocation: int
    n_linear: int

    @property
    def n_state_vars(self) -> int:
        return self.layout.n_state_vars

    @property
    def n_reduced(self) -> int:
        return self.transform.n_reduced

    @property
    def n(self) -> int:
        return self.n_state_vars + self.n_reduced

    @property
    def m(self) -> int:
        return self.n_ic + self.n_collocation + self.n_linear

    @property
    def state_columns(self) -> slice:
        return slice(0, self.n_state_vars)

    @property
    def parameter_columns(self) -> slice:
        return slice(self.n_state_vars, self.n)

    @property
    def equality_rows(self) -> slice:
        """Initial-condition and collocation rows: ``c(x) = 0``."""
        return slice(0, self.n_ic + self.n_collocation)

    @property
    def collocation_rows(self) -> slice:
        return slice(self.n_ic, self.n_ic + self.n_collocation)

    @property
    def linear_rows(self) -> slice:
        return slice(self.n_ic + self.n_collocation, self.m)

    def states(self, x: np.ndarray) -> np.ndarray:
        """``gamma``: the node states, flat (``VariableLayout`` order)."""
        return x[:self.n_state_vars]

    def reduced(self, x: np.ndarray) -> np.ndarray:
        """``r``: the reduced parameters."""
        return x[self.n_state_vars:]

    def parameters(self, x: np.ndarray) -> np.ndarray:
        """``p = P r + c``."""
        return self.transform.parameters(self.reduced(x))

    def pack(self, gamma: np.ndarray, r: np.ndarray) -> np.ndarray:
        """``x`` from flat node states and reduced parameters."""
        return np.concatenate([np.asarray(gamma, float).ravel(), np.asarray(r, float)])

    def with_reduced(self, x: np.ndarray, r: np.ndarray) -> np.ndarray:
        """A copy of ``x`` with the reduced parameters ``r``."""
        out = np.array(x, dtype=float, copy=True)
        out[self.n_state_vars:] = r
        return out

    def with_parameters(self, x: np.ndarray, p: np.ndarray) -> np.ndarray:
        """A copy of ``x`` whose reduced parameters best give ``p`` (least squares)."""
        return self.with_reduced(x, self.transform.reduced(p))

    def full(self, x: np.ndarray, T: sps.csr_matrix, w0: np.ndarray) -> np.ndarray:
        """``w = T x + w0``."""
        return T @ x + w0

    def from_full(self, w: np.ndarray) -> np.ndarray:
        """``x`` for a full ``w`` (least squares in the parameter part)."""
        S, p = self.layout.unpack(w)
        return np.concatenate([S.ravel(), self.transform.reduced(p)])

    def start(self, states: np.ndarray, p: np.ndarray) -> np.ndarray:
        """``x`` from node states (n_nodes, n_states) and a full parameter vector."""
        return self.from_full(self.layout.pack(states, p))


def _csr_rows(M: sps.csr_matrix, rows: np.ndarray):
    """Entries of the given CSR rows: (which input row, column, value) flattened."""
    starts = M.indptr[rows]
    counts = M.indptr[rows + 1] - starts
    owner = np.repeat(np.arange(rows.size), counts)
    offs = np.arange(counts.sum()) - np.repeat(np.cumsum(counts) - counts, counts)
    idx = starts[owner] + offs
    return owner, M.indices[idx], M.data[idx]


def _jac_triples(M: sps.csr_matrix, n_items: int, width: int, t_rows, t_cols, row_of):
    """Expand template Jacobian entries through the linear map M.

    For item ``i`` and template entry ``k = (t_rows[k], t_cols[k])``, the
    contribution to the Jacobian row ``row_of(i, t_rows[k])`` is
    ``value[i, k] * M[i*width + t_cols[k], :]``.
    Returns (row, col, src, coef) with ``src = i * len(t_rows) + k``.
    """
    t_rows = np.asarray(t_rows, dtype=np.int64)
    t_cols = np.asarray(t_cols, dtype=np.int64)
    nk = t_rows.size
    if nk == 0:
        e = np.empty(0, dtype=np.int64)
        return e, e, e, np.empty(0)
    item = np.repeat(np.arange(n_items), nk)
    k = np.tile(np.arange(nk), n_items)
    mrows = item * width + t_cols[k]
    owner, col, coef = _csr_rows(M, mrows)
    src = owner  # owner indexes (item, k) pairs in order
    row = row_of(item[owner], t_rows[k[owner]])
    return row, col, src, coef


def _hess_triples(M: sps.csr_matrix, n_items: int, width: int, t_rows, t_cols):
    """Expand lower-triangle template Hessian entries through ``M``: ``M^T Q M``.

    Returns (row, col, src, coef) in the lower triangle (row >= col).
    """
    t_rows = np.asarray(t_rows, dtype=np.int64)
    t_cols = np.asarray(t_cols, dtype=np.int64)
    nk = t_rows.size
    out = ([], [], [], [])
    for k in range(nk):
        a, b = t_rows[k], t_cols[k]
        ra = np.arange(n_items) * width + a
        rb = np.arange(n_items) * width + b
        oa, ca, va = _csr_rows(M, ra)
        ob, cb, vb = _csr_rows(M, rb)
        # all pairs per item: group by owner
        la = np.bincount(oa, minlength=n_items)
        lb = np.bincount(ob, minlength=n_items)
        sa = np.cumsum(la) - la
        sb = np.cumsum(lb) - lb
        npairs = la * lb
        item = np.repeat(np.arange(n_items), npairs)
        pos = np.arange(npairs.sum()) - np.repeat(np.cumsum(npairs) - npairs, npairs)
        ia = sa[item] + pos // np.maximum(lb[item], 1)
        ib = sb[item] + pos % np.maximum(lb[item], 1)
        ci, cj = ca[ia], cb[ib]
        coef = va[ia] * vb[ib]
        if a == b:
            # Q[a,a] M_a^T M_a: keep each unordered pair once
            keep = (ia - sa[item]) <= (ib - sb[item])
            # an unordered pair of distinct columns stands for H[ci, cj] and H[cj, ci], which
            # the lower triangle stores once: counted once is right
            ci, cj, coef, item = ci[keep], cj[keep], coef[keep], item[keep]
        else:
            coef = np.where(ci == cj, 2.0 * coef, coef)
        out[0].append(np.maximum(ci, cj))
        out[1].append(np.minimum(ci, cj))
        out[2].append(item * nk + k)
        out[3].append(coef)
    if not out[0]:
        e = np.empty(0, dtype=np.int64)
        return e, e, e, np.empty(0)
    return tuple(np.concatenate(o) for o in out)


DENSE_KEYS = 1 << 24
"""Key ranges up to this size are made unique by marking a dense array (O(entries), no sort); larger ones by
:func:`numpy.unique`."""


def _unique_keys(key: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """``numpy.unique(key, return_inverse=True)`` for non-negative integer keys (the same values; the inverse as
    32-bit integers on the dense path). A model whose output is nonlinear
    in the states of many samples (a time offset: every sample's output depends on it) expands to millions of
    Hessian entries on a few tens of thousands of places (15 million on 22 795 for RA-66M's 19 800 samples with
    ``time_offset_2``); sorting them took 5.5 s per NLP built, marking a dense array over the key range 0.07 s
    (``benchmarks/README.md``)."""
    top = int(key.max()) + 1
    if top > DENSE_KEYS:
        return np.unique(key, return_inverse=True)
    mark = np.zeros(top, bool)
    mark[key] = True
    uniq = np.flatnonzero(mark)
    where = np.zeros(top, np.int32)             # a place per key: at most 2^24 of them
    where[uniq] = np.arange(uniq.size, dtype=np.int32)
    return uniq.astype(np.int64), where[key]


def _assemble(triples, n_src_list, shape_rows_cols=None):
    """Unique (row, col) structure over several sources and one expansion matrix each."""
    rows = np.concatenate([t[0] for t in triples]) if triples else np.empty(0, np.int64)
    cols = np.concatenate([t[1] for t in triples]) if triples else np.empty(0, np.int64)
    if rows.size:
        key = rows.astype(np.int64, copy=False) * (cols.max() + 1 if cols.size else 1) + cols
        uniq, inverse = _unique_keys(key)
    else:
        uniq, inverse = np.empty(0, np.int64), np.empty(0, np.int64)
    ncolmax = (cols.max() + 1) if cols.size else 1
    s_rows = (uniq // ncolmax).astype(np.int64)
    s_cols = (uniq % ncolmax).astype(np.int64)
    Es = []
    start = 0
    for (r, c, src, coef), n_src in zip(triples, n_src_list):
        tgt = inverse[start:start + r.size]
        start += r.size
        Es.append(sps.csr_matrix((coef, (tgt, src)), shape=(uniq.size, n_src)))
    return s_rows, s_cols, Es


@dataclass(frozen=True)
class _ChannelMaps:
    """A measured channel's maps from ``x`` (independent of the offset ``c``)."""

    name: str
    index: int
    values: np.ndarray        # measured
    sigma: np.ndarray         # noise standard deviation per sample, shape (n,)
    fn: OutputFunction
    Mu: sps.csr_matrix        # u = Mu x + u0
    Mu_full: sps.csr_matrix   # u = Mu_full w (before the transform)
    data: np.ndarray
    n: int
    sel: sps.csr_matrix | None
    c0: float
    G: sps.csr_matrix | None  # linear: y = G x + g0

    @property
    def linear(self) -> bool:
        return self.fn.linear

    @cached_property
    def weights(self) -> np.ndarray:
        """``1 / sigma^2`` per sample, shape (n,)."""
        return 1.0 / self.sigma ** 2

    @cached_property
    def per_sample(self) -> bool:
        """True when the samples' sigmas differ (a per-sample sigma)."""
        return bool(np.any(self.sigma != self.sigma[0]))


@dataclass(frozen=True)
class _Channel:
    """A channel at one offset: its maps and ``u0`` (and ``g0`` when linear)."""

    maps: _ChannelMaps
    u0: np.ndarray
    g0: np.ndarray | None

    name = property(lambda self: self.maps.name)
    n = property(lambda self: self.maps.n)
    sigma = property(lambda self: self.maps.sigma)
    weights = property(lambda self: self.maps.weights)
    linear = property(lambda self: self.maps.fn.linear)
    values = property(lambda self: self.maps.values)

    def evaluate(self, x: np.ndarray, order: int = 0) -> tuple:
        """``(U, y, ...)``: the output variables at the samples, shape (n, n_u), then the
        output template's value and, for ``order`` 1 and 2, its gradient and Hessian."""
        mp = self.maps
        U = (mp.Mu @ x + self.u0).reshape(mp.n, -1)
        return (U,) + mp.fn.evaluate(U, mp.data, order)

    def output(self, x: np.ndarray) -> np.ndarray:
        """The model's output at the samples."""
        if self.linear:
            return self.maps.G @ x + self.g0
        return self.evaluate(x)[1]


@dataclass(frozen=True)
class NLPStructure:
    """Everything of the NLP that does not depend on the offset ``c``, built once.

    Sparsity of the constraint Jacobian and of the Lagrangian Hessian (lower
    triangle), the expansion matrices from template values to their non-zeros,
    the linear maps ``x -> points`` and ``x -> output variables``, the linear
    bound rows and the stacked linear channels. Re-offset NLPs (the sampling
    loop's (7.9) for many ``q2``) share one structure.
    """

    transcription: Transcription
    generated: GeneratedModel
    measurements: Measurements
    P: np.ndarray
    T: sps.csr_matrix
    Mz: sps.csr_matrix
    ic: sps.csr_matrix
    A_lin: sps.csr_matrix
    linear_bounds: bool
    lin_bounded: np.ndarray | None
    jac_rows: np.ndarray
    jac_cols: np.ndarray
    E_jac: sps.csr_matrix
    jac_const: np.ndarray
    channels: tuple
    G_lin: sps.csr_matrix | None
    GT_lin: sps.csr_matrix | None
    z_lin: np.ndarray | None
    w_lin: np.ndarray | None

    @property
    def n_states(self) -> int:
        return self.transcription.layout.n_states

    @property
    def n_collocation_points(self) -> int:
        return self.transcription.n_collocation

    @cached_property
    def offset_columns(self) -> tuple:
        """``(Mz_c, ic_c, (Mu_c, ...))``: the parameter columns of the transcription's maps
        ``w -> points``, ``w -> initial-condition rows`` and of each channel's ``w -> output
        variables``. The offset enters ``w0 = [0, c]`` through these columns alone, so a
        re-offset (:meth:`CollocationNLP.with_offset`) multiplies ``c`` by them instead of the
        whole maps (RA-66's three channel maps hold 0.8 million non-zeros: the re-offset of a
        sampling draw went from 2.3 to 0.8 ms, ``benchmarks/bench_draw.py``)."""
        tr = self.transcription
        nsv = tr.layout.n_state_vars

        def cols(M):
            return sps.csr_matrix(M)[:, nsv:].tocsr()

        return cols(tr.Mz), cols(tr.ic_matrix), tuple(cols(mp.Mu_full) for mp in self.channels)

    @cached_property
    def hessian(self) -> "HessianStructure":
        """The Lagrangian Hessian's structure, built once per structure (on first use) and shared
        by every NLP on it. Sensitivities, the estimability analysis and the score test never
        need it; building it eagerly cost 0.4-0.7 s per augmented model of the score test."""
        return _build_hessian(self)


@dataclass(frozen=True)
class HessianStructure:
    """The Lagrangian Hessian's lower-triangle sparsity and expansion matrices.

    Attributes
    ----------
    rows, cols : ndarray of int
    E_con : csr_matrix
        Constraint-template values -> non-zeros.
    obj_const : ndarray
        The linear channels' constant part ``G^T Cy^-1 G``.
    E_obj : tuple of csr_matrix
        Per nonlinear channel: its template values -> non-zeros.
    obj_templates : tuple
        ``(channel index, gi, ga, gb)`` per nonlinear channel.
    """

    rows: np.ndarray
    cols: np.ndarray
    E_con: sps.csr_matrix
    obj_const: np.ndarray
    E_obj: tuple
    obj_templates: tuple


def _build_structure(tr: Transcription, g: GeneratedModel, measurements: Measurements, P: np.ndarray,
                     linear_bounds: bool) -> NLPStructure:
    spec = tr.spec
    lay = tr.layout
    nsv = lay.n_state_vars
    ns = lay.n_states
    n_col = tr.n_collocation
    n = nsv + P.shape[1]
    T = sps.bmat([[sps.identity(nsv, format="csr"), None],
                  [None, sps.csr_matrix(P)]], format="csr")
    Mz = (tr.Mz @ T).tocsr()
    Mz.sort_indices()
    ic = (tr.ic_matrix @ T).tocsr()

    # linear rows for the bounds on p when transformed
    lo, hi = spec.lower, spec.upper
    if linear_bounds:
        bounded = np.isfinite(lo) | np.isfinite(hi)
        A = np.zeros((int(bounded.sum()), n))
        A[:, nsv:] = P[bounded]
        A_lin = sps.csr_matrix(A)
        lin_bounded = np.flatnonzero(bounded)
    else:
        A_lin = sps.csr_matrix((0, n))
        lin_bounded = None

    # ---- Jacobian structure: IC rows, collocation rows (expanded), linear rows
    jr, jc = g.JAC_ROWS, g.JAC_COLS
    col_tr = _jac_triples(Mz, n_col, tr.nz, jr, jc, lambda item, k: ns + item * ns + k)
    icc = ic.tocoo()
    lin = A_lin.tocoo()
    const_r = np.concatenate([icc.row, lin.row + ns + n_col * ns])
    const_c = np.concatenate([icc.col, lin.col])
    const_v = np.concatenate([icc.data, lin.data])
    const_tr = (const_r.astype(np.int64), const_c.astype(np.int64), np.arange(const_r.size), np.ones(const_r.size))
    rows, cols, (E_col, E_const) = _assemble([col_tr, const_tr], [n_col * len(jr), const_r.size])
    order = np.lexsort((cols, rows))
    Pm = sps.csr_matrix((np.ones(order.size), (np.arange(order.size), order)), shape=(order.size, order.size))
    jac_rows, jac_cols = rows[order], cols[order]
    E_jac = (Pm @ E_col).tocsr()
    jac_const = Pm @ (E_const @ const_v)

    # ---- channels (objective)
    chans = []
    for k, omap in enumerate(tr.outputs):
        ch = measurements[omap.name]
        sigma = ch.sigma_array(spec.outputs[omap.index].sigma)
        sigma.flags.writeable = False
        fn = g.outputs[omap.index]
        Mu = (omap.Mu @ T).tocsr()
        Mu.sort_indices()
        nsamp = omap.times.size
        G = sel = None
        c0 = 0.0
        if fn.linear:
            # y = sum_a c_a u_a + c0, constant c: fold into one sparse matrix
            Uz = np.zeros((1, tr.nu))
            gi = fn.grad_idx
            cvec = fn.gradient(Uz, np.zeros((1, 1)))[0]
            c0 = float(fn.value(Uz, np.zeros((1, 1)))[0])
            sel = sps.csr_matrix((np.tile(cvec, nsamp),
                                  (np.repeat(np.arange(nsamp), gi.size), (np.arange(nsamp)[:, None] * tr.nu + gi).ravel())),
                                 shape=(nsamp, nsamp * tr.nu))
            G = (sel @ Mu).tocsr()
        chans.append(_ChannelMaps(omap.name, k, ch.values, sigma, fn, Mu, omap.Mu, omap.data, nsamp, sel, c0, G))

    # the linear channels stacked: the objective and gradient are two sparse mat-vecs
    lin_ch = [ch for ch in chans if ch.linear]
    G_lin = GT_lin = z_lin = w_lin = None
    if lin_ch:
        G_lin = sps.vstack([ch.G for ch in lin_ch], format="csr")
        GT_lin = G_lin.T.tocsr()
        z_lin = np.concatenate([ch.values for ch in lin_ch])
        w_lin = np.concatenate([ch.weights for ch in lin_ch])

    return NLPStructure(
        transcription=tr, generated=g, measurements=measurements, P=P, T=T, Mz=Mz, ic=ic, A_lin=A_lin,
        linear_bounds=linear_bounds, lin_bounded=lin_bounded, jac_rows=jac_rows, jac_cols=jac_cols, E_jac=E_jac,
        jac_const=jac_const, channels=tuple(chans), G_lin=G_lin, GT_lin=GT_lin, z_lin=z_lin, w_lin=w_lin)


def _build_hessian(st: NLPStructure) -> HessianStructure:
    """The Lagrangian Hessian: the constraint part, the constant objective part of the linear
    channels and the nonlinear channels' parts."""
    tr, g = st.transcription, st.generated
    n = st.T.shape[1]
    n_col = tr.n_collocation
    hr, hc = g.HESS_ROWS, g.HESS_COLS
    triples = [_hess_triples(st.Mz, n_col, tr.nz, hr, hc)]
    nsrc = [n_col * len(hr)]
    H_lin = sps.csr_matrix((n, n))
    for ch in st.channels:
        if ch.linear:
            H_lin = H_lin + ch.G.T @ sps.diags(ch.weights) @ ch.G
    has, _, weight = tr.spec.prior_arrays()
    if has.any():
        # the priors' penalty is quadratic in p = P r + c: a constant P^T W P in the parameter block
        Hp = st.P.T @ (weight[:, None] * st.P)
        H_lin = H_lin + sps.block_diag([sps.csr_matrix((n - Hp.shape[0], n - Hp.shape[0])),
                                        sps.csr_matrix(np.where(np.abs(Hp) > 0, Hp, 0.0))], format="csr")
    H_lin = sps.tril(H_lin).tocoo()
    triples.append((H_lin.row.astype(np.int64), H_lin.col.astype(np.int64), np.arange(H_lin.nnz), np.ones(H_lin.nnz)))
    nsrc.append(H_lin.nnz)
    obj_templates = []
    for ch in st.channels:
        if ch.linear:
            continue
        gi = ch.fn.grad_idx
        # Gauss-Newton part: all lower pairs of gradient entries; then the curvature part
        ga, gb = np.tril_indices(gi.size)
        pr = np.concatenate([gi[ga], ch.fn.hess_rows])
        pc = np.concatenate([gi[gb], ch.fn.hess_cols])
        # pairs with row < col (from gi order) must be flipped into the lower triangle
        lo_r, lo_c = np.maximum(pr, pc), np.minimum(pr, pc)
        triples.append(_hess_triples(ch.Mu, ch.n, tr.nu, lo_r, lo_c))
        nsrc.append(ch.n * lo_r.size)
        obj_templates.append((ch.index, gi, ga, gb))
    rows, cols, Es = _assemble(triples, nsrc)
    order = np.lexsort((cols, rows))
    Pm = sps.csr_matrix((np.ones(order.size), (np.arange(order.size), order)), shape=(order.size, order.size))
    return HessianStructure(rows[order], cols[order], (Pm @ Es[0]).tocsr(), Pm @ (Es[1] @ H_lin.data),
                            tuple((Pm @ E).tocsr() for E in Es[2:]), tuple(obj_templates))


class _LastLinearResidual:
    """A memo of the linear channels' weighted residual at the last ``x`` (the objective and
    the gradient are evaluated at the same point). It never changes a value."""

    __slots__ = ("x", "r")

    def __init__(self):
        self.x = None
        self.r = None


@dataclass(frozen=True, eq=False)
class CollocationNLP:
    """The collocated maximum-likelihood NLP with exact sparse derivatives.

    Build it with :func:`build_nlp`. A frozen value: an :class:`NLPStructure` (built
    once and shared by re-offset copies: the Jacobian's sparsity, the expansion matrices and
    the linear maps eagerly; the Lagrangian Hessian's structure, :attr:`NLPStructure.hessian`,
    on the first call that needs it -- a solve -- because the sensitivities, the estimability
    analysis and the score test never do, and building it costs 0.4-0.7 s per augmented model
    of the score test), a :class:`ParameterTransform`, and the vectors that depend on the
    transform's offset. Its methods are the callbacks of a
    sparse NLP solver (cyipopt's contract: ``objective``, ``gradient``, ``constraints``,
    ``jacobian`` with ``jacobianstructure``, ``hessian`` (lower triangle) with
    ``hessianstructure``).

    Attributes
    ----------
    structure : NLPStructure
    transform : ParameterTransform
    layout : ReducedLayout
        Owner of ``x`` and of the constraint rows.
    transcription, generated, measurements, spec
    n, m : int
        Numbers of variables and constraints.
    x_lower, x_upper, c_lower, c_upper : ndarray
    """

    structure: NLPStructure
    transform: ParameterTransform
    _memo: _LastLinearResidual = field(default_factory=_LastLinearResidual, repr=False)

    def __post_init__(self):
        st = self.structure
        tf = self.transform
        if tf.P.shape != st.P.shape or not np.array_equal(tf.P, st.P):
            raise SettingsError("the transform's P differs from the structure's; build a new NLP with_transform()")
        tr = st.transcription
        spec = tr.spec
        lay = tr.layout
        nsv = lay.n_state_vars
        ns = lay.n_states
        n_col = tr.n_collocation
        c = tf.c
        set_ = object.__setattr__
        w0 = np.concatenate([np.zeros(nsv), c])
        set_(self, "layout", ReducedLayout(lay, tf, ns, n_col * ns, st.A_lin.shape[0]))
        set_(self, "w0", w0)
        Mz_c, ic_c, Mu_c = st.offset_columns
        set_(self, "_z0", Mz_c @ c)
        set_(self, "_ic_off", tr.ic_offset - ic_c @ c)
        chans = []
        for mp, M in zip(st.channels, Mu_c):
            u0 = M @ c
            chans.append(_Channel(mp, u0, (mp.sel @ u0 + mp.c0) if mp.linear else None))
        set_(self, "_channels", tuple(chans))
        lin = [ch for ch in chans if ch.linear]
        set_(self, "_g0_lin", np.concatenate([ch.g0 for ch in lin]) if lin else None)
        lo, hi = spec.lower, spec.upper
        if st.linear_bounds:
            b = st.lin_bounded
            lin_lo, lin_hi = (lo - c)[b], (hi - c)[b]
            x_lower, x_upper = np.full(self.n, -np.inf), np.full(self.n, np.inf)
        else:
            lin_lo = lin_hi = np.empty(0)
            x_lower = np.concatenate([np.full(nsv, -np.inf), lo - c if np.any(c) else lo])
            x_upper = np.concatenate([np.full(nsv, np.inf), hi - c if np.any(c) else hi])
        set_(self, "x_lower", x_lower)
        set_(self, "x_upper", x_upper)
        has, mean, weight = spec.prior_arrays()
        set_(self, "_prior", (mean, weight) if has.any() else None)
        set_(self, "c_lower", np.concatenate([np.zeros(ns + n_col * ns), lin_lo]))
        set_(self, "c_upper", np.concatenate([np.zeros(ns + n_col * ns), lin_hi]))

    # ------------------------------------------------------------------ sizes and parts
    transcription = property(lambda self: self.structure.transcription)
    generated = property(lambda self: self.structure.generated)
    measurements = property(lambda self: self.structure.measurements)
    spec = property(lambda self: self.structure.transcription.spec)
    T = property(lambda self: self.structure.T)

    @property
    def n(self) -> int:
        return self.layout.n

    @property
    def m(self) -> int:
        return self.layout.m

    @property
    def n_states_vars(self) -> int:
        return self.layout.n_state_vars

    @property
    def m_ic(self) -> int:
        return self.layout.n_ic

    @property
    def m_col(self) -> int:
        return self.layout.n_collocation

    @property
    def m_lin(self) -> int:
        return self.layout.n_linear

    @property
    def n_residuals(self) -> int:
        return sum(ch.n for ch in self._channels)

    @property
    def channel_names(self) -> tuple[str, ...]:
        return tuple(ch.name for ch in self._channels)

    @property
    def channel_sigmas(self) -> np.ndarray:
        """One sigma per channel, shape (n_channels,): the channel's sigma, or for a channel with
        per-sample sigmas the one with the same total weight, ``1 / sqrt(mean(1 / sigma_i^2))``
        (:func:`rocketid.data.equivalent_sigma`; the samples' own are :meth:`channel_sigma_arrays`)."""
        return np.array([equivalent_sigma(ch.sigma) if ch.maps.per_sample else float(ch.sigma[0])
                         for ch in self._channels])

    def channel_sigma_arrays(self) -> dict[str, np.ndarray]:
        """Each channel's noise standard deviation at its samples, ``{name: shape (n,)}``."""
        return {ch.name: ch.sigma for ch in self._channels}

    @property
    def per_sample_channels(self) -> tuple[str, ...]:
        """The channels whose samples have different sigmas (per-sample sigma)."""
        return tuple(ch.name for ch in self._channels if ch.maps.per_sample)

    def channel_slices(self) -> dict[str, slice]:
        """Each channel's rows in the stacked residuals (:meth:`output_jacobian`, :meth:`sigma_vector`)."""
        out, start = {}, 0
        for ch in self._channels:
            out[ch.name] = slice(start, start + ch.n)
            start += ch.n
        return out

    # ------------------------------------------------------------------ helpers
    def points(self, x: np.ndarray) -> np.ndarray:
        """Point variables ``Z`` at the collocation points, shape (n_col, nz)."""
        st = self.structure
        return (st.Mz @ x + self._z0).reshape(st.n_collocation_points, st.transcription.nz)

    def full_vector(self, x: np.ndarray) -> np.ndarray:
        """The collocation vector ``w = T x + w0``."""
        return self.layout.full(x, self.structure.T, self.w0)

    def reduced_vector(self, w: np.ndarray) -> np.ndarray:
        """``x`` for a full ``w`` (least squares in the parameter part)."""
        return self.layout.from_full(w)

    def initial_x(self, states: np.ndarray, p: np.ndarray) -> np.ndarray:
        """``x`` from node states and a full parameter vector."""
        return self.layout.start(states, p)

    def outputs(self, x: np.ndarray, linear: bool = True) -> list[np.ndarray]:
        """Model outputs at each channel's sample times (``linear=False``: only
        the channels with nonlinear outputs)."""
        return [ch.output(x) for ch in self._channels if linear or not ch.linear]

    def residuals(self, x: np.ndarray, linear: bool = True) -> list[np.ndarray]:
        """Model minus measurement, per channel (not divided by sigma)."""
        chans = [ch for ch in self._channels if linear or not ch.linear]
        return [y - ch.values for y, ch in zip(self.outputs(x, linear), chans)]

    # ------------------------------------------------------------ NLP callbacks
    def _linear_residual(self, x: np.ndarray) -> np.ndarray:
        """Weighted residual ``G x + g0 - z`` of the linear channels, memoized for the last x."""
        memo = self._memo
        if memo.x is not None and np.array_equal(memo.x, x):
            return memo.r
        st = self.structure
        r = st.G_lin @ x + (self._g0_lin - st.z_lin)
        memo.x, memo.r = np.array(x, copy=True), r
        return r

    def objective(self, x: np.ndarray) -> float:
        """``J = 1/2 sum ((y - y_meas)/sigma)^2`` (7.5)."""
        st = self.structure
        J = 0.0
        if st.G_lin is not None:
            r = self._linear_residual(x)
            # np.sum, not a BLAS dot: OpenBLAS threads ddot above 10 000 entries, and waking
            # (then spinning) its threads cost 15 ms a call on a busy 2-core machine
            J += 0.5 * float(np.sum(r * (st.w_lin * r)))
        for r, ch in zip(self.residuals(x, linear=False), (c for c in self._channels if not c.linear)):
            J += 0.5 * float(np.sum(r * r * ch.weights))
        return J + self.prior_objective(x)

    def prior_objective(self, x: np.ndarray) -> float:
        """The priors' penalty ``sum ((p - mean) / sd)^2 / 2`` at ``x`` (0 without priors)."""
        if self._prior is None:
            return 0.0
        mean, weight = self._prior
        d = self.layout.parameters(x) - mean
        return 0.5 * float(np.sum(weight * d * d))

    def gradient(self, x: np.ndarray) -> np.ndarray:
        st = self.structure
        if st.G_lin is not None:
            grad = st.GT_lin @ (st.w_lin * self._linear_residual(x))
        else:
            grad = np.zeros(self.n)
        for ch in self._channels:
            if ch.linear:
                continue
            U, y, gv = ch.evaluate(x, 1)
            r = (y - ch.values) * ch.weights
            dU = np.zeros_like(U)
            dU[:, ch.maps.fn.grad_idx] = gv * r[:, None]
            grad += ch.maps.Mu.T @ dU.ravel()
        if self._prior is not None:
            mean, weight = self._prior
            grad = np.array(grad, dtype=float)
            grad[self.layout.parameter_columns] += self.transform.P.T @ (weight * (self.layout.parameters(x) - mean))
        return grad

    def constraints(self, x: np.ndarray) -> np.ndarray:
        st = self.structure
        F = self.generated.residual(self.points(x), st.transcription.point_data)
        return np.concatenate([st.ic @ x - self._ic_off, F.ravel(), st.A_lin @ x])

    def jacobianstructure(self) -> tuple[np.ndarray, np.ndarray]:
        return self.structure.jac_rows, self.structure.jac_cols

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        st = self.structure
        vals = self.generated.jacobian(self.points(x), st.transcription.point_data)
        return st.E_jac @ vals.ravel() + st.jac_const

    def hessianstructure(self) -> tuple[np.ndarray, np.ndarray]:
        hs = self.structure.hessian
        return hs.rows, hs.cols

    def hessian(self, x: np.ndarray, lagrange: np.ndarray, obj_factor: float) -> np.ndarray:
        st = self.structure
        hs = st.hessian
        lam = np.asarray(lagrange)[self.layout.collocation_rows].reshape(st.n_collocation_points, st.n_states)
        vals = self.generated.hessian(self.points(x), st.transcription.point_data, lam)
        H = hs.E_con @ vals.ravel() + obj_factor * hs.obj_const
        for (index, gi, ga, gb), E in zip(hs.obj_templates, hs.E_obj):
            ch = self._channels[index]
            U, y, gv, hv = ch.evaluate(x, 2)
            w = ch.weights
            r = (y - ch.values) * w
            q = np.concatenate([gv[:, ga] * gv[:, gb] * w[:, None], hv * r[:, None]], axis=1)
            H = H + obj_factor * (E @ q.ravel())
        return H

    # ------------------------------------------------------- sparse matrices
    def jacobian_matrix(self, x: np.ndarray) -> sps.csr_matrix:
        """The constraint Jacobian as a sparse matrix (m, n)."""
        st = self.structure
        return sps.csr_matrix((self.jacobian(x), (st.jac_rows, st.jac_cols)), shape=(self.m, self.n))

    def output_jacobian(self, x: np.ndarray) -> sps.csr_matrix:
        """``dy/dx`` for all channels stacked, shape (n_residuals, n)."""
        blocks = []
        for ch in self._channels:
            if ch.linear:
                blocks.append(ch.maps.G)
            else:
                U, _, gv = ch.evaluate(x, 1)
                gi = ch.maps.fn.grad_idx
                sel = sps.csr_matrix((gv.ravel(), (np.repeat(np.arange(ch.n), gi.size),
                                                   (np.arange(ch.n)[:, None] * U.shape[1] + gi).ravel())),
                                     shape=(ch.n, U.size))
                blocks.append((sel @ ch.maps.Mu).tocsr())
        return sps.vstack(blocks, format="csr")

    def sigma_vector(self) -> np.ndarray:
        """Noise standard deviation of every stacked residual."""
        return np.concatenate([ch.sigma for ch in self._channels])

    # ------------------------------------------------------- new values
    def with_offset(self, c: np.ndarray) -> "CollocationNLP":
        """The same transformed problem with a new offset ``c`` in ``p = P r + c``.

        The structure is shared (no sparsity, no expansion matrices rebuilt); only the
        offset-dependent vectors are recomputed. This is the cheap path of the sampling
        loop, where (7.9) is re-solved for many values of the fixed ``q2``.
        """
        return CollocationNLP(self.structure, self.transform.with_offset(c))

    def with_transform(self, transform: ParameterTransform) -> "CollocationNLP":
        """The same problem with parameters ``p = P r + c`` (for (7.9)); the structure is
        shared when ``P`` is the same."""
        if transform.P.shape == self.transform.P.shape and np.array_equal(transform.P, self.transform.P) \
                and self.structure.linear_bounds == (not transform.is_identity):
            return CollocationNLP(self.structure, transform)
        st = self.structure
        return build_nlp(st.transcription, st.generated, st.measurements, transform)


def build_nlp(transcription: Transcription, generated: GeneratedModel, measurements: Measurements,
              transform: ParameterTransform | None = None) -> CollocationNLP:
    """Assemble the sparse NLP (7.5) or, with a transform, (7.9)."""
    spec = transcription.spec
    n_p = len(spec.parameters)
    if transform is None:
        transform = ParameterTransform.identity(spec.parameter_names)
    if transform.P.shape[0] != n_p:
        raise SettingsError(f"parameter transform has {transform.P.shape[0]} rows; the model has {n_p} parameters")
    structure = _build_structure(transcription, generated, measurements, transform.P, not transform.is_identity)
    return CollocationNLP(structure, transform)
