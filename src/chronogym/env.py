"""SimEnv: a gymnasium.Env built from a Task."""

from __future__ import annotations

import math
from typing import Any

import gymnasium as gym
import numpy as np

from chronogym.actions import check_invalid_action_mode, prepare_action
from chronogym.advance import Advancer
from chronogym.task import Task, check_task_definition, check_task_spaces
from chronogym.validation import check_int


def _all_finite(value: Any) -> bool:
    if isinstance(value, np.ndarray):
        return value.dtype.kind not in "fc" or bool(np.isfinite(value).all())
    if isinstance(value, dict):
        return all(_all_finite(v) for v in value.values())
    if isinstance(value, (tuple, list)):
        return all(_all_finite(v) for v in value)
    if isinstance(value, (float, np.floating)):
        return math.isfinite(value)
    return True


def _zero_non_finite(value: Any) -> Any:
    if isinstance(value, np.ndarray) and value.dtype.kind in "fc":
        return np.nan_to_num(value, nan=0.0, posinf=0.0, neginf=0.0)
    if isinstance(value, dict):
        return {k: _zero_non_finite(v) for k, v in value.items()}
    if isinstance(value, tuple):
        return tuple(_zero_non_finite(v) for v in value)
    return value


def _usable_render_modes(task: Task, render_mode: Any) -> list[str]:
    """The task's render modes if this process can render them, else ``[]``.

    Raise ValueError when ``render_mode`` is not None and not one of them.
    """
    declared = list(task.render_modes)
    reason = task.render_unavailable() if declared else None
    usable = [] if reason else declared
    if render_mode is None or render_mode in usable:
        return usable
    name = type(task).__name__
    if reason:
        why = f"{name} cannot render in this process: {reason}"
    elif not declared:
        why = (
            f"{name} does not render (its render_modes is empty; a Task renders when it "
            "declares render_modes = ('rgb_array',) and implements render(), a FunctionTask "
            "when given render=)"
        )
    else:
        why = f"{name} renders {declared} only"
        if render_mode == "human":
            why += " (for a window, wrap it in gymnasium.wrappers.HumanRendering)"
    expected = " or ".join(repr(m) for m in [None, *usable])
    raise ValueError(f"render_mode={render_mode!r}: {why}; expected {expected}")


class SimEnv(gym.Env):
    """One simulation as a Gymnasium environment.

    ``step(a)`` = ``task.apply_action(a)``, then ``task.k`` ticks of the
    advance operator with ``task.dt``, then observe / reward / terminated /
    truncated. The episode is truncated after ``max_episode_steps`` steps
    (argument, else ``task.max_episode_steps``; the value in force is written back
    to ``task.max_episode_steps``). A NaN/Inf observation or
    reward, or ``task.diverged()``, ends the episode with ``terminated=True``
    and ``info["diverged"] = True``; non-finite values are then replaced by 0.
    ``metadata["render_modes"]`` lists ``"rgb_array"`` only when the task
    renders and this process can (e.g. MuJoCo found an OpenGL backend);
    another ``render_mode`` than None or those is refused before ``task.init()``.
    """

    def __init__(
        self,
        task: Task,
        *,
        max_episode_steps: int | None = None,
        render_mode: str | None = None,
        invalid_action: str = "raise",
    ) -> None:
        check_task_definition(task)
        check_invalid_action_mode(invalid_action)
        if max_episode_steps is not None:
            check_int("max_episode_steps", max_episode_steps, 1, expected="None or an integer >= 1")
        render_modes = _usable_render_modes(task, render_mode)  # before init(): fail early
        self.task = task
        self.invalid_action = invalid_action
        task.init()
        check_task_spaces(task)
        self.observation_space = task.observation_space
        self.action_space = task.action_space
        self.dt = float(task.dt)
        self.k = int(task.k)
        self._advance = Advancer(task.advanceables, self.dt)
        self.max_episode_steps = (
            max_episode_steps if max_episode_steps is not None else task.max_episode_steps
        )
        task.max_episode_steps = self.max_episode_steps  # the task sees the horizon it runs under
        fps = task.render_fps or 1.0 / (self.dt * self.k)
        # A new dict per instance (gym.Env.metadata is a shared class attribute).
        self.metadata = {"render_modes": render_modes, "render_fps": fps}
        self.render_mode = render_mode
        self.sim_time = 0.0
        self.elapsed_steps = 0

    @property
    def control_dt(self) -> float:
        """Simulated seconds per env step (``dt * k``)."""
        return self.dt * self.k

    def reset(
        self, *, seed: int | None = None, options: dict[str, Any] | None = None
    ) -> tuple[Any, dict[str, Any]]:
        super().reset(seed=seed)
        self.sim_time = 0.0
        self.elapsed_steps = 0
        self.task.reset(self.np_random, options)
        obs = self.task.observe()
        info = dict(self.task.info())
        if not _all_finite(obs) or self.task.diverged():
            raise FloatingPointError(
                f"{type(self.task).__name__}.reset produced a non-finite or diverged state"
            )
        return obs, info

    def step(self, action: Any) -> tuple[Any, float, bool, bool, dict[str, Any]]:
        task = self.task
        action = prepare_action(action, self.action_space, None, self.invalid_action)
        task.apply_action(action)
        self._advance.run(self.sim_time, self.k)
        self.sim_time += self.k * self.dt
        self.elapsed_steps += 1
        obs = task.observe()
        reward = float(task.reward(action, obs))
        terminated = bool(task.terminated(obs))
        truncated = bool(task.truncated(obs))
        info = dict(task.info())
        if not (math.isfinite(reward) and _all_finite(obs)) or task.diverged():
            obs = _zero_non_finite(obs)
            reward = reward if math.isfinite(reward) else 0.0
            terminated = True
            info["diverged"] = True
        if self.max_episode_steps is not None and self.elapsed_steps >= self.max_episode_steps:
            truncated = True
        return obs, reward, terminated, truncated, info

    def render(self) -> np.ndarray | None:
        if self.render_mode is None:
            gym.logger.warn("render() called with render_mode=None; pass render_mode='rgb_array'")
            return None
        return self.task.render()

    def close(self) -> None:
        self.task.close()
        super().close()
