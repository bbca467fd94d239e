"""How long the socket transport should spin before it blocks: ``RayVectorEnv(spin_us=...)``.

With ``transport="socket"`` each end of a worker's socket polls for up to ``spin_us``
(yielding its core between polls) before a blocking read. A blocked read costs the
wake-up of an idle core, ~40 µs each way on a virtual machine, which is more than a cheap
MuJoCo step; spinning costs CPU while nothing arrives. This script first times a bare
socketpair round trip between two processes, blocking and spinning, then the barrier
``step`` of ``chronogym/CartPole-v0`` for several ``spin_us`` values, shapes and physics
costs, with and without "think" time on the driver between steps (busy work standing in
for a policy's forward pass, when a spinning worker gives up and blocks), and the CPU the
workers and the driver use. Prints a table and writes JSON
(default ``benchmarks/results/socket_spin.json``).

    python -m benchmarks.archive.socket_spin            # default sweep, ~4 min on 2 cores
    python -m benchmarks.archive.socket_spin --quick    # smoke run, < 1 min

Columns: ``µs/vstep`` = wall time per vector step (think time included), ``x_spin0`` =
the speed-up over the smallest spin (``0``: plain blocking reads) for the same row, ``cpu-w`` /
``cpu-d`` = % of one core used by the workers (summed) / the driver while stepping.
Rounds over the spin values are interleaved and the table shows medians, so a burst of
load on the machine hits every value alike.
"""

from __future__ import annotations

import argparse
import os
import select
import socket
import statistics
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

import chronogym
from benchmarks.common import RESULTS, Column, cpu_percent, header, settings, table, write_json
from benchmarks.vector import (
    throughput_timing as timing,  # this script's folder: the cart-pole timing helpers
)

DEFAULT_OUT = RESULTS / "socket_spin.json"


@dataclass(frozen=True)
class Shape:
    """One RayVectorEnv shape and physics cost."""

    num_envs: int
    envs_per_worker: int
    target_us: float
    k: int


@dataclass
class Row:
    """Medians of one (shape, think time, spin) over the rounds."""

    num_envs: int
    workers: int
    envs_per_worker: int
    physics_us_per_step: float
    think_us: float
    spin_us: float
    us_per_vstep: float
    cpu_workers: float
    cpu_driver: float
    x_spin0: float = 1.0


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Command-line options; ``--quick`` shrinks the sweep to a smoke run."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--spin-us", type=float, nargs="+", default=[0, 50, 100, 250, 500, 1000])
    parser.add_argument(
        "--shapes",
        nargs="+",
        default=["2x1", "2x2", "16x8"],
        help="NUMxPER: num_envs x envs_per_worker",
    )
    parser.add_argument("--targets-us", type=float, nargs="+", default=[50.0, 500.0])
    parser.add_argument(
        "--think-us",
        type=float,
        nargs="+",
        default=[0.0, 1000.0],
        help="driver busy time between steps (a policy's forward pass)",
    )
    parser.add_argument("--steps", type=int, default=400, help="timed vector steps per cell")
    parser.add_argument("--repeat", type=int, default=3, help="interleaved rounds (medians)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--quick", action="store_true", help="smoke run (< 1 min)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    if args.quick:
        args.spin_us, args.shapes, args.targets_us = [0, 250], ["2x2"], [50.0]
        args.steps, args.repeat = 100, 1
    for spec in args.shapes:
        num, _, per = spec.partition("x")
        if not (num.isdigit() and per.isdigit() and 1 <= int(per) <= int(num)):
            parser.error(f"--shapes {spec!r}: expected NUMxPER with 1 <= PER <= NUM, e.g. 16x8")
    return args


def busy_wait(us: float) -> None:
    """Keep this core busy for ``us`` µs (the driver's think time)."""
    end = time.perf_counter() + us * 1e-6
    while time.perf_counter() < end:
        pass


def time_steps(env: Any, steps: int, think_us: float, seed: int) -> float:
    """µs per vector step over ``steps`` steps with random actions (after a short warm-up)."""
    rng = np.random.default_rng(seed)
    actions = rng.uniform(-1.0, 1.0, size=(steps + 20, env.num_envs, 1)).astype(np.float32)
    for a in actions[:20]:
        env.step(a)
        busy_wait(think_us)
    start = time.perf_counter()
    for a in actions[20:]:
        env.step(a)
        busy_wait(think_us)
    return (time.perf_counter() - start) / steps * 1e6


def measure(shape: Shape, spin_us: float, args: argparse.Namespace) -> list[dict[str, float]]:
    """One RayVectorEnv: µs/vstep and CPU use for each think time."""
    env = chronogym.RayVectorEnv(
        timing.ENV_ID,
        shape.num_envs,
        envs_per_worker=shape.envs_per_worker,
        env_kwargs={"k": shape.k, **timing.TASK_KWARGS},
        transport="socket",
        spin_us=spin_us,
    )
    try:
        env.reset(seed=args.seed)
        pids = env.worker_pids()
        cells = []
        for think in args.think_us:
            timed: list[float] = []

            def run(t: float = think, out: list[float] = timed) -> None:
                out.append(time_steps(env, args.steps, t, args.seed))

            cpu = cpu_percent(pids, run)
            cells.append({"think_us": think, "us": timed[0], **cpu})
        return cells
    finally:
        env.close()


def pingpong_us(spin_s: float, rounds: int = 5000) -> float:
    """µs per round trip of 32 bytes between two processes over a Unix socketpair, each end
    spinning up to ``spin_s`` before a blocking read (what the socket transport does)."""
    from chronogym.vector.socket_transport import spin_until_readable

    ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
    pid = os.fork()
    if pid == 0:  # the echoing end
        ours.close()
        poller, buf = select.poll(), bytearray(64)
        poller.register(theirs, select.POLLIN)
        while True:
            spin_until_readable(poller, spin_s)
            n = theirs.recv_into(buf)
            if n == 0:
                os._exit(0)
            theirs.sendall(buf[:n])
    theirs.close()
    poller, buf, message = select.poll(), bytearray(64), b"x" * 32
    poller.register(ours, select.POLLIN)
    for _ in range(200):  # warm-up
        ours.sendall(message)
        spin_until_readable(poller, spin_s)
        ours.recv_into(buf)
    start = time.perf_counter()
    for _ in range(rounds):
        ours.sendall(message)
        spin_until_readable(poller, spin_s)
        ours.recv_into(buf)
    elapsed = time.perf_counter() - start
    ours.close()
    os.waitpid(pid, 0)
    return elapsed / rounds * 1e6


def physics_us(k: int, seed: int) -> float:
    """What one env step of ``k`` ticks costs in the raw loop, µs."""
    steps, elapsed = timing.run_raw(k, 0.5, seed)
    return elapsed / steps * 1e6


def run(args: argparse.Namespace) -> list[Row]:
    """Every shape x cost x spin, ``repeat`` interleaved rounds; medians per cell."""
    tick = timing.measure_tick_us(0.5, args.seed)
    levels = timing.choose_levels(args.targets_us, tick)
    shapes = [
        Shape(int(num), int(per), level.target_us, level.k)
        for spec in args.shapes
        for num, _, per in [spec.partition("x")]
        for level in levels
    ]
    cost = {level.k: physics_us(level.k, args.seed) for level in levels}
    samples: dict[tuple[Shape, float, float], list[dict[str, float]]] = {}
    plan = [(r, s, spin) for r in range(args.repeat) for s in shapes for spin in args.spin_us]
    for _, shape, spin in tqdm(plan, desc="configs", unit="cfg"):
        for cell in measure(shape, spin, args):
            samples.setdefault((shape, cell["think_us"], spin), []).append(cell)
    rows = []
    for (shape, think, spin), cells in samples.items():
        rows.append(
            Row(
                shape.num_envs,
                -(-shape.num_envs // shape.envs_per_worker),
                shape.envs_per_worker,
                cost[shape.k],
                think,
                spin,
                statistics.median(c["us"] for c in cells),
                statistics.median(c["workers"] for c in cells),
                statistics.median(c["driver"] for c in cells),
            )
        )

    def key(r: Row) -> tuple[int, int, float, float]:
        return (r.num_envs, r.envs_per_worker, r.physics_us_per_step, r.think_us)

    lowest = min(args.spin_us)
    base = {key(r): r for r in rows if r.spin_us == lowest}
    for r in rows:
        r.x_spin0 = base[key(r)].us_per_vstep / r.us_per_vstep
    return rows


COLUMNS = (
    Column("phys/step", 9, "{:.0f}µs", key="physics_us_per_step"),
    *timing.SHAPE_COLUMNS,
    Column("think", 6, "{:.0f}µs", key="think_us"),
    Column("spin_us", 7, "{:.0f}", key="spin_us"),
    Column("µs/vstep", 9, "{:.0f}", key="us_per_vstep"),
    Column("x_spin0", 7, "{:.2f}", key="x_spin0"),
    Column("cpu-w", 6, "{:.0f}%", key="cpu_workers"),
    Column("cpu-d", 6, "{:.0f}%", key="cpu_driver"),
)


def format_table(rows: list[Row]) -> str:
    """Aligned table, one line per cell."""
    order = sorted(
        rows,
        key=lambda r: (r.physics_us_per_step, r.num_envs, r.envs_per_worker, r.think_us, r.spin_us),
    )
    return table(COLUMNS, order, rule=True)


def main(argv: list[str] | None = None) -> int:
    """Run the sweep, print the table, write the JSON."""
    args = parse_args(argv)
    wall = time.perf_counter()
    pingpong = {"blocking": pingpong_us(0.0), "spinning_1ms": pingpong_us(1e-3)}
    print(
        f"socketpair round trip between two processes: {pingpong['blocking']:.1f} µs with "
        f"blocking reads, {pingpong['spinning_1ms']:.1f} µs when both ends spin\n"
    )
    timing.start_ray()
    rows = run(args)
    print(format_table(rows))
    print(
        "\nthink = driver busy time between steps; x_spin0 = µs/vstep at the smallest spin / "
        "this row's; cpu-w, cpu-d = % of one core used by the workers (summed) / the driver."
    )
    record = {
        **header("socket transport spin before blocking reads"),
        "pingpong_us": pingpong,
        "settings": settings(args),
        "rows": [asdict(r) for r in rows],
    }
    print()
    write_json(args.out, record, f" ({time.perf_counter() - wall:.0f} s in all)")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
