"""Small envs for the SB3 drop-in tests: any spaces, and attributes only some envs have.

Ray workers cannot import this folder by name: the tests register this module with
``ray.cloudpickle.register_pickle_by_value`` so its classes travel by value.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from space_envs import SpaceEnv


class EchoEnv(SpaceEnv):
    """SpaceEnv whose reward also weighs the flattened action, so a wrongly batched action
    changes the numbers (and fails the action-space check)."""

    def __init__(self, observation_space: spaces.Space, action_space: spaces.Space) -> None:
        super().__init__(observation_space, action_space)
        self._weights = np.arange(1.0, spaces.flatdim(action_space) + 1.0)

    def action_value(self, action: Any) -> float:
        flat = spaces.flatten(self.action_space, action).astype(np.float64)
        return float(flat @ self._weights)


class PlainEnv(gym.Env):
    """A one-number env with a counter that :meth:`bump` raises."""

    observation_space = spaces.Box(-1.0, 1.0, (1,), np.float32)
    action_space = spaces.Discrete(2)

    def __init__(self) -> None:
        self.counter = 0

    def bump(self, by: int = 1) -> int:
        self.counter += by
        return self.counter

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple:
        super().reset(seed=seed)
        return np.zeros(1, np.float32), {}

    def step(self, action: Any) -> tuple:
        return np.zeros(1, np.float32), 0.0, False, False, {}


class ExtraEnv(PlainEnv):
    """:class:`PlainEnv` with an attribute and a method the plain one lacks."""

    def __init__(self) -> None:
        super().__init__()
        self.bonus = 10

    def shout(self, text: str) -> str:
        return f"{text} (counter {self.counter})"


class Marker(gym.Wrapper):
    """A wrapper to find with ``env_is_wrapped``."""


def marked_plain_env() -> gym.Env:
    return Marker(PlainEnv())


#: Env 1 and 3 have ``bonus`` and ``shout``; env 2 is wrapped in Marker. The same
#: callable builds env 1 and env 3: each env still knows its own index.
MIXED_FACTORIES = [PlainEnv, ExtraEnv, marked_plain_env, ExtraEnv]
