"""SimEnv: a gymnasium.Env built from a Task."""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.envs.registration import EnvSpec

from chronogym.actions import check_invalid_action_mode, prepare_action
from chronogym.advance import Advancer
from chronogym.errors import RenderModeError, TaskDefinitionError
from chronogym.task import FunctionTask, Task, check_dt, check_task_definition, check_task_spaces
from chronogym.validation import check_int, show

#: Spaces whose elements are arrays of one shape and dtype (checked by shape and dtype).
_ARRAY_SPACES = (
    gym.spaces.Box,
    gym.spaces.Discrete,
    gym.spaces.MultiDiscrete,
    gym.spaces.MultiBinary,
)


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


def _observation_problem(obs: Any, space: gym.Space, path: str = "") -> tuple[str, str] | None:
    """What came back and what was expected when ``obs`` does not fit ``space`` (its shape,
    dtype or structure); None when it fits.

    Array spaces: the shape must match and the dtype must cast to the space's by NumPy's
    ``same_kind`` rule (float64 for a float32 Box passes, as Gymnasium's vector envs cast
    it; float for an integer space does not). Tuple and Dict: part by part. Other spaces:
    ``space.contains(obs)``. ``path`` names the part, e.g. ``obs['arm']``.
    """
    got = f"{path}: " if path else ""
    where = f"{path} in the observation space" if path else "the observation space"
    if isinstance(space, _ARRAY_SPACES):
        try:
            array = np.asarray(obs)
        except (ValueError, TypeError):  # ragged lists, objects NumPy cannot read
            array = None
        if array is not None and array.dtype != object:
            if array.shape == space.shape and np.can_cast(array.dtype, space.dtype, "same_kind"):
                return None
            kind = (
                "" if isinstance(obs, (np.ndarray, np.generic)) else f"a {type(obs).__name__} of "
            )
            got += f"{kind}shape {array.shape} {array.dtype}"
        else:
            got += f"a {type(obs).__name__} {show(obs)}"
        return got, (
            f"{where} is {space}: "
            f"expected shape {space.shape} and {space.dtype} (or a dtype NumPy casts to it)"
        )
    if isinstance(space, gym.spaces.Tuple):
        if not isinstance(obs, tuple) or len(obs) != len(space.spaces):
            size = f" of length {len(obs)}" if isinstance(obs, (tuple, list)) else ""
            return (
                f"{got}a {type(obs).__name__}{size}",
                f"{where} is {space}: expected a tuple of {len(space.spaces)}",
            )
        parts = enumerate(zip(obs, space.spaces, strict=True))
        found = (_observation_problem(o, s, f"{path or 'obs'}[{i}]") for i, (o, s) in parts)
        return next((problem for problem in found if problem), None)
    if isinstance(space, gym.spaces.Dict):
        if not isinstance(obs, dict) or set(obs) != set(space.spaces):
            keys = f" with keys {sorted(obs, key=str)}" if isinstance(obs, dict) else ""
            return (
                f"{got}a {type(obs).__name__}{keys}",
                f"{where} is {space}: expected a dict with keys {sorted(space.spaces, key=str)}",
            )
        items = space.spaces.items()
        found = (_observation_problem(obs[k], s, f"{path or 'obs'}[{k!r}]") for k, s in items)
        return next((problem for problem in found if problem), None)
    try:
        if space.contains(obs):
            return None
    except NotImplementedError:  # a custom space without contains(): nothing to check
        return None
    return f"{got}a {type(obs).__name__} {show(obs)}", f"{where} is {space}: not an element of it"


def check_observation(task: Task, obs: Any, space: gym.Space, where: str) -> None:
    """Raise TaskDefinitionError when ``obs``, what ``task.observe()`` returned in ``where``
    (``"reset()"``, ``"step()"``), does not fit ``space``; the message names the task, the
    space and what came back."""
    problem = _observation_problem(obs, space)
    if problem is None:
        return
    if isinstance(task, FunctionTask):
        fn = task._fns["observe"]
        who = f"FunctionTask's observe={getattr(fn, '__qualname__', fn)}"
    else:
        who = f"{type(task).__name__}.observe()"
    got, expected = problem
    raise TaskDefinitionError(f"{who} returned {got} in {where}; {expected}")


def _usable_render_modes(task: Task, render_mode: Any) -> list[str]:
    """The task's render modes if this process can render them, else ``[]``.

    Raise RenderModeError (a ValueError) when ``render_mode`` is not None and not one of them.
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
    if reason:  # the reason says what to set up; until then, only None works here
        raise RenderModeError(
            f"render_mode={render_mode!r}: {why}; until then, expected render_mode=None "
            "(runs without rendering)"
        )
    expected = " or ".join(repr(m) for m in [None, *usable])
    raise RenderModeError(f"render_mode={render_mode!r}: {why}; expected {expected}")


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
    The observation of every ``reset`` and of the first ``step`` is checked against
    ``observation_space`` (shape, and a dtype that casts to the space's): a mismatch raises
    TaskDefinitionError naming the task, the space and what came back.
    """

    _spec: EnvSpec | None = None

    @property
    def spec(self) -> EnvSpec | None:  # type: ignore[override]
        """The spec ``gymnasium.make`` gave this env, whose ``max_episode_steps`` is the
        task's horizon where the registry sets none. The horizon stays the env's own:
        ``gymnasium.make`` adds a ``TimeLimit`` only for a ``max_episode_steps`` it is given."""
        return self._spec

    @spec.setter
    def spec(self, value: EnvSpec | None) -> None:
        if value is not None and value.max_episode_steps is None:
            value = dataclasses.replace(value, max_episode_steps=self.max_episode_steps)
        self._spec = value

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
        check_dt(task)  # again: init() may have set it (MujocoTask: from the model)
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
        self._check_step_obs = True  # the first step's observation is checked, then none

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
        check_observation(self.task, obs, self.observation_space, "reset()")
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
        if self._check_step_obs:
            check_observation(task, obs, self.observation_space, "step()")
            self._check_step_obs = False
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
