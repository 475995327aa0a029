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
