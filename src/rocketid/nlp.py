"""The sparse NLP (7.5), and (7.9) with parameters transformed: exact derivatives by index arithmetic.

The collocated problem is

    min_x  J(x) = 1/2 sum_k sum_s ((g_k(u_ks) - y_ks) / sigma_k)^2
    s.t.   c(x) = [ IC w - s0 ;  F(z_c) for every collocation point c ;  A_lin x ]
           cl <= c(x) <= cu,  xl <= x <= xu

with the full decision vector ``w = T x + w0`` (``T`` is the identity for the
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

from dataclasses import dataclass, replace

import numpy as np
import scipy.sparse as sps

from .codegen import GeneratedModel
from .collocation.transcription import Transcription
from .data import Measurements
from .errors import SettingsError

__all__ = ["CollocationNLP", "ParameterTransform", "build_nlp"]


@dataclass(frozen=True)
class ParameterTransform:
    """``p = P r + c``: the parameters as an affine function of the reduced ones.

    The identity (``P = I``, ``c = 0``) is the full estimation (7.5); for
    (7.9) ``P = V1`` and ``c = V2 q2``.

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

    @classmethod
    def identity(cls, names) -> "ParameterTransform":
        n = len(names)
        return cls(np.eye(n), np.zeros(n), tuple(names))

    @property
    def is_identity(self) -> bool:
        return self.P.shape[0] == self.P.shape[1] and np.array_equal(self.P, np.eye(self.P.shape[0])) \
            and not np.any(self.c)


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


def _assemble(triples, n_src_list, shape_rows_cols=None):
    """Unique (row, col) structure over several sources and one expansion matrix each."""
    rows = np.concatenate([t[0] for t in triples]) if triples else np.empty(0, np.int64)
    cols = np.concatenate([t[1] for t in triples]) if triples else np.empty(0, np.int64)
    if rows.size:
        key = rows.astype(np.int64) * (cols.max() + 1 if cols.size else 1) + cols
        uniq, inverse = np.unique(key, return_inverse=True)
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
class _Channel:
    name: str
    index: int
    values: np.ndarray        # measured
    sigma: float
    linear: bool
    G: sps.csr_matrix | None  # linear: y = G x + g0
    g0: np.ndarray | None
    Mu: sps.csr_matrix        # u = Mu x + u0
    u0: np.ndarray
    data: np.ndarray
    n: int
    Mu_full: sps.csr_matrix   # u = Mu_full w (before the transform)
    sel: sps.csr_matrix | None
    c0: float


class CollocationNLP:
    """The collocated maximum-likelihood NLP with exact sparse derivatives.

    Build it with :func:`build_nlp`. It is immutable after construction; its
    methods are the callbacks of a sparse NLP solver (cyipopt's contract:
    ``objective``, ``gradient``, ``constraints``, ``jacobian`` with
    ``jacobianstructure``, ``hessian`` (lower triangle) with
    ``hessianstructure``).

    Attributes
    ----------
    transcription : Transcription
    generated : GeneratedModel
    measurements : Measurements
    transform : ParameterTransform
    n, m : int
        Numbers of variables and constraints.
    x_lower, x_upper, c_lower, c_upper : ndarray
    """

    def __init__(self, transcription: Transcription, generated: GeneratedModel, measurements: Measurements,
                 transform: ParameterTransform | None = None):
        tr = transcription
        spec = tr.spec
        lay = tr.layout
        self.transcription = tr
        self.generated = generated
        self.measurements = measurements
        self.spec = spec
        n_p = len(spec.parameters)
        if transform is None:
            transform = ParameterTransform.identity(spec.parameter_names)
        if transform.P.shape[0] != n_p:
            raise SettingsError(f"parameter transform has {transform.P.shape[0]} rows; the model has {n_p} parameters")
        self.transform = transform
        n_r = transform.P.shape[1]
        nsv = lay.n_state_vars
        # w = T x + w0
        T = sps.bmat([[sps.identity(nsv, format="csr"), None],
                      [None, sps.csr_matrix(transform.P)]], format="csr")
        w0 = np.concatenate([np.zeros(nsv), transform.c])
        self.T, self.w0 = T, w0
        self.n = nsv + n_r
        self.n_states_vars = nsv

        g = generated
        ns = lay.n_states
        n_col = tr.n_collocation
        self._ns, self._ncol, self._nz = ns, n_col, tr.nz
        self._Mz = (tr.Mz @ T).tocsr()
        self._Mz.sort_indices()
        self._z0 = tr.Mz @ w0
        self._D = tr.point_data
        self._ic = (tr.ic_matrix @ T).tocsr()
        self._ic_off = tr.ic_offset - tr.ic_matrix @ w0

        # linear rows for bounds on p when transformed
        lo, hi = spec.lower, spec.upper
        if transform.is_identity:
            self._A_lin = sps.csr_matrix((0, self.n))
            self.x_lower = np.concatenate([np.full(nsv, -np.inf), lo])
            self.x_upper = np.concatenate([np.full(nsv, np.inf), hi])
            lin_lo = lin_hi = np.empty(0)
        else:
            bounded = np.isfinite(lo) | np.isfinite(hi)
            A = np.zeros((int(bounded.sum()), self.n))
            A[:, nsv:] = transform.P[bounded]
            self._A_lin = sps.csr_matrix(A)
            lin_lo = (lo - transform.c)[bounded]
            lin_hi = (hi - transform.c)[bounded]
            self.x_lower = np.full(self.n, -np.inf)
            self.x_upper = np.full(self.n, np.inf)
        self._lin_bounded = None if transform.is_identity else np.flatnonzero(np.isfinite(lo) | np.isfinite(hi))
        self.m_ic, self.m_col, self.m_lin = ns, n_col * ns, self._A_lin.shape[0]
        self.m = self.m_ic + self.m_col + self.m_lin
        self.c_lower = np.concatenate([np.zeros(ns + n_col * ns), lin_lo])
        self.c_upper = np.concatenate([np.zeros(ns + n_col * ns), lin_hi])

        # ---- Jacobian structure: IC rows, collocation rows (expanded), linear rows
        jr, jc = g.JAC_ROWS, g.JAC_COLS
        col_tr = _jac_triples(self._Mz, n_col, tr.nz, jr, jc, lambda item, k: ns + item * ns + k)
        ic = self._ic.tocoo()
        lin = self._A_lin.tocoo()
        const_r = np.concatenate([ic.row, lin.row + ns + n_col * ns])
        const_c = np.concatenate([ic.col, lin.col])
        const_v = np.concatenate([ic.data, lin.data])
        const_tr = (const_r.astype(np.int64), const_c.astype(np.int64), np.arange(const_r.size), np.ones(const_r.size))
        rows, cols, (E_col, E_const) = _assemble([col_tr, const_tr], [n_col * len(jr), const_r.size])
        order = np.lexsort((cols, rows))
        perm = np.empty_like(order)
        perm[order] = np.arange(order.size)
        P = sps.csr_matrix((np.ones(order.size), (np.arange(order.size), order)), shape=(order.size, order.size))
        self._jac_rows, self._jac_cols = rows[order], cols[order]
        self._E_jac = (P @ E_col).tocsr()
        self._jac_const = P @ (E_const @ const_v)

        # ---- channels (objective)
        chans = []
        for k, omap in enumerate(tr.outputs):
            ch = measurements[omap.name]
            sigma = ch.sigma if ch.sigma is not None else spec.outputs[k].sigma
            Mu = (omap.Mu @ T).tocsr()
            Mu.sort_indices()
            u0 = omap.Mu @ w0
            lin = bool(g.OUTPUT_LINEAR[k])
            G = g0 = None
            nsamp = omap.times.size
            sel, c0 = None, 0.0
            if lin:
                # y = sum_a c_a u_a + c0, constant c: fold into one sparse matrix
                Uz = np.zeros((1, tr.nu))
                gi = np.asarray(g.OUTPUT_GRAD_IDX[k], dtype=np.int64)
                cvec = getattr(g, f"output_{k}_grad")(Uz, np.zeros((1, 1)))[0]
                c0 = float(getattr(g, f"output_{k}")(Uz, np.zeros((1, 1)))[0])
                sel = sps.csr_matrix((np.tile(cvec, nsamp),
                                      (np.repeat(np.arange(nsamp), gi.size), (np.arange(nsamp)[:, None] * tr.nu + gi).ravel())),
                                     shape=(nsamp, nsamp * tr.nu))
                G = (sel @ Mu).tocsr()
                g0 = sel @ u0 + c0
            chans.append(_Channel(omap.name, k, ch.values, float(sigma), lin, G, g0, Mu, u0, omap.data, nsamp,
                                  omap.Mu, sel, c0))
        self._channels = tuple(chans)
        self.n_residuals = sum(c.n for c in chans)
        self._stack_linear()

        self._hess_built = False  # the Hessian's structure is built on first use (_build_hessian)

    def _build_hessian(self) -> None:
        """Structure and expansion matrices of the Lagrangian Hessian: the
        constraint part, the constant objective part of the linear channels and
        the nonlinear channels' parts. Built on first use: sensitivities and the
        score test never need it."""
        if self._hess_built:
            return
        g = self.generated
        tr = self.transcription
        n_col = self._ncol
        chans = self._channels
        hr, hc = g.HESS_ROWS, g.HESS_COLS
        con_tr = _hess_triples(self._Mz, n_col, tr.nz, hr, hc)
        triples = [con_tr]
        nsrc = [n_col * len(hr)]
        H_lin = sps.csr_matrix((self.n, self.n))
        for ch in chans:
            if ch.linear:
                H_lin = H_lin + (ch.G.T @ ch.G) / ch.sigma ** 2
        H_lin = sps.tril(H_lin).tocoo()
        triples.append((H_lin.row.astype(np.int64), H_lin.col.astype(np.int64), np.arange(H_lin.nnz), np.ones(H_lin.nnz)))
        nsrc.append(H_lin.nnz)
        self._obj_templates = []
        for ch in chans:
            if ch.linear:
                continue
            gi = np.asarray(g.OUTPUT_GRAD_IDX[ch.index], dtype=np.int64)
            # Gauss-Newton part: all lower pairs of gradient entries; then the curvature part
            ga, gb = np.tril_indices(gi.size)
            pr = np.concatenate([gi[ga], np.asarray(g.OUTPUT_HESS_ROWS[ch.index], dtype=np.int64)])
            pc = np.concatenate([gi[gb], np.asarray(g.OUTPUT_HESS_COLS[ch.index], dtype=np.int64)])
            # pairs with row < col (from gi order) must be flipped into the lower triangle
            lo_r, lo_c = np.maximum(pr, pc), np.minimum(pr, pc)
            triples.append(_hess_triples(ch.Mu, ch.n, tr.nu, lo_r, lo_c))
            nsrc.append(ch.n * lo_r.size)
            self._obj_templates.append((ch, gi, ga, gb))
        rows, cols, Es = _assemble(triples, nsrc)
        order = np.lexsort((cols, rows))
        P = sps.csr_matrix((np.ones(order.size), (np.arange(order.size), order)), shape=(order.size, order.size))
        self._hess_rows, self._hess_cols = rows[order], cols[order]
        self._E_hess_con = (P @ Es[0]).tocsr()
        self._hess_obj_const = P @ (Es[1] @ H_lin.data)
        self._E_hess_obj = [(P @ E).tocsr() for E in Es[2:]]
        self._hess_built = True

    # ------------------------------------------------------------------ helpers
    def points(self, x: np.ndarray) -> np.ndarray:
        """Point variables ``Z`` at the collocation points, shape (n_col, nz)."""
        return (self._Mz @ x + self._z0).reshape(self._ncol, self._nz)

    def full_vector(self, x: np.ndarray) -> np.ndarray:
        """The collocation vector ``w = T x + w0``."""
        return self.T @ x + self.w0

    def reduced_vector(self, w: np.ndarray) -> np.ndarray:
        """``x`` for a full ``w`` (least squares in the parameter part)."""
        lay = self.transcription.layout
        S, p = lay.unpack(w)
        r = np.linalg.lstsq(self.transform.P, p - self.transform.c, rcond=None)[0]
        return np.concatenate([S.ravel(), r])

    def outputs(self, x: np.ndarray, linear: bool = True) -> list[np.ndarray]:
        """Model outputs at each channel's sample times (``linear=False``: only
        the channels with nonlinear outputs)."""
        out = []
        for ch in self._channels:
            if ch.linear and not linear:
                continue
            if ch.linear:
                out.append(ch.G @ x + ch.g0)
            else:
                U = (ch.Mu @ x + ch.u0).reshape(ch.n, -1)
                out.append(getattr(self.generated, f"output_{ch.index}")(U, ch.data))
        return out

    def residuals(self, x: np.ndarray, linear: bool = True) -> list[np.ndarray]:
        """Model minus measurement, per channel (not divided by sigma)."""
        chans = [ch for ch in self._channels if linear or not ch.linear]
        return [y - ch.values for y, ch in zip(self.outputs(x, linear), chans)]

    @property
    def channel_names(self) -> tuple[str, ...]:
        return tuple(ch.name for ch in self._channels)

    @property
    def channel_sigmas(self) -> np.ndarray:
        return np.array([ch.sigma for ch in self._channels])

    # ------------------------------------------------------------ NLP callbacks
    def _stack_linear(self) -> None:
        """Stack the linear channels into one ``G`` (and its transpose, as CSR)
        so that the objective and gradient are two sparse mat-vecs."""
        lin = [ch for ch in self._channels if ch.linear]
        self._lin_cache = (None, None)
        if not lin:
            self._G_lin = None
            return
        self._G_lin = sps.vstack([ch.G for ch in lin], format="csr")
        self._GT_lin = self._G_lin.T.tocsr()
        self._g0_lin = np.concatenate([ch.g0 for ch in lin])
        self._z_lin = np.concatenate([ch.values for ch in lin])
        self._w_lin = np.concatenate([np.full(ch.n, 1.0 / ch.sigma ** 2) for ch in lin])

    def _linear_residual(self, x: np.ndarray) -> np.ndarray:
        """Weighted residual ``w (G x + g0 - z)`` of the linear channels, cached for the last x."""
        last_x, last_r = self._lin_cache
        if last_x is not None and np.array_equal(last_x, x):
            return last_r
        r = self._G_lin @ x + (self._g0_lin - self._z_lin)
        self._lin_cache = (np.array(x, copy=True), r)
        return r

    def objective(self, x: np.ndarray) -> float:
        """``J = 1/2 sum ((y - y_meas)/sigma)^2`` (7.5)."""
        J = 0.0
        if self._G_lin is not None:
            r = self._linear_residual(x)
            # np.sum, not a BLAS dot: OpenBLAS threads ddot above 10 000 entries, and waking
            # (then spinning) its threads cost 15 ms a call on a busy 2-core machine
            J += 0.5 * float(np.sum(r * (self._w_lin * r)))
        for r, ch in zip(self.residuals(x, linear=False), (c for c in self._channels if not c.linear)):
            J += 0.5 * float(np.sum(r * r)) / ch.sigma ** 2
        return J

    def gradient(self, x: np.ndarray) -> np.ndarray:
        if self._G_lin is not None:
            grad = self._GT_lin @ (self._w_lin * self._linear_residual(x))
        else:
            grad = np.zeros(self.n)
        for ch in self._channels:
            if ch.linear:
                continue
            else:
                U = (ch.Mu @ x + ch.u0).reshape(ch.n, -1)
                gfun = self.generated
                r = (getattr(gfun, f"output_{ch.index}")(U, ch.data) - ch.values) / ch.sigma ** 2
                gv = getattr(gfun, f"output_{ch.index}_grad")(U, ch.data)
                gi = np.asarray(gfun.OUTPUT_GRAD_IDX[ch.index])
                dU = np.zeros_like(U)
                dU[:, gi] = gv * r[:, None]
                grad += ch.Mu.T @ dU.ravel()
        return grad

    def constraints(self, x: np.ndarray) -> np.ndarray:
        F = self.generated.residual(self.points(x), self._D)
        return np.concatenate([self._ic @ x - self._ic_off, F.ravel(), self._A_lin @ x])

    def jacobianstructure(self) -> tuple[np.ndarray, np.ndarray]:
        return self._jac_rows, self._jac_cols

    def jacobian(self, x: np.ndarray) -> np.ndarray:
        vals = self.generated.jacobian(self.points(x), self._D)
        return self._E_jac @ vals.ravel() + self._jac_const

    def hessianstructure(self) -> tuple[np.ndarray, np.ndarray]:
        self._build_hessian()
        return self._hess_rows, self._hess_cols

    def hessian(self, x: np.ndarray, lagrange: np.ndarray, obj_factor: float) -> np.ndarray:
        self._build_hessian()
        lam = np.asarray(lagrange)[self.m_ic:self.m_ic + self.m_col].reshape(self._ncol, self._ns)
        vals = self.generated.hessian(self.points(x), self._D, lam)
        H = self._E_hess_con @ vals.ravel() + obj_factor * self._hess_obj_const
        for (ch, gi, ga, gb), E in zip(self._obj_templates, self._E_hess_obj):
            g = self.generated
            U = (ch.Mu @ x + ch.u0).reshape(ch.n, -1)
            r = (getattr(g, f"output_{ch.index}")(U, ch.data) - ch.values) / ch.sigma ** 2
            gv = getattr(g, f"output_{ch.index}_grad")(U, ch.data)
            hv = getattr(g, f"output_{ch.index}_hess")(U, ch.data)
            q = np.concatenate([gv[:, ga] * gv[:, gb] / ch.sigma ** 2, hv * r[:, None]], axis=1)
            H = H + obj_factor * (E @ q.ravel())
        return H

    # ------------------------------------------------------- sparse matrices
    def jacobian_matrix(self, x: np.ndarray) -> sps.csr_matrix:
        """The constraint Jacobian as a sparse matrix (m, n)."""
        return sps.csr_matrix((self.jacobian(x), (self._jac_rows, self._jac_cols)), shape=(self.m, self.n))

    def output_jacobian(self, x: np.ndarray) -> sps.csr_matrix:
        """``dy/dx`` for all channels stacked, shape (n_residuals, n)."""
        blocks = []
        for ch in self._channels:
            if ch.linear:
                blocks.append(ch.G)
            else:
                U = (ch.Mu @ x + ch.u0).reshape(ch.n, -1)
                gv = getattr(self.generated, f"output_{ch.index}_grad")(U, ch.data)
                gi = np.asarray(self.generated.OUTPUT_GRAD_IDX[ch.index])
                sel = sps.csr_matrix((gv.ravel(), (np.repeat(np.arange(ch.n), gi.size),
                                                   (np.arange(ch.n)[:, None] * U.shape[1] + gi).ravel())),
                                     shape=(ch.n, U.size))
                blocks.append((sel @ ch.Mu).tocsr())
        return sps.vstack(blocks, format="csr")

    def sigma_vector(self) -> np.ndarray:
        """Noise standard deviation of every stacked residual."""
        return np.concatenate([np.full(ch.n, ch.sigma) for ch in self._channels])

    def with_offset(self, c: np.ndarray) -> "CollocationNLP":
        """The same transformed problem with a new offset ``c`` in ``p = P r + c``.

        Only the offset-dependent vectors are recomputed (no structure, no
        expansion matrices): this is the cheap path of the sampling loop,
        where (7.9) is re-solved for many values of the fixed ``q2``.
        """
        import copy
        # re-offset copies solve (7.9): build the Hessian structure once here, so that
        # every copy shares it instead of rebuilding it per solve
        self._build_hessian()
        c = np.asarray(c, dtype=float)
        if c.shape != self.transform.c.shape:
            raise SettingsError(f"offset has shape {c.shape}, expected {self.transform.c.shape}")
        new = copy.copy(self)
        new.transform = ParameterTransform(self.transform.P, c, self.transform.names)
        tr = self.transcription
        nsv = self.n_states_vars
        w0 = np.concatenate([np.zeros(nsv), c])
        new.w0 = w0
        new._z0 = tr.Mz @ w0
        new._ic_off = tr.ic_offset - tr.ic_matrix @ w0
        chans = []
        for ch in self._channels:
            u0 = ch.Mu_full @ w0
            g0 = (ch.sel @ u0 + ch.c0) if ch.linear else None
            chans.append(replace(ch, u0=u0, g0=g0))
        new._channels = tuple(chans)
        new._stack_linear()
        if self._obj_templates:
            new._obj_templates = [(chans[[c_.index for c_ in chans].index(t[0].index)],) + tuple(t[1:])
                                  for t in self._obj_templates]
        if self._lin_bounded is not None:
            lo, hi = self.spec.lower, self.spec.upper
            b = self._lin_bounded
            new.c_lower = np.concatenate([self.c_lower[:self.m_ic + self.m_col], (lo - c)[b]])
            new.c_upper = np.concatenate([self.c_upper[:self.m_ic + self.m_col], (hi - c)[b]])
        return new

    def with_transform(self, transform: ParameterTransform) -> "CollocationNLP":
        """The same problem with parameters ``p = P r + c`` (for (7.9))."""
        return CollocationNLP(self.transcription, self.generated, self.measurements, transform)

    def initial_x(self, states: np.ndarray, p: np.ndarray) -> np.ndarray:
        """``x`` from node states and a full parameter vector."""
        return self.reduced_vector(self.transcription.layout.pack(states, p))


def build_nlp(transcription: Transcription, generated: GeneratedModel, measurements: Measurements,
              transform: ParameterTransform | None = None) -> CollocationNLP:
    """Assemble the sparse NLP (7.5) or, with a transform, (7.9)."""
    return CollocationNLP(transcription, generated, measurements, transform)
