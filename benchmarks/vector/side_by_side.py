"""Vector envs of one workload side by side, round by round: wall, driver and worker CPU.

On a noisy machine (the 2-core VMs here swing by up to 1.5x within minutes), two runs of one
vector env minutes apart differ more than two vector envs do. This script builds every kind
at once and steps them in turn, round by round, the order alternating, so that each round's
noise falls on all of them:

- ``fork``: ``RayVectorEnv(transport="fork")``, W workers of ``--envs-per-worker`` envs;
- ``socket``: ``RayVectorEnv`` with Ray workers (its default transport; needs Ray);
- ``socket_held``: the same, each Ray worker's main thread held by a task from the first
  round to the end, so that Ray's check for signals, which wakes that thread every 10 ms,
  stops (the steps are served by another thread); a probe of what those wake-ups cost;
- ``async``: Gymnasium's ``AsyncVectorEnv``, one process per env;
- ``sync``: Gymnasium's ``SyncVectorEnv``, every env in the driver.

Per kind and W: the wall time, the driver process's CPU and its workers' CPU (``/proc``) per
vector step, medians over the rounds; and each kind's wall time over the first kind's, round
by round (its median and range: a kind ahead in every round is ahead, whatever the noise).
After the rounds, with nothing stepping, each kind's *idle wake-ups*: the context switches
per second of all its workers' threads over ``--idle-s`` (a Ray worker is a whole Ray core
worker, whose threads keep waking while it waits; on a machine with fewer cores than
workers each wake-up takes a core from a worker that steps), and, per thread name, the
wake-ups and CPU per second of one worker (``idle_threads`` in the JSON; ``main``: each
worker's first thread).

    python -m benchmarks.vector.side_by_side --env Ant-v5 --workers 1 4 --kinds fork async

Output: a table and JSON (default ``benchmarks/results/side_by_side.json``).
"""

from __future__ import annotations

import argparse
import os
import shutil
import statistics
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import (
    RESULTS,
    Column,
    header,
    json_object,
    positive_int,
    proc_cpu_s,
    proc_threads,
    settings,
    table,
    write_json,
)

DEFAULT_OUT = RESULTS / "side_by_side.json"
KINDS = ("fork", "socket", "socket_held", "async", "sync")
ACTION_ROWS = 64


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env", default="Ant-v5", help="a Gymnasium id with a Box action space")
    parser.add_argument("--env-kwargs", type=json_object, default={}, help="the env's kwargs, JSON")
    parser.add_argument("--workers", type=positive_int, nargs="+", default=[1])
    parser.add_argument("--envs-per-worker", type=positive_int, default=1)
    parser.add_argument("--kinds", choices=KINDS, nargs="+", default=["fork", "async"])
    parser.add_argument("--rounds", type=positive_int, default=7)
    parser.add_argument("--steps", type=positive_int, default=1000, help="timed per round")
    parser.add_argument("--warmup", type=positive_int, default=50, help="untimed per round")
    parser.add_argument(
        "--idle-s", type=float, default=2.0, help="seconds of idle wake-ups counted per W"
    )
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    if not 0 < args.idle_s <= 60:
        parser.error(f"--idle-s {args.idle_s}: expected seconds in (0, 60]")
    if len(set(args.kinds)) != len(args.kinds):
        parser.error(f"--kinds {' '.join(args.kinds)}: each kind once")
    return args


def build(
    kind: str, env_id: str, num_envs: int, envs_per_worker: int, env_kwargs: dict[str, Any]
) -> Any:
    """A vector env of ``kind`` (NextStep autoreset, as every kind's default)."""
    import gymnasium as gym
    from gymnasium.vector import AutoresetMode

    if kind in ("fork", "socket", "socket_held"):
        from chronogym import RayVectorEnv

        transport = "fork" if kind == "fork" else None
        return RayVectorEnv(
            env_id, num_envs, envs_per_worker=envs_per_worker, transport=transport,
            env_kwargs=env_kwargs,
        )  # fmt: skip
    mode = {"async": "async", "sync": "sync"}[kind]
    return gym.make_vec(
        env_id, num_envs, vectorization_mode=mode,
        vector_kwargs={"autoreset_mode": AutoresetMode.NEXT_STEP}, **env_kwargs,
    )  # fmt: skip


def worker_pids(kind: str, vec: Any) -> list[int]:
    """The processes that step the envs, besides the driver."""
    if kind == "async":
        return [p.pid for p in vec.processes]
    if kind == "sync":
        return []
    return [pid for pid in vec.worker_pids() if pid != os.getpid()]


def hold_main_threads(vec: Any, flag: Path) -> list[Any]:
    """Hold every Ray worker's main thread of ``vec`` with a task that waits until ``flag``
    exists (checked twice a second); the tasks' refs. The workers' serving threads still
    step; plain actor calls (``close``) wait until the flag is set."""

    def hold(_worker: Any, path: str) -> None:
        while not os.path.exists(path):
            time.sleep(0.5)

    refs = [actor.__ray_call__.remote(hold, str(flag)) for actor in vec._backend.actors]
    time.sleep(1.0)  # every hold has started (a task queued behind nothing starts at once)
    return refs


def measure(args: argparse.Namespace, workers: int) -> list[dict[str, Any]]:
    """Every kind at ``workers`` workers, round by round."""
    num_envs = workers * args.envs_per_worker
    vecs = {
        k: build(k, args.env, num_envs, args.envs_per_worker, args.env_kwargs) for k in args.kinds
    }
    samples: dict[str, list[tuple[float, float, float]]] = {k: [] for k in vecs}
    flag, held = Path(tempfile.mkdtemp()) / "release", []
    try:
        rng = np.random.default_rng(0)
        first = next(iter(vecs.values()))
        low, high = first.single_action_space.low, first.single_action_space.high
        shape = (ACTION_ROWS, num_envs, *first.single_action_space.shape)
        actions = rng.uniform(low, high, shape).astype(first.single_action_space.dtype)
        for vec in vecs.values():
            vec.reset(seed=0)
        pids = {k: worker_pids(k, v) for k, v in vecs.items()}  # before any hold: a Ray call
        if "socket_held" in vecs:
            held = hold_main_threads(vecs["socket_held"], flag)
        for r in range(args.rounds):
            order = list(vecs) if r % 2 == 0 else list(reversed(vecs))
            for kind in order:
                samples[kind].append(step_round(kind, vecs[kind], actions, args))
            print(f"  W={workers} round {r + 1}/{args.rounds}: " + ", ".join(
                f"{k} {samples[k][-1][0]:,.0f} µs" for k in vecs
            ), flush=True)  # fmt: skip
        threads = idle_threads(pids, args.idle_s)  # one idle window: the totals derive
        wakeups = total_wakeups(threads, pids)
    finally:
        flag.touch()
        if held:
            import ray

            ray.get(held, timeout=30)
        shutil.rmtree(flag.parent, ignore_errors=True)
        for vec in vecs.values():
            vec.close()
    base = args.kinds[0]
    rows = []
    for kind, got in samples.items():
        ratios = [s[0] / b[0] for s, b in zip(got, samples[base], strict=True)]
        rows.append({
            "kind": kind, "workers": workers, "envs_per_worker": args.envs_per_worker,
            "wall_us": statistics.median(s[0] for s in got),
            "driver_cpu_us": statistics.median(s[1] for s in got),
            "worker_cpu_us": statistics.median(s[2] for s in got),
            "wall_over_first": statistics.median(ratios),
            "wall_over_first_range": [min(ratios), max(ratios)],
            "idle_wakeups_per_s": wakeups[kind],
            "idle_threads": threads[kind],
            "rounds": [list(s) for s in got],
        })  # fmt: skip
    return rows


def idle_wakeups(pids: dict[str, list[int]], seconds: float) -> dict[str, float]:
    """Per kind: context switches per second of all its workers' threads while nothing steps."""
    return total_wakeups(idle_threads(pids, seconds), pids)


def total_wakeups(
    threads: dict[str, dict[str, dict[str, float]]], pids: dict[str, list[int]]
) -> dict[str, float]:
    """Per kind: all its workers' wake-ups per second, from :func:`idle_threads`' counts."""
    return {
        kind: len(pids[kind]) * sum(t["wakeups_per_s"] for t in per_thread.values())
        for kind, per_thread in threads.items()
    }


def idle_threads(
    pids: dict[str, list[int]], seconds: float
) -> dict[str, dict[str, dict[str, float]]]:
    """Per kind and thread name, while nothing steps: one worker's (the mean over the kind's
    workers) ``wakeups_per_s`` and ``cpu_us_per_s``, busiest first."""
    before = {pid: proc_threads(pid) for p in pids.values() for pid in p}
    time.sleep(seconds)
    out: dict[str, dict[str, dict[str, float]]] = {}
    for kind, kind_pids in pids.items():
        sums: dict[str, list[float]] = {}
        for pid in kind_pids:
            for name, (switches, cpu_ns) in proc_threads(pid).items():
                was = before[pid].get(name, (0, 0))
                total = sums.setdefault(name, [0.0, 0.0])
                total[0] += switches - was[0]
                total[1] += (cpu_ns - was[1]) / 1e3
        n = max(len(kind_pids), 1) * seconds
        ranked = sorted(sums.items(), key=lambda item: -item[1][0])
        out[kind] = {
            name: {"wakeups_per_s": s / n, "cpu_us_per_s": c / n} for name, (s, c) in ranked
        }
    return out


def step_round(
    kind: str, vec: Any, actions: np.ndarray, args: argparse.Namespace
) -> tuple[float, float, float]:
    """One round of ``vec``: (wall, driver CPU, workers' CPU) µs per vector step."""
    for t in range(args.warmup):
        vec.step(actions[t % ACTION_ROWS])
    pids = worker_pids(kind, vec)
    workers_before = sum(proc_cpu_s(pid) for pid in pids)
    cpu, start = time.process_time(), time.perf_counter()
    for t in range(args.steps):
        vec.step(actions[t % ACTION_ROWS])
    wall = time.perf_counter() - start
    cpu = time.process_time() - cpu
    workers = sum(proc_cpu_s(pid) for pid in pids) - workers_before
    return tuple(1e6 * x / args.steps for x in (wall, cpu, workers))  # type: ignore[return-value]


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    started = time.perf_counter()
    print(f"side_by_side: {args.env}, kinds {' '.join(args.kinds)}, W {args.workers}, "
          f"{args.rounds} rounds of {args.steps} steps")  # fmt: skip
    rows = [row for w in args.workers for row in measure(args, w)]
    first = args.kinds[0]
    cells = [
        (r["kind"], r["workers"], r["wall_us"], r["driver_cpu_us"], r["worker_cpu_us"],
         r["wall_over_first"], "{:.2f}-{:.2f}".format(*r["wall_over_first_range"]),
         r["idle_wakeups_per_s"])
        for r in rows
    ]  # fmt: skip
    print(table([
        Column("kind", 12, align="<"), Column("W", 4), Column("wall µs", 10, "{:,.0f}"),
        Column("driver CPU µs", 14, "{:,.0f}"), Column("workers' CPU µs", 16, "{:,.0f}"),
        Column(f"wall / {first}", 12, "{:.3f}"), Column("range", 12),
        Column("idle wake-ups/s", 16, "{:,.0f}"),
    ], cells, rule=True))  # fmt: skip
    record = {**header("side_by_side"), "settings": settings(args), "rows": rows,
              "seconds_in_all": time.perf_counter() - started}  # fmt: skip
    print_threads(rows)
    write_json(args.out, record)
    return 0


def print_threads(rows: list[dict[str, Any]], top: int = 4) -> None:
    """The threads that woke most in one idle worker of each kind, per W."""
    for r in rows:
        busiest = list(r["idle_threads"].items())[:top]
        if busiest:
            print(f"  idle, one {r['kind']} worker at W={r['workers']}: " + ", ".join(
                f"{name} {t['wakeups_per_s']:.0f}/s {t['cpu_us_per_s']:,.0f} µs/s"
                for name, t in busiest
            ))  # fmt: skip


if __name__ == "__main__":
    sys.exit(main())
