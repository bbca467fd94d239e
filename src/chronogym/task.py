"""The Task contract: a simulation described by small, explicitly scoped pieces.

A :class:`Task` is what a user writes; :class:`chronogym.SimEnv` turns it into a
``gymnasium.Env``. The pieces and when they run:

==================  ==========================================================
``init()``          once per process: build the advanceables and resources
``reset(rng, o)``   every episode: restore initial conditions by *mutating*
``apply_action(a)`` once per env step, before the physics ticks
(``k`` ticks)       ``advance_all(self.advanceables, dt)``, k times
``observe()``       after the ticks
``reward(a, obs)``  after ``observe``
``terminated(obs)`` solved or irrecoverably failed
``truncated(obs)``  external cutoff (the time limit is SimEnv's job)
==================  ==========================================================

Two forms share this one implementation: subclass :class:`Task`, or pass plain
functions to :class:`FunctionTask`, which is itself a Task.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np

from chronogym.errors import TaskDefinitionError
from chronogym.validation import invalid, is_int, is_number

REQUIRED_METHODS = ("init", "reset", "apply_action", "observe", "reward", "terminated")
# What ``SimEnv.render()`` can return: ``task.render()`` takes no mode, so one mode at most.
RENDER_MODES = ("rgb_array",)


class Task:
    """Base class of an instrumented simulation.

    Subclasses set ``dt`` (physics step, seconds), ``k`` (physics ticks per
    env step), and in ``init`` build ``self.advanceables`` plus
    ``self.observation_space`` / ``self.action_space`` (class attributes work
    too). Optional: ``max_episode_steps``, ``truncated``, ``info``,
    ``diverged``, ``render``, ``close``. A task that renders declares it with
    ``render_modes = ("rgb_array",)`` and implements ``render()``.
    """

    dt: float
    dt_from_init: bool = False
    """True when ``init()`` may set ``dt`` (``MujocoTask``: from the model's timestep);
    ``dt = None`` is then checked after ``init()``."""
    k: int = 1
    max_episode_steps: int | None = None
    observation_space: Any = None
    action_space: Any = None
    advanceables: Sequence[Any] = ()
    render_fps: float | None = None
    render_modes: tuple[str, ...] = ()
    """Render modes this task supports: ``()`` (none) or ``("rgb_array",)``."""

    def init(self) -> None:
        """Build advanceables and resources once; heavy work belongs here."""
        raise NotImplementedError

    def reset(self, rng: np.random.Generator, options: dict[str, Any] | None) -> None:
        """Restore initial conditions for a new episode by mutating what ``init`` built."""
        raise NotImplementedError

    def apply_action(self, action: Any) -> None:
        """Map an action onto the simulation (actuator targets, forces, driver inputs)."""
        raise NotImplementedError

    def observe(self) -> Any:
        """Return the observation of the current state."""
        raise NotImplementedError

    def reward(self, action: Any, obs: Any) -> float:
        """Return the reward of the step that just happened."""
        raise NotImplementedError

    def terminated(self, obs: Any) -> bool:
        """Return True when the task is solved or has irrecoverably failed."""
        raise NotImplementedError

    def truncated(self, obs: Any) -> bool:
        """Return True on an external cutoff. The time limit is handled by SimEnv."""
        return False

    def info(self) -> dict[str, Any]:
        """Return the info dict of the last reset or step."""
        return {}

    def diverged(self) -> bool:
        """Return True when the simulation state is numerically broken (NaN/Inf, blow-up)."""
        return False

    def render(self) -> np.ndarray | None:
        """Return an RGB frame (H, W, 3) uint8, or raise NotImplementedError."""
        raise NotImplementedError(f"{type(self).__name__} does not implement render()")

    def render_unavailable(self) -> str | None:
        """Why this process cannot render the declared modes (e.g. no OpenGL), or None.

        Called once by ``SimEnv`` before ``init()``; keep it cheap.
        """
        return None

    def close(self) -> None:
        """Release resources (renderers, files)."""


def is_overridden(task: Task, name: str) -> bool:
    """True when ``task`` provides its own ``name`` rather than Task's placeholder."""
    own = getattr(type(task), name, None)
    return own is not None and own is not getattr(Task, name, None)


def check_task_definition(task: Task) -> None:
    """Raise TaskDefinitionError when a piece is missing or ``dt``/``k`` are invalid."""
    if not isinstance(task, Task):
        raise TaskDefinitionError(
            f"expected a chronogym.Task instance, got {type(task).__name__}: {task!r}"
        )
    missing = [name for name in REQUIRED_METHODS if not is_overridden(task, name)]
    if missing:
        raise TaskDefinitionError(
            f"Task {type(task).__name__} is missing {', '.join(m + '()' for m in missing)}; "
            f"every Task must define {', '.join(REQUIRED_METHODS)}"
        )
    if not (task.dt_from_init and getattr(task, "dt", None) is None):
        check_dt(task)
    k = getattr(task, "k", None)
    if not (is_int(k) and k >= 1):
        raise invalid(f"Task {type(task).__name__}: k={k!r}, expected an integer >= 1", k)
    check_render_modes(task)
    steps = task.max_episode_steps
    if steps is not None and not (is_int(steps) and steps >= 1):
        raise invalid(
            f"Task {type(task).__name__}: max_episode_steps={steps!r}, "
            "expected None or an integer >= 1",
            steps,
        )


def check_dt(task: Task) -> None:
    """Raise TaskDefinitionError unless the task's ``dt`` is a finite float > 0."""
    dt = getattr(task, "dt", None)
    if not (is_number(dt) and math.isfinite(dt) and dt > 0):
        raise invalid(f"Task {type(task).__name__}: dt={dt!r}, expected a finite float > 0", dt)


def check_render_modes(task: Task) -> None:
    """Raise TaskDefinitionError unless ``render_modes`` is ``()`` or ``("rgb_array",)``
    and a task declaring a mode implements ``render()``."""
    name = type(task).__name__
    modes = task.render_modes
    if not isinstance(modes, (tuple, list)) or any(m not in RENDER_MODES for m in modes):
        raise TaskDefinitionError(
            f"Task {name}: render_modes={modes!r}, expected () or {RENDER_MODES!r}"
        )
    if modes and not is_overridden(task, "render"):
        raise TaskDefinitionError(
            f"Task {name} declares render_modes={modes!r} but does not implement render()"
        )


def check_task_spaces(task: Task) -> None:
    """Raise TaskDefinitionError when ``init`` left the spaces undefined."""
    for name in ("observation_space", "action_space"):
        space = getattr(task, name, None)
        if not isinstance(space, gym.spaces.Space):
            raise TaskDefinitionError(
                f"Task {type(task).__name__}.{name} is {space!r} after init(); "
                "expected a gymnasium.spaces.Space"
            )


class FunctionTask(Task):
    """A Task assembled from plain functions.

    ``init()`` returns ``(advanceables, resources)``; every other function
    receives ``resources`` first, e.g. ``observe(resources) -> obs``,
    ``reward(resources, action, obs) -> float``. ``observation_space`` and
    ``action_space`` are given directly or as ``fn(resources) -> Space``.
    It renders (``render_modes == ("rgb_array",)``) iff ``render`` is given.
    """

    def __init__(
        self,
        *,
        init: Callable[[], tuple[Sequence[Any], Any]],
        reset: Callable[[Any, np.random.Generator, dict[str, Any] | None], None],
        apply_action: Callable[[Any, Any], None],
        observe: Callable[[Any], Any],
        reward: Callable[[Any, Any, Any], float],
        terminated: Callable[[Any, Any], bool],
        dt: float,
        k: int = 1,
        observation_space: Any = None,
        action_space: Any = None,
        truncated: Callable[[Any, Any], bool] | None = None,
        info: Callable[[Any], dict[str, Any]] | None = None,
        diverged: Callable[[Any], bool] | None = None,
        render: Callable[[Any], np.ndarray] | None = None,
        close: Callable[[Any], None] | None = None,
        max_episode_steps: int | None = None,
    ) -> None:
        pieces = {
            "init": init,
            "reset": reset,
            "apply_action": apply_action,
            "observe": observe,
            "reward": reward,
            "terminated": terminated,
        }
        for name, fn in pieces.items():
            if not callable(fn):
                raise TaskDefinitionError(f"FunctionTask: {name}={fn!r}, expected a callable")
        optional = {
            "truncated": truncated,
            "info": info,
            "diverged": diverged,
            "render": render,
            "close": close,
        }
        for name, fn in optional.items():
            if fn is not None and not callable(fn):
                raise TaskDefinitionError(
                    f"FunctionTask: {name}={fn!r}, expected a callable or None"
                )
        self._fns = {**pieces, **{n: f for n, f in optional.items() if f is not None}}
        self.render_modes = RENDER_MODES if render is not None else ()
        self._space_sources = (observation_space, action_space)
        self.dt = dt
        self.k = k
        self.max_episode_steps = max_episode_steps
        self.resources: Any = None

    def init(self) -> None:
        built = self._fns["init"]()
        if not (isinstance(built, tuple) and len(built) == 2):
            raise TaskDefinitionError(
                f"FunctionTask: init() returned {type(built).__name__}, "
                "expected a tuple (advanceables, resources)"
            )
        self.advanceables, self.resources = list(built[0]), built[1]
        obs_space, act_space = self._space_sources
        self.observation_space = obs_space(self.resources) if callable(obs_space) else obs_space
        self.action_space = act_space(self.resources) if callable(act_space) else act_space

    def reset(self, rng: np.random.Generator, options: dict[str, Any] | None) -> None:
        self._fns["reset"](self.resources, rng, options)

    def apply_action(self, action: Any) -> None:
        self._fns["apply_action"](self.resources, action)

    def observe(self) -> Any:
        return self._fns["observe"](self.resources)

    def reward(self, action: Any, obs: Any) -> float:
        return self._fns["reward"](self.resources, action, obs)

    def terminated(self, obs: Any) -> bool:
        return self._fns["terminated"](self.resources, obs)

    def truncated(self, obs: Any) -> bool:
        fn = self._fns.get("truncated")
        return fn(self.resources, obs) if fn else False

    def info(self) -> dict[str, Any]:
        fn = self._fns.get("info")
        return fn(self.resources) if fn else {}

    def diverged(self) -> bool:
        fn = self._fns.get("diverged")
        return fn(self.resources) if fn else False

    def render(self) -> np.ndarray | None:
        fn = self._fns.get("render")
        if fn is None:
            raise NotImplementedError("this FunctionTask was given no render function")
        return fn(self.resources)

    def close(self) -> None:
        fn = self._fns.get("close")
        if fn is not None:
            fn(self.resources)
