"""The simulator's failures are results, not exceptions: a trajectory that cannot be integrated says why."""

from __future__ import annotations

import numpy as np

import rocketid as ri
def test_equations_that_cannot_be_evaluated_end_the_simulation_as_a_failure():
    """A right-hand side evaluated where it is not defined (here 1/t at t0 = 0; in a diagnosis, a
    hybrid rocket's start simulation with a refit's mass) is a failed trajectory with the reason, not
    an exception out of the integrator: the fit then starts from the data."""
    m = ri.Model("singular", t0=0.0, tf=2.0)
    y = m.state("y", initial=1.0)
    m.ode({y: 1 / m.t})
    m.output("y", y, sigma=1.0)
    traj = ri.simulate(m.freeze(), None, np.linspace(0.0, 2.0, 11))
    assert not traj.success
    assert "could not be evaluated (ZeroDivisionError" in traj.message and "[0, 2]" in traj.message


def test_an_expression_along_a_trajectory_is_compiled_once_for_a_model_with_more_parameters():
    """``evaluate_along`` compiles an expression with only the symbols it holds as arguments: the same Mach
    number on RA-66M and on RA-66M with a thrust error added (one parameter more, unused by it) is one
    compiled function -- a diagnosis's refits check every extended model's Mach range without printing it
    again -- and evaluates to the same values."""
    from rocketid.cases import ra66m, ra66m_truth
    from rocketid.diagnostics import with_effects
    from rocketid.simulate import _ALONG_CACHE, evaluate_along

    base = ra66m()
    more = with_effects(base, "thrust_level")
    mach = base.symbol("mach")
    expr = next(e for d, e in base.definitions if d == mach)
    traj = ri.simulate(base, ra66m_truth(base), np.linspace(0.0, 60.0, 31))
    _ALONG_CACHE.clear()
    a = evaluate_along(base, expr, traj.times, traj.states, traj.p)
    p_more = more.parameter_vector({str(k): v for k, v in base.parameter_dict(traj.p).items()})
    b = evaluate_along(more, expr, traj.times, traj.states, p_more)
    assert len(_ALONG_CACHE) == 1
    np.testing.assert_array_equal(a, b)
    assert 0.1 < a[-1] < 10
