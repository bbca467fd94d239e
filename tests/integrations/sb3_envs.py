"""Small envs for the SB3 drop-in tests: any spaces, and attributes only some envs have.

Ray workers cannot import this folder by name: the tests register this module with
``ray.cloudpickle.register_pickle_by_value`` so its classes travel by value.
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

EPISODE_LENGTH = 4


class EchoEnv(gym.Env):
    """Random observations of any space; the reward is a weighted sum of the flattened action.

    Each action is checked against the action space, so a wrongly batched action fails;
    episodes end at random (terminated) or after ``EPISODE_LENGTH`` steps (truncated).
    """

    def __init__(self, observation_space: spaces.Space, action_space: spaces.Space) -> None:
        self.observation_space = observation_space
        self.action_space = action_space
        size = spaces.flatdim(action_space)
        self._weights = np.arange(1.0, size + 1.0)
        self.t = 0

    def _sample(self) -> Any:
        self.observation_space.seed(int(self.np_random.integers(2**31)))
        return self.observation_space.sample()

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple:
        super().reset(seed=seed)
        self.t = 0
        return self._sample(), {"t": self.t}

    def step(self, action: Any) -> tuple:
        if not self.action_space.contains(action):
            raise ValueError(f"action {action!r} is not in {self.action_space}")
        self.t += 1
        flat = spaces.flatten(self.action_space, action).astype(np.float64)
        reward = float(flat @ self._weights) + float(self.np_random.random())
        terminated = bool(self.np_random.random() < 0.25)
        truncated = self.t >= EPISODE_LENGTH
        return self._sample(), reward, terminated, truncated, {"t": self.t, "r": reward}


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
