"""Asynchronous stepping: ``send`` / ``recv`` (EnvPool-style partial batches),
``step_async`` / ``step_wait`` (Gymnasium ``AsyncVectorEnv`` style) and ``async_reset``.

A call is always a whole worker's call: one remote call steps every env that
worker holds. Calls in flight are :class:`PendingCall`s; a worker that dies or
stays silent past ``step_timeout`` is replaced as in the barrier ``step``.
"""

from __future__ import annotations

import multiprocessing
import time
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium.error import AlreadyPendingCallError, NoAsyncCallError

from chronogym.errors import ChronogymError
from chronogym.vector.checks import check_min_envs
from chronogym.vector.wire import Backend, Outcome, StepPart


class EnvsInFlightError(ChronogymError, AlreadyPendingCallError, ValueError):
    """Envs were sent (``send`` / ``step_async`` / ``async_reset``) and not yet received.

    Raised by a second ``send`` to an env in flight, and by ``step``, ``reset``,
    ``call``, ``get_attr``, ``set_attr`` and ``render`` while any env is in
    flight. A Gymnasium ``AlreadyPendingCallError`` and a ``ValueError``.
    """

    def __init__(self, message: str, name: str = "step") -> None:
        AlreadyPendingCallError.__init__(self, message, name)


class RecvTimeoutError(ChronogymError, TimeoutError, multiprocessing.TimeoutError):
    """``recv`` / ``step_wait`` ran out of time; the envs stay in flight (call it again).

    Both the builtin ``TimeoutError`` and ``multiprocessing.TimeoutError`` (what
    Gymnasium's ``AsyncVectorEnv.step_wait`` raises).
    """


@dataclass
class PendingCall:
    """One worker's call in flight."""

    kind: str  # "step" or "reset"
    handle: Any  # what Backend.submit returned
    submitted: float  # time.monotonic() at submission
    args: tuple[Any, ...]  # kept to redo a reset on a replacement worker


def check_env_ids(env_ids: Any, num_envs: int) -> np.ndarray:
    """``env_ids`` as a 1-D int64 array of distinct ids in ``0..num_envs-1``."""
    if env_ids is None:
        return np.arange(num_envs, dtype=np.int64)
    array = np.asarray(env_ids)
    if array.ndim == 0:
        array = array.reshape(1)
    if array.ndim != 1 or array.size == 0 or array.dtype.kind not in "iu":
        raise ValueError(
            f"env_ids={_show(env_ids)}: expected a non-empty list or 1-D array of integer env "
            f"ids in 0..{num_envs - 1}"
        )
    bad = sorted({int(i) for i in array if not 0 <= i < num_envs})
    if bad:
        raise ValueError(
            f"env_ids={_show(env_ids)}: ids {bad} are out of range; expected integers in "
            f"0..{num_envs - 1} (num_envs={num_envs})"
        )
    values, counts = np.unique(array, return_counts=True)
    if (counts > 1).any():
        raise ValueError(
            f"env_ids={_show(env_ids)}: ids {values[counts > 1].tolist()} appear more than "
            "once; expected each env at most once"
        )
    return array.astype(np.int64, copy=False)


def workers_of(
    env_ids: np.ndarray, slices: Sequence[tuple[int, int]], envs_per_worker: int
) -> list[int]:
    """The workers holding ``env_ids`` (ascending); the ids must cover each of them whole."""
    chosen = set(env_ids.tolist())
    workers = sorted({i // envs_per_worker for i in chosen})
    for w in workers:
        lo, hi = slices[w]
        missing = [i for i in range(lo, hi) if i not in chosen]
        if missing:
            raise ValueError(
                f"env_ids={_show(env_ids)}: worker {w} holds envs {list(range(lo, hi))} but "
                f"envs {missing} are missing; send() steps whole workers "
                f"(envs_per_worker={envs_per_worker}), so expected every env of each worker "
                "it touches"
            )
    return workers


def _show(env_ids: Any) -> str:
    """A short rendering of user-given env ids for error messages."""
    if isinstance(env_ids, np.ndarray):
        env_ids = env_ids.tolist()
    text = repr(env_ids)
    return text if len(text) <= 80 else text[:77] + "..."


class AsyncStepping:
    """``send`` / ``recv``, ``step_async`` / ``step_wait`` and ``async_reset`` of
    :class:`~chronogym.vector.driver.WorkerVectorEnv` (a mixin: it uses the driver's
    workers, its checks and its joining of results)."""

    num_envs: int
    num_workers: int
    envs_per_worker: int
    _pending: dict[int, PendingCall]
    _slices: list[tuple[int, int]]
    _backend: Backend
    _last_parts: list[Any]

    @property
    def envs_in_flight(self) -> np.ndarray:
        """Ids of the envs sent and not yet received (ascending)."""
        ids = [np.arange(*self._slices[w], dtype=np.int64) for w in sorted(self._pending)]
        return np.concatenate(ids) if ids else np.zeros(0, dtype=np.int64)

    def send(self, actions: Any, env_ids: Any = None) -> None:
        """Start stepping the envs ``env_ids`` (default: all) with ``actions`` (one row each).

        ``actions`` rows follow ``env_ids`` order. Calls are per worker, so
        ``env_ids`` must hold every env of each worker it touches, and none of
        them may be in flight already. Results come back through :meth:`recv`.
        """
        self._check_open()
        ids = check_env_ids(env_ids, self.num_envs)
        workers = workers_of(ids, self._slices, self.envs_per_worker)
        busy = [w for w in workers if w in self._pending]
        if busy:
            envs = [i for w in busy for i in range(*self._slices[w])]
            raise EnvsInFlightError(
                f"env_ids={ids.tolist()}: envs {envs} are already in flight (sent, not yet "
                "received); expected envs not in flight; call recv() first"
            )
        unreset = [
            i for w in workers if self._last_parts[w] is None for i in range(*self._slices[w])
        ]
        if unreset:
            raise RuntimeError(f"send() to envs {unreset} before their first reset(); reset first")
        order = np.argsort(ids, kind="stable")
        self._submit("step", workers, self._step_args(workers, actions, order))

    def step_async(self, actions: Any) -> None:
        """Start stepping every env (Gymnasium ``AsyncVectorEnv`` semantics); see step_wait."""
        self._check_open()
        self._check_idle("step_async")
        self.send(actions)

    def step_wait(
        self, timeout: float | None = None
    ) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Wait for the step started by :meth:`step_async`; the same numbers as ``step``."""
        self._check_open()
        calls = self._pending.values()
        if len(self._pending) != self.num_workers or any(c.kind != "step" for c in calls):
            raise NoAsyncCallError(
                "step_wait() expects a step of every env in flight (from step_async()); envs "
                f"in flight: {self.envs_in_flight.tolist()}",
                "step",
            )
        return self.recv(min_envs=self.num_envs, timeout=timeout)[:5]

    def async_reset(
        self,
        *,
        seed: int | list[int | None] | None = None,
        options: dict[str, Any] | None = None,
    ) -> None:
        """Start resetting every env (seeds as in ``reset``); results come through recv()."""
        self._check_open()
        self._check_idle("async_reset")
        if options is not None and "reset_mask" in options:
            raise ValueError(
                "async_reset() resets every env; options['reset_mask'] is for reset(); "
                "expected options without 'reset_mask'"
            )
        seeds, options, _ = self._prepare_reset(seed, options)
        workers = list(range(self.num_workers))
        self._submit("reset", workers, [self._reset_args(w, seeds, options, None) for w in workers])

    def recv(
        self, min_envs: int | None = None, timeout: float | None = None
    ) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any], np.ndarray]:
        """Results of at least ``min_envs`` envs in flight (default: all of them).

        Returns as soon as the workers that answered hold ``min_envs`` envs,
        with every env whose worker has answered by then:
        ``(obs, rewards, terminations, truncations, infos, env_ids)``, rows in
        ascending ``env_ids`` order, infos batched over those rows. A reset
        comes back with reward 0 and both flags False.
        """
        self._check_open()
        if not self._pending:
            raise NoAsyncCallError(
                "recv() called with no envs in flight; call send(), step_async() or "
                "async_reset() first",
                "step",
            )
        need = check_min_envs(min_envs, len(self.envs_in_flight))
        outcomes = self._await(need, timeout)
        workers = sorted(outcomes)
        calls = {w: self._pending.pop(w) for w in workers}
        results = [self._pending_result(w, calls[w], outcomes[w]) for w in workers]
        env_ids = np.concatenate([np.arange(*self._slices[w], dtype=np.int64) for w in workers])
        return (*self._join_results(workers, results), env_ids)

    def _submit(self, kind: str, workers: list[int], args: list[tuple[Any, ...]]) -> None:
        method = self._step_method if kind == "step" else kind
        for w, a in zip(workers, args, strict=True):
            handle = self._backend.submit(w, method, *a)
            self._pending[w] = PendingCall(kind, handle, time.monotonic(), a)

    def _await(self, need: int, timeout: float | None) -> dict[int, Outcome]:
        """Wait until answered workers hold ``need`` envs; their outcomes (hung ones: lost)."""
        deadline = None if timeout is None else time.monotonic() + timeout
        ready = set(self._ready(sorted(self._pending), 0.0))
        overdue: set[int] = set()
        while self._count_envs(ready | overdue) < need:
            waiting = [w for w in sorted(self._pending) if w not in ready | overdue]
            ready |= set(self._ready(waiting, self._wait_budget(waiting, deadline), first=True))
            overdue |= set(self._overdue(waiting)) - ready
            if self._count_envs(ready | overdue) < need and _passed(deadline):
                raise RecvTimeoutError(
                    f"recv(min_envs={need}) timed out after {timeout} s with "
                    f"{self._count_envs(ready | overdue)} envs answered; the envs stay in "
                    "flight, call recv() again"
                )
        rest = [w for w in sorted(self._pending) if w not in ready | overdue]
        ready |= set(self._ready(rest, 0.0))
        answered = sorted(ready)
        gathered = self._backend.gather(answered, self._handles(answered))
        outcomes = dict(zip(answered, gathered, strict=True))
        message = f"no answer within step_timeout={self._step_timeout} s"
        outcomes.update({w: Outcome(False, None, message, lost=True) for w in overdue})
        return outcomes

    def _ready(self, workers: list[int], timeout: float | None, first: bool = False) -> list:
        """Which of ``workers`` have answered (wait up to ``timeout``; for one, if ``first``)."""
        if not workers:
            return []
        handles = self._handles(workers)
        done = self._backend.wait(handles, 1 if first else len(handles), timeout)
        return [workers[k] for k in done]

    def _handles(self, workers: Any) -> list[Any]:
        return [self._pending[w].handle for w in workers]

    def _count_envs(self, workers: set[int]) -> int:
        return sum(self._slices[w][1] - self._slices[w][0] for w in workers)

    @property
    def _step_timeout(self) -> float | None:
        return getattr(self._backend, "step_timeout", None)

    def _wait_budget(self, waiting: list[int], deadline: float | None) -> float | None:
        """Seconds to wait: up to the caller's deadline or the first call's step_timeout."""
        ends = [] if deadline is None else [deadline]
        if self._step_timeout is not None:
            ends += [self._pending[w].submitted + self._step_timeout for w in waiting]
        return max(0.0, min(ends) - time.monotonic()) if ends else None

    def _overdue(self, workers: list[int]) -> list[int]:
        if self._step_timeout is None:
            return []
        now = time.monotonic()
        return [w for w in workers if now - self._pending[w].submitted >= self._step_timeout]

    def _pending_result(self, w: int, call: PendingCall, outcome: Outcome) -> StepPart:
        """A step's or a reset's part; a failed reset is redone on a replacement worker."""
        if call.kind == "step":
            return self._step_result(w, outcome)
        while not outcome.ok:
            self._replace_worker(w, outcome.error)
            (outcome,) = self._call_all([w], "reset", [call.args])
        infos = self._take_reset(w, outcome.value)
        count = len(infos)
        zeros = np.zeros(count, dtype=np.bool_)
        return StepPart(self._last_parts[w], np.zeros(count), zeros, zeros.copy(), infos)


def _passed(deadline: float | None) -> bool:
    return deadline is not None and time.monotonic() >= deadline
