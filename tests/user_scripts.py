"""A user's own script, run in a subprocess: tests of ids registered outside chronogym."""

from __future__ import annotations

import subprocess
import sys
import textwrap
from pathlib import Path

#: A tiny task of the user's own (no physics engine), then ``ray.init``; a script appends
#: its ``register_task(ID, Drift)`` and what it checks.
DRIFT_TASK = textwrap.dedent(
    """
    import gymnasium as gym
    import numpy as np
    import ray
    from gymnasium import spaces

    import chronogym
    from chronogym import register_task


    class Drift(chronogym.Task):
        dt, k, max_episode_steps = 0.1, 1, 7

        def init(self):
            self.advanceables = []
            self.observation_space = spaces.Box(-np.inf, np.inf, (1,), np.float64)
            self.action_space = spaces.Box(-1, 1, (1,), np.float32)

        def reset(self, rng, options):
            self.x = float(rng.uniform(-1, 1))

        def apply_action(self, action):
            self.x += float(action[0])

        def observe(self):
            return np.array([self.x])

        def reward(self, action, obs):
            return -abs(self.x)

        def terminated(self, obs):
            return abs(self.x) > 3

    """
)


def run_user_script(folder: Path, text: str, timeout: float = 240) -> subprocess.CompletedProcess:
    """Run ``text`` as ``folder/user_script.py`` (its own process, cwd ``folder``)."""
    script = folder / "user_script.py"
    script.write_text(text)
    return subprocess.run(
        [sys.executable, str(script)], capture_output=True, text=True, timeout=timeout, cwd=folder
    )
