"""The byte format of a packed step (Box spaces), as the socket transport sends it.

Packed step (``EnvGroup.step_packed``): the request is the action bytes; the
answer is a :class:`~chronogym.vector.backend.StepAnswer` whose obs, rewards,
terminations and truncations are bytes, then the infos
(:func:`~chronogym.vector.infos.to_columns`: None when all are empty, else
columns or per-env dicts), the restarts (None when none) and, when the
driver asked for timings, ``(serde_s, compute_s)``. On a socket, an answer is
``<B 5I`` (status, then the lengths of obs, rewards, terminations, truncations
and tail) + those parts; the tail is the pickled tuple ``(infos, restarts)`` (or
``(infos, restarts, timings)``) when any of them is set, or a pickled
:class:`StepFailure` (status 1). A request is ``<I B`` (action byte count, timed
flag) + the action bytes.

Call (``transport="fork"``, whose workers have no Ray actor): any other method of the
worker's group travels as a request of kind :data:`CALL` whose bytes are the pickled
``(method, args)``; the answer is ``<Q`` (length) + the pickled
:class:`~chronogym.vector.backend.Outcome` of the call, as an in-process call gives it.
"""

from __future__ import annotations

import pickle
import socket
import struct
import traceback
from dataclasses import dataclass
from typing import Any

from chronogym.vector.backend import Outcome, StepAnswer, error_outcome

REQUEST = struct.Struct("<IB")  # action byte count, timed flag
ANSWER = struct.Struct("<BIIIII")  # status (0 ok, 1 failure), then 5 part lengths
OK, FAILED = 0, 1
CALL = 3  # REQUEST's flag byte: a pickled (method, args) call (ATTACH is 2, steps 0 and 1)
CALL_ANSWER = struct.Struct("<Q")  # byte count of the pickled Outcome that follows


@dataclass
class StepFailure:
    """A step that raised inside a worker, returned as a value (socket transport)."""

    error: Exception
    text: str


def encode_answer(answer: StepAnswer | StepFailure) -> bytes:
    """One answer of ``step_packed`` (or a StepFailure) as the bytes of an answer message."""
    if isinstance(answer, StepFailure):
        try:
            tail = pickle.dumps(answer)
        except Exception:  # an exception that cannot be pickled travels as its text
            tail = pickle.dumps(StepFailure(RuntimeError(answer.text), answer.text))
        return ANSWER.pack(FAILED, 0, 0, 0, 0, len(tail)) + tail
    if answer.timings is None:
        extra: tuple = (answer.infos, answer.restarts)
    else:
        extra = (answer.infos, answer.restarts, answer.timings)
    tail = pickle.dumps(extra) if any(x is not None for x in extra) else b""
    parts = (answer.obs, answer.rewards, answer.terminations, answer.truncations, tail)
    return ANSWER.pack(OK, *(len(p) for p in parts)) + b"".join(parts)


def answer_extra(sizes: list[int], view: memoryview) -> tuple:
    """An OK answer message's ``(infos, restarts[, timings])``, its tail unpickled."""
    if not sizes[4]:
        return (None, None)
    return pickle.loads(view[ANSWER.size + sum(sizes[:4]) :])  # trusted: own worker


def decode_answer(
    status: int, sizes: list[int], view: memoryview, extra: tuple | None = None
) -> Outcome:
    """An answer message as the Outcome an actor call gives for the same answer
    (``extra``: its :func:`answer_extra`, where the caller has read it already)."""
    parts, at = [], ANSWER.size
    for size in sizes:
        parts.append(view[at : at + size])
        at += size
    if status == FAILED:
        failure = pickle.loads(parts[4])  # trusted: own worker (a private socket)
        return error_outcome(failure.error, failure.text)
    obs, rewards, terminations, truncations, _ = parts
    extra = answer_extra(sizes, view) if extra is None else extra
    answer = StepAnswer(bytes(obs), bytes(rewards), bytes(terminations), bytes(truncations), *extra)
    return Outcome(True, answer)


def fill(sock: socket.socket, view: memoryview, got: int, need: int) -> int:
    """Read into ``view`` from ``got`` until at least ``need`` bytes are in; the count.
    EOFError when the peer closes first (both ends use it)."""
    while got < need:
        n = sock.recv_into(view[got:])
        if n == 0:
            raise EOFError(f"the peer closed its socket after {got} of {need} bytes")
        got += n
    return got


def read_call_answer(sock: socket.socket) -> bytes:
    """A call's answer as :func:`answer_call` wrote it (its length, then its pickled
    Outcome), read whole from ``sock``; EOFError when the peer closes first."""
    head = bytearray(CALL_ANSWER.size)
    fill(sock, memoryview(head), 0, CALL_ANSWER.size)
    (size,) = CALL_ANSWER.unpack(head)
    answer = head + bytearray(size)
    fill(sock, memoryview(answer), CALL_ANSWER.size, len(answer))
    return bytes(answer)


def answer_call(group: Any, request: bytes) -> bytes:
    """Run the pickled ``(method, args)`` on ``group``; its Outcome as an answer message.
    An exception is the Outcome an in-process call gives (:func:`error_outcome`); an answer
    that cannot be pickled travels as a failure naming why."""
    method, args = pickle.loads(request)  # trusted: own driver (its private socket)
    try:
        outcome = Outcome(True, getattr(group, method)(*args))
    except Exception as error:
        outcome = error_outcome(error, traceback.format_exc())
    try:
        body = _dumps(outcome)
    except Exception as error:
        text = f"{method}'s answer could not be pickled: {type(error).__name__}: {error}"
        if not outcome.ok:
            text = f"{outcome.error}\n({text})"
        body = pickle.dumps(Outcome(False, RuntimeError(text), text))
    return CALL_ANSWER.pack(len(body)) + body


def _dumps(value: Any) -> bytes:
    """``value`` pickled as Ray pickles a call's answer (cloudpickle: lambdas, local classes)."""
    import cloudpickle

    return cloudpickle.dumps(value)
