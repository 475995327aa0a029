"""Benchmark (issue 9, lever 2): IPOPT's cost per iteration under MUMPS options, OpenBLAS threads,
variable ordering and initialization options, on the core solve of RA-66.

Run ``nice python3 benchmarks/bench_ipopt_options.py`` (a few minutes; ``--repeat R``,
default 3; ``--sizes default,528``; ``--only permuting_scaling`` runs the defaults and the variants
whose names hold one of the given words). For each mesh, the full 8-parameter estimation from a
simulation at p0 is solved with rocketid's defaults and with each variant below, the
variants interleaved within each repetition (so that they share the load); the table gives
the median IPOPT CPU time (``print_timing_statistics``: the whole algorithm, of which the
linear-system solves and the symbolic factorization), the iterations, the wall time of the
IPOPT call, and the largest difference of the estimates from the defaults'.

OpenBLAS's thread count is fixed when the library loads, so each thread setting runs in its
own child process (``OPENBLAS_NUM_THREADS`` unset, i.e. one thread per core, and 1).

The variable ordering variant permutes the NLP: states and constraint rows interleaved
element by element in time, then the parameters (the order in which the KKT matrix is
banded); IPOPT gets the permuted callbacks, MUMPS then applies its own fill-reducing
ordering on top (AMD/AMF/QAMD/PORD in the bundled build, no METIS).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np

HERE = Path(__file__).resolve().parent
sys.path.insert(0, str(HERE))

from bench_core import ipopt_log, med, mesh_for, uptime  # noqa: E402

VARIANTS: list[tuple[str, dict]] = [
    ("rocketid's defaults", {}),
    ("mumps_pivtol=1e-6 (IPOPT's)", {"mumps_pivtol": 1e-6}),
    ("mumps_pivtol=1e-2", {"mumps_pivtol": 1e-2}),
    ("mumps_permuting_scaling=0 (IPOPT's: 7)", {"mumps_permuting_scaling": 0}),
    ("mumps_scaling=0 (IPOPT's: 77)", {"mumps_scaling": 0}),
    ("mumps_scaling=8", {"mumps_scaling": 8}),
    ("mumps_mem_percent=100 (IPOPT's: 1000)", {"mumps_mem_percent": 100}),
    ("least_square_init_duals=yes", {"least_square_init_duals": "yes"}),
    ("constr_mult_init_max=0 (no least-squares multipliers)", {"constr_mult_init_max": 0.0}),
    ("constr_mult_init_max=1e12 (keep them; IPOPT's: 1000)", {"constr_mult_init_max": 1e12}),
    ("nlp_scaling_method=none", {"nlp_scaling_method": "none"}),
    ("mu_strategy=monotone", {"mu_strategy": "monotone"}),
]


class Permuted:
    """The NLP's callbacks with variables and constraint rows permuted (``xp = x[pv]``,
    ``cp = c[pc]``): a cyipopt problem object for the ordering variant."""

    def __init__(self, nlp, pv, pc):
        self.nlp, self.pv, self.pc = nlp, pv, pc
        self.iv = np.argsort(pv)
        self.ic = np.argsort(pc)
        jr, jc = nlp.jacobianstructure()
        self.jr, self.jc = self.ic[jr], self.iv[jc]
        hr, hc = nlp.hessianstructure()
        r, c = self.iv[hr], self.iv[hc]
        self.hr, self.hc = np.maximum(r, c), np.minimum(r, c)
        self.n, self.m = nlp.n, nlp.m
        self.x_lower, self.x_upper = nlp.x_lower[pv], nlp.x_upper[pv]
        self.c_lower, self.c_upper = nlp.c_lower[pc], nlp.c_upper[pc]

    def _x(self, xp):
        return xp[self.iv]

    def objective(self, xp):
        return self.nlp.objective(self._x(xp))

    def gradient(self, xp):
        return self.nlp.gradient(self._x(xp))[self.pv]

    def constraints(self, xp):
        return self.nlp.constraints(self._x(xp))[self.pc]

    def jacobianstructure(self):
        return self.jr, self.jc

    def jacobian(self, xp):
        return self.nlp.jacobian(self._x(xp))

    def hessianstructure(self):
        return self.hr, self.hc

    def hessian(self, xp, lagrange, obj_factor):
        return self.nlp.hessian(self._x(xp), np.asarray(lagrange)[self.ic], obj_factor)


def time_ordering(nlp):
    """``(pv, pc)``: the variables and rows in time order (node states, collocation rows of
    the element after them), the parameters and linear rows last."""
    lay = nlp.layout
    tr = nlp.transcription
    ns, K = lay.layout.n_states, tr.mesh.K
    n_nodes = lay.layout.n_nodes
    node_of_var = np.repeat(np.arange(n_nodes), ns)                      # VariableLayout: node-major
    node_of_row = np.concatenate([np.zeros(lay.n_ic),                     # initial conditions: node 0
                                  np.repeat(np.arange(1, tr.n_collocation + 1), ns)])  # point c ends at node c+1
    key_v = np.concatenate([node_of_var * 2.0, np.full(lay.n_reduced, np.inf)])
    key_c = np.concatenate([node_of_row * 2.0 + 1.0, np.full(lay.n_linear, np.inf)])
    del K
    return np.argsort(key_v, kind="stable"), np.argsort(key_c, kind="stable")


def child(args) -> None:
    sys.path.insert(0, str(HERE))
    from bench_core import make_data

    from rocketid import prepare
    from rocketid.solve import solve_nlp
    spec, data, _, _, _ = make_data()
    out = {}
    logfile = os.path.join(tempfile.mkdtemp(prefix="ipopt_opt_"), "ipopt.txt")
    stat = {"print_timing_statistics": "yes", "output_file": logfile, "file_print_level": 5}
    for size in args.sizes.split(","):
        N, K = (None, 4) if size == "default" else (int(size), 3)
        prep = prepare(spec, data, mesh=mesh_for(spec, N, K))
        nlp = prep.nlp
        S0, _ = prep.initial_states(spec.guess)
        x0 = nlp.initial_x(S0, spec.guess)
        pv, pc = time_ordering(nlp)
        perm = Permuted(nlp, pv, pc)
        variants = VARIANTS + [("variables and rows in time order", {"__permuted__": True})]
        if args.only:
            keys = [k for k in args.only.split(",") if k]
            variants = [v for i, v in enumerate(variants) if i == 0 or any(k in v[0] for k in keys)]
        runs = {name: [] for name, _ in variants}
        load0 = uptime()
        for _ in range(args.repeat):
            for name, opts in variants:
                opts = dict(opts)
                if opts.pop("__permuted__", False):
                    sol = solve_nlp(perm, x0[pv], options={**opts, **stat})
                    x = sol.x[perm.iv]
                else:
                    sol = solve_nlp(nlp, x0, options={**opts, **stat})
                    x = sol.x
                lg = ipopt_log(logfile)
                runs[name].append({"solve_s": sol.solve_s, "iterations": sol.iterations, "success": sol.success,
                                   "cpu": lg["cpu"], "regularized": lg["regularized"],
                                   "p": nlp.layout.parameters(x).tolist()})
        p_def = np.array(runs[VARIANTS[0][0]][-1]["p"])
        rows = []
        for name, _ in variants:
            r = runs[name]
            rows.append({"variant": name, "solve_s": med(a["solve_s"] for a in r),
                         "cpu_total": med(a["cpu"].get("OverallAlgorithm") for a in r),
                         "cpu_evals": med(a["cpu"].get("Function Evaluations") for a in r),
                         "cpu_pd": med(a["cpu"].get("PDSystemSolverTotal") for a in r),
                         "cpu_symbolic": med(a["cpu"].get("LinearSystemSymbolicFactorization") for a in r),
                         "iterations": r[-1]["iterations"], "regularized": r[-1]["regularized"],
                         "success": all(a["success"] for a in r),
                         "max_dp": float(np.max(np.abs(np.array(r[-1]["p"]) - p_def)))})
        out[size] = {"n": nlp.n, "mesh": prep.transcription.mesh.describe(), "rows": rows, "load": [load0, uptime()]}
    print(json.dumps(out))


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--repeat", type=int, default=3)
    parser.add_argument("--sizes", default="default,528")
    parser.add_argument("--only", default="", help="comma-separated substrings: run the defaults and the variants "
                        "whose names hold one of them (e.g. 'permuting_scaling')")
    parser.add_argument("--child", action="store_true", help=argparse.SUPPRESS)
    args = parser.parse_args()
    if args.child:
        child(args)
        return
    results = {}
    for label, env_extra in (("OpenBLAS threads: default", {}), ("OPENBLAS_NUM_THREADS=1", {"OPENBLAS_NUM_THREADS": "1"})):
        env = {k: v for k, v in os.environ.items() if k not in ("OPENBLAS_NUM_THREADS", "OMP_NUM_THREADS")}
        env.update(env_extra)
        cmd = [sys.executable, __file__, "--child", "--repeat", str(args.repeat), "--sizes", args.sizes,
               "--only", args.only]
        t0 = time.perf_counter()
        res = subprocess.run(cmd, env=env, capture_output=True, text=True)
        if res.returncode:
            print(res.stderr, file=sys.stderr)
            raise SystemExit(f"child failed: {label}")
        results[label] = json.loads(res.stdout.strip().splitlines()[-1])
        print(f"{label}: {time.perf_counter() - t0:.0f} s", file=sys.stderr, flush=True)
    for size in args.sizes.split(","):
        first = results[next(iter(results))][size]
        print(f"\n### {first['mesh']} ({first['n']} variables), median of {args.repeat}\n")
        print("| OpenBLAS | variant | iterations (regularized) | IPOPT CPU ms | of which evaluations | PD solves "
              "| symbolic factorization | IPOPT call wall ms | max abs(p - p_default) |")
        print("| --- | --- | --- | --- | --- | --- | --- | --- | --- |")
        for label, res in results.items():
            for r in res[size]["rows"]:
                f = (lambda v: "—" if v is None else f"{v * 1e3:.1f}")
                ok = "" if r["success"] else " **failed**"
                print(f"| {label} | {r['variant']}{ok} | {r['iterations']} ({r['regularized']}) | {f(r['cpu_total'])} "
                      f"| {f(r['cpu_evals'])} | {f(r['cpu_pd'])} | {f(r['cpu_symbolic'])} | {f(r['solve_s'])} "
                      f"| {r['max_dp']:.1e} |")
        for label, res in results.items():
            print(f"\nLoad ({label}): `{res[size]['load'][0]}` … `{res[size]['load'][1]}`")


if __name__ == "__main__":
    main()
