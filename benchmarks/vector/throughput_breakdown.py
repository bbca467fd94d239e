"""``throughput.py --breakdown``: where one vector step's time goes, per transport and shape.

Not a script. Times ``step`` of SerialVectorEnv and of RayVectorEnv per transport and
``envs_per_worker`` at one cost level: unprofiled (wall time and the CPU the workers and the
driver use), then with ``profile_steps()`` (the driver's phases, each worker's compute and
(de)serialization), then idle (the CPU the workers use while nobody steps: a polling transport
shows there). The table checks each row against the overhead budget (100 µs + 5 µs per env)
and gives the parallel efficiency against the workers' own physics (``balance`` x
(1 - overhead / step)); ``--repeat`` rounds are interleaved and the table shows medians.
"""

from __future__ import annotations

import argparse
import math
import sys
import time
from dataclasses import asdict, dataclass
from typing import Any

import gymnasium as gym
import numpy as np
from tqdm import tqdm

import chronogym
from benchmarks.common import Column, cpu_percent, header, settings, table
from benchmarks.vector.throughput_report import ok
from benchmarks.vector.throughput_timing import (
    DEFAULT_TRANSPORT,
    ENV_ID,
    SHAPE_COLUMNS,
    TASK_KWARGS,
    TRANSPORT_BACKENDS,
    choose_levels,
    time_vector_env,
)


@dataclass
class Breakdown:
    """One vector env's step split into phases (µs per vector step), and its CPU use."""

    transport: str  # socket | actor | serial
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
        """The driver-overhead budget: 100 µs + 5 µs per env."""
        return 100.0 + 5.0 * self.num_envs


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


BREAKDOWN_COLUMNS = (  # header, phase key
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
TABLE_COLUMNS = (
    Column("transport", 9),
    *SHAPE_COLUMNS,
    Column("µs/vstep", 8, "{:.0f}"),
    *(Column(name, 9, "{:.0f}") for name, _ in BREAKDOWN_COLUMNS),
    Column("overhead", 8, "{:.0f}"),
    Column("budget", 6, "{:.0f}"),
    Column("drv", 4),
    Column("ovh", 4),
    Column("cpu-idle", 9),
    Column("cpu-busy", 9),
    Column("balance", 7, "{:.2f}"),
    Column("eff", 5, "{:.2f}"),
)


def format_breakdown(rows: list[Breakdown]) -> str:
    """The breakdown table (µs per vector step) and the overhead-budget check per row."""
    return table(TABLE_COLUMNS, [breakdown_cells(b) for b in rows], rule=True)


def breakdown_cells(b: Breakdown) -> list[Any]:
    """One row of the table, in TABLE_COLUMNS order."""
    serial = b.transport == "serial"
    return [
        b.transport,
        b.num_envs,
        b.workers,
        b.envs_per_worker,
        b.us_per_vstep,
        *(None if serial and key == "call" else b.phases[key] for _, key in BREAKDOWN_COLUMNS),
        b.overhead_us,
        b.budget_us,
        None if serial else ok(b.phases["driver"] <= b.budget_us),
        ok(b.overhead_us <= b.budget_us),
        f"{b.idle_cpu['workers']:>4.0f}/{b.idle_cpu['driver']:<4.0f}",
        f"{b.busy_cpu['workers']:>4.0f}/{b.busy_cpu['driver']:<4.0f}",
        b.balance,
        b.efficiency,
    ]


BREAKDOWN_NOTES = """\
µs per vector step. Driver: prep = check actions + split into per-worker bytes; submit = the
.remote() calls (socket: the socket writes); wait = the barrier (socket: also reads and
deserializes the answers); get = ray.get of the answers; join = unpack and join them.
Workers (measured inside, slowest worker of each step): w-comp = time in the envs' step;
w-serde = actions from bytes, results to bytes. call+xfer = wait - w-comp - w-serde: Ray's call
and transfer, and waiting for a core. driver = prep + submit + get + join (the driver's own work).
serial: everything runs inside submit (no Ray). µs/vstep: an unprofiled run.
overhead = profiled µs/vstep - w-comp; budget = 100 µs + 5 µs x N (the goal); drv / ovh:
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


def breakdown_record(args: argparse.Namespace, tick_us: float, rows: list[Breakdown]) -> dict:
    """Machine info, settings and every row, for the JSON."""
    return {
        **header("chronogym vector-step breakdown (cart-pole)"),
        "env_id": ENV_ID,
        "settings": settings(args),
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
