"""The interface between the driver and its workers: the ``Backend`` and what a call returns.

Both sides import this module and, below it, only :mod:`chronogym.vector.infos` (how
infos travel) and :mod:`chronogym.errors`. It holds the :class:`Backend` protocol the
driver (:class:`~chronogym.vector.worker_vector_env.WorkerVectorEnv`) talks to, the
:class:`Outcome` of one worker call, the typed answers of a worker's step and reset
(:class:`StepAnswer`, :class:`ResetAnswer`), what a worker reports besides its results
(:class:`Restart`), and :func:`gather_split`, the one place where a backend that serves
some handles itself (a socket, the driver's own worker) and leaves the rest to another
backend joins the two. How a packed step travels as bytes is
:mod:`chronogym.vector.wire_format`.

A Ray actor call returns an answer as the plain tuple of its fields
(:class:`~chronogym.vector.actor_transport.ActorGroup`), and the driver reads it back with
``StepAnswer.of`` / ``ResetAnswer.of``: Ray packs tuples, lists and bytes with msgpack and
pickles only what is left (arrays, infos), while a dataclass would be pickled whole, which
cost the actor path 10 % of its throughput (``benchmarks/results/compare_revisions_issue31.json``).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import gymnasium as gym

from chronogym.errors import DisabledAutoresetError
from chronogym.vector.infos import InfoColumns

EnvFactory = Callable[[], gym.Env]


@dataclass
class Outcome:
    """What one worker call gave back: a value, or the error that replaced it."""

    ok: bool
    value: Any = None
    error: str = ""
    lost: bool = False  # the worker process is gone or stopped answering


@dataclass
class Restart:
    """An env rebuilt inside its worker after its step or reset raised."""

    env_index: int
    error: str


@dataclass
class StepAnswer:
    """A worker's answer to ``step`` or ``step_packed``, for every env it holds.

    ``step``: per-env observations, then reward, termination and truncation arrays,
    per-env info dicts, and the restarts. ``step_packed`` (Box spaces): the first
    four as bytes, the infos as :func:`~chronogym.vector.infos.to_columns` gives
    them (None when all are empty), the restarts None when none, and
    ``timings`` = (seconds of (de)serialization, seconds in ``step``) when the
    driver asked for them.
    """

    obs: Any
    rewards: Any  # np.ndarray, or its bytes (packed)
    terminations: Any
    truncations: Any
    infos: InfoColumns | list[dict[str, Any]] | None
    restarts: list[Restart] | None
    timings: tuple[float, float] | None = None

    def as_tuple(self) -> tuple[Any, ...]:
        """The fields in order: the form in which a Ray actor sends the answer."""
        return (
            self.obs,
            self.rewards,
            self.terminations,
            self.truncations,
            self.infos,
            self.restarts,
            self.timings,
        )

    @classmethod
    def of(cls, value: StepAnswer | tuple[Any, ...]) -> StepAnswer:
        """``value`` as a StepAnswer: itself, or one built from :meth:`as_tuple`'s form."""
        return value if isinstance(value, cls) else cls(*value)


@dataclass
class ResetAnswer:
    """A worker's answer to ``reset`` / ``reset_restarted``: per-env obs, infos, restarts."""

    obs: list[Any]
    infos: list[dict[str, Any]]
    restarts: list[Restart]

    def as_tuple(self) -> tuple[Any, ...]:
        """The fields in order: the form in which a Ray actor sends the answer."""
        return (self.obs, self.infos, self.restarts)

    @classmethod
    def of(cls, value: ResetAnswer | tuple[Any, ...]) -> ResetAnswer:
        """``value`` as a ResetAnswer: itself, or one built from :meth:`as_tuple`'s form."""
        return value if isinstance(value, cls) else cls(*value)


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


def split_handles(handles: list[Any], own: type) -> tuple[list[int], list[int]]:
    """Indices of the handles of type ``own`` (served here), and of the others."""
    mine, others = [], []
    for k, handle in enumerate(handles):
        (mine if isinstance(handle, own) else others).append(k)
    return mine, others


def gather_split(
    workers: list[int],
    handles: list[Any],
    own: type | tuple[type, ...],
    resolve: Callable[[Any], Outcome],
    gather_others: Callable[[list[int], list[Any]], list[Outcome]],
) -> list[Outcome]:
    """Outcomes of ``handles`` in order: ``resolve`` each handle of type ``own``, and
    ``gather_others`` the rest in one call (the local/remote split of a backend)."""
    mine, others = split_handles(handles, own)
    outcomes: list[Outcome | None] = [None] * len(handles)
    for k in mine:
        outcomes[k] = resolve(handles[k])
    if others:
        gathered = gather_others([workers[k] for k in others], [handles[k] for k in others])
        for k, outcome in zip(others, gathered, strict=True):
            outcomes[k] = outcome
    return outcomes  # type: ignore[return-value]
