"""Torch CPU threads beside simulation workers: PPO iteration time of the Go1 task.

For each configuration (backend, n_env, torch threads in the learner) it trains a few PPO
iterations with the quadruped's training config and reports, per iteration, the rollout
(collection) time, the PPO update (learning) time and env steps/s, median over the iterations
after the first. ``default`` is torch's own choice (one thread per core it sees).

    python benchmarks/torch_threads.py [--iterations 8] [--num-envs 32]

Prints a table and writes ``benchmarks/results/torch_threads.json``.
"""

from __future__ import annotations

import argparse
import csv
import datetime
import json
import os
import platform
import statistics
import tempfile
from pathlib import Path

DEFAULT_OUT = Path(__file__).resolve().parent / "results" / "torch_threads.json"


def run(backend: str, num_envs: int, threads: int | None, iterations: int) -> dict:
    import torch

    from chronogym.rl.quadruped import train_quadruped

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
    print(f"{'backend':>8} {'threads':>8} {'collect s':>10} {'learn s':>8} {'steps/s':>8}")
    for r in results:
        print(
            f"{r['backend']:>8} {r['torch_threads']!s:>8} {r['collect_s']:10.3f} "
            f"{r['learn_s']:8.3f} {r['env_steps_per_s']:8.0f}"
        )
    args.out.parent.mkdir(parents=True, exist_ok=True)
    args.out.write_text(
        json.dumps(
            {
                "benchmark": "torch_threads",
                "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
                "machine": {"platform": platform.platform(), "cpus": os.cpu_count()},
                "iterations": args.iterations,
                "results": results,
            },
            indent=2,
        )
    )
    print(f"wrote {args.out}")


if __name__ == "__main__":
    main()
