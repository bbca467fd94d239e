"""Exceptions raised by chronogym."""

from __future__ import annotations

from gymnasium.error import ClosedEnvironmentError


class ChronogymError(Exception):
    """Base class of every error chronogym raises on purpose."""


class TaskDefinitionError(ChronogymError, TypeError):
    """A Task lacks a required piece or declares an invalid one."""


class WorkerCrashLoopError(ChronogymError, RuntimeError):
    """An environment kept failing after its restart budget was spent."""


class WorkerCallError(ChronogymError, RuntimeError):
    """A call to a vector-env worker failed (the worker is replaced, the call is not retried)."""


class VectorEnvClosedError(ChronogymError, ClosedEnvironmentError, RuntimeError):
    """A closed vector env was used (Gymnasium's ``ClosedEnvironmentError``)."""
