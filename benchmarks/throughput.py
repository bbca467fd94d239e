"""Throughput of chronogym's vector envs on the cart-pole task, against Gymnasium's AsyncVectorEnv.

Measures env-steps/s of ``chronogym/CartPole-v0`` for a raw MuJoCo loop, one SimEnv,
SerialVectorEnv, gymnasium's AsyncVectorEnv and RayVectorEnv (workers x envs per
worker), each at several physics costs per env step (``k`` ticks of ``dt`` = 2 ms).
Prints an aligned table and writes JSON (default ``benchmarks/results/throughput.json``).

    python benchmarks/throughput.py            # default sweep, < 4 min on 2 cores
    python benchmarks/throughput.py --quick    # smoke run, < 1 min
    python benchmarks/throughput.py --async-k  # adds RayVectorEnv send/recv with K = N/2
    python benchmarks/throughput.py --transports actor socket   # several RayVectorEnv transports
    python benchmarks/throughput.py --breakdown   # one vector step split into phases (µs)

Counting: the cart-pole runs with ``terminate=False`` (the pole may fall; episodes end
only by truncation after 500 steps), so every env step costs the same physics and no
worker waits for another because its envs happened to reset (with falling episodes,
up to half of all steps were physics-free autoresets at large ``k``, spread unevenly
over the workers). ``steps/s`` counts env steps as Gymnasium does, including the
autoreset steps of NEXT_STEP mode; ``sim-steps/s`` counts only the env steps that ran
physics; the AsyncVectorEnv ratio and the parallel efficiency use it, so they compare
like with like and against the raw single-env rate (``k`` ticks + observe per step).

``--breakdown`` replaces the sweep by a table of where one vector step's time goes (driver
prepare / submit / wait / get / join, worker compute and (de)serialization, Ray's call and
transfer) per transport and envs_per_worker at N = 16, with the CPU the workers use while idle
(polling) and the check against the overhead budget (100 µs + 5 µs per env); see
``RayVectorEnv.profile_steps``. The sweep ends with the goal table of the default transport:
x_async and efficiency per cost level side by side.

``--async-k`` adds ``ray-async`` rows: the same Ray shapes (two workers or more, default
transport) driven by ``send`` / ``recv(min_envs=N/2)``, each answered worker sent its next
actions at once, against the barrier ``step`` of the ``ray`` rows. Their
``µs/vstep`` is per ``recv``, which returns about N/2 envs.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import platform
import sys
import time
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from tqdm import tqdm

import chronogym
from chronogym.tasks.cartpole import CartPoleTask
from chronogym.vector.ray_vector_env import default_transport

ENV_ID = "chronogym/CartPole-v0"
DT = 0.002
#: Task arguments besides ``k``: endless episodes, so every step costs the same physics.
TASK_KWARGS = {"dt": DT, "terminate": False}
DEFAULT_OUT = Path(__file__).resolve().parent / "results" / "throughput.json"
BREAKDOWN_OUT = DEFAULT_OUT.with_name("throughput_breakdown.json")
# RayVectorEnv transport -> row label
TRANSPORT_BACKENDS = {"actor": "ray", "compiled": "ray-cg", "socket": "ray-sock"}
BACKEND_TRANSPORTS = {row: transport for transport, row in TRANSPORT_BACKENDS.items()}
VECTOR_BACKENDS = ("serial", "async", "ray", "ray-cg", "ray-sock", "ray-async")
DEFAULT_TRANSPORT = default_transport()  # what RayVectorEnv(transport=None) uses
RAW_MIN_SECONDS = 0.5  # shortest timing of the raw loop
RAY_SETTLE_S = 2.0  # let a fresh Ray cluster's processes finish starting before timing


@dataclass(frozen=True)
class CostLevel:
    """One physics cost per env step: the target and the ``k`` chosen for it.

    What a step really costs is measured by the level's raw-loop config.
    """

    target_us: float
    k: int


@dataclass(frozen=True)
class Config:
    """One measured configuration."""

    backend: str  # raw | simenv | serial | async | ray | ray-async
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


# -- command line ---------------------------------------------------------------------------


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Command-line options; ``--quick`` shrinks the sweep to a smoke run."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=2.0, help="timed wall time per config")
    parser.add_argument("--quick", action="store_true", help="smoke run (< 60 s)")
    parser.add_argument(
        "--num-envs", type=int, nargs="+", default=[2, 8, 16], help="num_envs values"
    )
    parser.add_argument(
        "--targets-us",
        type=float,
        nargs="+",
        default=[50.0, 500.0, 5000.0],
        help="physics cost per env step to aim for, in µs (k is chosen per target)",
    )
    parser.add_argument(
        "--one-per-worker",
        type=int,
        default=8,
        help="num_envs of the extra RayVectorEnv point with one env per worker (0: none)",
    )
    parser.add_argument(
        "--async-k",
        action="store_true",
        help="also time RayVectorEnv send/recv with min_envs = N/2 (shapes with >= 2 workers)",
    )
    parser.add_argument(
        "--transports",
        nargs="+",
        choices=tuple(TRANSPORT_BACKENDS),
        default=None,
        help=f"RayVectorEnv transports of the main sweep (default: {DEFAULT_TRANSPORT}, "
        "RayVectorEnv's default) and of --breakdown (default: all); compiled rows are "
        "labelled ray-cg, socket rows ray-sock",
    )
    parser.add_argument(
        "--breakdown",
        action="store_true",
        help="instead of the sweep: time each phase of one vector step per transport and "
        "envs_per_worker at the cheapest cost level (see --breakdown-envs)",
    )
    parser.add_argument(
        "--breakdown-envs", type=int, default=16, help="num_envs of the --breakdown table"
    )
    parser.add_argument(
        "--breakdown-per-worker",
        type=int,
        nargs="+",
        default=[16, 8, 4],
        help="envs_per_worker values of the --breakdown table",
    )
    parser.add_argument(
        "--repeat",
        type=int,
        default=3,
        help="--breakdown: rounds over every row, interleaved; the table shows medians",
    )
    parser.add_argument("--warmup", type=int, default=5, help="untimed vector steps per config")
    parser.add_argument("--seed", type=int, default=0, help="seed of envs and random actions")
    parser.add_argument(
        "--out",
        type=Path,
        default=None,
        help=f"JSON output (default {DEFAULT_OUT.name}; --breakdown: {BREAKDOWN_OUT.name})",
    )
    args = parser.parse_args(argv)
    if args.out is None:
        args.out = BREAKDOWN_OUT if args.breakdown else DEFAULT_OUT
    if args.transports is None and not args.breakdown:
        args.transports = [DEFAULT_TRANSPORT]
    if args.quick:
        args.seconds = min(args.seconds, 0.3)
        args.num_envs = [2, 8]
        args.targets_us = [50.0, 5000.0]
        args.warmup = 2
    return args


# -- machine --------------------------------------------------------------------------------


def cpu_count() -> int:
    """CPUs this process may use (the affinity mask where the OS has one)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def machine_info() -> dict[str, Any]:
    """CPU count, platform and library versions, for the JSON report."""
    import mujoco
    import ray

    return {
        "cpu_count": os.cpu_count(),
        "usable_cpus": cpu_count(),
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "python": platform.python_version(),
        "chronogym": chronogym.__version__,
        "ray": ray.__version__,
        "mujoco": mujoco.__version__,
        "gymnasium": gym.__version__,
        "numpy": np.__version__,
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
    }


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


# -- vector envs ----------------------------------------------------------------------------


def make_vector_env(config: Config) -> gym.vector.VectorEnv:
    """Build the vector env a config names."""
    env_kwargs = {"k": config.level.k, **TASK_KWARGS}
    if config.backend == "serial":
        return chronogym.SerialVectorEnv(ENV_ID, config.num_envs, env_kwargs=env_kwargs)
    if config.backend == "async":
        return gym.make_vec(ENV_ID, config.num_envs, vectorization_mode="async", **env_kwargs)
    if config.backend in ("ray", "ray-cg", "ray-sock", "ray-async"):
        return chronogym.RayVectorEnv(
            ENV_ID,
            config.num_envs,
            envs_per_worker=config.envs_per_worker,
            env_kwargs=env_kwargs,
            transport=BACKEND_TRANSPORTS.get(config.backend, DEFAULT_TRANSPORT),
        )
    raise ValueError(f"backend={config.backend!r}: expected one of {VECTOR_BACKENDS}")


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
    """Serial, Async and the Ray sweep (with ``async_k``: send/recv too) at one level and N.

    Compiled-graph rows (``ray-cg``) skip the one-env-per-worker shape: its actors poll.
    """
    configs = [
        Config("serial", num_envs, 1, num_envs, level),
        Config("async", num_envs, num_envs, 1, level),
    ]
    for workers, per in ray_shapes(num_envs, one_per_worker):
        for transport in transports:
            if transport != "compiled" or per > 1 or num_envs == 1:
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


# -- derived numbers and output -------------------------------------------------------------


def derive(results: list[Result], cpus: int) -> None:
    """Fill each result's ratio to AsyncVectorEnv, efficiency and physics per remote call."""
    raw = {r.config.level.k: r.sim_steps_per_s for r in results if r.config.backend == "raw"}
    asyncs = {
        (r.config.level.k, r.config.num_envs): r.sim_steps_per_s
        for r in results
        if r.config.backend == "async"
    }
    for r in results:
        c = r.config
        base = raw[c.level.k]
        physics_us = 1e6 / base
        ref = asyncs.get((c.level.k, c.num_envs)) if c.backend in VECTOR_BACKENDS else None
        r.derived = {
            "physics_us_per_step": physics_us,
            "physics_us_per_call": c.envs_per_worker * physics_us,
            "vs_async": r.sim_steps_per_s / ref if ref else None,
            "efficiency": r.sim_steps_per_s / (c.workers * base),
            "efficiency_per_cpu": r.sim_steps_per_s / (min(c.workers, cpus) * base),
        }


COLUMNS = (  # header, width, format
    ("phys/step", 10, "{:.0f}µs"),
    ("backend", 9, "{}"),
    ("N", 3, "{}"),
    ("wrk", 3, "{}"),
    ("e/w", 3, "{}"),
    ("phys/call", 9, "{:.2f}ms"),
    ("steps/s", 9, "{:.0f}"),
    ("sim-st/s", 9, "{:.0f}"),
    ("µs/vstep", 9, "{:.0f}"),
    ("x_async", 6, "{:.2f}"),
    ("eff", 5, "{:.2f}"),
    ("eff/cpu", 7, "{:.2f}"),
)


def row_values(r: Result) -> list[Any]:
    """The table cells of one result, in COLUMNS order."""
    c, d = r.config, r.derived
    return [
        d["physics_us_per_step"],
        c.backend,
        c.num_envs,
        c.workers,
        c.envs_per_worker,
        d["physics_us_per_call"] / 1000,  # type: ignore[operator]
        r.steps_per_s,
        r.sim_steps_per_s,
        r.us_per_call,
        d["vs_async"],
        d["efficiency"],
        d["efficiency_per_cpu"],
    ]


def format_table(results: list[Result]) -> str:
    """Aligned text table; a blank line between cost levels."""
    header = "  ".join(name.rjust(width) for name, width, _ in COLUMNS)
    lines, last_k = [header, "-" * len(header)], None
    for r in results:
        if last_k is not None and r.config.level.k != last_k:
            lines.append("")
        last_k = r.config.level.k
        cells = [
            ("-" if value is None else fmt.format(value)).rjust(width)
            for (_, width, fmt), value in zip(COLUMNS, row_values(r), strict=True)
        ]
        lines.append("  ".join(cells))
    return "\n".join(lines)


def notes(cpus: int, tick_us: float, results: list[Result]) -> str:
    """The explanations printed under the table."""
    ks = ", ".join(
        f"k={r.config.level.k} -> {r.derived['physics_us_per_step']:.0f} µs"
        for r in results
        if r.config.backend == "raw"
    )
    return "\n".join(
        [
            f"physics tick (mj_step) = {tick_us:.2f} µs; per env step (raw loop): {ks}",
            "steps/s counts autoreset steps (no physics); sim-st/s counts steps that ran "
            "physics, and x_async / eff use it.",
            "eff = sim-steps/s / (workers x raw single-env rate); eff/cpu uses min(workers, "
            "CPUs) instead; wrk = Ray workers, Async processes, 1 for serial.",
            "phys/call = envs per worker x physics per env step (what one remote call carries).",
            *(
                ["ray-async = send / recv(min_envs=N/2) (µs/vstep: per recv) vs ray's barrier."]
                if any(r.config.min_envs for r in results)
                else []
            ),
            f"NOTE: this machine has {cpus} CPU(s). More than {cpus} busy processes (Async with "
            f"N > {cpus}, Ray with more than {cpus} workers, plus the driver) oversubscribe the "
            "cores: their eff is bounded by CPUs / workers, and all numbers are noisy when the "
            "machine is shared.",
        ]
    )


def write_json(
    path: Path,
    info: dict[str, Any],
    args: argparse.Namespace,
    tick_us: float,
    results: list[Result],
) -> None:
    """Write machine info, settings, cost levels and every result as JSON."""
    levels = [
        {**asdict(r.config.level), "physics_us_per_step": r.derived["physics_us_per_step"]}
        for r in results
        if r.config.backend == "raw"
    ]
    payload = {
        "benchmark": "chronogym throughput (cart-pole)",
        "env_id": ENV_ID,
        "dt": DT,
        "task_kwargs": TASK_KWARGS,
        "machine": info,
        "settings": {
            key: (str(value) if isinstance(value, Path) else value)
            for key, value in vars(args).items()
        },
        "tick_us": tick_us,
        "default_transport": DEFAULT_TRANSPORT,
        "cost_levels": levels,
        "results": [result_record(r) for r in results],
    }
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(payload, indent=2) + "\n")


def result_record(r: Result) -> dict[str, Any]:
    """One result as a flat JSON record."""
    c = r.config
    return {
        "backend": c.backend,
        "num_envs": c.num_envs,
        "workers": c.workers,
        "envs_per_worker": c.envs_per_worker,
        "min_envs": c.min_envs or None,
        "k": c.level.k,
        "target_us": c.level.target_us,
        "env_steps": r.env_steps,
        "sim_steps": r.sim_steps,
        "calls": r.calls,
        "seconds": r.seconds,
        "setup_s": r.setup_s,
        "steps_per_s": r.steps_per_s,
        "sim_steps_per_s": r.sim_steps_per_s,
        "us_per_call": r.us_per_call,
        **r.derived,
    }


# -- goals ----------------------------------------------------------------------------------

CHEAP_X_ASYNC = 1.5  # goal on the cheapest cost level
X_ASYNC = 1.0  # goal at every cost level
EFFICIENCY = 0.9  # goal where one remote call carries >= EFFICIENCY_MIN_CALL_MS of physics
EFFICIENCY_MIN_CALL_MS = 1.0


def best_rows(results: list[Result], backend: str) -> list[Result]:
    """Per (cost level, N): the ``backend`` row with the most sim-steps/s."""
    best: dict[tuple[int, int], Result] = {}
    for r in results:
        key = (r.config.level.k, r.config.num_envs)
        if r.config.backend == backend and (
            key not in best or r.sim_steps_per_s > best[key].sim_steps_per_s
        ):
            best[key] = r
    return list(best.values())


def goal_table(results: list[Result], backend: str) -> str:
    """x_async and efficiency of ``backend``'s best shape per cost level and N, with the goals."""
    cheapest = min(r.config.level.k for r in results)
    lines = [
        f"goals for {backend} (best shape per row): x_async >= {X_ASYNC} everywhere, >= "
        f"{CHEAP_X_ASYNC} on the cheapest cost; eff >= {EFFICIENCY} where phys/call >= "
        f"{EFFICIENCY_MIN_CALL_MS:g} ms",
        f"{'phys/step':>10}  {'N':>3}  {'wrk':>3}  {'e/w':>3}  {'phys/call':>9}  "
        f"{'x_async':>7}  {'goal':>5}  {'eff':>5}  {'goal':>5}",
    ]
    for r in best_rows(results, backend):
        c, d = r.config, r.derived
        x_goal = CHEAP_X_ASYNC if c.level.k == cheapest else X_ASYNC
        x_ok = d["vs_async"] is not None and d["vs_async"] >= x_goal
        call_ms = d["physics_us_per_call"] / 1000  # type: ignore[operator]
        eff_ok = "-" if call_ms < EFFICIENCY_MIN_CALL_MS else _ok(d["efficiency"] >= EFFICIENCY)
        lines.append(
            f"{d['physics_us_per_step']:>8.0f}µs  {c.num_envs:>3}  {c.workers:>3}  "
            f"{c.envs_per_worker:>3}  {call_ms:>7.2f}ms  {d['vs_async'] or 0:>7.2f}  "
            f"{_ok(x_ok):>5}  {d['efficiency']:>5.2f}  {eff_ok:>5}"
        )
    return "\n".join(lines)


def _ok(passed: bool) -> str:
    return "ok" if passed else "MISS"


# -- per-phase breakdown (--breakdown) -----------------------------------------------------


@dataclass
class Breakdown:
    """One vector env's step split into phases (µs per vector step), and its CPU use."""

    transport: str  # actor | compiled | serial
    num_envs: int
    workers: int
    envs_per_worker: int
    k: int
    us_per_vstep: float  # wall time of an unprofiled vector step
    phases: dict[str, float]  # StepProfile.per_step_us() of a profiled run
    busy_cpu: dict[str, float]  # % of one core while stepping: workers (sum), driver
    idle_cpu: dict[str, float]  # % of one core while nobody steps: workers (sum), driver

    @property
    def overhead_us(self) -> float:
        """µs per profiled vector step that are not the slowest worker's physics."""
        return self.phases["total"] - self.phases["compute"]

    @property
    def balance(self) -> float:
        """Mean worker's physics / slowest worker's, per step (1: evenly loaded workers)."""
        mean = self.phases["compute_sum"] / self.workers
        return mean / self.phases["compute"] if self.phases["compute"] else 1.0

    @property
    def efficiency(self) -> float:
        """Share of the workers' wall time spent in physics: mean worker's physics / step."""
        return self.phases["compute_sum"] / (self.workers * self.phases["total"])

    @property
    def budget_us(self) -> float:
        """The issue's driver-overhead budget: 100 µs + 5 µs per env."""
        return 100.0 + 5.0 * self.num_envs


def proc_cpu_s(pid: int) -> float:
    """CPU seconds (user + system) process ``pid`` used so far (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def cpu_percent(pids: list[int], run: Any) -> dict[str, float]:
    """% of one core the ``pids`` (summed) and this process used while ``run()`` ran."""
    before = [proc_cpu_s(pid) for pid in pids]
    driver, start = time.process_time(), time.perf_counter()
    run()
    wall = time.perf_counter() - start
    used = sum(proc_cpu_s(pid) for pid in pids) - sum(before)
    return {
        "workers": 100 * used / wall,
        "driver": 100 * (time.process_time() - driver) / wall,
    }


def breakdown_env(transport: str, num_envs: int, per: int, k: int) -> gym.vector.VectorEnv:
    """The vector env of one breakdown row."""
    env_kwargs = {"k": k, **TASK_KWARGS}
    if transport == "serial":
        return chronogym.SerialVectorEnv(ENV_ID, num_envs, env_kwargs=env_kwargs)
    return chronogym.RayVectorEnv(
        ENV_ID, num_envs, envs_per_worker=per, env_kwargs=env_kwargs, transport=transport
    )


def run_breakdown_one(
    transport: str, num_envs: int, per: int, k: int, args: argparse.Namespace
) -> Breakdown:
    """Time ``step`` unprofiled (with CPU use), then profiled, then the idle CPU use."""
    env = breakdown_env(transport, num_envs, per, k)
    try:
        pids = [] if transport == "serial" else env.worker_pids()
        timed: dict[str, Any] = {}

        def plain() -> None:
            timed["calls"], _, timed["s"] = time_vector_env(
                env, args.seconds, args.warmup, args.seed
            )

        busy = cpu_percent(pids, plain)
        profile = env.profile_steps()
        time_vector_env(env, args.seconds, args.warmup, args.seed)
        env.profile_steps(enabled=False)
        phases = profile.per_step_us()
        idle = cpu_percent(pids, lambda: time.sleep(min(args.seconds, 1.0)))
    finally:
        env.close()
    workers = 1 if transport == "serial" else math.ceil(num_envs / per)
    return Breakdown(
        transport,
        num_envs,
        workers,
        num_envs if transport == "serial" else per,
        k,
        timed["s"] / timed["calls"] * 1e6,
        phases,
        busy,
        idle,
    )


def median_breakdown(runs: list[Breakdown]) -> Breakdown:
    """Each number of the row: its median over ``runs`` (the same row, repeated)."""

    def med(values: list[float]) -> float:
        return float(np.median(values))

    first = runs[0]
    return Breakdown(
        first.transport,
        first.num_envs,
        first.workers,
        first.envs_per_worker,
        first.k,
        med([b.us_per_vstep for b in runs]),
        {key: med([b.phases[key] for b in runs]) for key in first.phases},
        {key: med([b.busy_cpu[key] for b in runs]) for key in first.busy_cpu},
        {key: med([b.idle_cpu[key] for b in runs]) for key in first.idle_cpu},
    )


def breakdown_plan(args: argparse.Namespace) -> list[tuple[str, int]]:
    """(transport, envs_per_worker) rows: serial, then each transport at each shape."""
    n = args.breakdown_envs
    pers = [p for p in args.breakdown_per_worker if 1 <= p <= n]
    transports = args.transports or list(TRANSPORT_BACKENDS)
    return [("serial", n)] + [(t, p) for t in transports for p in pers]


BREAKDOWN_COLUMNS = (  # header, width, phase key or property
    ("prep", "prepare"),
    ("submit", "submit"),
    ("wait", "wait"),
    ("get", "get"),
    ("join", "join"),
    ("w-comp", "compute"),
    ("w-serde", "serde"),
    ("call+xfer", "call"),
    ("driver", "driver"),
)


def format_breakdown(rows: list[Breakdown]) -> str:
    """The breakdown table (µs per vector step) and the overhead-budget check per row."""
    head = f"{'transport':>9}  {'N':>3}  {'wrk':>3}  {'e/w':>3}  {'µs/vstep':>8}  "
    head += "  ".join(f"{name:>9}" for name, _ in BREAKDOWN_COLUMNS)
    head += f"  {'overhead':>8}  {'budget':>6}  {'drv':>4}  {'ovh':>4}  {'cpu-idle':>9}  "
    head += f"{'cpu-busy':>9}  {'balance':>7}  {'eff':>5}"
    lines = [head, "-" * len(head)]
    for b in rows:
        cells = "  ".join(
            f"{'-' if b.transport == 'serial' and key == 'call' else round(b.phases[key]):>9}"
            for _, key in BREAKDOWN_COLUMNS
        )
        lines.append(
            f"{b.transport:>9}  {b.num_envs:>3}  {b.workers:>3}  {b.envs_per_worker:>3}  "
            f"{b.us_per_vstep:>8.0f}  {cells}  {b.overhead_us:>8.0f}  {b.budget_us:>6.0f}  "
            f"{'-' if b.transport == 'serial' else _ok(b.phases['driver'] <= b.budget_us):>4}"
            f"  {_ok(b.overhead_us <= b.budget_us):>4}"
            f"  {b.idle_cpu['workers']:>4.0f}/{b.idle_cpu['driver']:<4.0f}"
            f"  {b.busy_cpu['workers']:>4.0f}/{b.busy_cpu['driver']:<4.0f}"
            f"  {b.balance:>7.2f}  {b.efficiency:>5.2f}"
        )
    return "\n".join(lines)


BREAKDOWN_NOTES = """\
µs per vector step. Driver: prep = check actions + split into per-worker bytes; submit = the
.remote() calls (compiled: the graph's execute; socket: the socket writes); wait = the barrier
(compiled, socket: also reads and deserializes the answers); get = ray.get of the answers;
join = unpack and join them.
Workers (measured inside, slowest worker of each step): w-comp = time in the envs' step;
w-serde = actions from bytes, results to bytes. call+xfer = wait - w-comp - w-serde: Ray's call
and transfer, and waiting for a core. driver = prep + submit + get + join (the driver's own work).
serial: everything runs inside submit (no Ray). µs/vstep: an unprofiled run.
overhead = profiled µs/vstep - w-comp; budget = 100 µs + 5 µs x N (the issue's goal); drv / ovh:
driver / overhead within budget. cpu-idle, cpu-busy: % of one core used by the workers (summed) /
the driver while nothing steps / while stepping (a polling transport shows up in cpu-idle).
balance = mean worker's w-comp / slowest worker's (the barrier waits for the slowest); eff =
mean worker's w-comp / profiled µs per vector step: the share of each worker's wall time spent
in physics, = balance x (1 - overhead / step). Run at a dearer cost (--targets-us) to check the
goal eff >= 0.9 at >= 1 ms of physics per call."""


def run_breakdown(args: argparse.Namespace, tick_us: float) -> list[Breakdown]:
    """Every breakdown row at the cheapest cost level; prints the table."""
    (level,) = choose_levels([min(args.targets_us)], tick_us)
    plan = breakdown_plan(args)
    rounds: list[list[Breakdown]] = [[] for _ in plan]
    steps = [(i, row) for _ in range(max(args.repeat, 1)) for i, row in enumerate(plan)]
    for i, (transport, per) in tqdm(steps, desc="breakdown", file=sys.stderr):
        rounds[i].append(run_breakdown_one(transport, args.breakdown_envs, per, level.k, args))
    rows = [median_breakdown(runs) for runs in rounds]
    print(f"breakdown at k={level.k} ({level.k * tick_us:.0f} µs of physics per env step)")
    print(format_breakdown(rows))
    print()
    print(BREAKDOWN_NOTES)
    return rows


# -- main -----------------------------------------------------------------------------------


def start_ray() -> None:
    """One local Ray cluster for the whole run (RayVectorEnv then reuses it)."""
    import ray

    ray.init(
        address="local",
        num_cpus=os.cpu_count(),
        include_dashboard=False,
        log_to_driver=False,
        logging_level="ERROR",
    )
    time.sleep(RAY_SETTLE_S)


def main(argv: list[str] | None = None) -> int:
    """Run the sweep, print the table, write the JSON."""
    args = parse_args(argv)
    wall = time.perf_counter()
    cpus = cpu_count()
    tick_us = measure_tick_us(max(args.seconds, 0.3), args.seed)
    if args.breakdown:
        return main_breakdown(args, tick_us, wall)
    levels = choose_levels(args.targets_us, tick_us)
    plan = build_plan(levels, args)
    import ray

    start_ray()
    results: list[Result] = []
    try:
        for config in tqdm(plan, desc="configs", unit="cfg", file=sys.stderr):
            results.append(run_config(config, args))
    finally:
        ray.shutdown()
    derive(results, cpus)
    print(format_table(results))
    print()
    print(notes(cpus, tick_us, results))
    for transport in args.transports:
        print()
        print(goal_table(results, TRANSPORT_BACKENDS[transport]))
    write_json(args.out, machine_info(), args, tick_us, results)
    print(f"\nwrote {args.out} ({time.perf_counter() - wall:.0f} s in all)")
    return 0


def main_breakdown(args: argparse.Namespace, tick_us: float, wall: float) -> int:
    """The --breakdown mode: the phase table per transport and shape, and its JSON."""
    import ray

    start_ray()
    try:
        rows = run_breakdown(args, tick_us)
    finally:
        ray.shutdown()
    payload = {
        "benchmark": "chronogym vector-step breakdown (cart-pole)",
        "env_id": ENV_ID,
        "machine": machine_info(),
        "settings": {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()},
        "tick_us": tick_us,
        "default_transport": DEFAULT_TRANSPORT,
        "rows": [
            {
                **asdict(b),
                "overhead_us": b.overhead_us,
                "budget_us": b.budget_us,
                "balance": b.balance,
                "efficiency": b.efficiency,
            }
            for b in rows
        ],
    }
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(json.dumps(payload, indent=2) + "\n")
    print(f"\nwrote {args.out} ({time.perf_counter() - wall:.0f} s in all)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
