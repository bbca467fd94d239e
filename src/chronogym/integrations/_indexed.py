"""The env wrapper behind per-env ``indices=`` in the SB3 adapter (no SB3 import here).

A Gymnasium vector env's ``call`` and ``set_attr`` reach every env. Each env built by
``make_sb3_vec_env``, ``RayVecEnv`` or ``SerialVecEnv`` is wrapped in :class:`IndexedEnv`,
which knows its own index, so one ``call`` to every env can act on the chosen ones only.
:class:`~chronogym.vector.driver_registry.DriverRegistry` carries the driver's Gymnasium ids
to the workers, for factories that call ``gymnasium.make`` with an id registered in the
user's script.
Ray workers import this module to rebuild the envs, so it must stay free of
Stable-Baselines3 and torch.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import gymnasium as gym
from gymnasium.envs.registration import EnvSpec

import chronogym  # noqa: F401  (registers the chronogym/... ids in this process)
from chronogym.vector.driver_registry import DriverRegistry, make_with_driver_ids

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
    env = make_with_driver_ids(env_fn, registry)
    if not isinstance(env, gym.Env):
        raise TypeError(
            f"env_fns[{index}]={env_fn!r} returned {env!r} (a {type(env).__name__}); "
            "expected a gymnasium.Env"
        )
    return IndexedEnv(env, index)
