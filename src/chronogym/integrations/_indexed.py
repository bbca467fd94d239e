"""The env wrapper behind per-env ``indices=`` in the SB3 adapter (no SB3 import here).

A Gymnasium vector env's ``call`` and ``set_attr`` reach every env. Each env built by
``make_sb3_vec_env``, ``RayVecEnv`` or ``SerialVecEnv`` is wrapped in :class:`IndexedEnv`,
which knows its own index, so one ``call`` to every env can act on the chosen ones only.
Ray workers import this module to rebuild the envs, so it must stay free of
Stable-Baselines3 and torch.
"""

from __future__ import annotations

import os
from collections.abc import Callable
from typing import Any

import gymnasium as gym

import chronogym  # noqa: F401  (registers the chronogym/... ids in this process)

INDEX_ATTR = "chronogym_env_index"
HOOK = "chronogym_sb3_op"
OPS = ("call", "get", "has", "set", "is_wrapped", "identity")


class IndexedEnv(gym.Wrapper):
    """Carries the env's index in its vector env; :meth:`chronogym_sb3_op` acts on chosen ones."""

    def __init__(self, env: gym.Env, index: int) -> None:
        super().__init__(env)
        self.chronogym_env_index = index

    def chronogym_sb3_op(self, op: str, indices: list[int], *args: Any) -> Any:
        """Run ``op`` if this env's index is in ``indices`` (else do nothing, return None).

        ``op``: ``"call"`` (name, args, kwargs), ``"get"`` (name), ``"has"`` (name),
        ``"set"`` (name, value), ``"is_wrapped"`` (wrapper class) or ``"identity"`` (the
        process id and the ``id`` of the unwrapped env). Attributes are looked up and set
        as Gymnasium's vector envs do (``get_wrapper_attr`` / ``set_wrapper_attr``).
        """
        if self.chronogym_env_index not in indices:
            return None
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
        if op == "identity":
            return os.getpid(), id(self.unwrapped)
        raise ValueError(f"op={op!r}: expected one of {OPS}")


def make_indexed_env(env_id: str, index: int, env_kwargs: dict[str, Any] | None) -> IndexedEnv:
    """``gymnasium.make(env_id, **env_kwargs)`` wrapped in :class:`IndexedEnv`."""
    return IndexedEnv(gym.make(env_id, **(env_kwargs or {})), index)


def build_indexed_env(env_fn: Callable[[], gym.Env], index: int) -> IndexedEnv:
    """``env_fn()`` wrapped in :class:`IndexedEnv` (``env_fn`` must return a Gymnasium env)."""
    env = env_fn()
    if not isinstance(env, gym.Env):
        raise TypeError(
            f"env_fns[{index}]={env_fn!r} returned {env!r} (a {type(env).__name__}); "
            "expected a gymnasium.Env"
        )
    return IndexedEnv(env, index)
