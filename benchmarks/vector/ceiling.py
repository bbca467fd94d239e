"""The machine's ceiling for E(W): W processes stepping their own synthetic envs, no vector env.

``scaling.py`` reads E(W) / E(1) as the vector env's own cost. On a machine with fewer cores
than workers, part of the loss is not the vector env's at all: each env step's own CPU (a
``SyntheticEnv`` step that sleeps 10 ms still costs its process ~0.1 ms of CPU on a VM: the
wake-up, cold caches, NumPy) queues for the cores. This script measures that part alone:
path ``bare`` is W processes (forked, as AsyncVectorEnv's are), each stepping its
``envs_per_worker`` envs back to back with no driver, no barrier and no transport, started
together and timed for ``--seconds``; its E(W) / E(1) is the most any vector env can reach
on this machine at that W. Side by side, W by W, the same settings through ``fork`` (and,
with ``--paths``, ``socket`` and ``async``) give each path's share of the loss:
``x_ceiling`` is a path's env-steps/s over ``bare``'s at the same W and step cost.

    python -m benchmarks.vector.ceiling --workers 1 16 64 --step-ms 10     # ~1 min

Per ``bare`` setting it also reports each process's CPU per env step (``/proc``), what the
cores must absorb: with W processes on C cores, ``t(W) >= t(1) + (W - C) * cpu / C`` once W
exceeds C.

Output: a table, JSON (default ``benchmarks/results/ceiling.json``).
"""

from __future__ import annotations

import argparse
import multiprocessing
import os
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import (
    RESULTS,
    Column,
    header,
    non_negative_int,
    positive_float,
    positive_int,
    settings,
    table,
    write_json,
)

DEFAULT_OUT = RESULTS / "ceiling.json"
PATHS = ("fork", "socket", "async")
WARMUP_STEPS = 5


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--workers", type=positive_int, nargs="+", default=[1, 4, 16, 64])
    parser.add_argument("--envs-per-worker", type=positive_int, default=1)
    parser.add_argument("--step-ms", type=positive_float, nargs="+", default=[10.0])
    parser.add_argument(
        "--paths", nargs="+", choices=PATHS, default=["fork", "async"], help="beside bare"
    )
    parser.add_argument("--seconds", type=positive_float, default=2.0, help="timed per setting")
    parser.add_argument("--min-steps", type=positive_int, default=20, help="timed, at least")
    parser.add_argument("--warmup", type=non_negative_int, default=10, help="untimed steps")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="JSON")
    args = parser.parse_args(argv)
    # what scaling.py's helpers read
    args.obs_dim, args.info_floats, args.info_scalars = 16, 0, 0
    args.driver_cpus, args.other_cpus = [], []
    return args


def cpu_seconds(pid: int) -> float:
    """User + system CPU of ``pid`` so far, s (``/proc``)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def _bare_worker(epw: int, step_ms: float, start: Any, stop: Any, out: Any) -> None:
    """One process: its envs stepped back to back from ``start`` until ``stop`` is set."""
    from chronogym.testing import SyntheticEnv

    envs = [SyntheticEnv(step_ms=step_ms, max_steps=10**9) for _ in range(epw)]
    action = np.zeros(2, dtype=np.float32)
    for seed, env in enumerate(envs):
        env.reset(seed=seed)
    for _ in range(WARMUP_STEPS):
        for env in envs:
            env.step(action)
    start.wait()
    steps, cpu0 = 0, time.process_time()
    while not stop.is_set():
        for env in envs:
            env.step(action)
        steps += epw
    out.put((steps, time.process_time() - cpu0))


def run_bare(workers: int, epw: int, step_ms: float, seconds: float) -> dict[str, Any]:
    """``workers`` processes stepping on their own for ``seconds``: env-steps/s and CPU."""
    context = multiprocessing.get_context("fork")
    start, stop, out = context.Barrier(workers + 1), context.Event(), context.Queue()
    procs = [
        context.Process(target=_bare_worker, args=(epw, step_ms, start, stop, out))
        for _ in range(workers)
    ]
    for proc in procs:
        proc.start()
    start.wait()
    t0 = time.perf_counter()
    time.sleep(seconds)
    stop.set()
    results = [out.get(timeout=60 + 10 * step_ms) for _ in procs]
    wall = time.perf_counter() - t0
    for proc in procs:
        proc.join()
    steps = sum(n for n, _ in results)
    return {
        "env_steps_per_s": steps / wall,
        "worker_cpu_us_per_env_step": 1e6 * sum(c for _, c in results) / max(steps, 1),
    }


def run_path(path: str, workers: int, epw: int, step_ms: float, args: argparse.Namespace):
    """One vector env of ``path`` (scaling.py's), timed at ``step_ms``: its row."""
    from benchmarks.vector.scaling import ideal_rate, measure, start

    built = start(path, workers, epw, args, None)
    try:
        return measure(built, step_ms, args, ideal_rate(workers, epw, step_ms))
    finally:
        built.vec.close()


COLUMNS = (
    Column("path", 6, align="<", key="path"),
    Column("W", 4, key="workers"),
    Column("step ms", 7, "{:g}", key="step_ms"),
    Column("env-steps/s", 11, "{:,.0f}", key="env_steps_per_s"),
    Column("E(W)", 6, "{:.3f}", key="efficiency"),
    Column("E/E(1)", 6, "{:.3f}", key="efficiency_rel_w1"),
    Column("x ceiling", 9, "{:.2f}", key="x_ceiling"),
    Column("env CPU us/step", 15, "{:.0f}", key="worker_cpu_us_per_env_step"),
)


def relate(rows: list[dict[str, Any]]) -> None:
    """E(W) / E(1) per path and step cost, and each path's rate over bare's."""
    first = {(r["path"], r["step_ms"]): r["efficiency"] for r in rows if r["workers"] == 1}
    bare = {(r["workers"], r["step_ms"]): r["env_steps_per_s"] for r in rows if r["path"] == "bare"}
    for row in rows:
        base = first.get((row["path"], row["step_ms"]))
        row["efficiency_rel_w1"] = row["efficiency"] / base if base else None
        ceiling = bare.get((row["workers"], row["step_ms"]))
        row["x_ceiling"] = row["env_steps_per_s"] / ceiling if ceiling else None


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    from benchmarks.vector.scaling import ideal_rate
    from benchmarks.vector.throughput_timing import start_ray

    if "socket" in args.paths:
        start_ray()
    record: dict[str, Any] = {**header("vector/ceiling"), "settings": settings(args)}
    rows: list[dict[str, Any]] = []
    epw = args.envs_per_worker
    for workers in args.workers:
        for step_ms in args.step_ms:
            ideal = ideal_rate(workers, epw, step_ms)
            bare = run_bare(workers, epw, step_ms, args.seconds)
            bare.update(path="bare", workers=workers, step_ms=step_ms)
            bare["efficiency"] = bare["env_steps_per_s"] / ideal
            rows.append(bare)
            print(f"  bare, W={workers}, {step_ms:g} ms: {bare['env_steps_per_s']:,.0f}")
            for path in args.paths:
                row = run_path(path, workers, epw, step_ms, args)
                rows.append(row)
                print(f"  {path}, W={workers}, {step_ms:g} ms: {row['env_steps_per_s']:,.0f}")
    relate(rows)
    record["rows"] = rows
    print()
    keys = [c.key for c in COLUMNS]
    print(table(COLUMNS, [{k: r.get(k) for k in keys} for r in rows], rule=True))
    write_json(args.out, record)
    return 0


if __name__ == "__main__":
    sys.exit(main())
