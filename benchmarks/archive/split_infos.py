"""The driver's CPU per step with a worker's infos kept apart from its rows, and without.

``SharedStep.step(split_infos=True)`` (what the driver's own block uses) keeps a step whose
workers add only infos to their rows on the whole-batch path; ``split_infos=False`` sends
every such answer down the per-worker path, as before the change. This probe steps one forked
``RayVectorEnv`` and switches between the two round by round (the same processes, the same
envs), so the difference is the driver's own work, read as the stepping thread's CPU
(``time.thread_time``) per vector step:

    python -m benchmarks.archive.split_infos --workers 1 8

Output: a table and JSON (default ``benchmarks/results/split_infos.json``).

Since the infos' rows (``chronogym.vector.info_rows``, 2026-12-07), Ant-v5's infos no longer
travel in the tail slot, so on later revisions both settings take the rows' path: the probe
answers its question only for revisions before cb8036a (or an env whose infos are not
numeric scalars).
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import RESULTS, header, positive_int, settings, write_json

DEFAULT_OUT = RESULTS / "split_infos.json"


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--env", default="Ant-v5", help="an env id that reports infos")
    parser.add_argument("--workers", type=positive_int, nargs="+", default=[1, 8])
    parser.add_argument("--steps", type=positive_int, default=1000, help="per round and W=1")
    parser.add_argument("--rounds", type=positive_int, default=9)
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    return parser.parse_args(argv)


def measure(env_id: str, workers: int, steps: int, rounds: int) -> dict[str, Any]:
    """Rounds alternating split on / off on one forked vector env of ``workers`` x 1 env."""
    from gymnasium.vector import AutoresetMode

    from chronogym import RayVectorEnv
    from chronogym.vector.shared_step import SharedStep

    vec = RayVectorEnv(env_id, workers, transport="fork", autoreset_mode=AutoresetMode.NEXT_STEP)
    step = SharedStep.step
    split: dict[bool, list[tuple[float, float]]] = {True: [], False: []}
    try:
        vec.reset(seed=0)
        rng = np.random.default_rng(0)
        actions = rng.uniform(-1, 1, (64, *vec.action_space.shape)).astype(np.float32)
        for r in range(rounds):
            for on in (True, False) if r % 2 == 0 else (False, True):
                SharedStep.step = lambda self, *a, on=on, **k: step(  # type: ignore[method-assign]
                    self, *a, **{**k, "split_infos": on and k.get("split_infos", False)}
                )
                for t in range(20):
                    vec.step(actions[t % 64])
                cpu, wall = time.thread_time(), time.perf_counter()
                for t in range(steps):
                    vec.step(actions[t % 64])
                cpu, wall = time.thread_time() - cpu, time.perf_counter() - wall
                split[on].append((1e6 * cpu / steps, 1e6 * wall / steps))
    finally:
        SharedStep.step = step  # type: ignore[method-assign]
        vec.close()
    row: dict[str, Any] = {"env": env_id, "workers": workers, "steps": steps, "rounds": rounds}
    for on, name in ((True, "split"), (False, "per_worker")):
        row[f"{name}_cpu_us"] = statistics.median(c for c, _ in split[on])
        row[f"{name}_wall_us"] = statistics.median(w for _, w in split[on])
    return row


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    rows = []
    for workers in args.workers:
        steps = max(50, args.steps // workers)
        rows.append(measure(args.env, workers, steps, args.rounds))
        r = rows[-1]
        print(
            f"{args.env} W={workers}: driver CPU per step {r['per_worker_cpu_us']:.1f} -> "
            f"{r['split_cpu_us']:.1f} us, wall {r['per_worker_wall_us']:.1f} -> "
            f"{r['split_wall_us']:.1f} us (medians of {args.rounds} rounds)"
        )
    record = {**header("archive/split_infos"), "settings": settings(args), "rows": rows}
    write_json(args.out, record)
    return 0


if __name__ == "__main__":
    sys.exit(main())
