"""The sweep of ``throughput.py``: which configurations it measures, and measuring one.

Not a script. Per cost level: the raw loop and one SimEnv, then at each ``--num-envs``
SerialVectorEnv, gymnasium's AsyncVectorEnv and RayVectorEnv at 1 and 2 workers (plus one env
per worker at ``--one-per-worker``) for each transport of the run, and with ``--async-k`` the
``send`` / ``recv(min_envs=N/2)`` rows. The numbers derived from the results (ratio to
AsyncVectorEnv, efficiency) and the tables are in ``throughput_report.py``.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import dataclass, field

import gymnasium as gym
from tqdm import tqdm

import chronogym
from benchmarks.vector.throughput_timing import (
    DEFAULT_TRANSPORT,
    ENV_ID,
    RAW_MIN_SECONDS,
    TASK_KWARGS,
    TRANSPORT_BACKENDS,
    CostLevel,
    choose_levels,
    run_raw,
    run_simenv,
    start_ray,
    time_async_env,
    time_vector_env,
)

BACKEND_TRANSPORTS = {row: transport for transport, row in TRANSPORT_BACKENDS.items()}
VECTOR_BACKENDS = ("serial", "async", "ray", "ray-sock", "ray-async")


@dataclass(frozen=True)
class Config:
    """One measured configuration."""

    backend: str  # raw | simenv | serial | async | ray | ray-sock | ray-async
    num_envs: int
    workers: int  # processes stepping envs (1 for raw, simenv, serial)
    envs_per_worker: int
    level: CostLevel
    min_envs: int = 0  # ray-async: recv(min_envs=...); 0 for the others


@dataclass
class Result:
    """What one configuration measured."""

    config: Config
    env_steps: int  # as Gymnasium counts them (autoreset steps included)
    sim_steps: int  # env steps that ran physics
    calls: int  # vector steps (recv calls for ray-async; single-env steps for raw, simenv)
    seconds: float
    setup_s: float
    derived: dict[str, float | None] = field(default_factory=dict)

    @property
    def steps_per_s(self) -> float:
        """Env steps per second, Gymnasium's count."""
        return self.env_steps / self.seconds

    @property
    def sim_steps_per_s(self) -> float:
        """Env steps that ran physics, per second."""
        return self.sim_steps / self.seconds

    @property
    def us_per_call(self) -> float:
        """Wall time of one vector step (one env step for raw and simenv), in µs."""
        return self.seconds / self.calls * 1e6


def make_vector_env(config: Config) -> gym.vector.VectorEnv:
    """Build the vector env a config names."""
    env_kwargs = {"k": config.level.k, **TASK_KWARGS}
    if config.backend == "serial":
        return chronogym.SerialVectorEnv(ENV_ID, config.num_envs, env_kwargs=env_kwargs)
    if config.backend == "async":
        return gym.make_vec(ENV_ID, config.num_envs, vectorization_mode="async", **env_kwargs)
    if config.backend in ("ray", "ray-sock", "ray-async"):
        return chronogym.RayVectorEnv(
            ENV_ID,
            config.num_envs,
            envs_per_worker=config.envs_per_worker,
            env_kwargs=env_kwargs,
            transport=BACKEND_TRANSPORTS.get(config.backend, DEFAULT_TRANSPORT),
        )
    raise ValueError(f"backend={config.backend!r}: expected one of {VECTOR_BACKENDS}")


def run_vector(config: Config, seconds: float, warmup: int, seed: int) -> Result:
    """Build, warm up, time and close one vector env."""
    start = time.perf_counter()
    env = make_vector_env(config)
    setup_s = time.perf_counter() - start
    try:
        if config.min_envs:
            calls, steps, sim_steps, elapsed = time_async_env(
                env, config.min_envs, seconds, warmup, seed
            )
        else:
            calls, sim_steps, elapsed = time_vector_env(env, seconds, warmup, seed)
            steps = calls * config.num_envs
    finally:
        env.close()
    return Result(config, steps, sim_steps, calls, elapsed, setup_s)


def run_single(config: Config, seconds: float, seed: int) -> Result:
    """Time the raw loop or one SimEnv."""
    if config.backend == "raw":  # the normaliser of every efficiency: time it a bit longer
        steps, elapsed = run_raw(config.level.k, max(seconds, RAW_MIN_SECONDS), seed)
    else:
        steps, elapsed = run_simenv(config.level.k, seconds, seed)
    return Result(config, steps, steps, steps, elapsed, 0.0)


def run_config(config: Config, args: argparse.Namespace) -> Result:
    """Measure one configuration."""
    if config.backend in ("raw", "simenv"):
        return run_single(config, args.seconds, args.seed)
    return run_vector(config, args.seconds, args.warmup, args.seed)


# -- the plan -------------------------------------------------------------------------------


def ray_shapes(num_envs: int, one_per_worker: int) -> list[tuple[int, int]]:
    """(workers, envs_per_worker) points for RayVectorEnv: 1 and 2 workers, maybe 1 env each."""
    shapes = []
    for workers in (1, 2):
        if workers <= num_envs:
            per = math.ceil(num_envs / workers)
            shapes.append((math.ceil(num_envs / per), per))
    if num_envs == one_per_worker:
        shapes.append((num_envs, 1))
    return list(dict.fromkeys(shapes))


def vector_configs(
    level: CostLevel,
    num_envs: int,
    one_per_worker: int,
    async_k: bool = False,
    transports: tuple[str, ...] = ("actor",),
) -> list[Config]:
    """Serial, Async and the Ray sweep (with ``async_k``: send/recv too) at one level and N."""
    configs = [
        Config("serial", num_envs, 1, num_envs, level),
        Config("async", num_envs, num_envs, 1, level),
    ]
    for workers, per in ray_shapes(num_envs, one_per_worker):
        for transport in transports:
            configs.append(Config(TRANSPORT_BACKENDS[transport], num_envs, workers, per, level))
        if async_k and workers >= 2:
            configs.append(Config("ray-async", num_envs, workers, per, level, num_envs // 2))
    return configs


def build_plan(levels: list[CostLevel], args: argparse.Namespace) -> list[Config]:
    """Every configuration, grouped by cost level so each group is measured side by side."""
    plan = []
    for level in levels:
        plan += [Config("raw", 1, 1, 1, level), Config("simenv", 1, 1, 1, level)]
        for num_envs in args.num_envs:
            plan += vector_configs(
                level, num_envs, args.one_per_worker, args.async_k, tuple(args.transports)
            )
    return plan


def run_sweep(args: argparse.Namespace, tick_us: float) -> list[Result]:
    """Every configuration of the plan, on one local Ray cluster."""
    import ray

    plan = build_plan(choose_levels(args.targets_us, tick_us), args)
    start_ray()
    results: list[Result] = []
    try:
        for config in tqdm(plan, desc="configs", unit="cfg", file=sys.stderr):
            results.append(run_config(config, args))
    finally:
        ray.shutdown()
    return results
