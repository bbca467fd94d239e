"""Gymnasium ids for chronogym tasks: ``gymnasium.make("chronogym/CartPole-v0")``."""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

import gymnasium as gym

if TYPE_CHECKING:
    from chronogym.env import SimEnv
    from chronogym.task import Task

NAMESPACE = "chronogym"

TASKS: dict[str, str] = {
    "CartPole-v0": "chronogym.tasks.cartpole.mujoco:CartPoleTask",
    "Go1Velocity-v0": "chronogym.tasks.quadruped.task:Go1VelocityTask",
}

# Tasks on an optional engine: registered all the same (the id resolves lazily), but
# ``gymnasium.make`` raises an error naming the missing package and how to install it.
OPTIONAL_TASKS: dict[str, str] = {
    "ChronoCartPole-v0": "chronogym.tasks.cartpole.chrono:ChronoCartPoleTask",  # pychrono
    "ChronoGo1Velocity-v0": "chronogym.tasks.quadruped.chrono_task:ChronoGo1VelocityTask",
}


def load_task_class(path: str) -> type[Task]:
    """Import ``"package.module:ClassName"`` and return the Task class."""
    module_name, _, attr = path.partition(":")
    if not attr:
        raise ValueError(f"task={path!r}: expected 'package.module:TaskClass'")
    return getattr(importlib.import_module(module_name), attr)


def make_sim_env(
    task: str | type[Task],
    render_mode: str | None = None,
    max_episode_steps: int | None = None,
    invalid_action: str = "raise",
    **task_kwargs: Any,
) -> SimEnv:
    """Build a SimEnv from a Task class (or its import path) and its keyword arguments."""
    from chronogym.env import SimEnv  # here: `import chronogym` registers ids, loads no env

    task_cls = load_task_class(task) if isinstance(task, str) else task
    return SimEnv(
        task_cls(**task_kwargs),
        render_mode=render_mode,
        max_episode_steps=max_episode_steps,
        invalid_action=invalid_action,
    )


def register_task(env_id: str, task: str | type[Task], **default_kwargs: Any) -> None:
    """Register a Task under a Gymnasium id; keyword arguments of ``make`` reach the Task."""
    if env_id in gym.registry:
        return
    gym.register(
        id=env_id,
        entry_point="chronogym.registration:make_sim_env",
        kwargs={"task": task, **default_kwargs},
    )


def register_envs() -> None:
    """Register every task shipped with chronogym (idempotent)."""
    for name, path in {**TASKS, **OPTIONAL_TASKS}.items():
        register_task(f"{NAMESPACE}/{name}", path)
