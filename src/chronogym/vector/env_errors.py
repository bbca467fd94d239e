"""An env's own Python exception, carried from its worker to the driver and raised there.

A Python exception raised by env or task code (construction, ``reset``, ``step``, ``call``,
``render``...) is the user's bug; a dead worker process (a signal, ``os._exit``, the OOM
killer, a lost node, ``step_timeout``) is a fault. Faults replace the worker and truncate its
envs. Exceptions follow ``env_errors``:

- ``"raise"`` (the default, as Gymnasium's vector envs): the worker answers with an
  :class:`EnvRaised` instead of a result, and the driver re-raises the env's own exception
  (:func:`driver_error`) from ``reset`` / ``step`` / ``recv`` / ``call``: its original class
  where it pickles (else :class:`~chronogym.errors.WorkerEnvError`), with the worker's
  traceback chained as a :class:`~chronogym.errors.RemoteTraceback` and the env index and id
  in the traceback.
- ``"restart"`` (long unattended runs): the env is rebuilt in its worker, reseeded and
  reported truncated with ``info["worker_error"]``, up to ``max_restarts`` times. An env
  whose construction or reset fails again right after it was rebuilt is a crash loop:
  :class:`~chronogym.errors.WorkerCrashLoopError` at once, with a short message.

Construction errors are raised in both modes: there is nothing to restart from.
"""

from __future__ import annotations

import functools
import pickle
import traceback
from dataclasses import dataclass
from typing import Any

from gymnasium.envs.registration import EnvSpec

from chronogym.errors import RemoteTraceback, WorkerCrashLoopError, WorkerEnvError

#: The values of ``env_errors``: what a Python exception of an env's own code does.
ENV_ERRORS = ("raise", "restart")
#: Lines of the last traceback a crash-loop message keeps (its last frame and the error).
CRASH_LOOP_TAIL = 3


def check_env_errors(env_errors: Any) -> str:
    """``env_errors`` checked: ``"raise"`` or ``"restart"``."""
    if not isinstance(env_errors, str) or env_errors not in ENV_ERRORS:
        raise ValueError(
            f"env_errors={env_errors!r}: expected 'raise' (an env's exception is raised in the "
            "driver, the default) or 'restart' (the env is rebuilt and reported truncated)"
        )
    return env_errors


def env_label(env_fn: Any) -> str:
    """What an env was made from, for messages: its id, or its factory's name."""
    if isinstance(env_fn, EnvSpec):
        return env_fn.id
    if isinstance(env_fn, str):
        return env_fn
    while isinstance(env_fn, functools.partial):
        env_fn = env_fn.func
    return getattr(env_fn, "__qualname__", None) or type(env_fn).__qualname__


class EnvRaised(Exception):
    """An env's exception, as its worker sends it to the driver (always picklable).

    ``payload`` is the exception pickled in the worker (None where it does not pickle);
    ``crash_loop`` marks a failure right after a rebuild (``env_errors="restart"``).
    """

    def __init__(
        self,
        env_index: int,
        method: str,
        label: str,
        type_name: str,
        message: str,
        text: str,
        payload: bytes | None = None,
        crash_loop: bool = False,
    ) -> None:
        super().__init__(f"env {env_index} ({label}) raised {type_name} in {method}: {message}")
        self.env_index = env_index
        self.method = method
        self.label = label
        self.type_name = type_name
        self.message = message
        self.text = text
        self.payload = payload
        self.crash_loop = crash_loop

    def __reduce__(self) -> tuple:
        fields = (self.env_index, self.method, self.label, self.type_name, self.message)
        return (type(self), (*fields, self.text, self.payload, self.crash_loop))

    @classmethod
    def capture(
        cls, error: BaseException, env_index: int, method: str, label: str, crash_loop=False
    ) -> EnvRaised:
        """``error`` (being handled in a worker) with its traceback and pickled form."""
        text = "".join(traceback.format_exception(type(error), error, error.__traceback__))
        return cls(
            env_index,
            method,
            label,
            type_name(type(error)),
            str(error),
            text,
            _pickled(error),
            crash_loop,
        )


def type_name(cls: type) -> str:
    """``ValueError`` for builtins, ``module.Class`` otherwise."""
    if cls.__module__ == "builtins":
        return cls.__qualname__
    return f"{cls.__module__}.{cls.__qualname__}"


def _pickled(error: BaseException) -> bytes | None:
    """``error`` pickled by value where plain pickle cannot (a class of a user's script)."""
    error = _without_traceback(error)
    try:
        return pickle.dumps(error)
    except Exception:
        pass
    try:
        import cloudpickle

        return cloudpickle.dumps(error)
    except Exception:
        return None


def _without_traceback(error: BaseException) -> BaseException:
    """``error`` with its traceback and chain dropped (they do not pickle; the text has them)."""
    error.__traceback__ = None
    error.__context__ = None
    error.__cause__ = None
    return error


def _unpickled(raised: EnvRaised) -> BaseException | None:
    if raised.payload is None:
        return None
    try:
        error = pickle.loads(raised.payload)  # trusted: own worker
    except Exception:
        return None
    return error if isinstance(error, BaseException) else None


def where(raised: EnvRaised, worker: int) -> str:
    """``env 3 (newuser/Pendulum-v0) in step(), worker 1``: where an env raised."""
    return f"env {raised.env_index} ({raised.label}) in {raised.method}(), worker {worker}"


def driver_error(raised: EnvRaised, worker: int) -> BaseException:
    """The exception to raise in the driver for ``raised``: the env's own (or
    WorkerEnvError), its worker's traceback chained as cause; a crash loop's
    WorkerCrashLoopError with a short message."""
    if raised.crash_loop:
        tail = "\n".join(raised.text.rstrip().splitlines()[-CRASH_LOOP_TAIL:])
        return WorkerCrashLoopError(
            f"{where(raised, worker)} failed again right after it was rebuilt: a crash loop, "
            "so it is not rebuilt again (env_errors='restart'). The last error:\n"
            f"{tail}\nIts full traceback is this error's `traceback` attribute; with "
            "env_errors='raise' (the default) the env's own exception is raised instead.",
            raised.text,
        )
    error = _unpickled(raised)
    if error is None:
        error = WorkerEnvError(
            f"{raised.type_name}: {raised.message} (raised by {where(raised, worker)}; its "
            "class could not be rebuilt here)",
            raised.type_name,
        )
    note = f"raised by {where(raised, worker)} (chronogym: the worker's traceback is above)"
    if hasattr(error, "add_note"):
        error.add_note(note)
    error.__cause__ = RemoteTraceback(f"raised by {where(raised, worker)}:\n{raised.text}")
    return error


@dataclass
class EnvErrorSeen:
    """The first env exception of a call over several workers, raised once all are read."""

    error: EnvRaised | None = None
    worker: int = -1

    def keep(self, raised: EnvRaised, worker: int) -> None:
        if self.error is None:
            self.error, self.worker = raised, worker

    def to_raise(self) -> BaseException | None:
        """The exception to raise in the driver (None when no env raised)."""
        return None if self.error is None else driver_error(self.error, self.worker)
