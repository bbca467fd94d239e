"""Asynchronous stepping helpers: calls in flight, env-id checks, errors.

:class:`~chronogym.vector.driver.WorkerVectorEnv` uses these for ``send`` /
``recv`` (EnvPool-style partial batches) and ``step_async`` / ``step_wait``
(Gymnasium ``AsyncVectorEnv`` style). A call is always a whole worker's call:
one remote call steps every env that worker holds.
"""

from __future__ import annotations

import multiprocessing
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium.error import AlreadyPendingCallError

from chronogym.errors import ChronogymError


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
