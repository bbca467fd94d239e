"""make_vec: one call for every way chronogym can batch an env."""

from __future__ import annotations

from typing import Any

import gymnasium as gym

import chronogym  # noqa: F401  (registers the chronogym/... ids)
from chronogym.vector.ray_vector_env import RayVectorEnv
from chronogym.vector.serial import SerialVectorEnv

#: The ``backend`` names of make_vec (and of the SB3 adapter's make_sb3_vec_env).
BACKENDS = ("ray", "serial", "sync", "async")


def make_vec(
    env_id: str, num_envs: int, backend: str = "ray", **kwargs: Any
) -> gym.vector.VectorEnv:
    """Create ``num_envs`` copies of ``env_id`` batched by ``backend``.

    ``"ray"``: :class:`RayVectorEnv`; ``"serial"``: :class:`SerialVectorEnv`;
    ``"sync"`` / ``"async"``: Gymnasium's own SyncVectorEnv / AsyncVectorEnv
    (for comparison). Other keyword arguments go to the vector env, except
    ``env_kwargs``, which go to ``gymnasium.make``.
    """
    if backend == "ray":
        return RayVectorEnv(env_id, num_envs, **kwargs)
    if backend == "serial":
        return SerialVectorEnv(env_id, num_envs, **kwargs)
    if backend in ("sync", "async"):
        env_kwargs = kwargs.pop("env_kwargs", None) or {}
        mode = "sync" if backend == "sync" else "async"
        return gym.make_vec(
            env_id, num_envs, vectorization_mode=mode, vector_kwargs=kwargs, **env_kwargs
        )
    raise ValueError(f"backend={backend!r}: expected one of {BACKENDS}")
