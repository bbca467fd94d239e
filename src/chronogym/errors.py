"""Exceptions raised by chronogym."""

from __future__ import annotations

import multiprocessing

from gymnasium.error import AlreadyPendingCallError, ClosedEnvironmentError


class ChronogymError(Exception):
    """Base class of every error chronogym raises on purpose."""


class BoolArgumentError(ChronogymError, TypeError, ValueError):
    """A bool where a number was expected, or anything but a bool where a bool was expected.

    Raised by every check of :mod:`chronogym.validation` (``check_bool``, and ``check_int`` /
    ``check_number`` / ``check_positive`` given ``True`` or ``False``). Both a ``TypeError`` and
    a ``ValueError``, so either ``except`` catches it.
    """


class TaskDefinitionError(ChronogymError, TypeError):
    """A Task lacks a required piece or declares an invalid one."""


class RenderModeError(ChronogymError, ValueError, TypeError):
    """A ``render_mode`` this env cannot render (its task does not render that mode, or this
    process lacks what rendering needs).

    A ``ValueError``, and also a ``TypeError``: Stable-Baselines3's ``make_vec_env`` asks
    every id for ``render_mode="rgb_array"`` and falls back to no render mode on a
    ``TypeError`` only. ``gymnasium.make`` re-raises a ``TypeError`` of an env's constructor
    with "was raised from the environment creator for <id> with kwargs (...)" appended; here
    the id goes first instead, and the kwargs (which hold the render mode already) go.
    """

    GYMNASIUM_SUFFIX = " was raised from the environment creator for "

    def __init__(self, message: str) -> None:
        head, found, where = message.partition(self.GYMNASIUM_SUFFIX)
        if found:
            message = f"{where.split(' with kwargs ')[0]}: {head}"
        super().__init__(message)


class WorkerCrashLoopError(ChronogymError, RuntimeError):
    """An environment kept failing: it failed again right after being rebuilt (a crash loop at
    construction or reset), or it spent its restart budget (``max_restarts``).

    ``traceback`` holds the last error's full text (the message keeps only its end).
    """

    def __init__(self, message: str, traceback: str = "") -> None:
        super().__init__(message)
        self.traceback = traceback

    def __reduce__(self) -> tuple:
        return (type(self), (str(self), self.traceback))


class WorkerEnvError(ChronogymError, RuntimeError):
    """An env raised inside a worker, and its exception could not be rebuilt in the driver.

    With ``env_errors="raise"`` (the default) a vector env re-raises an env's exception in
    the driver as its own class; when that class cannot travel (it does not pickle, or
    the driver cannot import it) this is raised instead. ``type_name`` is the original
    class's qualified name; the worker's traceback is chained as ``__cause__``.
    """

    def __init__(self, message: str, type_name: str = "") -> None:
        super().__init__(message)
        self.type_name = type_name

    def __reduce__(self) -> tuple:
        return (type(self), (str(self), self.type_name))


class RemoteTraceback(Exception):
    """The traceback of an exception raised in a worker process, chained as ``__cause__`` of
    the exception re-raised in the driver (as ``concurrent.futures`` does)."""

    def __init__(self, text: str) -> None:
        super().__init__(text)
        self.text = text

    def __str__(self) -> str:
        return self.text


class WorkerCallError(ChronogymError, RuntimeError):
    """A call to a vector-env worker failed (the worker is replaced, the call is not retried)."""


class VectorEnvClosedError(ChronogymError, ClosedEnvironmentError, RuntimeError):
    """A closed vector env was used (Gymnasium's ``ClosedEnvironmentError``)."""


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


class DisabledAutoresetError(ChronogymError, RuntimeError):
    """An env that ended was stepped while ``autoreset_mode`` is DISABLED (reset it first)."""
