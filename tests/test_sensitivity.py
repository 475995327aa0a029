"""Sensitivities and the reduced Hessian (7.6) from the KKT blocks (``rocketid.sensitivity``).

The reference is independent of the collocation: central finite differences of the
high-accuracy simulator (``rocketid.simulate``, DOP853 at rtol = atol = 1e-12) on RA-66.

Finite-difference step: 1e-3 of each parameter's value. Measured on RA-66 (default mesh,
66 elements, K = 4), the largest per-column relative error (2-norm over the 19800
outputs) is the same, 1.9e-5 at p0 and 9.1e-5 at the truth, for steps from 1e-2 to 1e-4:
the truncation error of the difference is negligible and what is left is the collocation's
own error in S. At 1e-5 the simulator's integration error divided by the step shows
(1.3e-3 on CD0 at p0, where the step is 1e-6), so 1e-3 sits in the middle of the plateau.
That the rest is the collocation's error, not the reference's: at the truth the same
comparison gives 9.1e-5 (N = 66, K = 4), 3.2e-5 (N = 264) and 2.5e-6 (N = 528), and
N = 66 against N = 528 differs by the same 9e-5 as N = 66 against the simulator.
"""

from __future__ import annotations

import numpy as np
import pytest
import scipy.sparse as sps
import sympy as sp

import rocketid as ri
from rocketid.errors import SensitivityError
from rocketid.sensitivity import Sensitivity, sensitivity_at, sensitivity_of, solve_collocation

FD_STEP = 1e-3           # relative central-difference step
S_TOLERANCE = 1e-3       # the per-column tolerance on S


# ---------------------------------------------------------------------------
# RA-66 against the simulator
# ---------------------------------------------------------------------------


def simulator_outputs(spec, p, prepared):
    """Outputs stacked in the NLP's channel order, and states at the mesh nodes."""
    samples = ri.ra66_times()
    nodes = prepared.transcription.mesh.node_times
    times = np.union1d(samples, nodes)
    traj = ri.simulate(spec, p, times)
    assert traj.success, traj.message
    out = traj.outputs()
    at_samples = np.searchsorted(times, samples)
    y = np.concatenate([out[name][at_samples] for name in prepared.nlp.channel_names])
    states = traj.states[np.searchsorted(times, nodes)]
    return y, states


def central_differences(spec, p, prepared):
    """``dy/dp`` (ny, n_p) and ``dstates/dp`` at the nodes (n_nodes, n_states, n_p)."""
    p = np.asarray(p, float)
    dy, ds = [], []
    for j in range(p.size):
        h = FD_STEP * abs(p[j])
        up, down = p.copy(), p.copy()
        up[j] += h
        down[j] -= h
        y1, s1 = simulator_outputs(spec, up, prepared)
        y0, s0 = simulator_outputs(spec, down, prepared)
        dy.append((y1 - y0) / (2 * h))
        ds.append((s1 - s0) / (2 * h))
    return np.stack(dy, axis=1), np.stack(ds, axis=2)


def column_errors(A, B):
    """Per-column relative error ``||A_j - B_j|| / ||B_j||`` (2-norm)."""
    return np.linalg.norm(A - B, axis=0) / np.linalg.norm(B, axis=0)


@pytest.fixture(scope="module", params=["p0", "truth"])
def at_point(request, ra66_spec, ra66_p_true, ra66_clean_prepared):
    p = ra66_spec.guess if request.param == "p0" else np.array(ra66_p_true)
    sens = sensitivity_at(ra66_clean_prepared, p)
    S_fd, dstates_fd = central_differences(ra66_spec, p, ra66_clean_prepared)
    return request.param, p, sens, S_fd, dstates_fd


def test_S_agrees_with_finite_differences_of_the_simulator(at_point, record_property):
    where, p, sens, S_fd, _ = at_point
    err = column_errors(sens.S, S_fd)
    figure = ", ".join(f"{n} {e:.1e}" for n, e in zip(sens.parameter_names, err))
    print(f"\nS vs central differences of the simulator at {where} (step {FD_STEP:g} relative): "
          f"max {err.max():.2e}; {figure}")
    record_property(f"S_error_{where}", float(err.max()))
    assert err.max() <= S_TOLERANCE, figure


def test_state_sensitivities_agree_with_finite_differences(at_point):
    where, p, sens, _, dstates_fd = at_point
    assert sens.state_sensitivity.shape == dstates_fd.shape
    worst = {}
    for i, name in enumerate(("x", "h", "v", "theta")):
        # the start is fixed: its sensitivity is zero in both
        err = column_errors(sens.state_sensitivity[1:, i, :], dstates_fd[1:, i, :])
        worst[name] = float(err.max())
    print(f"\nstate sensitivities at {where}: max per-column relative error "
          + ", ".join(f"{k} {v:.1e}" for k, v in worst.items()))
    assert max(worst.values()) <= S_TOLERANCE, worst
    assert np.abs(sens.state_sensitivity[0]).max() <= 1e-12


def test_H_r_agrees_with_finite_differences(at_point):
    """``H_r`` against ``S_fd^T Cy^-1 S_fd``, entrywise relative to ``sqrt(H_ii H_jj)``
    (which bounds every entry); a per-column error e in S gives at most about 2e here."""
    where, p, sens, S_fd, _ = at_point
    W = S_fd / sens.sigma[:, None]
    H_fd = W.T @ W
    scale = np.sqrt(np.outer(np.diag(H_fd), np.diag(H_fd)))
    err = np.abs(sens.H_r - H_fd) / scale
    print(f"\nH_r vs finite differences at {where}: max |dH_ij| / sqrt(H_ii H_jj) = {err.max():.2e}")
    assert err.max() <= 2 * S_TOLERANCE
    # the eigenvalues in the chapter's nominal scaling (CD 0.5, CL 0.1)
    D = np.diag(np.array([0.5] * 7 + [0.1]))
    lam = np.linalg.eigvalsh(D @ sens.H_r @ D)
    lam_fd = np.linalg.eigvalsh(D @ H_fd @ D)
    assert np.max(np.abs(lam / lam_fd - 1)) <= 1e-2


# ---------------------------------------------------------------------------
# Structure of the result: (7.6) itself
# ---------------------------------------------------------------------------


@pytest.fixture(scope="module")
def at_p0(ra66_clean_prepared):
    return sensitivity_at(ra66_clean_prepared)


def test_Z_spans_the_null_space_of_the_constraint_Jacobian(ra66_clean_prepared, at_p0):
    """``[J_p  J_w] Z = 0`` with the constraints ``c(gamma, p) = 0`` and ``h(gamma) - y = 0``."""
    nlp = ra66_clean_prepared.nlp
    nsv, n_p = nlp.n_states_vars, at_p0.n_parameters
    x = np.concatenate([at_p0.gamma, at_p0.p])
    m_eq = nlp.m_ic + nlp.m_col
    J = nlp.jacobian_matrix(x)[:m_eq].tocsr()
    Hy = nlp.output_jacobian(x).tocsr()
    ny = Hy.shape[0]
    # columns ordered (p, gamma, y), as Z
    A = sps.bmat([[J[:, nsv:], J[:, :nsv], None],
                  [Hy[:, nsv:], Hy[:, :nsv], -sps.identity(ny)]], format="csr")
    Z = at_p0.Z
    assert Z.shape == (n_p + nsv + ny, n_p)
    assert np.array_equal(Z[:n_p], np.eye(n_p))
    residual = A @ Z
    assert np.abs(residual).max() <= 1e-8 * np.abs(A).max() * np.abs(Z).max()
    # the y rows of Z are S and the gamma rows are the state sensitivities
    assert np.array_equal(Z[n_p + nsv:], at_p0.S)
    assert np.array_equal(Z[n_p:n_p + nsv].reshape(at_p0.state_sensitivity.shape), at_p0.state_sensitivity)


def test_H_r_matches_finite_differences_of_the_collocated_outputs(ra66_clean_prepared, at_p0):
    """H_r = S^T Cy^-1 S with S from central differences of the outputs, each side a fresh
    Newton solve of the collocation equations at the moved p: no LU of J_w, no Z."""
    nlp = ra66_clean_prepared.nlp
    lay = nlp.layout
    p0 = at_p0.p
    cols = []
    for i in range(p0.size):
        h = 1e-5 * max(1.0, abs(p0[i]))
        ys = []
        for sign in (1.0, -1.0):
            p = p0.copy()
            p[i] += sign * h
            gamma = solve_collocation(nlp, p, at_p0.gamma, tol=1e-13)
            ys.append(np.concatenate(nlp.outputs(lay.pack(gamma, p))))
        cols.append((ys[0] - ys[1]) / (2 * h))
    S_fd = np.stack(cols, axis=1)
    W = 1.0 / nlp.sigma_vector() ** 2
    H_fd = S_fd.T @ (W[:, None] * S_fd)
    scale = np.sqrt(np.outer(np.diag(H_fd), np.diag(H_fd)))
    assert np.abs(at_p0.H_r - H_fd).max() / scale.max() < 1e-6
    np.testing.assert_allclose(np.diag(at_p0.H_r), np.diag(H_fd), rtol=1e-5)
    assert np.array_equal(at_p0.H_r, at_p0.H_r.T)
    assert np.all(np.linalg.eigvalsh(at_p0.H_r) > 0)


def test_result_fields(ra66_clean_prepared, at_p0):
    assert isinstance(at_p0, Sensitivity)
    assert at_p0.parameter_names == ("CD0", "CD1", "CD2", "CD3", "CD4", "CD5", "CD6", "CL")
    assert np.array_equal(at_p0.p, ra66_clean_prepared.spec.guess)
    assert set(at_p0.channel_slices) == {"x", "h", "v"}
    assert at_p0.output_sensitivity("h").shape == (6600, 8)
    assert at_p0.formed_s > 0
    assert 1e6 < at_p0.condition_number < 1e9
    assert at_p0.notes == ()


def test_sensitivity_of_a_fit_equals_sensitivity_at_its_estimate(ra66_noisy_fit):
    a = sensitivity_of(ra66_noisy_fit)
    b = sensitivity_at(ra66_noisy_fit.prepared, ra66_noisy_fit.p)
    assert np.allclose(a.S, b.S, rtol=1e-7, atol=1e-9 * np.abs(b.S).max())


def test_newton_from_the_fit_s_states_reaches_the_sensitivities_a_simulated_start_does(ra66_noisy_fit, ra66_noisy):
    """The hold-out check's window fits form the sensitivities at the full fit's estimate on the window's data,
    their Newton solve started from the full fit's node states (no simulation): the same as from the
    simulation at that estimate."""
    fit = ra66_noisy_fit
    window = ri.prepare(fit.spec, ra66_noisy.window(0.0, 45.0), mesh=fit.prepared.transcription.mesh)
    simulated = sensitivity_at(window, fit.p)
    started = sensitivity_at(window, fit.p, gamma=fit.state_trajectories.ravel())
    assert np.allclose(started.S, simulated.S, rtol=1e-8, atol=1e-8 * np.abs(simulated.S).max())


def test_a_feasible_gamma_is_used_as_given(ra66_clean_prepared, at_p0):
    again = sensitivity_at(ra66_clean_prepared, at_p0.p, gamma=at_p0.gamma, solve=False)
    assert np.array_equal(again.S, at_p0.S)


def test_an_infeasible_gamma_is_refused(ra66_clean_prepared, at_p0):
    with pytest.raises(SensitivityError, match="does not satisfy the collocation equations"):
        sensitivity_at(ra66_clean_prepared, at_p0.p, gamma=at_p0.gamma + 1.0, solve=False)


# ---------------------------------------------------------------------------
# Refusals and notes on small models
# ---------------------------------------------------------------------------

TIMES = np.linspace(0.1, 5.0, 50)
MESH = ri.uniform_mesh(0.0, 5.0, 10, 4)


def decay_with_gain(*, unused: bool = False, degenerate: bool = False) -> ri.ModelSpec:
    """``dx/dt = -k x + g u(t)``; optionally a parameter ``c`` that enters nothing, or the
    degenerate implicit form ``k (dx/dt - g u) = 0``, whose Jacobian is singular at k = 0."""
    m = ri.Model("decay_gain", 0.0, 5.0)
    x = m.state("x", 0.0)
    u = m.input("u", 1 + sp.sin(2 * m.t))
    k = m.parameter("k", 0.5, bounds=(0.0, 10.0))
    g = m.parameter("g", 1.0, bounds=(0.01, 10.0))
    if unused:
        m.parameter("c", 1.0, bounds=(0.0, 2.0))
    if degenerate:
        m.implicit({x: k * (m.der(x) - g * u)})
    else:
        m.ode({x: -k * x + g * u})
    m.output("x", x, sigma=0.05)
    return m.freeze()


def test_singular_jacobian_is_refused_with_the_reason():
    spec = decay_with_gain(degenerate=True)
    data = ri.simulate_measurements(spec, [1.0, 1.0], TIMES, seed=0)
    prepared = ri.prepare(spec, data, mesh=MESH)
    assert sensitivity_at(prepared, [1.0, 1.0]).H_r.shape == (2, 2)   # regular at k = 1
    # at k = 0 every trajectory satisfies the equations: J_w is singular
    gamma = np.zeros(prepared.nlp.n_states_vars)
    for solve in (True, False):
        with pytest.raises(SensitivityError, match=r"singular.*no unique trajectory"):
            sensitivity_at(prepared, [0.0, 1.0], gamma=gamma, solve=solve)


def test_a_parameter_that_enters_nothing_is_noted():
    spec = decay_with_gain(unused=True)
    data = ri.simulate_measurements(spec, None, TIMES, seed=0)
    sens = sensitivity_at(ri.prepare(spec, data, mesh=MESH))
    assert np.all(sens.S[:, 2] == 0)
    assert np.all(sens.H_r[2] == 0)
    assert len(sens.notes) == 1 and "parameter c has no effect on the outputs" in sens.notes[0]
    assert sens.condition_number == float("inf")
