"""Torch CPU threads beside simulation workers: PPO iteration time of the Go1 task.

For each configuration (backend, n_env, torch threads in the learner) it trains a few PPO
iterations with the quadruped's training config and reports, per iteration, the rollout
(collection) time, the PPO update (learning) time and env steps/s, median over the iterations
after the first. ``default`` is torch's own choice (one thread per core it sees).

    python -m benchmarks.archive.torch_threads [--iterations 8] [--num-envs 32]

Prints a table and writes ``benchmarks/results/torch_threads.json``.
"""

from __future__ import annotations

import argparse
import csv
import statistics
import tempfile
from pathlib import Path

from benchmarks.common import RESULTS, Column, header, table, write_json

DEFAULT_OUT = RESULTS / "torch_threads.json"
COLUMNS = (
    Column("backend", 8, key="backend"),
    Column("threads", 8, key="torch_threads"),
    Column("collect s", 10, "{:.3f}", key="collect_s"),
    Column("learn s", 8, "{:.3f}", key="learn_s"),
    Column("steps/s", 8, "{:.0f}", key="env_steps_per_s"),
)


def run(backend: str, num_envs: int, threads: int | None, iterations: int) -> dict:
    import torch

    from chronogym.tasks.quadruped.training import train_quadruped

    count = threads if threads is not None else torch.get_num_threads()
    with tempfile.TemporaryDirectory() as out:
        train_quadruped(
            out,
            num_envs=num_envs,
            backend=backend,
            iterations=iterations,
            torch_threads=count,
            progress=False,
        )
        with open(Path(out) / "progress.csv", newline="") as handle:
            rows = list(csv.DictReader(handle))[1:]  # the first iteration warms up
    collect = statistics.median(float(r["collect_s"]) for r in rows)
    learn = statistics.median(float(r["learn_s"]) for r in rows)
    steps = (int(rows[-1]["env_steps"]) - int(rows[0]["env_steps"])) / max(len(rows) - 1, 1)
    return {
        "backend": backend,
        "num_envs": num_envs,
        "torch_threads": "default" if threads is None else threads,
        "threads_used": count,
        "collect_s": collect,
        "learn_s": learn,
        "env_steps_per_s": steps / (collect + learn),
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--iterations", type=int, default=8)
    parser.add_argument("--num-envs", type=int, default=32)
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args()
    if args.iterations < 3:
        parser.error(f"--iterations={args.iterations}: expected >= 3")
    configs = [(backend, threads) for backend in ("ray", "serial") for threads in (1, 2, None)]
    results = []
    for backend, threads in configs:
        print(f"== {backend}, {args.num_envs} envs, torch threads {threads or 'default'}")
        results.append(run(backend, args.num_envs, threads, args.iterations))
    print(table(COLUMNS, results, sep=" "))
    record = {**header("torch_threads", "torch"), "iterations": args.iterations}
    write_json(args.out, {**record, "results": results})


if __name__ == "__main__":
    main()
