"""The driver's Gymnasium ids, carried to the workers for factories that call ``gym.make``.

An env factory such as ``lambda: gym.make("newuser/Pendulum-v0")`` runs in a Ray worker,
where an id registered by the user's script does not exist (the worker never runs the
script), and fails with ``NamespaceNotFound``. The driver therefore sends the specs of the ids
its script registered (:func:`script_registered_ids`: those registered after chronogym's
import) as a :class:`DriverRegistry`; when a factory fails on an unregistered id, the
worker registers them (:meth:`DriverRegistry.register_missing`) and runs the factory once
more (:func:`make_with_driver_ids`). Each spec is unpickled only then, so a spec whose code
a worker cannot import harms no other id.
"""

from __future__ import annotations

import os
import pickle
from collections.abc import Callable, Iterable
from typing import Any

import gymnasium as gym
from gymnasium.envs.registration import EnvSpec


class DriverRegistry:
    """Specs of the driver's Gymnasium registry (``ids``: those only), each pickled apart."""

    def __init__(self, dumps: Callable[[Any], bytes], ids: Iterable[str] | None = None) -> None:
        self.specs: dict[str, bytes] = {}
        wanted = None if ids is None else set(ids)
        for env_id, spec in list(gym.registry.items()):
            if wanted is not None and env_id not in wanted:
                continue
            try:
                self.specs[env_id] = dumps(spec)
            except Exception:  # an unpicklable spec: the workers go without that id
                continue

    def __len__(self) -> int:
        return len(self.specs)

    def register_missing(self) -> tuple[list[str], dict[str, str]]:
        """Register the specs this process lacks: the ids registered, and the ids whose
        spec could not be loaded here (its code does not import), with the error."""
        added, failed = [], {}
        for env_id, data in self.specs.items():
            if env_id in gym.registry:
                continue
            try:
                # the driver's own bytes, as trusted as every Ray argument it sends
                spec = pickle.loads(data)  # trusted: own worker's driver
            except Exception as error:  # its code does not import here: leave that id out
                failed[env_id] = f"{type(error).__name__}: {error}"
                continue
            if isinstance(spec, EnvSpec):
                gym.registry[env_id] = spec
                added.append(env_id)
        return added, failed


def make_with_driver_ids(env_fn: Callable[[], Any], registry: DriverRegistry | None) -> Any:
    """``env_fn()``; one that fails on an id this process has not registered runs again,
    once, after the driver's missing ids (``registry``) are registered here."""
    try:
        return env_fn()
    except gym.error.UnregisteredEnv as error:
        if registry is None:
            raise
        added, failed = registry.register_missing()
        if failed:
            error = type(error)(
                f"{error} (in worker pid {os.getpid()}: the driver's specs of {sorted(failed)} "
                f"could not be loaded here: {'; '.join(failed.values())}; make the env's "
                "module importable on every worker, or define the env in the script)"
            )
        if not added:
            raise error from None
        try:
            return env_fn()
        except gym.error.UnregisteredEnv:
            if not failed:
                raise
            raise error from None


_IDS_AT_IMPORT: frozenset[str] = frozenset()


def note_import_ids() -> None:
    """Remember the ids every process has once chronogym is imported (called at import)."""
    global _IDS_AT_IMPORT
    _IDS_AT_IMPORT = frozenset(gym.registry)


def script_registered_ids() -> list[str]:
    """Ids registered in this process after chronogym's import (by the user's script): the
    ones a Ray worker lacks."""
    return [env_id for env_id in gym.registry if env_id not in _IDS_AT_IMPORT]
