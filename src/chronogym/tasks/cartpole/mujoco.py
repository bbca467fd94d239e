"""Cart-pole balancing on MuJoCo: the small task behind the demo, tests and benchmarks.

Observation (float64, 4): cart position, pole angle (wrapped to [-pi, pi]), cart velocity,
pole angular velocity.
Action (float32, 1): normalized force on the cart in [-1, 1] (10 N at 1).
Reward: 1 per step while the pole is up. Terminated when |angle| > 0.2 rad or the
cart leaves [-0.9, 0.9] m (``terminate=False``: never, so that every step costs the same
physics -- the throughput benchmarks use it).
Physics: ``dt`` = 2 ms, ``k`` = 10 ticks per step (50 Hz control).
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import numpy as np
from gymnasium import spaces

from chronogym.engines.mujoco import MujocoTask
from chronogym.validation import check_bool

XML_PATH = Path(__file__).with_name("cartpole.xml")


class CartPoleTask(MujocoTask):
    """Keep a pole upright by pushing its cart."""

    max_angle = 0.2
    max_position = 0.9
    render_camera = "front"

    def __init__(
        self,
        dt: float = 0.002,
        k: int = 10,
        max_episode_steps: int | None = 500,
        reset_noise: float = 0.05,
        terminate: bool = True,
    ) -> None:
        if not reset_noise >= 0:
            raise ValueError(f"reset_noise={reset_noise!r}: expected a float >= 0")
        self.terminate = check_bool("terminate", terminate)
        self.dt = dt
        self.k = k
        self.max_episode_steps = max_episode_steps
        self.reset_noise = float(reset_noise)

    def load_model(self) -> Any:
        import mujoco

        return mujoco.MjModel.from_xml_path(str(XML_PATH))

    def setup(self) -> None:
        high = np.array([np.inf, np.pi, np.inf, np.inf])  # the rail's end stop is soft
        self.observation_space = spaces.Box(-high, high, dtype=np.float64)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)

    def reset(self, rng: np.random.Generator, options: dict[str, Any] | None) -> None:
        noise = self.reset_noise if not options else float(options.get("noise", self.reset_noise))
        self.reset_data()
        self.data.qpos[:] = rng.uniform(-noise, noise, size=self.model.nq)
        self.data.qvel[:] = rng.uniform(-noise, noise, size=self.model.nv)
        self.forward()

    def apply_action(self, action: np.ndarray) -> None:
        self.data.ctrl[0] = action[0]

    def observe(self) -> np.ndarray:
        obs = np.concatenate([self.data.qpos, self.data.qvel])
        obs[1] = (obs[1] + np.pi) % (2 * np.pi) - np.pi
        return obs

    def reward(self, action: np.ndarray, obs: np.ndarray) -> float:
        return 1.0

    def terminated(self, obs: np.ndarray) -> bool:
        if not self.terminate:
            return False
        return abs(obs[1]) > self.max_angle or abs(obs[0]) > self.max_position
