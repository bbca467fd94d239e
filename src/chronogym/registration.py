"""Gymnasium ids for chronogym tasks: ``gymnasium.make("chronogym/CartPole-v0")``.

Each id has an entry point (:func:`make_sim_env`: the SimEnv, whose ``spec`` shows the
task's horizon) and a vector entry point (:func:`make_task_vector_env`: a RayVectorEnv, or
another backend, for ``gymnasium.make_vec(..., vectorization_mode="vector_entry_point")``).
Plain Gymnasium envs that are not tasks (:data:`ENVS`: ``chronogym/Synthetic-v0``) have
their own entry points, and vector entry points built on :func:`make_vector_env`.
"""

from __future__ import annotations

import functools
import importlib
import warnings
from collections.abc import Callable, Mapping
from typing import TYPE_CHECKING, Any

import gymnasium as gym

if TYPE_CHECKING:
    from gymnasium.envs.registration import EnvSpec

    from chronogym.env import SimEnv
    from chronogym.task import Task

NAMESPACE = "chronogym"
ENTRY_POINT = "chronogym.registration:make_sim_env"
VECTOR_ENTRY_POINT = "chronogym.registration:make_task_vector_env"

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

# Plain Gymnasium envs (not Tasks): (entry point, vector entry point); the id's keyword
# arguments go to the env's constructor.
ENVS: dict[str, tuple[str, str]] = {
    "Synthetic-v0": (
        "chronogym.testing.synthetic:SyntheticEnv",
        "chronogym.testing.synthetic:make_synthetic_vector_env",
    ),
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


def make_task_vector_env(
    num_envs: int,
    *,
    backend: str = "ray",
    vector_options: Mapping[str, Any] | None = None,
    **env_kwargs: Any,
) -> gym.vector.VectorEnv:
    """The vector entry point of every registered task: ``num_envs`` envs on ``backend``.

    ``gymnasium.make_vec(id, n, vectorization_mode="vector_entry_point", **kwargs)`` calls
    it with the id's registered keyword arguments updated by ``kwargs``. ``backend`` is one
    of ``chronogym.make_vec``'s (``"ray"``: RayVectorEnv, the default; ``"serial"``,
    ``"sync"``, ``"async"``); ``vector_options`` go to that vector env's constructor
    (``envs_per_worker``, ``num_cpus``, ``autoreset_mode``...); every other keyword
    argument goes to :func:`make_sim_env` (the task's arguments, ``render_mode``...).
    """
    factory = functools.partial(make_sim_env, **env_kwargs)
    return make_vector_env(factory, num_envs, backend=backend, vector_options=vector_options)


def make_vector_env(
    factory: Callable[[], gym.Env],
    num_envs: int,
    *,
    backend: str = "ray",
    vector_options: Mapping[str, Any] | None = None,
) -> gym.vector.VectorEnv:
    """``num_envs`` envs built by ``factory`` on ``backend`` (see
    :func:`make_task_vector_env`), ``vector_options`` to the vector env's constructor."""
    from chronogym.vector.factory import BACKENDS

    if backend not in BACKENDS:
        raise ValueError(f"backend={backend!r}: expected one of {BACKENDS}")
    if vector_options is None:
        vector_options = {}
    if not isinstance(vector_options, Mapping):
        raise TypeError(
            f"vector_options={vector_options!r}: expected a dict of the {backend!r} vector "
            "env's keyword arguments (Gymnasium refuses vector_kwargs in this mode)"
        )
    if backend == "ray":
        from chronogym.vector.ray_vector_env import RayVectorEnv

        return RayVectorEnv(factory, num_envs, **vector_options)
    if backend == "serial":
        from chronogym.vector.serial import SerialVectorEnv

        return SerialVectorEnv(factory, num_envs, **vector_options)
    vector_cls = gym.vector.SyncVectorEnv if backend == "sync" else gym.vector.AsyncVectorEnv
    return vector_cls([factory] * num_envs, **vector_options)


def _same_registration(spec: EnvSpec, kwargs: dict[str, Any]) -> bool:
    """True when ``spec`` is this module's registration with these keyword arguments."""
    if spec.entry_point != ENTRY_POINT or spec.vector_entry_point != VECTOR_ENTRY_POINT:
        return False
    try:
        return bool(spec.kwargs == kwargs)
    except Exception:  # e.g. numpy arrays among the defaults: not provably the same
        return False


def register_task(env_id: str, task: str | type[Task], **default_kwargs: Any) -> None:
    """Register a Task under a Gymnasium id; keyword arguments of ``make`` reach the Task.

    Registering the same task and arguments again does nothing. Another task (a class
    defined again in a notebook counts as another) or other arguments replace the old
    registration, with a warning that names both.
    """
    kwargs = {"task": task, **default_kwargs}
    old = gym.registry.get(env_id)
    if old is not None:
        if _same_registration(old, kwargs):
            return
        old_task = old.kwargs.get("task", old.entry_point)
        warnings.warn(
            f"register_task({env_id!r}): replacing the registered {_name(old_task)} "
            f"(kwargs {old.kwargs}) with {_name(task)} (kwargs {kwargs})",
            UserWarning,
            stacklevel=2,
        )
        del gym.registry[env_id]  # Gymnasium would warn once more
    gym.register(
        id=env_id,
        entry_point=ENTRY_POINT,
        vector_entry_point=VECTOR_ENTRY_POINT,
        kwargs=kwargs,
    )


def _name(task: Any) -> str:
    if isinstance(task, type):
        return f"{task.__module__}.{task.__qualname__}"
    return repr(task)


def register_envs() -> None:
    """Register every task and plain env shipped with chronogym (idempotent)."""
    for name, path in {**TASKS, **OPTIONAL_TASKS}.items():
        register_task(f"{NAMESPACE}/{name}", path)
    for name, (entry_point, vector_entry_point) in ENVS.items():
        if f"{NAMESPACE}/{name}" not in gym.registry:
            gym.register(
                id=f"{NAMESPACE}/{name}",
                entry_point=entry_point,
                vector_entry_point=vector_entry_point,
            )
    from chronogym.vector.driver_registry import note_import_ids

    note_import_ids()  # what a worker has too: the ids registered later are the script's
