"""The sampling coordinator as a state machine, driven without an executor (unit tier).

Outcomes are made up: the tests fix what eta each draw gives and in which order the
batches come back, and check the hand-out rule, the in-order stopping rule, waste and
cancellation against the algorithm worked out by hand.
"""

from __future__ import annotations

import math

from rocketid.sampling.checkpoint import RunState
from rocketid.sampling.scheduler import Batch, Scheduler
from rocketid.sampling.worker import DrawOutcome


def _outcomes(batch: Batch, etas: dict[int, float]) -> list[DrawOutcome]:
    out = []
    for k in range(batch.k0, batch.k1):
        eta = etas[k]
        ok = math.isfinite(eta)
        out.append(DrawOutcome(batch.seed, k, ok, 0 if ok else -1, "ok" if ok else "failed", eta, (0.0,) * 4, 1.0, 3,
                               (0.5,), (0.1,), (0.2,), 0.01))
    return out


def test_serial_run_stops_n_iter_draws_after_the_last_improvement():
    # n_iter = 3: draw 2 improves last, so draws 3, 4, 5 without improvement stop the run at 5
    etas = {1: 5.0, 2: 4.0, 3: 6.0, 4: math.nan, 5: 8.0, 6: 0.1}
    sched = Scheduler([RunState(7)], n_iter=3, max_draws=None, batch_size=2)
    handed = []
    while not sched.done:
        batches = sched.hand_out()
        assert len(batches) == 1  # serial: one batch in flight
        handed += batches
        sched.receive(batches[0], _outcomes(batches[0], etas))
    # certain work only: draws 1-3 are needed whatever they give, then 3-5 after the improvement at 2
    assert handed == [Batch(7, 1, 3), Batch(7, 3, 5), Batch(7, 5, 6)]
    st = sched.states[7]
    assert st.stopped_by == "n_iter" and st.draws == 5 and st.improvements == [1, 2] and st.best.draw == 2
    assert st.failures == [(4, -1, "failed")]  # a failed draw counts as no improvement
    assert sched.n_evaluated == 5 and sched.n_wasted == 0 and sched.n_cancelled == 0


def test_speculative_draws_past_the_stop_are_waste_and_in_flight_ones_are_offered_for_cancelling():
    sched = Scheduler([RunState(1)], n_iter=2, max_draws=None, batch_size=4, max_inflight=4, speculative=True)
    first = sched.hand_out()
    # certain draws 1-2, then speculative single draws until a batch's worth is in flight
    assert first == [Batch(1, 1, 3), Batch(1, 3, 4), Batch(1, 4, 5)]
    etas = {1: 5.0, 2: 6.0, 3: 7.0, 4: 1.0}
    got = sched.receive(Batch(1, 4, 5), _outcomes(Batch(1, 4, 5), etas))  # out of order: it waits
    assert got.processed == 0 and not got.stopped
    got = sched.receive(Batch(1, 1, 3), _outcomes(Batch(1, 1, 3), etas))
    assert got.processed == 2 and not got.stopped
    got = sched.receive(Batch(1, 3, 4), _outcomes(Batch(1, 3, 4), etas))
    # draw 3 is the second draw in a row without improvement: stop; draw 4 (eta 1, better!) is past
    # the stop and must not count, exactly as in a serial loop
    assert got.stopped and got.processed == 1 and got.to_cancel == ()
    st = sched.states[1]
    assert st.draws == 3 and st.best.eta == 5.0 and sched.n_wasted == 1 and sched.done


def test_a_stopped_run_offers_its_batches_in_flight_and_counts_the_cancelled_ones():
    sched = Scheduler([RunState(1)], n_iter=2, max_draws=None, batch_size=4, max_inflight=4, speculative=True)
    sched.hand_out()
    etas = {1: 5.0, 2: 6.0, 3: 7.0}
    sched.receive(Batch(1, 1, 3), _outcomes(Batch(1, 1, 3), etas))
    got = sched.receive(Batch(1, 3, 4), _outcomes(Batch(1, 3, 4), etas))
    assert got.stopped and got.to_cancel == (Batch(1, 4, 5),)
    assert not sched.done  # still in flight
    sched.cancelled(Batch(1, 4, 5))
    assert sched.n_cancelled == 1 and sched.done and sched.hand_out() == []
    # a batch that could not be cancelled comes back as waste
    sched2 = Scheduler([RunState(1)], n_iter=2, max_draws=None, batch_size=4, max_inflight=4, speculative=True)
    sched2.hand_out()
    sched2.receive(Batch(1, 1, 3), _outcomes(Batch(1, 1, 3), etas))
    sched2.receive(Batch(1, 3, 4), _outcomes(Batch(1, 3, 4), etas))
    late = sched2.receive(Batch(1, 4, 5), _outcomes(Batch(1, 4, 5), {4: 0.5}))
    assert late.wasted and late.processed == 0 and sched2.n_wasted == 1 and sched2.done


def test_certain_work_goes_first_to_the_run_with_least_in_flight_then_by_seed_order():
    sched = Scheduler([RunState(3), RunState(1)], n_iter=4, max_draws=None, batch_size=2, max_inflight=3,
                      speculative=True)
    assert sched.hand_out() == [Batch(3, 1, 3), Batch(1, 1, 3), Batch(3, 3, 5)]


def test_the_cap_stops_a_run_and_a_resumed_state_continues_where_it_stopped():
    st = RunState(5)
    sched = Scheduler([st], n_iter=10, max_draws=3, batch_size=2)
    while not sched.done:
        for b in sched.hand_out():
            sched.receive(b, _outcomes(b, {k: 10.0 - k for k in range(1, 20)}))
    assert st.stopped_by == "max_draws" and st.draws == 3 and sched.n_evaluated == 3
    resumed = RunState(6, draws=4, since=1)
    assert Scheduler([resumed], n_iter=3, max_draws=None, batch_size=5).hand_out() == [Batch(6, 5, 7)]
