"""The bottom layer of the vector envs: what crosses between driver and workers.

Both sides import this module and, below it, only :mod:`chronogym.vector.infos` (how
infos travel) and :mod:`chronogym.errors`: the outcome of a worker
call, what a worker reports besides its results (restarts, a failed step), the
``Backend`` interface the driver talks to, and the byte format of a packed
step (Box spaces) as the socket transport sends it.

Packed step (``EnvGroup.step_packed``): the request is the action bytes; the
answer is ``(obs, rewards, terminations, truncations)`` as bytes, then the
infos (:func:`~chronogym.vector.infos.to_columns`: None when all are empty, else
columns or per-env dicts), the restarts (None when none) and, when the
driver asked for timings, ``(serde_s, compute_s)``. On a socket, an answer is
``<B 5I`` (status, then the lengths of obs, rewards, terminations, truncations
and tail) + those parts; the tail is the pickled extras when any is set, or a
pickled :class:`StepFailure` (status 1). A request is ``<I B`` (action byte
count, timed flag) + the action bytes.
"""

from __future__ import annotations

import pickle
import socket
import struct
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import gymnasium as gym
import numpy as np

from chronogym.errors import DisabledAutoresetError
from chronogym.vector.infos import InfoColumns

EnvFactory = Callable[[], gym.Env]

REQUEST = struct.Struct("<IB")  # action byte count, timed flag
ANSWER = struct.Struct("<BIIIII")  # status (0 ok, 1 failure), then 5 part lengths
OK, FAILED = 0, 1


@dataclass
class Outcome:
    """What one worker call gave back: a value, or the error that replaced it."""

    ok: bool
    value: Any = None
    error: str = ""
    lost: bool = False  # the worker process is gone or stopped answering


@dataclass
class StepPart:
    """One worker's share of a step (or of an asynchronous reset)."""

    obs: Any
    rewards: np.ndarray
    terminations: np.ndarray
    truncations: np.ndarray
    infos: InfoColumns | list[dict[str, Any]] | None  # None: every env's info is empty


@dataclass
class StepFailure:
    """A step that raised inside a worker, returned as a value (socket transport)."""

    error: Exception
    text: str


@dataclass
class Restart:
    """An env rebuilt inside its worker after its step or reset raised."""

    env_index: int
    error: str


class Backend(Protocol):
    """Where the workers (``EnvGroup``s) live: in this process, or in Ray actors.

    ``submit`` starts one call and returns a handle; ``wait`` tells which
    handles have answered; ``gather`` turns handles into :class:`Outcome`s
    (waiting for them). A failed call is an Outcome, never an exception.
    """

    step_timeout: float | None

    def start(self, group_kwargs: list[dict[str, Any]]) -> None: ...
    def replace(self, worker: int, kwargs: dict[str, Any]) -> None: ...
    def submit(self, worker: int, method: str, *args: Any) -> Any: ...
    def gather(self, workers: list[int], handles: list[Any]) -> list[Outcome]: ...
    def wait(self, handles: list[Any], num_returns: int, timeout: float | None) -> list[int]: ...
    def pid(self, worker: int) -> int: ...
    def shutdown(self) -> None: ...


def error_outcome(error: BaseException, text: str) -> Outcome:
    """A call that raised ``error`` (traceback ``text``); a DisabledAutoresetError keeps
    only its message, as it is re-raised to the caller."""
    if isinstance(error, DisabledAutoresetError):
        return Outcome(False, error, str(error))
    return Outcome(False, error, text)


def encode_answer(answer: tuple[Any, ...] | StepFailure) -> bytes:
    """One answer of ``step_packed`` (or a StepFailure) as the bytes of an answer message."""
    if isinstance(answer, StepFailure):
        try:
            tail = pickle.dumps(answer)
        except Exception:  # an exception that cannot be pickled travels as its text
            tail = pickle.dumps(StepFailure(RuntimeError(answer.text), answer.text))
        return ANSWER.pack(FAILED, 0, 0, 0, 0, len(tail)) + tail
    extra = answer[4:]
    tail = pickle.dumps(extra) if any(x is not None for x in extra) else b""
    parts = (*answer[:4], tail)
    return ANSWER.pack(OK, *(len(p) for p in parts)) + b"".join(parts)


def decode_answer(status: int, sizes: list[int], view: memoryview) -> Outcome:
    """An answer message as the Outcome an actor call gives for the same answer."""
    parts, at = [], ANSWER.size
    for size in sizes:
        parts.append(view[at : at + size])
        at += size
    if status == FAILED:
        failure = pickle.loads(parts[4])  # trusted: own worker (a private socket)
        return error_outcome(failure.error, failure.text)
    extra = pickle.loads(parts[4]) if sizes[4] else (None, None)  # trusted: own worker
    return Outcome(True, (*(bytes(p) for p in parts[:4]), *extra))


def fill(sock: socket.socket, view: memoryview, got: int, need: int) -> int:
    """Read into ``view`` from ``got`` until at least ``need`` bytes are in; the count.
    EOFError when the peer closes first (both ends use it)."""
    while got < need:
        n = sock.recv_into(view[got:])
        if n == 0:
            raise EOFError(f"the peer closed its socket after {got} of {need} bytes")
        got += n
    return got
