"""The coordinator of steps 5-10 as a small state machine, without an executor.

:class:`Scheduler` decides which batches of draws to hand out (:meth:`Scheduler.hand_out`)
and what to do with the outcomes that come back (:meth:`Scheduler.receive`); whoever drives
it submits the batches to an executor, or, in a unit test, makes the outcomes up. It owns
the runs' :class:`~rocketid.sampling.checkpoint.RunState` values while they change.

States of a run: *active* (draws are handed out and processed in draw order) and
*stopped* (by the n_iter rule or the cap; outcomes that still arrive are waste, batches
still in flight are offered for cancellation).

Hand-out rule (exact for every executor): *certain* work first -- with ``since`` draws
already without improvement a run needs at least its next ``n_iter - since`` draws,
whatever they give; the run with the fewest draws in flight goes first, ties by seed
order. Only a speculative executor then evaluates draws past that point, in small batches
and at most about one batch ahead per run, so the waste stays bounded.
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Iterable, Sequence

from .checkpoint import RunState
from .worker import DrawOutcome

__all__ = ["Batch", "Received", "Scheduler"]


@dataclass(frozen=True)
class Batch:
    """Draws ``k0 .. k1 - 1`` of the run with seed ``seed``."""

    seed: int
    k0: int
    k1: int

    @property
    def size(self) -> int:
        return self.k1 - self.k0


@dataclass(frozen=True)
class Received:
    """What one returned batch did.

    Attributes
    ----------
    seed : int
    processed : int
        Draws processed in order because of it (0: they wait for earlier draws, or waste).
    wasted : bool
        The run had stopped: the outcomes were discarded.
    stopped : bool
        The run stopped on these outcomes.
    to_cancel : tuple of Batch
        The stopped run's batches still in flight: cancel them if the executor can, and
        report each cancelled one with :meth:`Scheduler.cancelled`.
    """

    seed: int
    processed: int
    wasted: bool
    stopped: bool
    to_cancel: tuple = ()


class Scheduler:
    """Which draws to evaluate next, and the in-order processing of their outcomes.

    Parameters
    ----------
    states : sequence of RunState
        One per run, in seed order (fresh or from checkpoints).
    n_iter : int
        Draws in a row without improvement that stop a run.
    max_draws : int or None
        A cap on a run's draws.
    batch_size : int
        Draws per batch.
    max_inflight : int
        Batches in flight at once (1 for a serial executor).
    speculative : bool
        Hand out draws past the certain ones when nothing certain is left (parallel executors).
    """

    def __init__(self, states: Sequence[RunState], *, n_iter: int, max_draws: int | None, batch_size: int,
                 max_inflight: int = 1, speculative: bool = False):
        self.states = {st.seed: st for st in states}
        self.order = {st.seed: i for i, st in enumerate(states)}
        self.n_iter, self.max_draws, self.batch_size = n_iter, max_draws, batch_size
        self.max_inflight, self.speculative = max_inflight, speculative
        self.spec_batch = max(1, min(batch_size, n_iter // 2))
        self.active = [st.seed for st in states if st.stopped_by is None]
        self.pending: dict[int, dict[int, DrawOutcome]] = {s: {} for s in self.states}
        self.next_submit = {s: st.next_draw for s, st in self.states.items()}
        self.inflight: list[Batch] = []
        self.inflight_draws = {s: 0 for s in self.states}
        self.n_evaluated = self.n_wasted = self.n_cancelled = 0

    # ---- state
    @property
    def done(self) -> bool:
        """Nothing is in flight and nothing is left to hand out."""
        return not self.inflight and not self._pick()

    def sort_key(self, batch: Batch) -> tuple[int, int]:
        """Returned batches are received in seed order, then draw order."""
        return self.order[batch.seed], batch.k0

    # ---- hand out
    def _pick(self) -> Batch | None:
        certain = [s for s in self.active if self.next_submit[s] < self._certain_end(s)]
        if certain:
            s = min(certain, key=self._load)
            end = self._certain_end(s)
        elif self.speculative:
            ok = [s for s in self.active if (self.max_draws is None or self.next_submit[s] <= self.max_draws)
                  and self.inflight_draws[s] < self.batch_size]
            if not ok:
                return None
            s = min(ok, key=self._load)
            end = self.next_submit[s] + self.spec_batch
            if self.max_draws is not None:
                end = min(end, self.max_draws + 1)
        else:
            return None
        k0 = self.next_submit[s]
        return Batch(s, k0, min(k0 + self.batch_size, end))

    def _certain_end(self, s: int) -> int:
        return self.states[s].certain_end(self.n_iter, self.max_draws)

    def _load(self, s: int) -> tuple[int, int]:
        return self.inflight_draws[s], self.order[s]

    def hand_out(self) -> list[Batch]:
        """The batches to submit now (they count as in flight from here on)."""
        out = []
        while len(self.inflight) < self.max_inflight:
            b = self._pick()
            if b is None:
                break
            self.inflight.append(b)
            self.inflight_draws[b.seed] += b.size
            self.next_submit[b.seed] = b.k1
            out.append(b)
        return out

    # ---- receive
    def receive(self, batch: Batch, outcomes: Iterable[DrawOutcome]) -> Received:
        """Take a returned batch: keep its outcomes until their turn and process every draw
        whose predecessors are in (steps 7-10), stopping the run when the rule says so."""
        self._leave(batch)
        outcomes = tuple(outcomes)
        self.n_evaluated += len(outcomes)
        s = batch.seed
        if s not in self.active:
            self.n_wasted += len(outcomes)
            return Received(s, 0, True, False)
        st = self.states[s]
        for o in outcomes:
            self.pending[s][o.draw] = o
        before = st.draws
        while st.stopped_by is None and st.next_draw in self.pending[s]:
            st.process(self.pending[s].pop(st.next_draw), self.n_iter, self.max_draws)
        to_cancel = self._stop(s) if st.stopped_by is not None else ()
        return Received(s, st.draws - before, False, st.stopped_by is not None, to_cancel)

    def _stop(self, s: int) -> tuple:
        self.active.remove(s)
        self.n_wasted += len(self.pending[s])
        self.pending[s].clear()
        return tuple(b for b in self.inflight if b.seed == s)

    def cancelled(self, batch: Batch) -> None:
        """``batch`` (offered by :meth:`receive`) was cancelled by the executor."""
        self._leave(batch)
        self.n_cancelled += batch.size

    def _leave(self, batch: Batch) -> None:
        self.inflight.remove(batch)
        self.inflight_draws[batch.seed] -= batch.size
