"""The env wrapper behind per-env ``indices=`` in the SB3 adapter (no SB3 import here).

A Gymnasium vector env's ``call`` and ``set_attr`` reach every env. Each env built by
``make_sb3_vec_env``, ``RayVecEnv`` or ``SerialVecEnv`` is wrapped in :class:`IndexedEnv`,
which knows its own index, so one ``call`` to every env can act on the chosen ones only.
:class:`DriverRegistry` carries the driver's Gymnasium ids to the workers, for factories
that call ``gymnasium.make`` with an id registered in the user's script.
Ray workers import this module to rebuild the envs, so it must stay free of
Stable-Baselines3 and torch.
"""

from __future__ import annotations

import os
import pickle
from collections.abc import Callable
from typing import Any

import gymnasium as gym
from gymnasium.envs.registration import EnvSpec

import chronogym  # noqa: F401  (registers the chronogym/... ids in this process)

INDEX_ATTR = "chronogym_env_index"
HOOK = "chronogym_sb3_op"
OPS = ("call", "get", "has", "set", "is_wrapped", "identity")


class IndexedEnv(gym.Wrapper):
    """Carries the env's index in its vector env; :meth:`chronogym_sb3_op` acts on chosen ones."""

    def __init__(self, env: gym.Env, index: int) -> None:
        super().__init__(env)
        self.chronogym_env_index = index

    def chronogym_sb3_op(self, op: str, indices: list[int], *args: Any) -> list[Any] | None:
        """Run ``op`` once per time this env's index is in ``indices``: the list of results.

        None when the index is not there. ``op``: ``"call"`` (name, args, kwargs),
        ``"get"`` (name), ``"has"`` (name), ``"set"`` (name, value), ``"is_wrapped"``
        (wrapper class) or ``"identity"`` (the process id and the ``id`` of the unwrapped
        env). Attributes are looked up and set as Gymnasium's vector envs do
        (``get_wrapper_attr`` / ``set_wrapper_attr``). An index given twice runs ``op``
        twice, as SB3's ``DummyVecEnv`` does.
        """
        if op not in OPS:
            raise ValueError(f"op={op!r}: expected one of {OPS}")
        times = indices.count(self.chronogym_env_index)
        if times == 0:
            return None
        return [self._op(op, *args) for _ in range(times)]

    def _op(self, op: str, *args: Any) -> Any:
        if op == "call":
            name, call_args, call_kwargs = args
            return self.get_wrapper_attr(name)(*call_args, **call_kwargs)
        if op == "get":
            return self.get_wrapper_attr(args[0])
        if op == "has":
            return self.has_wrapper_attr(args[0])
        if op == "set":
            self.set_wrapper_attr(args[0], args[1])
            return None
        if op == "is_wrapped":
            env = self.env
            while isinstance(env, gym.Wrapper):
                if isinstance(env, args[0]):
                    return True
                env = env.env
            return False
        return os.getpid(), id(self.unwrapped)  # "identity"


class DriverRegistry:
    """The driver's Gymnasium registry, each spec pickled apart, for the workers.

    A factory such as SB3's ``make_vec_env`` closure calls ``gymnasium.make(env_id)`` in the
    worker, where an id registered by the user's script does not exist. When a factory
    fails with ``gymnasium.error.UnregisteredEnv``, :meth:`register_missing` registers the
    driver's specs that this process lacks, and the factory runs again. Each spec is
    unpickled only then, so a spec whose code a worker cannot import harms no other id.
    """

    def __init__(self, dumps: Callable[[Any], bytes]) -> None:
        self.specs: dict[str, bytes] = {}
        for env_id, spec in list(gym.registry.items()):
            try:
                self.specs[env_id] = dumps(spec)
            except Exception:  # an unpicklable spec: the workers go without that id
                continue

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


def make_indexed_env(
    env_id: str | EnvSpec, index: int, env_kwargs: dict[str, Any] | None
) -> IndexedEnv:
    """``gymnasium.make(env_id, **env_kwargs)`` wrapped in :class:`IndexedEnv`.

    ``env_id`` may be the driver's ``EnvSpec`` of the id, so that an id registered in the
    user's script is made the same way in a worker.
    """
    return IndexedEnv(gym.make(env_id, **(env_kwargs or {})), index)


def build_indexed_env(
    env_fn: Callable[[], gym.Env], index: int, registry: DriverRegistry | None = None
) -> IndexedEnv:
    """``env_fn()`` wrapped in :class:`IndexedEnv` (``env_fn`` must return a Gymnasium env).

    With ``registry``: a factory that fails on an id this process has not registered runs
    again, once, after the driver's missing ids are registered here.
    """
    try:
        env = env_fn()
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
            raise error
        try:
            env = env_fn()
        except gym.error.UnregisteredEnv:
            if not failed:
                raise
            raise error from None
    if not isinstance(env, gym.Env):
        raise TypeError(
            f"env_fns[{index}]={env_fn!r} returned {env!r} (a {type(env).__name__}); "
            "expected a gymnasium.Env"
        )
    return IndexedEnv(env, index)
