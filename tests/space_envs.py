"""An env for any pair of Gymnasium spaces, and the spaces Gymnasium's own tests use.

Importable by Ray workers (tests/ is on their PYTHONPATH, see conftest.py).
"""

from __future__ import annotations

from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces

EPISODE_LENGTH = 4


class SpaceEnv(gym.Env):
    """Samples observations of any space from its seeded RNG; checks every action.

    Episodes end at random (terminated) or after ``EPISODE_LENGTH`` steps
    (truncated), so a short rollout crosses both kinds of autoreset.
    """

    def __init__(self, observation_space: spaces.Space, action_space: spaces.Space) -> None:
        self.observation_space = observation_space
        self.action_space = action_space
        self.t = 0

    def action_value(self, action: Any) -> float:
        """What the action adds to the reward (none here; subclasses may weigh it)."""
        return 0.0

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
        reward = self.action_value(action) + float(self.np_random.random())
        terminated = bool(self.np_random.random() < 0.25)
        truncated = self.t >= EPISODE_LENGTH
        return self._sample(), reward, terminated, truncated, {"t": self.t, "r": reward}


def _box(**kwargs: Any) -> spaces.Box:
    return spaces.Box(**kwargs)


#: Every kind of space Gymnasium's own space and vector tests use, each a few ways.
TESTING_SPACES: dict[str, spaces.Space] = {
    "box": _box(low=-1.0, high=1.0, shape=(3,), dtype=np.float32),
    "box-2d-f64": _box(low=-2.0, high=2.0, shape=(2, 2), dtype=np.float64),
    "box-uint8": _box(low=0, high=255, shape=(2, 3), dtype=np.uint8),
    "box-int-scalar": _box(low=-5, high=5, shape=(), dtype=np.int64),
    "discrete": spaces.Discrete(3),
    "discrete-start": spaces.Discrete(3, start=-1),
    "multi-discrete": spaces.MultiDiscrete([2, 3, 4]),
    "multi-discrete-2d": spaces.MultiDiscrete([[2, 3], [3, 2]]),
    "multi-binary": spaces.MultiBinary(4),
    "multi-binary-2d": spaces.MultiBinary([2, 3]),
    "text": spaces.Text(6),
    "text-charset": spaces.Text(min_length=1, max_length=5, charset="abc"),
    "tuple": spaces.Tuple((spaces.Discrete(2), _box(low=0.0, high=1.0, shape=(2,)))),
    "dict": spaces.Dict(position=_box(low=-1.0, high=1.0, shape=(2,)), mode=spaces.Discrete(3)),
    "nested": spaces.Dict(
        a=spaces.Tuple((spaces.Text(3), spaces.MultiBinary(2))),
        b=spaces.Dict(c=spaces.Discrete(4), d=_box(low=0.0, high=1.0, shape=(1,))),
    ),
    "graph": spaces.Graph(
        node_space=_box(low=-1.0, high=1.0, shape=(2,)), edge_space=spaces.Discrete(3)
    ),
    "graph-no-edges": spaces.Graph(node_space=spaces.Discrete(4), edge_space=None),
    "sequence": spaces.Sequence(spaces.Discrete(3)),
    "sequence-stacked": spaces.Sequence(_box(low=0.0, high=1.0, shape=(2,)), stack=True),
    "one-of": spaces.OneOf((spaces.Discrete(2), _box(low=0.0, high=1.0, shape=(2,)))),
    "dict-of-sequence-and-text": spaces.Dict(
        s=spaces.Sequence(spaces.MultiDiscrete([2, 2])), t=spaces.Text(4)
    ),
    "tuple-of-graph-and-one-of": spaces.Tuple(
        (
            spaces.Graph(node_space=spaces.Discrete(2), edge_space=None),
            spaces.OneOf((spaces.Text(2), spaces.Discrete(3))),
        )
    ),
}
