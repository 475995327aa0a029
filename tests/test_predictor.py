"""The sampling draw's predictor (issue 9, lever 1): the KKT factors at the reference solution
of (7.9) predict each draw's solution, and IPOPT starts from the prediction.

The truths are IPOPT's own cold solves of the same (7.9) problems (from a simulation, no
multipliers, nothing shared with the predictor but the NLP), and the draws made without the
predictor (IPOPT warm-started from the reference, the path before the predictor).
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np
import pytest

import rocketid as ri
from rocketid.errors import SensitivityError, SettingsError
from rocketid.estimability import estimate_q1
from rocketid.sampling import SamplingSettings, prepare_sampling
from rocketid.sampling.worker import WorkerContext, evaluate_draw, learning_offsets, trial_parameters
from rocketid.sensitivity import SolutionPredictor, SolutionSurface

SEED = 7
DRAWS = range(1, 9)


@pytest.fixture(scope="module")
def problem(ra66_spec, ra66_noisy):
    prepared = ri.prepare(ra66_spec, ra66_noisy)
    return prepare_sampling(prepared, settings=SamplingSettings(n_iter=5))


@pytest.fixture(scope="module")
def ctx(problem):
    return WorkerContext.build(problem.recipe, problem.prepared)


@pytest.fixture(scope="module")
def draws(ctx):
    """Each draw with the predictor, without it, and a cold IPOPT solve of the same (7.9)."""
    est = ctx.recipe.estimability
    without = replace(ctx, predictor=None)
    out = []
    for k in DRAWS:
        q2 = est.q2_of(trial_parameters(ctx.recipe, SEED, k))
        cold = estimate_q1(ctx.prepared, est, q2)
        out.append((evaluate_draw(ctx, SEED, k), evaluate_draw(without, SEED, k), cold))
    return out


def test_the_worker_forms_the_predictor(ctx):
    assert isinstance(ctx.predictor, SolutionPredictor)
    assert ctx.predictor.solution is ctx.reference.solution


def test_each_draw_equals_a_cold_ipopt_solve(draws, ctx):
    D = ctx.recipe.estimability.D
    for predicted, _, cold in draws:
        assert predicted.success and cold.success and cold.iterations >= 5
        # the same minimum to IPOPT's tolerance: the parameters (in the scaled coordinates the
        # sampling works in) and the objective of (7.9)
        np.testing.assert_allclose(np.array(predicted.p) / D, cold.p / D, rtol=0, atol=1e-7)
        assert abs(predicted.objective - cold.objective) <= 1e-9 * cold.objective


def test_draws_are_unchanged_by_the_predictor(draws):
    etas_with, etas_without = [], []
    for predicted, plain, _ in draws:
        assert predicted.success and plain.success
        # eta to 1e-9 (relative for a poor draw's large eta: both solves stop within IPOPT's
        # tolerance of the same minimum, and eta of the residuals magnifies what is left)
        assert abs(predicted.eta - plain.eta) <= 1e-9 * max(1.0, plain.eta)
        np.testing.assert_allclose(predicted.moments, plain.moments, rtol=1e-9, atol=1e-9)
        np.testing.assert_allclose(predicted.p, plain.p, rtol=1e-8, atol=0)
        etas_with.append(predicted.eta)
        etas_without.append(plain.eta)
    assert int(np.argmin(etas_with)) == int(np.argmin(etas_without))   # the same best draw


def test_ipopt_starts_at_the_prediction(draws):
    its_with = [d[0].iterations for d in draws]
    its_without = [d[1].iterations for d in draws]
    # IPOPT accepts most predictions at iteration 0 and needs at most 2 iterations for any;
    # from the reference itself it needs 3-4
    assert max(its_with) <= 2 and sum(its_with) <= 3
    assert min(its_without) >= 2 and sum(its_without) > 3 * sum(its_with) + len(draws)


#: Draws of run SEED whose prediction leaves the bounds of p (found by the predictor itself;
#: the test below checks that they do).
ACROSS_A_BOUND = (51, 67)


def test_a_prediction_across_a_bound_is_held_on_it(ctx):
    """A prediction that crosses a bound of p starts IPOPT badly (10-18 iterations against 4-8
    from the reference solution): the predictor holds the crossed rows on their bounds and
    predicts again (the KKT conditions with those rows as equalities), and IPOPT needs at most
    one iteration from there; the draw still equals a cold solve."""
    est, ref, D = ctx.recipe.estimability, ctx.reference, ctx.recipe.estimability.D
    without = replace(ctx, predictor=None)
    spec = ctx.prepared.spec
    for k in ACROSS_A_BOUND:
        q2 = est.q2_of(trial_parameters(ctx.recipe, SEED, k))
        nlp = ref.nlp.with_offset(est.transform(q2).c)
        across = ctx.predictor.predict(nlp, hold=False)
        assert across is not None and not across.feasible and not across.active
        p_across = nlp.layout.parameters(across.x)
        assert np.any(p_across < spec.lower) or np.any(p_across > spec.upper), p_across
        held = ctx.predictor.predict(nlp)
        assert held.feasible and held.converged and held.active
        rows = nlp.layout.linear_rows
        a = nlp.structure.A_lin @ held.x
        bound = np.where(a[list(held.active)] <= nlp.c_lower[rows][list(held.active)] + 1e-6,
                         nlp.c_lower[rows][list(held.active)], nlp.c_upper[rows][list(held.active)])
        np.testing.assert_allclose(a[list(held.active)], bound, rtol=0, atol=1e-8)   # on the bound
        drawn, plain = evaluate_draw(ctx, SEED, k), evaluate_draw(without, SEED, k)
        assert drawn.success and drawn.iterations <= 1 < plain.iterations <= 8
        cold = estimate_q1(ctx.prepared, est, q2)
        np.testing.assert_allclose(np.array(drawn.p) / D, cold.p / D, rtol=0, atol=1e-7)
        assert abs(drawn.objective - cold.objective) <= 1e-9 * cold.objective


def test_first_order_prediction(ctx):
    """One step with the reference factors is the first-order change of the solution: its
    error against IPOPT's converged solution falls with the square of the change of q2."""
    est, ref = ctx.recipe.estimability, ctx.reference
    pred = replace(ctx.predictor, surface=None)    # the steps from the reference solution
    q2_ref = ctx.recipe.reference_q2
    direction = est.q2_of(trial_parameters(ctx.recipe, SEED, 1)) - q2_ref
    errors, moves = [], []
    for t in (0.02, 0.01):
        q2 = q2_ref + t * direction
        nlp = ref.nlp.with_offset(est.transform(q2).c)
        first = pred.predict(nlp, max_steps=1)
        solved = estimate_q1(ctx.prepared, est, q2)
        assert first.steps == 1 and solved.success
        errors.append(np.max(np.abs(nlp.layout.reduced(first.x) - nlp.layout.reduced(solved.x))))
        moves.append(np.max(np.abs(nlp.layout.reduced(ref.x) - nlp.layout.reduced(solved.x))))
    # the prediction is far better than the reference, and second order: halving the change
    # divides its error by about 4 (while the solution moves by about half)
    assert errors[0] < 0.05 * moves[0]
    assert 0.4 < moves[1] / moves[0] < 0.6
    assert 0.15 < errors[1] / errors[0] < 0.35


def test_a_warm_restart_at_a_solution_takes_at_most_one_step(ra66_noisy_fit, ra66_spec, ra66_noisy):
    """IPOPT caps warm-start multipliers at 1e6 unless told otherwise; RA-66's reach 1e8-1e11, and
    the cap made a re-solve from the exact solution take 2 iterations (0 for (7.9), whose
    parameters have no variable bounds, and 1 here)."""
    fit = ra66_noisy_fit
    assert np.max(np.abs(fit.solution.mult_g)) > 1e8   # IPOPT's default cap: 1e6
    again = ri.estimate(ra66_spec, ra66_noisy, prepared=fit.prepared, warm_start=fit)
    assert again.success and again.iterations <= 1
    np.testing.assert_allclose(again.p, fit.p, rtol=1e-8)


def test_predictor_refuses_what_it_cannot_predict(ctx, problem):
    failed = replace(ctx.reference.solution, status=-1, message="Maximum_Iterations_Exceeded")
    with pytest.raises(SensitivityError, match="did not converge"):
        SolutionPredictor.at(ctx.reference.nlp, failed)
    # another structure (the untransformed NLP): no prediction, IPOPT starts from the reference
    assert ctx.predictor.predict(problem.prepared.nlp) is None
    est = ctx.recipe.estimability
    other = replace(ctx.reference, solution=replace(ctx.reference.solution))
    with pytest.raises(SettingsError, match="another solution"):
        estimate_q1(ctx.prepared, est, ctx.recipe.reference_q2, warm_start=other, predictor=ctx.predictor)


def test_bordered_banded_solve_matches_a_dense_solve():
    """The predictor's KKT solver against NumPy's dense solve: a symmetric matrix with a zero
    block (like a KKT matrix), banded but for 3 dense border rows and columns, in a shuffled
    order; and a matrix that is not banded, which it declines."""
    import scipy.sparse as sps

    from rocketid.sensitivity import _BorderedBanded
    rng = np.random.default_rng(3)
    nb, w, k = 300, 6, 3
    band = sps.diags([rng.normal(size=nb - abs(d)) for d in range(-w, w + 1)], list(range(-w, w + 1)))
    band = band + band.T + sps.diags(np.where(np.arange(nb) % 2 == 0, 0.0, 10.0))  # zero diagonal entries
    B = rng.normal(size=(nb, k))
    K = sps.bmat([[band, sps.csr_matrix(B)], [sps.csr_matrix(B.T), None]]).toarray()
    shuffle = rng.permutation(nb + k)
    Ks = sps.csc_matrix(K[shuffle][:, shuffle])
    border = np.flatnonzero(shuffle >= nb)
    solver = _BorderedBanded.factor(Ks, border)
    assert solver is not None and solver.kl <= 4 * w
    b = rng.normal(size=nb + k)
    np.testing.assert_allclose(solver.solve(b), np.linalg.solve(Ks.toarray(), b), rtol=1e-8, atol=1e-10)
    dense = sps.csc_matrix(rng.normal(size=(60, 60)))
    assert _BorderedBanded.factor(dense, np.array([0])) is None


def test_the_learnt_surface_starts_the_steps_near_the_solution(ctx):
    """Each worker's predictor learns the solution as a polynomial in the offset from 100
    offsets drawn like the draws' (a stream of its own). Started from the polynomial, the steps
    reach the same point as from the reference solution (both within IPOPT's tolerances of the
    one solution) in far fewer back-solves."""
    est, ref = ctx.recipe.estimability, ctx.reference
    surface = ctx.predictor.surface
    assert isinstance(surface, SolutionSurface)
    assert surface.basis.shape[1] == len(ctx.recipe.reference_q2)      # the offsets move in q2's space
    assert surface.degree >= 2 and surface.n_learnt >= 90
    from_reference = replace(ctx.predictor, surface=None)
    steps_surface, steps_reference = [], []
    for k in range(1, 21):
        q2 = est.q2_of(trial_parameters(ctx.recipe, SEED, k))
        nlp = ref.nlp.with_offset(est.transform(q2).c)
        a, b = ctx.predictor.predict(nlp), from_reference.predict(nlp)
        assert a.converged and b.converged and not b.from_surface
        if a.from_surface:
            steps_surface.append(a.steps)
            steps_reference.append(b.steps)
        D = est.D
        pa, pb = nlp.layout.parameters(a.x), nlp.layout.parameters(b.x)
        np.testing.assert_allclose(pa / D, pb / D, rtol=0, atol=1e-8)
    assert len(steps_surface) >= 15                                  # most draws are inside the learnt range
    assert np.mean(steps_surface) <= 0.5 * np.mean(steps_reference)  # RA-66: about 2 against 6


def test_the_surface_declines_offsets_it_has_not_learnt(ctx):
    """Outside the learnt offsets' span or range the polynomial is not used (an extrapolated
    polynomial is a poor start): the steps start from the reference solution."""
    surface = ctx.predictor.surface
    inside = learning_offsets(ctx.recipe, 3)[0]
    assert surface.start(inside) is not None
    across = surface.c_ref + surface.basis[:, 0] * 3.0 * (surface.hi[0] - surface.lo[0] + 1.0)
    assert surface.start(across) is None
    off_span = surface.c_ref.copy()
    # a direction orthogonal to the learnt span (the offsets of (7.9) never move there)
    free = np.linalg.svd(surface.basis.T)[2][-1]
    assert surface.start(off_span + 0.1 * free) is None
    nlp = ctx.reference.nlp.with_offset(across)
    got = ctx.predictor.predict(nlp, max_steps=1)
    assert got is None or not got.from_surface


def test_learning_offsets_are_reproducible_and_not_a_runs_draws(ctx):
    a, b = learning_offsets(ctx.recipe, 5), learning_offsets(ctx.recipe, 5)
    np.testing.assert_array_equal(a, b)
    est = ctx.recipe.estimability
    run = np.array([est.transform(est.q2_of(trial_parameters(ctx.recipe, s, 1))).c for s in range(5)])
    assert not np.any(np.all(np.isclose(a[:, None, :], run[None, :, :]), axis=2))
