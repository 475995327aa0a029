"""Benchmark (issue 2): RA-66 set-up and solve against an independent CasADi peer, as N grows.

Run ``nice python3 benchmarks/bench_core.py`` (a few minutes; ``--quick`` for a short run,
``--repeat R`` for the number of repetitions of each solve, default 5). Writes
``benchmarks/results/core.json`` (``core_quick.json`` with ``--quick``) and prints Markdown
tables with the machine load (``uptime``) beside each.

What is measured, for K = 3 and N = 33, 66, 132, 264, 528 elements, and rocketid's default
discretization (66 elements, K = 4):

Set-up
    rocketid *first run*: a fresh Python process with an empty ``ROCKETID_CACHE_DIR``:
    model build (``ra66()``) + ``prepare`` (derivation, code generation, transcription, NLP);
    ``import rocketid`` is timed separately. *Cached*: the same in a fresh process whose cache
    holds the generated module, and in this process (``ra66()`` + ``prepare``, median of R).
    Peer: ``CasadiRA66(...)`` (symbolic build + ``nlpsol``), after a warm-up instance.
Solve
    ``solve_s`` is the IPOPT call alone (rocketid: ``EstimationResult.timings``; peer: the
    ``nlpsol`` call), median of R, both from a simulation at p0; rocketid and the peer
    alternate within each repetition, so the ratio rocketid / peer is measured under the same
    load. CPU seconds (``time.process_time``, all threads) of the same solves are given too:
    on a shared machine they are steadier than wall time.
Warm-started re-solves
    the same problem from its solution (rocketid ``estimate(..., warm_start=fit)``, peer
    ``resolve_fixed(p_hat, [], res)``); the peer's re-solve with CD0, CD6, CL fixed at the
    truth (its comparable figure, docs/performance.md); and rocketid's (7.9) path: ``estimate_q1`` at q2 of
    a uniform draw within the bounds, warm-started from the index-0 solution (nominal scaling).
Breakdown (``--profile-sizes``)
    where the IPOPT call's time goes, from IPOPT's own timing statistics
    (``print_timing_statistics``), timers on rocketid's callbacks and cProfile: rocketid's NLP
    with its defaults, with ``mu_strategy=monotone`` (the peer's), with ``mumps_pivtol=1e-6``
    (IPOPT's default, rocketid's before commit dfb2e0a) and with the objective's old BLAS dot
    (before commit 60c3a14); the peer's NLP in CasADi; and the peer's NLP (CasADi functions as
    callbacks) through rocketid's IPOPT (cyipopt), which separates the NLP from the IPOPT build.

Mesh: rocketid's CLI mesh (``rocketid.cli.make_mesh``, i.e. ``default_mesh`` with elements of
66/N s split so that the CD knots, every 11 s, fall on element boundaries). N = 33 gives 2 s
elements, which do not divide 11 s: the mesh becomes 36 equal elements (6 per knot interval);
both tools then use those 36 elements. The other N are used as they are.

Data: rocketid's ``simulate_measurements(ra66(), truth, ra66_times(), seed=0)``; the peer gets
the same arrays. (``peer_casadi.make_data(0)`` draws the same 19 800 normal numbers but assigns
them sample-major, rocketid channel after channel; the script checks and records this.)

Compare ratios within one run; absolute times depend on the machine and its load.
"""

from __future__ import annotations

import argparse
import cProfile
import json
import os
import pstats
import re
import shutil
import subprocess
import sys
import tempfile
import time
import warnings
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
DEFAULT_SIZES = (33, 66, 132, 264, 528)
FIXED_IDX = (0, 6, 7)  # CD0, CD6, CL: the peer's warm re-solve with three parameters fixed


# --------------------------------------------------------------------------- utilities
def uptime() -> str:
    """The ``uptime`` line (machine load), or the load averages where uptime is missing."""
    try:
        return subprocess.run(["uptime"], capture_output=True, text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        return "load average: " + ", ".join(f"{v:.2f}" for v in os.getloadavg())


def med(values):
    vals = [v for v in values if v is not None and np.isfinite(v)]
    return float(np.median(vals)) if vals else None


def fmt(v, spec=".3f"):
    return "—" if v is None else format(v, spec)


def ipopt_log(path: str) -> dict:
    """IPOPT's timing statistics (CPU seconds) and iteration log from an ``output_file``."""
    text = Path(path).read_text()
    start = text.rfind("This is Ipopt version")
    text = text[start:] if start >= 0 else text
    out = {"version": None, "iterations": None, "regularized": None, "cpu": {}, "wall": {}}
    m = re.search(r"This is Ipopt version ([\w.]+), running with linear solver (.+?)\.\n", text)
    if m:
        out["version"] = f"Ipopt {m.group(1)}, {m.group(2)}"
    body = text[text.find("iter "):text.find("Number of Iterations")].splitlines()[1:]
    rows = [ln.split() for ln in body if ln.strip() and ln.split()[0].rstrip("r").isdigit()]
    out["iterations"] = int(rows[-1][0].rstrip("r")) if rows else None
    out["regularized"] = sum(1 for r in rows if len(r) > 6 and r[6] != "-")
    for name, cpu, wall in re.findall(r"^ *([A-Za-z][\w ]*?)\.{2,}: +([\d.]+) \(sys: +[\d.]+ wall: +([\d.]+)\)",
                                      text, flags=re.M):
        out["cpu"][name.strip()] = float(cpu)
        out["wall"][name.strip()] = float(wall)
    return out


def versions() -> dict:
    import casadi

    from rocketid.output import environment
    out = {**environment(), "cpus": os.cpu_count(), "casadi": casadi.__version__}
    out["blas_threads_env"] = {k: os.environ[k] for k in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS",
                                                          "MKL_NUM_THREADS") if k in os.environ}
    try:
        out["git_commit"] = subprocess.run(["git", "rev-parse", "--short", "HEAD"], cwd=HERE, capture_output=True,
                                           text=True, timeout=10).stdout.strip()
    except (OSError, subprocess.SubprocessError):
        pass
    return out


# --------------------------------------------------------------------------- set-up (child)
def child_setup(arg: str) -> None:
    """Run in a fresh process: import, build, prepare; print the timings as JSON."""
    job = json.loads(arg)
    t0 = time.perf_counter()
    import rocketid as ri
    import rocketid.codegen as cg
    import rocketid.solve as rs
    t_import = time.perf_counter() - t0

    timers: dict[str, float] = {}

    def timed(name, fn):
        def wrapper(*a, **k):
            t = time.perf_counter()
            try:
                return fn(*a, **k)
            finally:
                timers[name] = timers.get(name, 0.0) + time.perf_counter() - t
        return wrapper

    # prepare() calls these names at run time: time each step without changing what runs
    cg.derive = timed("derive_s", cg.derive)
    cg.generate_source = timed("codegen_s", cg.generate_source)
    rs.generate = timed("generate_s", rs.generate)
    rs.transcribe = timed("transcribe_s", rs.transcribe)
    rs.CollocationNLP = timed("nlp_s", rs.CollocationNLP)

    npz = np.load(job["data"])
    data = ri.Measurements.from_arrays(npz["t"], {k: npz[k] for k in ("x", "h", "v")},
                                       sigma={k: 1.0 for k in ("x", "h", "v")})
    t0 = time.perf_counter()
    spec = ri.ra66()
    t_build = time.perf_counter() - t0
    if job["K"] == 4 and job["N"] is None:
        mesh = ri.default_mesh(spec)
    else:
        from rocketid.cli import make_mesh
        mesh = make_mesh(spec, job["N"], K=job["K"])
    prep = ri.prepare(spec, data, mesh=mesh)
    out = {"import_s": t_import, "build_s": t_build, "prepare_s": prep.setup_s,
           "setup_s": t_build + prep.setup_s, "cached": prep.codegen_cached, "n": prep.nlp.n, "m": prep.nlp.m}
    out.update(timers)
    if "generate_s" in out:
        out["write_load_s"] = out["generate_s"] - out.get("derive_s", 0.0) - out.get("codegen_s", 0.0)
    print("RESULT " + json.dumps(out))


def run_child(data_path: str, cache: str, N, K) -> dict:
    env = dict(os.environ, ROCKETID_CACHE_DIR=cache)
    job = json.dumps({"data": data_path, "N": N, "K": K})
    proc = subprocess.run([sys.executable, str(Path(__file__).resolve()), "--child-setup", job], env=env,
                          capture_output=True, text=True, timeout=1800)
    for line in proc.stdout.splitlines():
        if line.startswith("RESULT "):
            return json.loads(line[7:])
    raise RuntimeError(f"set-up child failed (exit {proc.returncode}):\n{proc.stderr[-3000:]}")


# --------------------------------------------------------------------------- data
def make_data():
    """rocketid's data (seed 0) and the check against peer_casadi.make_data."""
    import peer_casadi as pc

    import rocketid as ri
    spec = ri.ra66()
    times = ri.ra66_times()
    data = ri.simulate_measurements(spec, ri.ra66_truth(spec), times, seed=0)
    clean = ri.simulate_measurements(spec, ri.ra66_truth(spec), times, noise=False)
    for ch in data.channels:
        if not np.array_equal(ch.times, times):
            raise RuntimeError("channels do not share the sample times")
    _, y_peer = pc.make_data(0)
    _, y_peer_clean = pc.make_data(0, sigma=0.0)
    names = ("x", "h", "v")
    noise_r = np.column_stack([data[n].values - clean[n].values for n in names])
    noise_p = y_peer - y_peer_clean
    check = {
        "simulators_max_abs_diff": {n: float(np.abs(clean[n].values - y_peer_clean[:, k]).max())
                                    for k, n in enumerate(names)},
        "noise_same_arrays_max_abs_diff": float(np.abs(noise_r - noise_p).max()),
        "noise_same_draws_other_order_max_abs_diff": float(np.abs(noise_r.T.ravel() - noise_p.ravel()).max()),
        "note": "peer_casadi.make_data draws rng.standard_normal((6600, 3)) (sample-major); "
                "simulate_measurements draws 6600 per channel, channel after channel: the same numbers in "
                "another order. Both tools get rocketid's arrays.",
    }
    Y = np.column_stack([data[n].values for n in names])
    return spec, data, times, Y, check


# --------------------------------------------------------------------------- one row
def mesh_for(spec, N, K):
    import rocketid as ri
    from rocketid.cli import make_mesh
    return ri.default_mesh(spec) if N is None else make_mesh(spec, N, K=K)


def bench_row(label, N, K, spec, data, times, Y, data_path, root, repeat, log) -> dict:
    import peer_casadi as pc

    import rocketid as ri
    from rocketid.estimability import analyze, estimate_q1
    from rocketid.solve import solve_nlp

    row = {"label": label, "N_requested": N, "K": K, "load_start": uptime()}
    mesh = mesh_for(spec, N, K)
    n_el = mesh.n_elements
    uniform = np.allclose(mesh.boundaries, np.linspace(0.0, 66.0, n_el + 1), rtol=0, atol=1e-9)
    row.update(N_elements=n_el, mesh=mesh.describe(), peer_same_mesh=bool(uniform))
    log(f"[{label}] {mesh.describe()}")

    # ---- set-up: first run and cached, fresh processes; then in-process cached
    cache = tempfile.mkdtemp(prefix="cache_", dir=root)
    row["setup_first"] = run_child(data_path, cache, N, K)
    row["setup_cached_fresh"] = run_child(data_path, cache, N, K)
    os.environ["ROCKETID_CACHE_DIR"] = cache
    builds = []
    prep = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        spec_r = ri.ra66()
        t_build = time.perf_counter() - t0
        prep = ri.prepare(spec_r, data, mesh=mesh)
        builds.append((t_build + prep.setup_s, t_build, prep.setup_s, prep.codegen_cached))
    row["setup_cached_inprocess"] = {"setup_s": med(b[0] for b in builds), "build_s": med(b[1] for b in builds),
                                     "prepare_s": med(b[2] for b in builds), "cached": all(b[3] for b in builds)}
    spec = prep.spec
    nlp = prep.nlp
    jr, _ = nlp.jacobianstructure()
    hr, _ = nlp.hessianstructure()
    row["rocketid_size"] = {"n": nlp.n, "m": nlp.m, "jac_nnz": int(len(jr)), "hess_nnz": int(len(hr))}

    peer = pc.CasadiRA66(times, Y, N=n_el, K=K)
    row["peer_setup_s"] = peer.setup_s
    row["peer_size"] = {"n": peer.nw, "m": peer.n_con}
    log(f"[{label}] set-up: rocketid first {row['setup_first']['setup_s']:.2f} s, cached "
        f"{row['setup_cached_fresh']['setup_s']:.2f} s (fresh process) / "
        f"{row['setup_cached_inprocess']['setup_s']:.3f} s (in-process); peer {peer.setup_s:.2f} s")

    # ---- full estimation from p0, alternating with the peer
    S0, _ = prep.initial_states(spec.guess)
    x0 = nlp.initial_x(S0, spec.guess)
    w0 = peer.initial_guess(pc.P0)
    r_solve, r_cpu, p_solve, p_cpu, r_wall = [], [], [], [], []
    fit = res = None
    for _ in range(repeat):
        t0 = time.perf_counter()
        fit = ri.estimate(spec, data, prepared=prep)
        r_wall.append(time.perf_counter() - t0)
        r_solve.append(fit.timings["solve_s"])
        res = peer.solve(pc.P0)
        p_solve.append(res["solve_s"])
        c0 = time.process_time()
        solve_nlp(nlp, x0)
        r_cpu.append(time.process_time() - c0)
        c0 = time.process_time()
        peer.solve(pc.P0, init=w0)
        p_cpu.append(time.process_time() - c0)
    row["rocketid"] = {"solve_s": med(r_solve), "solve_s_all": r_solve, "cpu_s": med(r_cpu),
                       "estimate_wall_s": med(r_wall), "iterations": fit.iterations, "objective": fit.objective,
                       "success": bool(fit.success), "p": fit.p.tolist()}
    row["peer"] = {"solve_s": med(p_solve), "solve_s_all": p_solve, "cpu_s": med(p_cpu),
                   "iterations": res["iterations"], "objective": res["objective"], "success": bool(res["success"]),
                   "p": res["p"].tolist()}
    row["ratio_solve"] = row["rocketid"]["solve_s"] / row["peer"]["solve_s"]
    row["ratio_cpu"] = row["rocketid"]["cpu_s"] / row["peer"]["cpu_s"]
    row["max_abs_dp"] = float(np.abs(fit.p - res["p"]).max())
    log(f"[{label}] solve: rocketid {row['rocketid']['solve_s']:.4f} s ({fit.iterations} it), peer "
        f"{row['peer']['solve_s']:.4f} s ({res['iterations']} it), ratio {row['ratio_solve']:.2f}")

    # ---- warm-started re-solves
    rw, pw, pf = [], [], []
    for _ in range(repeat):
        w = ri.estimate(spec, data, prepared=prep, warm_start=fit)
        rw.append((w.timings["solve_s"], w.iterations, w.success))
        r2 = peer.resolve_fixed(res["p"], [], res)
        pw.append((r2["solve_s"], r2["iterations"], r2["success"]))
        r3 = peer.resolve_fixed(pc.P_TRUE, list(FIXED_IDX), res)
        pf.append((r3["solve_s"], r3["iterations"], r3["success"]))
    row["warm"] = {
        "rocketid_same_problem": {"solve_s": med(a for a, _, _ in rw), "iterations": rw[-1][1],
                                  "success": all(s for _, _, s in rw)},
        "peer_same_problem": {"solve_s": med(a for a, _, _ in pw), "iterations": pw[-1][1],
                              "success": all(s for _, _, s in pw), "warm_solver_setup_s": peer.warm_setup_s},
        "peer_cd0_cd6_cl_fixed_at_truth": {"solve_s": med(a for a, _, _ in pf), "iterations": pf[-1][1],
                                           "success": all(s for _, _, s in pf)},
    }
    row["warm"]["ratio_same_problem"] = (row["warm"]["rocketid_same_problem"]["solve_s"]
                                         / row["warm"]["peer_same_problem"]["solve_s"])

    # ---- (7.9): q2 fixed, warm-started after a change of q2
    try:
        t0 = time.perf_counter()
        est = analyze(prep, scaling="nominal")
        t_an = time.perf_counter() - t0
        first = estimate_q1(prep, est, est.q2_of(spec.guess))
        p_trial = np.random.default_rng(1).uniform(spec.lower, spec.upper)
        q2 = est.q2_of(p_trial)
        q = []
        for _ in range(repeat):
            t0 = time.perf_counter()
            r = estimate_q1(prep, est, q2, warm_start=first)
            q.append((r.timings["solve_s"], r.iterations, r.success, r.timings["setup_s"], time.perf_counter() - t0))
        row["q79"] = {"analyze_s": t_an, "n_estimated": est.n_estimated,
                      "index0": {"solve_s": first.timings["solve_s"], "setup_s": first.timings["setup_s"],
                                 "iterations": first.iterations, "success": bool(first.success)},
                      "warm": {"solve_s": med(a[0] for a in q), "iterations": q[-1][1],
                               "success": all(a[2] for a in q), "setup_s": med(a[3] for a in q),
                               "wall_s": med(a[4] for a in q)}}
    except Exception as exc:  # noqa: BLE001 - report, do not lose the other rows
        row["q79"] = {"error": f"{type(exc).__name__}: {exc}"}
    row["load_end"] = uptime()
    return row


# --------------------------------------------------------------------------- breakdown
def profile_row(label, N, K, spec, data, times, Y, root, repeat, log) -> dict:
    """Where the time of one IPOPT call goes, rocketid against the peer."""
    import casadi as ca
    import cyipopt
    import peer_casadi as pc

    import rocketid as ri
    from rocketid.solve import solve_nlp

    out = {"label": label, "load_start": uptime()}
    mesh = mesh_for(spec, N, K)
    prep = ri.prepare(spec, data, mesh=mesh)
    nlp = prep.nlp
    S0, _ = prep.initial_states(spec.guess)
    x0 = nlp.initial_x(S0, spec.guess)
    logfile = os.path.join(tempfile.mkdtemp(prefix="ipopt_", dir=root), "ipopt.txt")
    stat_opts = {"print_timing_statistics": "yes", "output_file": logfile, "file_print_level": 5}

    def objective_blas_dot(x):
        """The objective as it was before commit 60c3a14: ``r @ (w * r)`` (an OpenBLAS ddot)."""
        r = nlp._linear_residual(x)
        return 0.5 * float(r @ (nlp.structure.w_lin * r))

    def rocketid_config(options, objective=None):
        class Timed:
            """The NLP with timed callbacks (the prepared NLP, a frozen value, is left alone)."""

            def __getattr__(self, name):
                return getattr(nlp, name)

        timed = Timed()
        acc: dict[str, list] = {}

        def wrap(name, fn=None):
            fn = fn or getattr(nlp, name)

            def w(*a):
                t = time.process_time()
                r = fn(*a)
                acc.setdefault(name, [0.0, 0])
                acc[name][0] += time.process_time() - t
                acc[name][1] += 1
                return r
            setattr(timed, name, w)
        for name in ("gradient", "constraints", "jacobian", "hessian"):
            wrap(name)
        wrap("objective", objective)
        runs = []
        for _ in range(repeat):
            acc.clear()
            t0 = time.perf_counter()
            c0 = time.process_time()
            sol = solve_nlp(timed, x0, options={**options, **stat_opts})
            cpu = time.process_time() - c0
            wall = time.perf_counter() - t0
            lg = ipopt_log(logfile)
            runs.append({"wall_s": wall, "solve_s": sol.solve_s, "outside_ipopt_s": wall - sol.solve_s,
                         "process_cpu_s": cpu, "iterations": sol.iterations, "ipopt": lg,
                         "callbacks_s": sum(v[0] for v in acc.values()),
                         "callbacks": {k: {"s": v[0], "calls": v[1]} for k, v in acc.items()}})
        return summarize(runs)

    def summarize(runs):
        keys = ("OverallAlgorithm", "Function Evaluations", "PDSystemSolverTotal",
                "LinearSystemSymbolicFactorization", "LinearSystemBackSolve", "UpdateBarrierParameter",
                "InitializeIterates")
        s = {"runs": runs, "iterations": runs[-1]["ipopt"]["iterations"],
             "regularized": runs[-1]["ipopt"]["regularized"], "ipopt_version": runs[-1]["ipopt"]["version"],
             "solve_s": med(r["solve_s"] for r in runs),
             "cpu": {k: med(r["ipopt"]["cpu"].get(k) for r in runs) for k in keys}}
        if "callbacks_s" in runs[-1]:
            s["callbacks_s"] = med(r["callbacks_s"] for r in runs)
            s["outside_ipopt_s"] = med(r["outside_ipopt_s"] for r in runs)
        c = s["cpu"]
        if c["OverallAlgorithm"] is not None and c["Function Evaluations"] is not None:
            s["cpu"]["IPOPT proper"] = c["OverallAlgorithm"] - c["Function Evaluations"]
        return s

    out["rocketid"] = rocketid_config({})
    out["rocketid_monotone"] = rocketid_config({"mu_strategy": "monotone"})
    out["rocketid_pivtol_1e-6"] = rocketid_config({"mumps_pivtol": 1e-6})
    if nlp.structure.G_lin is not None and not any(not ch.linear for ch in nlp.structure.channels):
        out["rocketid_blas_dot_objective"] = rocketid_config({}, objective=objective_blas_dot)

    # cProfile of one rocketid solve: Python-level view of the same call
    pr = cProfile.Profile()
    pr.enable()
    solve_nlp(nlp, x0)
    pr.disable()
    st = pstats.Stats(pr)
    top = sorted(st.stats.items(), key=lambda kv: kv[1][2], reverse=True)[:10]
    out["cprofile_top_tottime"] = [{"function": f"{Path(k[0]).name}:{k[1]}({k[2]})", "calls": v[1],
                                    "tottime_s": v[2], "cumtime_s": v[3]} for k, v in top]

    # the peer in CasADi, with IPOPT's statistics
    peer = pc.CasadiRA66(times, Y, N=mesh.n_elements, K=K, ipopt_options=stat_opts)
    runs = []
    for _ in range(repeat):
        c0 = time.process_time()
        r = peer.solve(pc.P0, init=peer.initial_guess(pc.P0))
        runs.append({"solve_s": r["solve_s"], "process_cpu_s": time.process_time() - c0, "ipopt": ipopt_log(logfile),
                     "casadi_stats": {k: v for k, v in peer.solver.stats().items() if k.startswith("t_wall_")}})
    out["peer"] = summarize(runs)

    # the peer's NLP through cyipopt (rocketid's IPOPT build), CasADi functions as callbacks
    w, f, g = peer._nlp["x"], peer._nlp["f"], peer._nlp["g"]
    lam, sig = ca.SX.sym("lam", g.shape[0]), ca.SX.sym("sig")
    jac = ca.jacobian(g, w)
    hess = ca.tril(ca.hessian(sig * f + ca.dot(lam, g), w)[0])
    F, GF, G = ca.Function("F", [w], [f]), ca.Function("GF", [w], [ca.gradient(f, w)]), ca.Function("G", [w], [g])
    JF, HF = ca.Function("JF", [w], [jac]), ca.Function("HF", [w, lam, sig], [hess])
    jrow, jcol = (np.array(a) for a in jac.sparsity().get_triplet())
    hrow, hcol = (np.array(a) for a in hess.sparsity().get_triplet())

    class PeerCallbacks:
        def objective(self, x):
            return float(F(x))

        def gradient(self, x):
            return np.asarray(GF(x)).ravel()

        def constraints(self, x):
            return np.asarray(G(x)).ravel()

        def jacobianstructure(self):
            return jrow, jcol

        def jacobian(self, x):
            return np.asarray(JF(x).nonzeros())

        def hessianstructure(self):
            return hrow, hcol

        def hessian(self, x, lagrange, obj_factor):
            return np.asarray(HF(x, lagrange, obj_factor).nonzeros())

    xp0 = peer.initial_guess(pc.P0)
    runs = []
    for _ in range(repeat):
        prob = cyipopt.Problem(n=peer.nw, m=peer.n_con, problem_obj=PeerCallbacks(), lb=peer.lbx, ub=peer.ubx,
                               cl=np.zeros(peer.n_con), cu=np.zeros(peer.n_con))
        for k, v in {"tol": 1e-8, "print_level": 0, "sb": "yes", **stat_opts}.items():
            prob.add_option(k, v)
        c0 = time.process_time()
        t0 = time.perf_counter()
        with warnings.catch_warnings():
            warnings.simplefilter("ignore")
            prob.solve(xp0)
        runs.append({"solve_s": time.perf_counter() - t0, "process_cpu_s": time.process_time() - c0,
                     "ipopt": ipopt_log(logfile)})
        prob.close()
    out["peer_nlp_via_cyipopt"] = summarize(runs)
    out["load_end"] = uptime()
    log(f"[profile {label}] rocketid {out['rocketid']['solve_s']:.4f} s, peer {out['peer']['solve_s']:.4f} s, "
        f"peer NLP via cyipopt {out['peer_nlp_via_cyipopt']['solve_s']:.4f} s")
    return out


# --------------------------------------------------------------------------- tables
def tables(result: dict) -> str:
    rows = result["rows"]
    L = []
    L.append(f"Command: `{result['command']}`  ")
    L.append(f"Versions: {json.dumps(result['versions'])}  ")
    L.append(f"Load at start: `{result['load_start']}`; at end: `{result['load_end']}`")
    L.append("")
    L.append("#### Set-up (s)")
    L.append("")
    L.append(f"Load: `{rows[0]['load_start']}` … `{rows[-1]['load_end']}`")
    L.append("")
    L.append("| N (elements used) | K | rocketid n × m | peer n × m | rocketid first run | of which derive + codegen "
             "| cached, fresh process | cached, in-process | import rocketid | peer set-up |")
    L.append("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        f1, fc, ip = r["setup_first"], r["setup_cached_fresh"], r["setup_cached_inprocess"]
        L.append(f"| {r['label']} ({r['N_elements']}) | {r['K']} | {r['rocketid_size']['n']} × {r['rocketid_size']['m']} "
                 f"| {r['peer_size']['n']} × {r['peer_size']['m']} | {f1['setup_s']:.2f} "
                 f"| {f1.get('derive_s', 0) + f1.get('codegen_s', 0):.2f} | {fc['setup_s']:.2f} | {ip['setup_s']:.3f} "
                 f"| {fc['import_s']:.2f} | {r['peer_setup_s']:.2f} |")
    L.append("")
    L.append("#### Full 8-parameter estimation from p0 (median of "
             f"{result['repeat']}; solve = the IPOPT call alone)")
    L.append("")
    L.append(f"Load: `{rows[0]['load_start']}` … `{rows[-1]['load_end']}`")
    L.append("")
    L.append("| N (elements used) | K | rocketid solve s | it | objective | peer solve s | it | objective "
             "| **ratio** rocketid / peer | CPU ratio | max abs(p_r − p_peer) |")
    L.append("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        a, b = r["rocketid"], r["peer"]
        fa, fb = ("" if a["success"] else " **failed**"), ("" if b["success"] else " **failed**")
        L.append(f"| {r['label']} ({r['N_elements']}) | {r['K']} | {a['solve_s']:.4f}{fa} | {a['iterations']} "
                 f"| {a['objective']:.4f} | {b['solve_s']:.4f}{fb} | {b['iterations']} | {b['objective']:.4f} "
                 f"| **{r['ratio_solve']:.2f}** | {r['ratio_cpu']:.2f} | {r['max_abs_dp']:.1e} |")
    L.append("")
    L.append(f"#### Warm-started re-solves (median of {result['repeat']}; s (iterations))")
    L.append("")
    L.append(f"Load: `{rows[0]['load_start']}` … `{rows[-1]['load_end']}`")
    L.append("")
    L.append("| N (elements used) | K | rocketid, same problem | peer, same problem | ratio | rocketid (7.9) index 0, cold "
             "| rocketid (7.9) warm after a change of q2 | its set-up s | peer, CD0 CD6 CL fixed at truth |")
    L.append("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    def cell(d):
        return f"{d['solve_s']:.4f} ({d['iterations']})" + ("" if d["success"] else " **failed**")

    for r in rows:
        w = r["warm"]
        a, b, c = w["rocketid_same_problem"], w["peer_same_problem"], w["peer_cd0_cd6_cl_fixed_at_truth"]
        q = r.get("q79", {})
        if "error" in q:
            q0 = qw = qs = q["error"]
        else:
            q0, qw = cell(q["index0"]), cell(q["warm"])
            qs = f"{q['warm']['setup_s']:.4f}"
        L.append(f"| {r['label']} ({r['N_elements']}) | {r['K']} | {cell(a)} | {cell(b)} "
                 f"| {w['ratio_same_problem']:.2f} | {q0} | {qw} | {qs} | {cell(c)} |")
    if result.get("profile"):
        L.append("")
        L.append("#### Where the IPOPT call's time goes (IPOPT's own timing statistics, CPU s, median of "
                 f"{result['profile_repeat']})")
        L.append("")
        for p in result["profile"]:
            L.append(f"{p['label']}; load: `{p['load_start']}` … `{p['load_end']}`")
            L.append("")
            L.append("| configuration | IPOPT build | iterations (regularized) | solve s (wall) | IPOPT total CPU "
                     "| function evaluations | of which callback bodies | IPOPT proper | of which PD solves "
                     "| symbolic factorization | outside the IPOPT call (wall) |")
            L.append("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
            for key, name in (("rocketid", "rocketid (its defaults)"),
                              ("rocketid_monotone", "rocketid, mu_strategy=monotone (the peer's)"),
                              ("rocketid_pivtol_1e-6", "rocketid, mumps_pivtol=1e-6 (IPOPT's; before dfb2e0a)"),
                              ("rocketid_blas_dot_objective", "rocketid, objective as before 60c3a14 (BLAS dot)"),
                              ("peer", "peer in CasADi"),
                              ("peer_nlp_via_cyipopt", "peer's NLP through cyipopt")):
                if key not in p:
                    continue
                s = p[key]
                c = s["cpu"]
                L.append(f"| {name} | {s['ipopt_version']} | {s['iterations']} ({s['regularized']}) | {s['solve_s']:.4f} "
                         f"| {fmt(c['OverallAlgorithm'])} | {fmt(c['Function Evaluations'])} "
                         f"| {fmt(s.get('callbacks_s'))} | {fmt(c.get('IPOPT proper'))} "
                         f"| {fmt(c['PDSystemSolverTotal'])} | {fmt(c['LinearSystemSymbolicFactorization'])} "
                         f"| {fmt(s.get('outside_ipopt_s'), '.4f')} |")
            L.append("")
    return "\n".join(L)


# --------------------------------------------------------------------------- main
def main() -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--quick", action="store_true", help="N = 33, 66, 132 and the default, R = 2, one profile")
    ap.add_argument("--repeat", type=int, default=None, help="repetitions of each solve (default 5; 2 with --quick)")
    ap.add_argument("--sizes", type=int, nargs="+", default=None, help="numbers of elements at K = 3")
    ap.add_argument("--no-default", action="store_true", help="skip the default discretization (66, K = 4)")
    ap.add_argument("--profile-sizes", type=int, nargs="*", default=None,
                    help="K = 3 sizes for the time breakdown (default 66 528; 66 with --quick; none: skip)")
    ap.add_argument("--out", type=Path, default=None, help="JSON output (default results/core.json)")
    ap.add_argument("--print", type=Path, metavar="JSON", help="print the tables of an earlier run and exit")
    ap.add_argument("--child-setup", help=argparse.SUPPRESS)
    args = ap.parse_args()
    if args.child_setup:
        child_setup(args.child_setup)
        return
    if args.print:
        print(tables(json.loads(args.print.read_text())))
        return
    sys.path.insert(0, str(HERE))
    repeat = args.repeat or (2 if args.quick else 5)
    sizes = args.sizes or ((33, 66, 132) if args.quick else DEFAULT_SIZES)
    prof = args.profile_sizes if args.profile_sizes is not None else ([66] if args.quick else [66, 528])
    out_path = args.out or HERE / "results" / ("core_quick.json" if args.quick else "core.json")

    def log(msg):
        print(msg, file=sys.stderr, flush=True)

    result = {"command": "python3 benchmarks/bench_core.py " + " ".join(sys.argv[1:]), "repeat": repeat,
              "load_start": uptime(), "versions": versions(),
              "started": time.strftime("%Y-%m-%d %H:%M:%S %z")}
    log(f"load: {result['load_start']}")
    spec, data, times, Y, check = make_data()
    result["data_check"] = check
    root = tempfile.mkdtemp(prefix="rocketid_bench_core_")
    data_path = os.path.join(root, "data.npz")
    np.savez(data_path, t=times, **{n: data[n].values for n in ("x", "h", "v")})

    import peer_casadi as pc
    pc.CasadiRA66(times, Y, N=6, K=3)  # warm-up: CasADi's IPOPT plugin is loaded once per process

    plan = [(str(n), n, 3) for n in sizes]
    if not args.no_default:
        plan.append(("default", None, 4))
    result["rows"] = []
    for label, N, K in plan:
        result["rows"].append(bench_row(label, N, K, spec, data, times, Y, data_path, root, repeat, log))
    result["profile_repeat"] = min(repeat, 3)
    result["profile"] = [profile_row(f"N = {n}, K = 3", n, 3, spec, data, times, Y, root, result["profile_repeat"], log)
                         for n in prof]
    shutil.rmtree(root, ignore_errors=True)
    result["load_end"] = uptime()
    result["finished"] = time.strftime("%Y-%m-%d %H:%M:%S %z")
    out_path.parent.mkdir(parents=True, exist_ok=True)
    out_path.write_text(json.dumps(result, indent=1, default=float) + "\n")
    print(tables(result))
    log(f"wrote {out_path}")


if __name__ == "__main__":
    main()
