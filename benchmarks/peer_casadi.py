"""Independent CasADi peer of rocketid's RA-66 estimation NLP (chapter eq. 7.5).

This file deliberately does not import rocketid: it is a second code base that
solves the same problem (docs/design.md, 'The problem, as rocketid fixes it') so that rocketid's benchmark can
compare against it.

Contents
--------
- ``yang_density(h)``: Yang's closed-form fit of the US Standard Atmosphere 1976 as a
  CasADi expression (``casadi.if_else`` over four layers; geometric altitude in m).
- ``simulate_ra66(p, t_eval)``: high-accuracy scipy DOP853 integration of RA-66 (the
  flight-path angle is integrated as delta = theta - pi/2, guarded at v = 0).
- ``make_data(seed, sigma)``: the 6600 synthetic x, h, v samples.
- ``CasadiRA66``: Radau collocation NLP solved by IPOPT through ``casadi.nlpsol``.

Run ``python benchmarks/peer_casadi.py`` for the benchmark numbers.
"""

from __future__ import annotations

import math
import time
import warnings

import casadi as ca
import numpy as np
import scipy.sparse as sp
import scipy.sparse.linalg as spla
from scipy.integrate import solve_ivp

# ----------------------------------------------------------------------------- RA-66 data
RE = 6371000.0  # Earth radius, m
G0 = 9.80665  # m/s^2
PE = 400000.0  # thrust, N
SM = math.pi * 1.0**2  # reference area, m^2
M0 = 20000.0  # kg
MDOT = 100.0  # kg/s
T_F = 66.0  # s
CD_KNOTS = np.linspace(0.0, 66.0, 7)  # 0, 11, ..., 66 s
ALPHA_KINKS = (4.0, 24.0)
ALPHA_AMP = -8.0 * math.pi / 180.0
P_TRUE = (0.5,) * 7 + (0.1,)
P0 = (0.1, 0.6, 0.1, 0.6, 0.1, 0.6, 0.1, 0.12)
P_LB, P_UB = 1e-4, 1.0
STATE0 = (0.0, 0.0, 0.0, math.pi / 2)  # x, h, v, theta

# Yang's fit (docs/design.md, 'Yang's atmosphere'): rho = 1.2250 * c * W^a, H geopotential in km.
RHO_SL = 1.2250
R0_GEOPOT_KM = 6356.766
_Z_BOUNDS_KM = (11.0191, 20.0631, 32.1619)  # geometric; above 47.3501 km the last layer is reused


def _geopotential_km(z_km):
    return z_km / (1.0 + z_km / R0_GEOPOT_KM)


def yang_density(h):
    """Yang's density fit as a CasADi expression of geometric altitude h (m).

    Works for SX/MX symbols and numeric input (returns a DM for numbers).
    """
    if not isinstance(h, (ca.SX, ca.MX, ca.DM)):
        h = ca.DM(np.asarray(h, float))
    z = h / 1000.0
    H = _geopotential_km(z)
    r1 = (1.0 - H / 44.3308) ** 4.2559
    r2 = 0.15898 * ca.exp((14.9647 - H) / 6.3416)
    r3 = 0.032722 * (1.0 + (H - 24.9021) / 221.552) ** (-35.1629)
    r4 = 3.2617e-3 * (1.0 + (H - 39.7500) / 89.4107) ** (-13.2011)
    b1, b2, b3 = _Z_BOUNDS_KM
    ratio = ca.if_else(z < b1, r1, ca.if_else(z < b2, r2, ca.if_else(z < b3, r3, r4)))
    return RHO_SL * ratio


def _yang_density_float(h: float) -> float:
    """Same fit in plain floats (for the scipy simulator)."""
    z = h / 1000.0
    H = _geopotential_km(z)
    b1, b2, b3 = _Z_BOUNDS_KM
    if z < b1:
        r = (1.0 - H / 44.3308) ** 4.2559
    elif z < b2:
        r = 0.15898 * math.exp((14.9647 - H) / 6.3416)
    elif z < b3:
        r = 0.032722 * (1.0 + (H - 24.9021) / 221.552) ** (-35.1629)
    else:
        r = 3.2617e-3 * (1.0 + (H - 39.7500) / 89.4107) ** (-13.2011)
    return RHO_SL * r


def alpha_of_t(t: float) -> float:
    """Attack angle (rad): -8 deg sin^2(pi (t-4)/20) on [4, 24] s, else 0."""
    if 4.0 <= t <= 24.0:
        return ALPHA_AMP * math.sin(math.pi * (t - 4.0) / 20.0) ** 2
    return 0.0


def _cd_weights(t: float) -> np.ndarray:
    """Weights w with CD(t) = w @ p[:7] (piecewise linear in time on CD_KNOTS)."""
    w = np.zeros(len(CD_KNOTS))
    tt = min(max(t, CD_KNOTS[0]), CD_KNOTS[-1])
    k = min(int(np.searchsorted(CD_KNOTS, tt, side="right")) - 1, len(CD_KNOTS) - 2)
    k = max(k, 0)
    s = (tt - CD_KNOTS[k]) / (CD_KNOTS[k + 1] - CD_KNOTS[k])
    w[k] = 1.0 - s
    w[k + 1] = s
    return w


# ----------------------------------------------------------------------------- simulator
def simulate_ra66(p_true=P_TRUE, t_eval=None, rtol=1e-12, atol=1e-12):
    """High-accuracy integration of RA-66 at parameters p = [CD0..CD6, CL].

    Integrates (x, h, v, delta = theta - pi/2) with DOP853, split at the CD knots and
    at alpha's kinks; d(delta)/dt = 0 while v < 1e-9 (picks the solution that leaves
    the pad vertically, docs/design.md 'The simulator integrates deviations'). Returns x, h, v, theta at t_eval.
    """
    p = np.asarray(p_true, dtype=float)
    cd_nodes, cl = p[:7], float(p[7])
    t_eval = np.atleast_1d(np.asarray(t_eval if t_eval is not None else np.linspace(0, T_F, 661), float))
    if t_eval.min() < 0.0 or t_eval.max() > T_F + 1e-12:
        raise ValueError("t_eval must lie in [0, 66] s")
    t_eval = np.clip(t_eval, 0.0, T_F)

    breaks = np.unique(np.concatenate([CD_KNOTS, ALPHA_KINKS]))
    out = np.full((4, t_eval.size), np.nan)
    state = np.array([0.0, 0.0, 0.0, 0.0])  # delta = 0
    done = np.zeros(t_eval.size, dtype=bool)

    for a, b in zip(breaks[:-1], breaks[1:]):
        # CD linear on [a, b] (a, b never straddle a knot)
        ca_, cb_ = float(np.interp(a, CD_KNOTS, cd_nodes)), float(np.interp(b, CD_KNOTS, cd_nodes))
        slope = (cb_ - ca_) / (b - a)

        def rhs(t, s, a=a, ca_=ca_, slope=slope):
            _, h, v, d = s
            m = M0 - MDOT * t
            al = alpha_of_t(t)
            rho = _yang_density_float(h)
            r = RE + h
            g = G0 * (RE / r) ** 2
            st = math.cos(d)  # sin(theta)
            ct = -math.sin(d)  # cos(theta)
            q = 0.5 * rho * v * v * SM
            cd = ca_ + slope * (t - a)
            dx = RE / r * v * ct
            dh = v * st
            dv = PE * math.cos(al) / m - q * cd / m - g * st
            if v < 1e-9:
                dd = 0.0
            else:
                dd = PE * math.sin(al) / (m * v) + q * cl / (m * v) - g * ct / v + v * ct / r
            return [dx, dh, dv, dd]

        sel = (~done) & (t_eval >= a) & (t_eval <= b)
        te = t_eval[sel]
        order = np.argsort(te)
        te_sorted = te[order]
        # always ask for the end point b as well, to start the next segment exactly there
        te_full = np.concatenate([te_sorted, [b]]) if (te.size == 0 or te_sorted[-1] < b) else te_sorted
        sol = solve_ivp(rhs, (a, b), state, method="DOP853", rtol=rtol, atol=atol, t_eval=te_full)
        if sol.status != 0:
            raise RuntimeError(f"integration failed on [{a}, {b}]: {sol.message}")
        if te.size:
            idx = np.flatnonzero(sel)[order]
            out[:, idx] = sol.y[:, : te.size]
            done[idx] = True
        state = sol.y[:, -1].copy()

    x, h, v, d = out
    return x, h, v, d + math.pi / 2


def make_data(seed=0, sigma=1.0):
    """Synthetic RA-66 measurements: t = 0.01 k, k = 1..6600; y = (x, h, v) + sigma N(0, 1).

    Returns (t, y_meas) with y_meas of shape (6600, 3).
    """
    t = 0.01 * np.arange(1, 6601)
    x, h, v, _ = simulate_ra66(P_TRUE, t)
    y = np.column_stack([x, h, v])
    rng = np.random.default_rng(seed)
    return t, y + sigma * rng.standard_normal(y.shape)


# ----------------------------------------------------------------------------- collocation
def _lagrange_polys(nodes):
    """Lagrange basis polynomials l_j (np.poly1d) on the given nodes."""
    polys = []
    for j, tj in enumerate(nodes):
        pj = np.poly1d([1.0])
        for k, tk in enumerate(nodes):
            if k != j:
                pj = pj * np.poly1d([1.0, -tk]) / (tj - tk)
        polys.append(pj)
    return polys


def _sparse_dm(M):
    """scipy sparse matrix -> casadi.DM with the same sparsity."""
    M = sp.csc_matrix(M, copy=True)
    M.sum_duplicates()
    M.sort_indices()
    spy = ca.Sparsity(M.shape[0], M.shape[1], M.indptr.tolist(), M.indices.tolist())
    return ca.DM(spy, M.data.tolist())


class CasadiRA66:
    """RA-66 estimation NLP (7.5) on Radau collocation, solved with IPOPT via CasADi.

    Decision variables: w = [gamma (N*K*4 state values, point-major, state order
    x, h, v, theta), p (8)] and, with ``condensed=False``, y (n*3) after them.
    The element-start state of element i > 0 is the last Radau point (tau = 1) of
    element i-1, so there are no continuity rows; the initial state is fixed.
    Collocation rows per point: D z - h f(z) for x, h, v and v * (D theta) - h * v f_theta.

    Objective 1/2 sum(((A gamma + b) - y_meas) / sigma)^2 with the fixed sparse Lagrange
    map A (b carries the fixed initial state). ``condensed=True`` writes it on gamma
    directly: ``objective_form="quadratic"`` (default) as 1/2 d'Q d + c'd with Q = A'A/sigma^2
    and d = gamma - gamma_ref (gamma_ref the unconstrained least-squares fit of the data; the
    constant is added back to the reported objective), ``"residual"`` as the sum of squares
    of A gamma + b - y_meas. ``condensed=False`` adds y as variables with rows y - A gamma - b.
    ``symbolic=None`` picks SX for the condensed NLP and MX (with the collocation rows as one
    SX function call) for the uncondensed one: the faster builds, measured.
    """

    NS = 4
    NP = 8

    def __init__(self, t_meas, y_meas, N=66, K=3, condensed=True, sigma=1.0, t_f=T_F,
                 ipopt_options=None, symbolic=None, objective_form="quadratic"):
        t_start = time.perf_counter()
        self.t_meas = np.asarray(t_meas, float)
        self.y_meas = np.asarray(y_meas, float).reshape(-1, 3)
        self.N, self.K, self.condensed = int(N), int(K), bool(condensed)
        self.t_f = float(t_f)
        n = self.t_meas.size
        self.sigma = np.broadcast_to(np.asarray(sigma, float), (n, 3)).copy()
        self._ipopt_options = dict(ipopt_options or {})

        N, K, NS = self.N, self.K, self.NS
        self._f_offset = 0.0
        if symbolic is None:  # whichever builds faster (measured): SX condensed, MX otherwise
            symbolic = "SX" if self.condensed else "MX"
        self.hstep = self.t_f / N
        self.tau = np.concatenate([[0.0], np.asarray(ca.collocation_points(K, "radau"), float)])
        polys = _lagrange_polys(self.tau)
        dpolys = [pl.deriv() for pl in polys]
        D = np.array([[dpolys[k](self.tau[j]) for k in range(K + 1)] for j in range(1, K + 1)])
        self.t_col = np.array([[i * self.hstep + self.hstep * self.tau[j] for j in range(1, K + 1)]
                               for i in range(N)])  # (N, K)
        self.ng = N * K * NS
        self.nw = self.ng + self.NP + (0 if self.condensed else 3 * n)

        # collocation residuals are always built in SX, vectorized over the N*K collocation
        # points (columns, point-major: element i, Radau point j -> column i*K + j-1); with
        # symbolic="MX" they become one call node of an SX Function inside an MX graph
        NK = N * K
        hs = self.hstep
        wc = ca.SX.sym("wc", self.ng + self.NP)
        p = wc[self.ng: self.ng + self.NP]
        G = ca.reshape(wc[: self.ng], NS, NK)  # 4 x NK, column = one collocation point
        Zj = [None] + [G[:, list(range(j - 1, NK, K))] for j in range(1, K + 1)]  # 4 x N each
        Z0 = ca.horzcat(ca.DM(STATE0), Zj[K][:, : N - 1])  # element starts (initial state fixed)
        # rows of D sum to zero: differencing against the element start first keeps the
        # rounding noise of the residuals ~10x lower (x, h reach 1e4 m)
        dZ = [Zj[k] - Z0 for k in range(1, K + 1)]
        derj = [sum(float(D[j - 1, k]) * dZ[k - 1] for k in range(1, K + 1)) for j in range(1, K + 1)]
        perm = [(j - 1) * N + i for i in range(N) for j in range(1, K + 1)]
        DER = ca.horzcat(*derj)[:, perm]  # 4 x NK, point-major

        tc = self.t_col.ravel()  # point-major times
        al = np.array([alpha_of_t(t) for t in tc])
        m = M0 - MDOT * tc
        Wcd = sp.csc_matrix(np.array([_cd_weights(t) for t in tc]).T)  # 7 x NK
        cd = ca.mtimes(p[:7].T, _sparse_dm(Wcd))  # 1 x NK
        cl = p[7]
        xx, hh, vv, th = G[0, :], G[1, :], G[2, :], G[3, :]
        rho = yang_density(hh)
        r = RE + hh
        grav = G0 * (RE / r) ** 2
        st, ct = ca.sin(th), ca.cos(th)
        qS = 0.5 * SM * rho * vv * vv
        inv_m = ca.DM(1.0 / m).T
        fx = RE / r * vv * ct
        fh = vv * st
        fv = ca.DM(PE * np.cos(al) / m).T - qS * cd * inv_m - grav * st
        # v * dtheta/dt, regular at v = 0
        vfth = ca.DM(PE * np.sin(al) / m).T + qS * cl * inv_m - grav * ct + vv * vv * ct / r
        R = ca.vertcat(DER[0, :] - hs * fx, DER[1, :] - hs * fh, DER[2, :] - hs * fv,
                       vv * DER[3, :] - hs * vfth)
        g_col_sx = ca.vec(R)  # per point: x, h, v, theta rows (aligned with gamma)
        self._colloc_sx = (wc, g_col_sx)
        self._rootfinder = None
        if symbolic == "SX":
            w = wc if self.condensed else ca.vertcat(wc, ca.SX.sym("y", 3 * n))
            g_col = g_col_sx
        elif symbolic == "MX":
            w = ca.MX.sym("w", self.nw)
            g_col = ca.Function("colloc", [wc], [g_col_sx])(w[: self.ng + self.NP])
        else:
            raise ValueError("symbolic must be 'SX' or 'MX'")
        gamma = w[: self.ng]

        # measurement map y = A gamma + b (fixed, sparse; Lagrange interpolation on the element)
        el = np.clip(np.floor(self.t_meas / hs + 1e-12).astype(int), 0, N - 1)
        taus = (self.t_meas - el * hs) / hs
        L = np.array([pl(taus) for pl in polys]).T  # (n, K+1)
        b = np.zeros((n, 3))
        rows, cols, vals = [], [], []
        q = np.arange(n)
        for k in range(K + 1):
            if k == 0:
                first = el == 0  # element 0 starts at the fixed initial state
                b[first] += L[first, :1] * np.asarray(STATE0[:3])[None, :]
                qq = q[~first]
                base = ((el[qq] - 1) * K + (K - 1)) * NS
            else:
                qq = q
                base = (el * K + (k - 1)) * NS
            for s_ in range(3):
                rows.append(3 * qq + s_)
                cols.append(base + s_)
                vals.append(L[qq, k])
        self.A = sp.csc_matrix((np.concatenate(vals), (np.concatenate(rows), np.concatenate(cols))),
                               shape=(3 * n, self.ng))
        self.b = b.ravel()
        b = self.b
        A_dm = _sparse_dm(self.A)
        ym = self.y_meas.ravel()
        wgt = 1.0 / self.sigma.ravel()
        if self.condensed and objective_form == "quadratic":
            # J = 1/2 |W (A gamma + b - ym)|^2 = 1/2 d'Q d + c'd + J_ref, d = gamma - gamma_ref,
            # Q = A'W^2 A (constant, banded). gamma_ref is the unconstrained least-squares fit of
            # the data, so c ~ 0 and J_ref ~ J: no cancellation between large terms.
            WA = sp.diags(wgt) @ self.A
            Q = (WA.T @ WA).tocsc()
            gamma_ref = self._ls_reference(WA, wgt * (ym - b))
            r_ref = wgt * (self.A @ gamma_ref + b - ym)
            c = WA.T @ r_ref
            J_ref = 0.5 * float(r_ref @ r_ref)
            Q_dm = _sparse_dm(Q)
            d = gamma - ca.DM(gamma_ref)
            # the constant J_ref is left out of the NLP (it only adds rounding noise that upsets
            # IPOPT's filter near convergence) and added back to the reported objective
            f = 0.5 * ca.dot(d, ca.mtimes(Q_dm, d)) + ca.dot(ca.DM(c), d)
            self._f_offset = J_ref
            g_all = g_col
        elif self.condensed and objective_form == "residual":
            r = (ca.mtimes(A_dm, gamma) + ca.DM(b - ym)) * ca.DM(wgt)
            f = 0.5 * ca.dot(r, r)
            g_all = g_col
        elif self.condensed:
            raise ValueError("objective_form must be 'quadratic' or 'residual'")
        else:
            y = w[self.ng + self.NP:]
            r = (y - ca.DM(ym)) * ca.DM(wgt)
            f = 0.5 * ca.dot(r, r)
            g_all = ca.vertcat(g_col, y - ca.mtimes(A_dm, gamma) - ca.DM(b))
        self.n_con = g_all.shape[0]
        self.symbolic = symbolic
        self._nlp = {"x": w, "f": f, "g": g_all}

        self.lbx = np.full(self.nw, -np.inf)
        self.ubx = np.full(self.nw, np.inf)
        self.lbx[self.ng: self.ng + self.NP] = P_LB
        self.ubx[self.ng: self.ng + self.NP] = P_UB

        opts = {"ipopt.tol": 1e-8, "ipopt.print_level": 0, "print_time": False, "ipopt.sb": "yes"}
        opts.update({"ipopt." + k: v for k, v in self._ipopt_options.items()})
        self._opts = opts
        self.solver = ca.nlpsol("peer_ra66", "ipopt", self._nlp, opts)
        self._warm_solver = None
        self.setup_s = time.perf_counter() - t_start

    # ------------------------------------------------------------------ helpers
    @staticmethod
    def _ls_reference(WA, rhs):
        """Least-squares fit of the weighted data by the measured state columns (a reference
        point that makes the condensed quadratic objective well conditioned numerically)."""
        cols = np.flatnonzero(np.asarray(abs(WA).sum(axis=0)).ravel() > 0)
        M = WA[:, cols].tocsc()
        gref = np.zeros(WA.shape[1])
        try:
            with warnings.catch_warnings():
                warnings.simplefilter("error")
                sol = spla.spsolve((M.T @ M).tocsc(), M.T @ rhs)
            if not np.all(np.isfinite(sol)):
                raise RuntimeError("singular")
        except Exception:  # singular normal equations (fewer samples than nodes somewhere)
            sol = spla.lsqr(M, rhs, atol=1e-14, btol=1e-14, iter_lim=20000)[0]
        gref[cols] = sol
        return gref

    def initial_guess(self, p0):
        """Primal guess: simulate_ra66 at p0 at the collocation points (and y = A gamma + b)."""
        x, h, v, th = simulate_ra66(p0, self.t_col.ravel())
        gamma = np.column_stack([x, h, v, th]).ravel()
        w0 = np.concatenate([gamma, np.asarray(p0, float)])
        if not self.condensed:
            w0 = np.concatenate([w0, self.A @ gamma + self.b])
        return w0

    def outputs(self, w):
        """y = A gamma + b as an (n, 3) array for a primal vector w."""
        return (self.A @ np.asarray(w)[: self.ng] + self.b).reshape(-1, 3)

    def objective_of(self, w):
        r = (self.outputs(w) - self.y_meas) / self.sigma
        return 0.5 * float(np.sum(r * r))

    def _run(self, solver, x0, lbx, ubx, lam_x0=None, lam_g0=None):
        args = dict(x0=x0, lbx=lbx, ubx=ubx, lbg=0.0, ubg=0.0)
        if lam_x0 is not None:
            args["lam_x0"] = lam_x0
        if lam_g0 is not None:
            args["lam_g0"] = lam_g0
        t0 = time.perf_counter()
        sol = solver(**args)
        solve_s = time.perf_counter() - t0
        st = solver.stats()
        w = np.asarray(sol["x"]).ravel()
        return {
            "p": w[self.ng: self.ng + self.NP].copy(),
            "objective": float(sol["f"]) + self._f_offset,
            "iterations": int(st["iter_count"]),
            "solve_s": solve_s,
            "success": bool(st["success"]),
            "return_status": st.get("return_status"),
            "x_opt": w,
            "lam_g": np.asarray(sol["lam_g"]).ravel(),
            "lam_x": np.asarray(sol["lam_x"]).ravel(),
        }

    # ------------------------------------------------------------------ API
    def solve(self, p0, init=None):
        """Cold solve from p0; init (full primal vector) defaults to the simulation at p0."""
        x0 = self.initial_guess(p0) if init is None else np.asarray(init, float)
        x0 = x0.copy()
        x0[self.ng: self.ng + self.NP] = np.clip(p0, P_LB, P_UB)
        return self._run(self.solver, x0, self.lbx, self.ubx)

    def _get_warm_solver(self):
        if self._warm_solver is None:
            t0 = time.perf_counter()
            opts = dict(self._opts)
            opts["ipopt.warm_start_init_point"] = "yes"
            self._warm_solver = ca.nlpsol("peer_ra66_warm", "ipopt", self._nlp, opts)
            self.warm_setup_s = time.perf_counter() - t0
        return self._warm_solver

    def resolve_fixed(self, p, fixed_idx, warm):
        """Warm-started re-solve with p[fixed_idx] fixed (lbx = ubx) from a previous solve."""
        solver = self._get_warm_solver()
        p = np.asarray(p, float)
        lbx, ubx = self.lbx.copy(), self.ubx.copy()
        x0 = np.asarray(warm["x_opt"], float).copy()
        for k in fixed_idx:
            lbx[self.ng + k] = ubx[self.ng + k] = p[k]
            x0[self.ng + k] = p[k]
        return self._run(solver, x0, lbx, ubx, lam_x0=warm["lam_x"], lam_g0=warm["lam_g"])

    def solve_at(self, p, init=None, method="newton"):
        """Collocation solution at fixed p: the square system c(gamma, p) = 0.

        method="newton": CasADi's Newton rootfinder with a sparse direct solver (robust: IPOPT
        with all p fixed works at N=66 but, from N=264 on, MUMPS's default ordering ran out
        of memory and IPOPT aborted in restoration); method="ipopt": the estimation NLP with
        all 8 parameters fixed through lbx = ubx.
        """
        p = np.asarray(p, float)
        x0 = self.initial_guess(p) if init is None else np.asarray(init, float).copy()
        x0[self.ng: self.ng + self.NP] = p
        if method == "ipopt":
            lbx, ubx = self.lbx.copy(), self.ubx.copy()
            lbx[self.ng: self.ng + self.NP] = p
            ubx[self.ng: self.ng + self.NP] = p
            return self._run(self.solver, x0, lbx, ubx)
        if method != "newton":
            raise ValueError("method must be 'newton' or 'ipopt'")
        if self._rootfinder is None:
            wc, g = self._colloc_sx
            self._colloc_fun = ca.Function("colloc", [wc], [g])
            gam_s, par_s = ca.SX.sym("gam", self.ng), ca.SX.sym("par", self.NP)
            F = ca.Function("F", [gam_s, par_s], [self._colloc_fun(ca.vertcat(gam_s, par_s))])
            self._rootfinder = ca.rootfinder("colloc_rf", "newton", F,
                                             {"linear_solver": "csparse", "abstol": 1e-9,
                                              "max_iter": 50, "error_on_fail": False})
        t0 = time.perf_counter()
        gam = np.asarray(self._rootfinder(x0[: self.ng], p)).ravel()
        solve_s = time.perf_counter() - t0
        st = self._rootfinder.stats()
        w = x0.copy()
        w[: self.ng] = gam
        resid = np.asarray(self._colloc_fun(w[: self.ng + self.NP])).ravel()
        return {
            "p": p.copy(),
            "objective": self.objective_of(w),
            "iterations": int(st.get("iter_count", -1)),
            "solve_s": solve_s,
            "success": bool(st.get("success", np.max(np.abs(resid)) < 1e-6)),
            "return_status": st.get("return_status"),
            "max_residual": float(np.max(np.abs(resid))),
            "x_opt": w,
        }


def collocation_error_at_truth(model: CasadiRA66, t=None):
    """Max |x|, |h|, |v| error of the collocation solution at P_TRUE against simulate_ra66."""
    t = model.t_meas if t is None else t
    res = model.solve_at(P_TRUE)
    y_col = model.outputs(res["x_opt"])
    x, h, v, _ = simulate_ra66(P_TRUE, t)
    err = np.abs(y_col - np.column_stack([x, h, v])).max(axis=0)
    return err, res


def _jac_hess_nnz(model: CasadiRA66):
    w, f, g = model._nlp["x"], model._nlp["f"], model._nlp["g"]
    lam = type(w).sym("lam", g.shape[0])
    jac = ca.jacobian(g, w).nnz()
    hl = ca.hessian(f + ca.dot(lam, g), w)[0]
    return jac, hl.nnz(), ca.tril(hl).nnz()


def _main(Ns=(66,), Ks=(3,)):
    np.set_printoptions(precision=6, suppress=True, linewidth=120)
    t, y = make_data(seed=0, sigma=1.0)
    tt = np.array([40.0, 66.0])
    x, h, v, th = simulate_ra66(P_TRUE, tt)
    for k in range(2):
        print(f"simulate_ra66 at the truth, t={tt[k]:.0f} s: x={x[k]:.3f} m h={h[k]:.3f} m "
              f"v={v[k]:.4f} m/s theta={math.degrees(th[k]):.4f} deg")
    t_c, y_c = make_data(seed=0, sigma=0.0)
    for N in Ns:
        for K in Ks:
            variants = [(True, {}), (False, {}), (False, {"mumps_pivot_order": 0})]
            for condensed, ipo in variants:
                mdl = CasadiRA66(t, y, N=N, K=K, condensed=condensed, ipopt_options=ipo)
                res = mdl.solve(P0)
                res2 = mdl.solve(P0)  # repeat: the first call includes one-off start-up costs
                J = res["objective"]
                print(f"\nN={N} K={K} condensed={condensed} symbolic={mdl.symbolic} ipopt extra={ipo}: "
                      f"{mdl.nw} variables, {mdl.n_con} equality constraints")
                print(f"  setup_s={mdl.setup_s:.3f} iterations={res['iterations']} "
                      f"solve_s={res['solve_s']:.4f} (repeat {res2['solve_s']:.4f}) "
                      f"success={res['success']} ({res['return_status']})")
                print(f"  objective={J:.6f} 2J/19800={2 * J / 19800:.6f}")
                print(f"  p={res['p']}")
                fixed = [0, 6, 7]
                for label, pf in (("truth", np.array(P_TRUE)), ("own optimum", res["p"])):
                    rw = mdl.resolve_fixed(pf, fixed, res)
                    print(f"  warm re-solve, p{fixed} fixed at {label}: iterations={rw['iterations']} "
                          f"solve_s={rw['solve_s']:.4f} success={rw['success']} "
                          f"objective={rw['objective']:.4f}")
                print(f"  (warm solver set-up {mdl.warm_setup_s:.3f} s)")
                if not condensed:
                    continue
                jac, hfull, hlow = _jac_hess_nnz(mdl)
                print(f"  nnz: constraint Jacobian {jac}, Lagrangian Hessian {hfull} "
                      f"(lower triangle {hlow})")
                err, rt = collocation_error_at_truth(mdl)
                print(f"  collocation solution at the truth ({rt['iterations']} it, {rt['return_status']}):"
                      f" max |x|, |h|, |v| error over the 6600 samples = {err}")
                ri = mdl.solve_at(P_TRUE, method="ipopt")
                ei = np.abs(mdl.outputs(ri["x_opt"]) - mdl.outputs(rt["x_opt"])).max(axis=0)
                print(f"  same via IPOPT with all p fixed: {ri['iterations']} it, {ri['return_status']}, "
                      f"max |y| difference to the Newton solution {ei}")
                y0 = mdl.outputs(rt["x_opt"])
                for tq in (40.0, 66.0):
                    q = int(round(tq / 0.01)) - 1
                    print(f"    at t={t[q]:.2f} s: x={y0[q, 0]:.3f} m h={y0[q, 1]:.3f} m v={y0[q, 2]:.4f} m/s")
                mc = CasadiRA66(t_c, y_c, N=N, K=K, condensed=True)
                rc = mc.solve(P0)
                print(f"  noise-free fit: iterations={rc['iterations']} success={rc['success']} "
                      f"p - p_true = {rc['p'] - np.array(P_TRUE)}")


if __name__ == "__main__":
    import argparse

    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--N", type=int, nargs="+", default=[66])
    ap.add_argument("--K", type=int, nargs="+", default=[3])
    args = ap.parse_args()
    _main(args.N, args.K)
