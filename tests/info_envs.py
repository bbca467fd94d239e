"""Envs whose infos exercise every way a vector env batches them (tests/vector/test_infos.py)."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
from gymnasium import spaces

#: Info styles: what kind of values env ``i`` reports (see InfoEnv.info).
STYLES = ("scalars", "int_or_float", "numpy_bool", "extra_key")


class InfoEnv(gym.Env):
    """A random walk of length <= 12 whose info depends on ``style`` and its index."""

    def __init__(self, index: int = 0, style: str = "scalars") -> None:
        self.index, self.style = index, style
        self.observation_space = spaces.Box(-np.inf, np.inf, (2,), np.float64)
        self.action_space = spaces.Box(-1.0, 1.0, (1,), np.float32)
        self.t, self.x = 0, 0.0

    def info(self) -> dict:
        base = {
            "x": float(self.x),
            "x32": np.float32(self.x),
            "t": int(self.t),
            "done_soon": bool(self.t > 8),
        }
        if self.style == "int_or_float" and self.index >= 2:
            base["t"] = float(self.t)  # envs 0-1 report an int, the others a float
        elif self.style == "numpy_bool":
            base["done_soon"] = np.bool_(self.t > 8)  # Gymnasium batches these as objects
        elif self.style == "extra_key" and self.t % 3 == self.index % 3:
            base["every_third"] = self.t
        return base

    def reset(self, *, seed=None, options=None):
        super().reset(seed=seed)
        self.t, self.x = 0, float(self.np_random.uniform(-1, 1))
        return np.array([self.x, 0.0]), {"start": self.x}

    def step(self, action):
        self.t += 1
        self.x += float(action[0]) + float(self.np_random.normal(0, 0.1))
        terminated = abs(self.x) > 2.5
        truncated = self.t >= 12
        return np.array([self.x, self.t]), -abs(self.x), terminated, truncated, self.info()


def info_env_fns(style: str, num_envs: int) -> list:
    """One factory per env (each knows its index)."""
    return [lambda i=i: InfoEnv(i, style) for i in range(num_envs)]
