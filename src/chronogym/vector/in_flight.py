"""Calls in flight: which workers were sent a call, and waiting until enough have answered.

:class:`InFlight` knows only the backend and which envs each worker holds; the
driver's ``send`` / ``recv`` / ``step_async`` / ``step_wait`` / ``async_reset``
(:class:`~chronogym.vector.worker_vector_env.WorkerVectorEnv`) decide what to send
and what the answers mean. A call is always a whole worker's call: one remote call steps
every env that worker holds.
"""

from __future__ import annotations

import time
from collections.abc import Sequence
from dataclasses import dataclass
from enum import Enum
from typing import Any

import numpy as np

from chronogym.errors import RecvTimeoutError
from chronogym.vector.backend import Backend, Outcome


class CallKind(Enum):
    """What a call in flight does: a step (``send``, ``step_async``), a reset
    (``async_reset``), or a trial of :mod:`chronogym.optim.parallel`."""

    STEP = "step"
    RESET = "reset"
    TRIAL = "trial"


@dataclass
class PendingCall:
    """One worker's call in flight."""

    kind: CallKind
    handle: Any  # what Backend.submit returned
    submitted: float  # time.monotonic() at submission
    args: tuple[Any, ...]  # kept to redo a reset on a replacement worker
    outcome: Outcome | None = None  # answered, but left for a later collect (``limit``)


class InFlight:
    """The calls in flight, at most one per worker, and the waiting for their answers."""

    def __init__(
        self,
        backend: Backend,
        slices: Sequence[tuple[int, int]],
        overdue_message: str | None = None,
    ) -> None:
        """``slices``: the envs ``(lo, hi)`` of each worker; ``overdue_message``: the error
        of a call lost to the backend's ``step_timeout`` (default: one naming it)."""
        self._backend = backend
        self._slices = slices
        self._overdue_message = overdue_message
        self.calls: dict[int, PendingCall] = {}  # worker -> its call in flight

    def __bool__(self) -> bool:
        return bool(self.calls)

    def __contains__(self, worker: int) -> bool:
        return worker in self.calls

    def env_ids(self) -> np.ndarray:
        """Ids of the envs in flight (ascending)."""
        ids = [np.arange(*self._slices[w], dtype=np.int64) for w in sorted(self.calls)]
        return np.concatenate(ids) if ids else np.zeros(0, dtype=np.int64)

    def kinds(self) -> set[CallKind]:
        return {call.kind for call in self.calls.values()}

    def submit(self, kind: CallKind, method: str, workers: list[int], args: list[tuple]) -> None:
        """Send each of ``workers`` its call (``args`` in the same order)."""
        for w, a in zip(workers, args, strict=True):
            handle = self._backend.submit(w, method, *a)
            self.calls[w] = PendingCall(kind, handle, time.monotonic(), a)

    def clear(self) -> None:
        self.calls.clear()

    def collect(
        self, need: int, timeout: float | None, limit: int | None = None
    ) -> dict[int, tuple[PendingCall, Outcome]]:
        """Wait until answered workers hold ``need`` envs; take their calls and outcomes.

        Every worker answered by then is taken too, up to ``limit`` envs (None: no limit):
        the earliest sent first, the rest left answered for the next collect, which takes
        them first. One silent past the backend's ``step_timeout`` counts as lost. On
        ``timeout``, RecvTimeoutError and nothing is taken.
        """
        outcomes = self._wait_outcomes(need, timeout)
        taken = sorted(outcomes, key=lambda w: (self.calls[w].submitted, w))
        if limit is not None:
            kept = self._fit(taken, limit)
            if self._count_envs(set(kept)) < need:  # a smaller last worker in the way
                kept = self._fit(sorted(taken, key=lambda w: -self._count_envs({w})), limit)
            for w in set(taken) - set(kept):
                self.calls[w].outcome = outcomes[w]  # answered: the next collect's
            taken = kept
        return {w: (self.calls.pop(w), outcomes[w]) for w in sorted(taken)}

    def _fit(self, workers: list[int], limit: int) -> list[int]:
        """``workers`` in order, each kept while the envs kept stay within ``limit``."""
        kept, count = [], 0
        for w in workers:
            size = self._count_envs({w})
            if count + size <= limit:
                kept.append(w)
                count += size
        return kept

    def _wait_outcomes(self, need: int, timeout: float | None) -> dict[int, Outcome]:
        """The outcomes of every worker answered once ``need`` envs have answered."""
        known = {w: call.outcome for w, call in self.calls.items() if call.outcome is not None}
        deadline = None if timeout is None else time.monotonic() + timeout
        ready = set(known) | set(
            self._ready([w for w in sorted(self.calls) if w not in known], 0.0)
        )
        overdue: set[int] = set()
        while self._count_envs(ready | overdue) < need:
            waiting = [w for w in sorted(self.calls) if w not in ready | overdue]
            ready |= set(self._ready(waiting, self._wait_budget(waiting, deadline), first=True))
            overdue |= set(self._overdue(waiting)) - ready
            if self._count_envs(ready | overdue) < need and _passed(deadline):
                raise RecvTimeoutError(
                    f"recv(min_envs={need}) timed out after {timeout} s with "
                    f"{self._count_envs(ready | overdue)} envs answered; the envs stay in "
                    "flight, call recv() again"
                )
        rest = [w for w in sorted(self.calls) if w not in ready | overdue]
        ready |= set(self._ready(rest, 0.0))
        answered = sorted(ready - set(known))
        gathered = self._backend.gather(answered, [self.calls[w].handle for w in answered])
        outcomes = {**known, **dict(zip(answered, gathered, strict=True))}
        message = self._overdue_message or f"no answer within step_timeout={self._step_timeout} s"
        outcomes.update({w: Outcome(False, None, message, lost=True) for w in overdue})
        return outcomes

    def _ready(self, workers: list[int], timeout: float | None, first: bool = False) -> list:
        """Which of ``workers`` have answered (wait up to ``timeout``; for one, if ``first``)."""
        if not workers:
            return []
        handles = [self.calls[w].handle for w in workers]
        done = self._backend.wait(handles, 1 if first else len(handles), timeout)
        return [workers[k] for k in done]

    def _count_envs(self, workers: set[int]) -> int:
        return sum(self._slices[w][1] - self._slices[w][0] for w in workers)

    @property
    def _step_timeout(self) -> float | None:
        return getattr(self._backend, "step_timeout", None)

    def _wait_budget(self, waiting: list[int], deadline: float | None) -> float | None:
        """Seconds to wait: up to the caller's deadline or the first call's step_timeout."""
        ends = [] if deadline is None else [deadline]
        if self._step_timeout is not None:
            ends += [self.calls[w].submitted + self._step_timeout for w in waiting]
        return max(0.0, min(ends) - time.monotonic()) if ends else None

    def _overdue(self, workers: list[int]) -> list[int]:
        if self._step_timeout is None:
            return []
        now = time.monotonic()
        return [w for w in workers if now - self.calls[w].submitted >= self._step_timeout]


def _passed(deadline: float | None) -> bool:
    return deadline is not None and time.monotonic() >= deadline
