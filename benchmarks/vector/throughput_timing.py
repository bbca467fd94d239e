"""The timed loops of the cart-pole throughput benchmarks (``throughput.py``, ``socket_spin.py``).

Not a script. The task: ``chronogym/CartPole-v0`` with ``terminate=False`` (endless episodes,
so every env step costs the same physics; see ``throughput.py``). Here: the raw MuJoCo loop
(the normaliser of every efficiency), the cost levels (``k`` per physics target), one SimEnv,
a vector env's barrier ``step`` and its ``send`` / ``recv(min_envs)`` loop, and the one local
Ray cluster a run uses.
"""

from __future__ import annotations

import os
import time
from dataclasses import dataclass
from typing import Any

import gymnasium as gym
import numpy as np

from benchmarks.common import Column
from chronogym.ray_runtime import WORKER_NICENESS, worker_niceness_env
from chronogym.tasks.cartpole import CartPoleTask
from chronogym.vector.ray_vector_env import default_transport

ENV_ID = "chronogym/CartPole-v0"
DT = 0.002
#: Task arguments besides ``k``: endless episodes, so every step costs the same physics.
TASK_KWARGS = {"dt": DT, "terminate": False}
#: RayVectorEnv transport -> row label.
TRANSPORT_BACKENDS = {"actor": "ray", "socket": "ray-sock"}
DEFAULT_TRANSPORT = default_transport()  # what RayVectorEnv(transport=None) uses
RAW_MIN_SECONDS = 0.5  # shortest timing of the raw loop
RAY_SETTLE_S = 2.0  # let a fresh Ray cluster's processes finish starting before timing
#: The table columns of a vector env's shape: num_envs, workers, envs_per_worker (the fields
#: of that name where a row is an object).
SHAPE_COLUMNS = (
    Column("N", 3, key="num_envs"),
    Column("wrk", 3, key="workers"),
    Column("e/w", 3, key="envs_per_worker"),
)


@dataclass(frozen=True)
class CostLevel:
    """One physics cost per env step: the target and the ``k`` chosen for it.

    What a step really costs is measured by the level's raw-loop config.
    """

    target_us: float
    k: int


# -- single env: raw MuJoCo loop and SimEnv ---------------------------------------------------


def raw_task(k: int) -> CartPoleTask:
    """The cart-pole task with its model and data built, outside any Gymnasium env."""
    task = CartPoleTask(k=k, **TASK_KWARGS)
    task.init()
    return task


def run_raw(k: int, seconds: float, seed: int) -> tuple[int, float]:
    """Tight loop: set the control, ``mj_step(nstep=k)``, observe; reset when the pole falls.

    Returns (env steps, seconds). Resets are timed but not counted as steps.
    """
    import mujoco

    task = raw_task(k)
    model, data, step = task.model, task.data, mujoco.mj_step
    rng = np.random.default_rng(seed)
    task.reset(rng, None)
    steps, start = 0, time.perf_counter()
    while True:
        data.ctrl[0] = rng.uniform(-1.0, 1.0)
        step(model, data, nstep=k)
        obs = task.observe()
        steps += 1
        if task.terminated(obs):
            task.reset(rng, None)
        elapsed = time.perf_counter() - start
        if elapsed >= seconds and steps >= 3:
            return steps, elapsed


def measure_tick_us(seconds: float, seed: int) -> float:
    """Cost of one physics tick (``mj_step``) in the raw loop, in µs."""
    k = 100
    steps, elapsed = run_raw(k, seconds, seed)
    return elapsed / (steps * k) * 1e6


def choose_levels(targets_us: list[float], tick_us: float) -> list[CostLevel]:
    """A ``k`` per target physics cost per env step (at least 1 tick)."""
    return [CostLevel(target, max(1, round(target / tick_us))) for target in targets_us]


def run_simenv(k: int, seconds: float, seed: int) -> tuple[int, float]:
    """``gymnasium.make(...).unwrapped`` stepped with random actions, reset on done."""
    env = gym.make(ENV_ID, k=k, **TASK_KWARGS).unwrapped
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    steps, start = 0, time.perf_counter()
    try:
        while True:
            action = rng.uniform(-1.0, 1.0, size=(1,)).astype(np.float32)
            _, _, terminated, truncated, _ = env.step(action)
            steps += 1
            if terminated or truncated:
                env.reset()
            elapsed = time.perf_counter() - start
            if elapsed >= seconds and steps >= 3:
                return steps, elapsed
    finally:
        env.close()


# -- vector envs: the barrier step and send / recv ------------------------------------------


def step_vector(
    env: gym.vector.VectorEnv, rng: np.random.Generator, done: np.ndarray
) -> tuple[int, np.ndarray]:
    """One vector step with random actions; returns (envs that ran physics, new done mask)."""
    actions = rng.uniform(-1.0, 1.0, size=(env.num_envs, 1)).astype(np.float32)
    _, _, terminated, truncated, _ = env.step(actions)
    return int(env.num_envs - done.sum()), np.logical_or(terminated, truncated)


def time_vector_env(
    env: gym.vector.VectorEnv, seconds: float, warmup: int, seed: int
) -> tuple[int, int, float]:
    """Reset, warm up, then step for ``seconds``; returns (vector steps, sim steps, seconds)."""
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    done = np.zeros(env.num_envs, dtype=np.bool_)
    for _ in range(warmup):
        _, done = step_vector(env, rng, done)
    calls, sim_steps, start = 0, 0, time.perf_counter()
    while True:
        ran, done = step_vector(env, rng, done)
        calls, sim_steps = calls + 1, sim_steps + ran
        elapsed = time.perf_counter() - start
        if elapsed >= seconds and calls >= 3:
            return calls, sim_steps, elapsed


def recv_and_send(
    env: Any, min_envs: int, rng: np.random.Generator, done: np.ndarray
) -> tuple[int, int]:
    """One ``recv(min_envs)``, then send the answered envs random actions.

    Returns (envs received, envs among them that ran physics); updates ``done``.
    """
    _, _, terminated, truncated, _, ids = env.recv(min_envs=min_envs)
    ran = int(len(ids) - done[ids].sum())
    done[ids] = np.logical_or(terminated, truncated)
    env.send(rng.uniform(-1.0, 1.0, size=(len(ids), 1)).astype(np.float32), ids)
    return len(ids), ran


def time_async_env(
    env: Any, min_envs: int, seconds: float, warmup: int, seed: int
) -> tuple[int, int, int, float]:
    """Like time_vector_env with send/recv; returns (recvs, env steps, sim steps, seconds)."""
    rng = np.random.default_rng(seed)
    env.reset(seed=seed)
    done = np.zeros(env.num_envs, dtype=np.bool_)
    env.send(rng.uniform(-1.0, 1.0, size=(env.num_envs, 1)).astype(np.float32))
    for _ in range(warmup * 2):
        recv_and_send(env, min_envs, rng, done)
    calls, steps, sim_steps, start = 0, 0, 0, time.perf_counter()
    try:
        while True:
            got, ran = recv_and_send(env, min_envs, rng, done)
            calls, steps, sim_steps = calls + 1, steps + got, sim_steps + ran
            elapsed = time.perf_counter() - start
            if elapsed >= seconds and calls >= 3:
                return calls, steps, sim_steps, elapsed
    finally:
        env.recv()  # drain what is still in flight


def start_ray(num_cpus: int | None = None) -> None:
    """One local Ray cluster for the whole run (``num_cpus``: default this machine's), its
    workers at chronogym's nice value (0), as ``chronogym.ray_runtime.ensure_ray`` starts
    one; RayVectorEnv then reuses it."""
    import ray

    extra = worker_niceness_env(WORKER_NICENESS)
    os.environ.update(extra)  # read by the raylet that ray.init starts
    try:
        ray.init(
            address="local",
            num_cpus=num_cpus or os.cpu_count(),
            include_dashboard=False,
            log_to_driver=False,
            logging_level="ERROR",
        )
    finally:
        for key in extra:
            os.environ.pop(key, None)
    time.sleep(RAY_SETTLE_S)
