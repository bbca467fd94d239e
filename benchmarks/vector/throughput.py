"""Throughput of chronogym's vector envs on the cart-pole task, against Gymnasium's AsyncVectorEnv.

Measures env-steps/s of ``chronogym/CartPole-v0`` for a raw MuJoCo loop, one SimEnv,
SerialVectorEnv, gymnasium's AsyncVectorEnv and RayVectorEnv (workers x envs per
worker), each at several physics costs per env step (``k`` ticks of ``dt`` = 2 ms).
Prints an aligned table and writes JSON (default ``benchmarks/results/throughput.json``).

    python -m benchmarks.vector.throughput            # default sweep, < 4 min on 2 cores
    python -m benchmarks.vector.throughput --quick    # smoke run, < 1 min
    python -m benchmarks.vector.throughput --async-k  # adds RayVectorEnv send/recv with K = N/2
    python -m benchmarks.vector.throughput --transports actor socket   # RayVectorEnv transports
    python -m benchmarks.vector.throughput --breakdown   # one vector step split into phases (µs)

Counting: the cart-pole runs with ``terminate=False`` (the pole may fall; episodes end
only by truncation after 500 steps), so every env step costs the same physics and no
worker waits for another because its envs happened to reset (with falling episodes,
up to half of all steps are physics-free autoresets at large ``k``, spread unevenly
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
actions at once, against the barrier ``step`` of the same transport's rows. Their
``µs/vstep`` is per ``recv``, which returns about N/2 envs.

The transports are ``socket`` (rows ``ray-sock``, RayVectorEnv's default) and ``actor``
(``ray``).

This file is the command line; the work is done by ``throughput_timing.py`` (the timed loops),
``throughput_sweep.py`` (the configurations), ``throughput_report.py`` (ratios, efficiency,
goals, tables) and ``throughput_breakdown.py`` (``--breakdown``); ``common.py`` holds what every
benchmark shares (JSON header, machine record, tables).
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

from benchmarks.common import RESULTS, usable_cpus, write_json
from benchmarks.vector.throughput_breakdown import breakdown_record, run_breakdown
from benchmarks.vector.throughput_report import (
    derive,
    format_table,
    goal_table,
    notes,
    sweep_record,
)
from benchmarks.vector.throughput_sweep import run_sweep
from benchmarks.vector.throughput_timing import (
    DEFAULT_TRANSPORT,
    TRANSPORT_BACKENDS,
    measure_tick_us,
    start_ray,
)

DEFAULT_OUT = RESULTS / "throughput.json"
BREAKDOWN_OUT = DEFAULT_OUT.with_name("throughput_breakdown.json")


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
        "RayVectorEnv's default) and of --breakdown (default: all); actor rows are labelled "
        "ray, socket rows ray-sock",
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


def main(argv: list[str] | None = None) -> int:
    """Run the sweep (or the breakdown), print the tables, write the JSON."""
    args = parse_args(argv)
    wall = time.perf_counter()
    tick_us = measure_tick_us(max(args.seconds, 0.3), args.seed)
    if args.breakdown:
        return main_breakdown(args, tick_us, wall)
    results = run_sweep(args, tick_us)
    cpus = usable_cpus()
    derive(results, cpus)
    print(format_table(results))
    print()
    print(notes(cpus, tick_us, results))
    for transport in args.transports:
        print()
        print(goal_table(results, TRANSPORT_BACKENDS[transport]))
    print()
    write_json(
        args.out,
        sweep_record(args, tick_us, results),
        f" ({time.perf_counter() - wall:.0f} s in all)",
    )
    return 0


def main_breakdown(args: argparse.Namespace, tick_us: float, wall: float) -> int:
    """The --breakdown mode: the phase table per transport and shape, and its JSON."""
    import ray

    start_ray()
    try:
        rows = run_breakdown(args, tick_us)
    finally:
        ray.shutdown()
    print()
    write_json(
        args.out,
        breakdown_record(args, tick_us, rows),
        f" ({time.perf_counter() - wall:.0f} s in all)",
    )
    return 0


if __name__ == "__main__":
    sys.exit(main())
