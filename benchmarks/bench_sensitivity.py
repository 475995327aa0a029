"""Benchmark: the reduced Hessian (7.6) against the solve, and the warm-started (7.9) re-solve.

Run ``python benchmarks/bench_sensitivity.py`` (about three minutes; ``--quick`` for fewer
repetitions, ``--slow`` to run the default-options solve at N = 528 too, about ten
minutes more). Three parts, printed as Markdown tables:

1. RA-66 (noisy data, seed 0) on N = 66 and N = 528 elements, K = 4: the set-up of the NLP,
   the full IPOPT solve from p0 (with the default options, and with mumps_pivtol = 1e-4),
   and forming H_r at the estimate: ``formed`` is J_w's
   assembly, its sparse LU and the 8 back-solves; ``sensitivity_of`` adds Newton's check
   of the collocation equations at the estimate.
2. The sampling algorithm's inner loop: (7.9) re-solved after a change of q2 (q2 =
   V2^T p_trial, p_trial uniform within the bounds, nominal scaling, np = 5), warm-started
   from the index-0 solution, against a cold solve (simulation + IPOPT from scratch).
3. IPOPT options for the warm re-solve, each on the same q2 draws: median wall time of
   ``estimate_q1``, iterations, and the largest difference of the estimates from the
   default's (so that a faster setting that stops elsewhere shows).

Times are medians over the draws, wall-clock and CPU time of the process (the CPU time is
less disturbed by other jobs on a shared machine); compare within one run.
"""

from __future__ import annotations

import argparse
import platform
import time

import numpy as np

import rocketid as ri
from rocketid.estimability import analyze, estimate_q1
from rocketid.sensitivity import sensitivity_at, sensitivity_of

WARM_VARIANTS: list[tuple[str, dict]] = [
    ("default (estimate_q1's warm start)", {}),
    ("mehrotra_algorithm=yes", {"mehrotra_algorithm": "yes"}),
    ("nlp_scaling_method=none", {"nlp_scaling_method": "none"}),
    ("mu_init=1e-8", {"mu_init": 1e-8}),
    ("mu_init=1e-4", {"mu_init": 1e-4}),
    ("mu_strategy=adaptive", {"mu_strategy": "adaptive"}),
    ("warm_start_*_push=1e-6", {"warm_start_bound_push": 1e-6, "warm_start_slack_bound_push": 1e-6,
                                "warm_start_mult_bound_push": 1e-6}),
    ("bound_relax_factor=0", {"bound_relax_factor": 0.0}),
    ("nlp_scaling_method=none, mu_init=1e-8", {"nlp_scaling_method": "none", "mu_init": 1e-8}),
    ("mumps_pivtol=1e-4", {"mumps_pivtol": 1e-4}),
    ("mumps_pivtol=1e-4, mehrotra_algorithm=yes", {"mumps_pivtol": 1e-4, "mehrotra_algorithm": "yes"}),
    ("tol=1e-6 (looser)", {"tol": 1e-6}),
]


def median_time(fn, repeats: int):
    times, out = [], None
    for _ in range(repeats):
        t0 = time.perf_counter()
        out = fn()
        times.append(time.perf_counter() - t0)
    return float(np.median(times)), out


def part_hr_vs_solve(spec, data, repeats: int, slow: bool) -> None:
    """At N = 528 IPOPT with rocketid's defaults (MUMPS, mumps_pivtol 1e-6) needed 21
    iterations and 695 s, almost all in MUMPS's numerical factorization (it asks for more
    memory: delayed pivots); mumps_pivtol = 1e-4 solves in 5 iterations. IPOPT checks
    max_wall_time only between iterations, so that solve cannot be capped: it runs only
    with ``--slow``."""
    print("\n### H_r formation against the solve (RA-66, K = 4)\n")
    print("| N | NLP variables | set-up s | IPOPT, defaults: s (iterations) | IPOPT, mumps_pivtol=1e-4: s "
          "(iterations) | H_r formed s | sensitivity_of s | sensitivity_at(p0) s |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- |")
    for n_elements in (66, 528):
        mesh = ri.ra66_mesh(n_elements, K=4)
        t_setup, prepared = median_time(lambda: ri.prepare(spec, data, mesh=mesh), 1)
        if n_elements > 100 and not slow:
            default_cell = "not run (--slow)"
        else:
            t_def, fit_def = median_time(lambda: ri.estimate(spec, data, prepared=prepared),
                                         1 if n_elements > 100 else repeats)
            default_cell = (f"{fit_def.timings['solve_s']:.3f} ({fit_def.iterations})" if fit_def.success
                            else f"failed: {fit_def.message}")
        t_solve, fit = median_time(lambda: ri.estimate(spec, data, prepared=prepared,
                                                       options={"mumps_pivtol": 1e-4}), repeats)
        assert fit.success, fit.message
        sens_times, formed = [], []
        for _ in range(repeats):
            t0 = time.perf_counter()
            s = sensitivity_of(fit)
            sens_times.append(time.perf_counter() - t0)
            formed.append(s.formed_s)
        t_at, _ = median_time(lambda: sensitivity_at(prepared), repeats)
        print(f"| {n_elements} | {prepared.nlp.n} | {t_setup:.2f} | {default_cell} "
              f"| {fit.timings['solve_s']:.3f} ({fit.iterations}) | {np.median(formed):.3f} "
              f"| {np.median(sens_times):.3f} | {t_at:.3f} |", flush=True)


def part_warm(spec, data, n_trials: int, seed: int = 1):
    prepared = ri.prepare(spec, data)
    est = analyze(prepared, scaling="nominal")
    t0 = time.perf_counter()
    first = estimate_q1(prepared, est, est.q2_of(spec.guess))
    t_first = time.perf_counter() - t0
    rng = np.random.default_rng(seed)
    q2s = [est.q2_of(rng.uniform(spec.lower, spec.upper)) for _ in range(n_trials)]
    print("\n### (7.9) with q2 fixed: warm re-solve after a change of q2 (RA-66, N = 66, K = 4, np = 5)\n")
    print(f"index-0 solve (cold, NLP built): {t_first:.3f} s, {first.iterations} iterations\n")
    print("| start | median wall s | median CPU s | median IPOPT s | median set-up s | iterations (mean / max) "
          "| failures |")
    print("| --- | --- | --- | --- | --- | --- | --- |")
    for label, kwargs in (("warm (previous solution)", {"warm_start": first}), ("cold (simulation)", {})):
        walls, cpus, solves, setups, its, fails = [], [], [], [], [], 0
        for q2 in q2s[: n_trials if kwargs else max(5, n_trials // 4)]:
            t0, c0 = time.perf_counter(), time.process_time()
            r = estimate_q1(prepared, est, q2, **kwargs)
            walls.append(time.perf_counter() - t0)
            cpus.append(time.process_time() - c0)
            solves.append(r.timings["solve_s"])
            setups.append(r.timings["setup_s"])
            its.append(r.iterations)
            fails += not r.success
        print(f"| {label} | {np.median(walls):.4f} | {np.median(cpus):.4f} | {np.median(solves):.4f} "
              f"| {np.median(setups):.4f} "
              f"| {np.mean(its):.1f} / {max(its)} | {fails} |", flush=True)
    return prepared, est, first, q2s


def part_options(prepared, est, first, q2s) -> None:
    """Every variant also gets max_iter = 50; a variant is abandoned after 3 failures (a
    failed warm solve is retried cold by estimate_q1, with the same options) or 120 s."""
    print("\n### IPOPT options for the warm re-solve (same q2 draws)\n")
    print("| options (over the warm defaults) | median wall s | median CPU s | iterations (mean / max) | failures "
          "| max abs(p - p_default) |")
    print("| --- | --- | --- | --- | --- | --- |")
    reference = None
    for label, opts in WARM_VARIANTS:
        walls, cpus, its, ps, fails = [], [], [], [], 0
        started = time.perf_counter()
        for q2 in q2s:
            t0, c0 = time.perf_counter(), time.process_time()
            r = estimate_q1(prepared, est, q2, warm_start=first, options={"max_iter": 50, **opts})
            walls.append(time.perf_counter() - t0)
            cpus.append(time.process_time() - c0)
            its.append(r.iterations)
            ps.append(r.p if r.success else np.full(r.p.shape, np.nan))
            fails += not r.success
            if fails >= 3 or time.perf_counter() - started > 120:
                break
        ps = np.array(ps)
        if reference is None:
            reference = ps
        diff = np.nanmax(np.abs(ps - reference[: len(ps)])) if np.isfinite(ps).any() else float("nan")
        done = "" if len(ps) == len(q2s) else f" (abandoned after {len(ps)} draws)"
        print(f"| {label} | {np.median(walls):.4f} | {np.median(cpus):.4f} | {np.mean(its):.1f} / {max(its)} | {fails}{done} "
              f"| {diff:.1e} |", flush=True)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--quick", action="store_true", help="fewer repetitions")
    parser.add_argument("--only", choices=["hr", "warm"], default=None,
                        help="run only part 1 (hr) or parts 2-3 (warm)")
    parser.add_argument("--slow", action="store_true",
                        help="also run the default-options solve at N = 528 (about 10 minutes)")
    args = parser.parse_args()
    repeats, n_trials = (1, 10) if args.quick else (3, 40)
    print(f"rocketid {ri.__version__}, Python {platform.python_version()}, {platform.machine()}")
    spec = ri.ra66()
    data = ri.simulate_measurements(spec, ri.ra66_truth(spec), ri.ra66_times(), seed=0)
    if args.only in (None, "hr"):
        part_hr_vs_solve(spec, data, repeats, args.slow)
    if args.only in (None, "warm"):
        prepared, est, first, q2s = part_warm(spec, data, n_trials)
        part_options(prepared, est, first, q2s)


if __name__ == "__main__":
    main()
