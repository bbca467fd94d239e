"""PPO training throughput on Go1, configurations side by side in one run, with a breakdown.

Each configuration trains from scratch for ``--iterations`` PPO iterations in its own
subprocess (its own local Ray for the Ray backend); the configurations alternate round by
round, so machine noise falls on all of them. Reported per configuration (medians over the
rounds, each round the median over iterations after ``--warmup``): env-steps/s, the
iteration's wall time, its rollout (``collect_s``) and update (``learn_s``) seconds, and the
ratio to the first configuration.

    python -m benchmarks.rl.train_throughput                        # default comparison
    python -m benchmarks.rl.train_throughput --configs serial:16:0 ray:16:0 ray:16:1 --rounds 3

A configuration is
``<ray|serial>:<num_envs>:<policy_lag>[:<steps_per_env>[:<physics_ms>[:<update_threads>]]]``
(steps per env per iteration default to the Go1 settings, 48; the physics step to the task's,
10 ms; a synchronous update's threads to ``train_quadruped``'s, every CPU). ``serial:32:0:48:5:1``
is serial, synchronous PPO at 5 ms physics with a 1-thread update.
"""

from __future__ import annotations

import argparse
import itertools
import json
import statistics
import subprocess
import sys
import tempfile
from dataclasses import dataclass
from pathlib import Path

from benchmarks.common import RESULTS, Column, header, settings, table, write_json

DEFAULT_CONFIGS = ("serial:32:0:48:5:1", "ray:32:0", "serial:32:0", "ray:32:1")
OUT = RESULTS / "train_throughput.json"

# Runs in the subprocess: train one configuration, print its per-iteration rows as JSON.
TRAIN = r"""
import csv, json, sys
from chronogym.tasks.quadruped.training import quadruped_train_config, train_quadruped
backend, num_envs, lag, steps, task_kwargs, threads, iterations, out = json.loads(sys.argv[1])
cfg = quadruped_train_config(**({"num_steps_per_env": steps} if steps else {}))
result = train_quadruped(out, num_envs=num_envs, backend=backend, iterations=iterations,
                         policy_lag=lag, train_cfg=cfg, progress=False, task_kwargs=task_kwargs,
                         update_threads=threads)
with open(result.csv_path, newline="") as handle:
    print(json.dumps(list(csv.DictReader(handle))))
"""


@dataclass(frozen=True)
class TrainConfig:
    """``<ray|serial>:<num_envs>:<policy_lag>[:<steps_per_env>[:<physics_ms>[:<threads>]]]``."""

    backend: str
    num_envs: int
    policy_lag: int
    steps: int | None = None  # steps per env per iteration (None: the Go1 default, 48)
    physics_ms: float | None = None  # physics step in ms (None: the task's default)
    update_threads: int | None = None  # threads of a synchronous update (None: the default)

    def task_kwargs(self) -> dict[str, float | int]:
        """The task's ``dt`` and ``k`` for ``physics_ms`` (20 ms per decision), or none."""
        if self.physics_ms is None:
            return {}
        return {"dt": self.physics_ms / 1000, "k": round(CONTROL_MS / self.physics_ms)}


CONTROL_MS = 20.0  # the Go1 task's decision interval


def parse_config(text: str) -> TrainConfig:
    parts = text.split(":")
    try:
        config = TrainConfig(
            parts[0],
            int(parts[1]),
            int(parts[2]),
            int(parts[3]) if len(parts) > 3 else None,
            float(parts[4]) if len(parts) > 4 else None,
            int(parts[5]) if len(parts) > 5 else None,
        )
    except (IndexError, ValueError):
        config = None
    ms = config.physics_ms if config else None
    if (
        config is None
        or config.backend not in ("ray", "serial")
        or len(parts) > 6
        or config.num_envs < 1
        or (config.update_threads is not None and config.update_threads < 1)
        or (config.update_threads is not None and config.policy_lag == 1)
        or config.policy_lag not in (0, 1)
        or (config.steps is not None and config.steps < 1)
        or (ms is not None and not (ms > 0 and (CONTROL_MS / ms).is_integer()))
    ):
        raise argparse.ArgumentTypeError(
            f"config {text!r}: expected '<ray|serial>:<num_envs>:<policy_lag 0|1>"
            "[:<steps_per_env>[:<physics_ms dividing 20>[:<update threads, lag 0 only>]]]', "
            "e.g. ray:32:0 or serial:32:0:48:5:1"
        )
    return config


def run_once(config: str, iterations: int, warmup: int) -> dict[str, float]:
    """Train ``config`` once; medians over its iterations after ``warmup``."""
    c = parse_config(config)
    with tempfile.TemporaryDirectory(prefix="chronogym-train-") as out:
        arg = json.dumps([c.backend, c.num_envs, c.policy_lag, c.steps, c.task_kwargs(),
                          c.update_threads, iterations, out])  # fmt: skip
        done = subprocess.run(
            [sys.executable, "-c", TRAIN, arg], capture_output=True, text=True, check=False
        )
    if done.returncode != 0:
        raise RuntimeError(f"{config} failed:\n{done.stderr[-3000:]}")
    rows = json.loads(done.stdout.strip().splitlines()[-1])[warmup:]
    walls = [float(r["wall_time"]) for r in rows]
    per_it = [b - a for a, b in itertools.pairwise(walls)]
    samples = (int(rows[1]["env_steps"]) - int(rows[0]["env_steps"])) if len(rows) > 1 else 0
    it_s = statistics.median(per_it)
    return {
        "iteration_s": it_s,
        "env_steps_per_s": samples / it_s,
        "collect_s": statistics.median(float(r["collect_s"]) for r in rows),
        "learn_s": statistics.median(float(r["learn_s"]) for r in rows),
        "samples_per_iteration": samples,
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--configs", nargs="+", default=list(DEFAULT_CONFIGS))
    parser.add_argument("--iterations", type=int, default=30)
    parser.add_argument("--warmup", type=int, default=5, help="iterations left out")
    parser.add_argument("--rounds", type=int, default=2)
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args(argv)
    for config in args.configs:
        parse_config(config)
    if args.iterations < args.warmup + 3 or args.rounds < 1:
        parser.error(
            f"--iterations={args.iterations} --rounds={args.rounds}: expected iterations >= "
            "warmup + 3 and rounds >= 1"
        )
    runs: dict[str, list[dict[str, float]]] = {c: [] for c in args.configs}
    for r in range(args.rounds):
        order = args.configs if r % 2 == 0 else list(reversed(args.configs))
        for config in order:
            runs[config].append(run_once(config, args.iterations, args.warmup))
            rate = runs[config][-1]["env_steps_per_s"]
            print(f"round {r + 1}/{args.rounds} {config}: {rate:,.0f} env-steps/s", flush=True)
    base = statistics.median(x["env_steps_per_s"] for x in runs[args.configs[0]])
    rows = []
    for config, samples in runs.items():
        med = {k: statistics.median(x[k] for x in samples) for k in samples[0]}
        rows.append({"config": config, **med, "vs_first": med["env_steps_per_s"] / base,
                     "rounds": samples})  # fmt: skip
    columns = [
        Column("config", 14, align="<", key="config"),
        Column("env-steps/s", 11, "{:,.0f}", key="env_steps_per_s"),
        Column("x first", 7, "{:.2f}", key="vs_first"),
        Column("iter s", 7, "{:.3f}", key="iteration_s"),
        Column("collect s", 9, "{:.3f}", key="collect_s"),
        Column("learn s", 7, "{:.3f}", key="learn_s"),
    ]
    print()
    print(table(columns, rows, rule=True))
    record = {**header("train_throughput", "torch", "rsl-rl-lib"), "settings": settings(args)}
    write_json(args.out, {**record, "rows": rows})


if __name__ == "__main__":
    main()
