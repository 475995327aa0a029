"""Collocation error of RA-66 at the true parameters, for several meshes (docs/accuracy.md).

For each mesh, the collocation equations are solved with every parameter fixed at the
truth (a square problem: ``ParameterTransform`` with ``P`` of shape (8, 0) and ``c`` the
truth), and the collocation polynomial's x, h, v at the 6600 sample times are compared
with the high-accuracy simulation (``rocketid.simulate``, DOP853 at rtol = atol = 1e-12
on deviations from the initial state). The noise is N(0, 1) in m, m, m/s, so 0.01 is
1 % of it (docs/design.md, 'Default mesh').

Run::

    python benchmarks/collocation_accuracy.py            # prints the Markdown table
    python benchmarks/collocation_accuracy.py --json out.json
"""

from __future__ import annotations

import argparse
import json
import time

import numpy as np
import scipy.sparse.linalg as spl

import rocketid as ri
from rocketid.nlp import ParameterTransform
from rocketid.solve import solve_nlp


def newton(nlp, x, *, tol=1e-10, max_iter=20):
    """Solve the square collocation equations ``c(x) = 0`` (initial conditions and
    collocation rows; the parameter-bound rows of a transformed NLP are constant) by
    Newton's method with a sparse LU."""
    eq = nlp.m_ic + nlp.m_col
    for _ in range(max_iter):
        c = nlp.constraints(x)[:eq]
        J = nlp.jacobian_matrix(x).tocsr()[:eq].tocsc()
        dx = spl.spsolve(J, c)
        x = x - dx
        if np.abs(dx).max() <= tol * max(1.0, np.abs(x).max()):
            break
    else:
        raise RuntimeError("Newton's method did not converge on the square collocation equations")
    return x


def collocation_error(spec, clean, p_true, mesh):
    """Max |collocation - simulation| per channel at ``p_true`` on ``mesh``, the theta
    error at 1 s and 66 s, the number of NLP variables, and IPOPT's status on the same
    square problem: the largest output difference between its solution and Newton's
    (None when IPOPT failed).

    The square problem is solved by Newton's method (:func:`newton`); IPOPT
    (``solve_nlp``, default tolerances) is run on it as well for comparison.
    """
    pr = ri.prepare(spec, clean, mesh=mesh)
    fixed = ParameterTransform(np.zeros((len(p_true), 0)), np.asarray(p_true, float), ())
    nlp = pr.nlp.with_transform(fixed)
    S, _ = pr.initial_states(p_true)
    x0 = nlp.initial_x(S, p_true)
    x = newton(nlp, x0)
    sol = solve_nlp(nlp, x0)
    gap = None
    if sol.success:
        gap = max(float(np.abs(a - b).max()) for a, b in zip(nlp.outputs(x), nlp.outputs(sol.x)))
    errors = {}
    for name, y in zip(nlp.channel_names, nlp.outputs(x)):
        errors[name] = float(np.abs(y - clean[name].values).max())
    # the flight-path angle, not measured, shows where the error is made: at the singular start
    j = spec.state_symbols.index(spec.symbol("theta"))
    probe = np.array([1.0, 66.0])
    reference = ri.simulate(spec, p_true, probe).states[:, j]
    colloc = pr.transcription.states_at(nlp.full_vector(x), probe)[:, j]
    theta_err = np.abs(colloc - reference)
    return errors, theta_err, nlp.n, gap


def _first_second_kept(n_elements: int, K: int) -> ri.Mesh:
    """``n_elements`` uniform elements, except that the first second stays one element."""
    h = 66.0 / n_elements
    return ri.Mesh(np.concatenate([[0.0], np.arange(round(1.0 / h), n_elements + 1) * h]), K)


# (label, mesh): the study grid, then meshes that locate the error
MESHES = [(f"uniform N = {N}", ri.uniform_mesh(0.0, 66.0, N, K)) for N in (66, 132, 264) for K in (2, 3, 4)]
MESHES += [
    ("uniform N = 66", ri.uniform_mesh(0.0, 66.0, 66, 5)),
    ("graded_mesh(0, 66, 66, 3, refine_first=2)", ri.graded_mesh(0.0, 66.0, 66, 3, refine_first=2)),
    ("graded_mesh(0, 66, 66, 4, refine_first=2)", ri.graded_mesh(0.0, 66.0, 66, 4, refine_first=2)),
    ("graded_mesh(0, 66, 132, 3, refine_first=2)", ri.graded_mesh(0.0, 66.0, 132, 3, refine_first=2)),
    ("N = 264 except the first 1 s element", _first_second_kept(264, 3)),
]


def main(argv=None):
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--json", help="also write the results as JSON to this file")
    args = ap.parse_args(argv)
    spec = ri.ra66()
    p_true = ri.ra66_truth(spec)
    clean = ri.simulate_measurements(spec, p_true, ri.ra66_times(), noise=False)
    rows = []
    for label, mesh in MESHES:
        t0 = time.perf_counter()
        err, theta_err, n, gap = collocation_error(spec, clean, p_true, mesh)
        rows.append(dict(mesh=label, K=mesh.K, elements=mesh.n_elements, variables=n,
                         x=err["x"], h=err["h"], v=err["v"], theta_error_1s=float(theta_err[0]), theta_error_66s=float(theta_err[1]), ipopt_vs_newton=gap,
                         seconds=time.perf_counter() - t0))
    print("| mesh | elements | K | NLP variables | max x error, m | max h error, m | max v error, m/s "
          "| theta error at 1 s, rad | theta error at 66 s, rad | within 0.01 | IPOPT on the same problem |")
    print("| --- | --- | --- | --- | --- | --- | --- | --- | --- | --- | --- |")
    for r in rows:
        label = r["mesh"]
        ipopt = "fails (MUMPS: singular)" if r["ipopt_vs_newton"] is None else f"agrees to {r['ipopt_vs_newton']:.0e}"
        ok = "yes" if max(r["x"], r["h"], r["v"]) <= 0.01 else "no"
        print(f"| {label} | {r['elements']} | {r['K']} | {r['variables']} | {r['x']:.2e} | {r['h']:.2e} "
              f"| {r['v']:.2e} | {r['theta_error_1s']:.1e} | {r['theta_error_66s']:.1e} | {ok} | {ipopt} |")
    if args.json:
        with open(args.json, "w") as fh:
            json.dump(rows, fh, indent=2)


if __name__ == "__main__":
    main()
