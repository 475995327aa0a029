"""Time guards (issue 8, item 8): every refit and hold-out prediction gives up after its time limit
and says so, instead of crawling on (a diagnosis once ran 21 minutes in one prediction)."""

from __future__ import annotations

import numpy as np
import pytest

import rocketid as ri
from rocketid.cases import ra66m, ra66m_truth
from rocketid.diagnostics import CATALOGUE, with_effects
from rocketid.diagnostics.refit import RefitTask, refit_all, run_refit
from rocketid.errors import SettingsError


def test_a_simulation_gives_up_after_its_wall_time():
    spec = ra66m()
    traj = ri.simulate(spec, None, np.linspace(0, 66, 50), rtol=1e-13, atol=1e-13, max_wall_time=1e-4)
    assert not traj.success and "gave up after 0.0001 s of wall time" in traj.message
    assert np.isnan(traj.states[-1]).all()
    with pytest.raises(SettingsError, match="max_wall_time"):
        ri.simulate(spec, None, [0.0, 1.0], max_wall_time=0)


def _thrust_refit(timeout: float) -> RefitTask:
    """RA-66M data with a +2 % thrust error, and the refit that adds thrust_level, under ``timeout``."""
    base = ra66m()
    truth = with_effects(base, "thrust_level", {"eps_thrust": 0.02})
    data = ri.simulate_measurements(truth, ra66m_truth(truth), ri.ra66_times(), seed=0)
    mesh = ri.default_mesh(base, refine_first=3)
    return RefitTask(base_spec=base, data=data, mesh=mesh, effects=(CATALOGUE["thrust_level"],),
                     added=("thrust_level",), start={}, sizes={"eps_thrust": 0.02}, base_objective=1e6,
                     base_n_estimated=8, base_parameters=base.parameter_names, options={}, timeout=timeout)


def test_a_refit_that_exceeds_its_limit_is_reported_as_given_up():
    task = _thrust_refit(timeout=1e-3)
    refit, _ = run_refit(task)
    assert not refit.success and refit.gave_up, refit.message
    # in a worker process too (two tasks: the forked workers run them)
    both = refit_all([task, task], workers=2)
    assert all(r.gave_up and not r.success for r in both)


def test_a_refits_time_limit_holds_for_all_its_solves(monkeypatch):
    """The limit is the refit's, not each solve's: once the first solve has used it up, the solve from the
    model's own guesses is not started (it used to get a full limit of its own, and a located shape's held
    first solve a third)."""
    from rocketid.diagnostics import refit as R
    task = _thrust_refit(timeout=1e-3)
    limits = []
    real = R.estimate

    def counted(*args, **kw):
        limits.append(kw["options"]["max_wall_time"])
        return real(*args, **kw)

    monkeypatch.setattr(R, "estimate", counted)
    refit, _ = run_refit(task)
    assert refit.gave_up and len(limits) == 1 and limits[0] <= 1e-3


def test_a_located_shapes_solve_from_the_guesses_keeps_its_scans_start():
    """The solve from the model's own guesses (after a warm solve that ends above the noise) resets the
    base coefficients to their guesses, but a located shape keeps where its scan put it: at its own guesses
    (no size, its time at the start of the flight) the objective has no gradient in its time, and IPOPT
    crawled there under heavy regularization for the refit's whole limit (Osprey-A's throttle window).
    An effect that is not located starts from its guesses, as before."""
    from rocketid.diagnostics.effects import throttle_step_effect
    from rocketid.diagnostics.refit import _guesses_start, refit_spec
    base = ra66m()
    step = throttle_step_effect(base.t0, base.tf, 1.0)
    fitted = {n: 1.1 * base.parameter(n).guess + 0.01 for n in base.parameter_names}   # a distorted base fit
    task = RefitTask(base_spec=base, data=None, mesh=None, effects=(step,), added=("throttle_step",),
                     start={**fitted, "t_step": 20.0, "d_step": 0.03}, sizes={"d_step": 0.05},
                     base_objective=1e6, base_n_estimated=8, base_parameters=base.parameter_names, options={},
                     timeout=60.0)
    model = refit_spec(task, {})
    cold = _guesses_start(task, model)
    assert cold.parameter("t_step").guess == 20.0 and cold.parameter("d_step").guess == 0.03
    for n in base.parameter_names:
        assert cold.parameter(n).guess == base.parameter(n).guess      # not the distorted fit's
    assert refit_spec(task).parameter("CD_M_0").guess == pytest.approx(fitted["CD_M_0"])   # the warm start's
    plain = RefitTask(base_spec=base, data=None, mesh=None, effects=(CATALOGUE["thrust_level"],),
                      added=("thrust_level",), start={**fitted, "eps_thrust": 0.02}, sizes={"eps_thrust": 0.02},
                      base_objective=1e6, base_n_estimated=8, base_parameters=base.parameter_names, options={},
                      timeout=60.0)
    m = refit_spec(plain, {})
    assert _guesses_start(plain, m) is m and m.parameter("eps_thrust").guess == 0.0
