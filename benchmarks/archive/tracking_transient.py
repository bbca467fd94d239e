"""How much of a Go1 policy's episode x-velocity MSE is its start from rest.

Every evaluation episode (``chronogym play``, ``time_to_walk.py``) starts standing still
with the command already set, so the episode-mean MSE holds the acceleration to the
commanded speed. For each checkpoint and command this rolls out the criterion's episodes
(seeds 0..``--episodes``-1) and splits the episode x-velocity MSE into the part the first
``--head-s`` seconds add and the MSE of the rest (with its mean error: a steady offset).
Prints a table and writes ``results/tracking_transient.json``.

    python -m benchmarks.archive.tracking_transient runs/time_to_walk/ray-32-0-48-s0/model_819.pt \\
        runs/time_to_walk/ray-32-0-48-s1/model_1059.pt --commands 1 0 0 --commands 0.5 0 0
"""

from __future__ import annotations

import argparse
import math
from collections.abc import Callable
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import chronogym  # noqa: F401  (registers the envs)
from benchmarks.common import RESULTS, Column, header, settings, table, write_json

OUT = RESULTS / "tracking_transient.json"
DEFAULT_COMMANDS = ((1.0, 0.0, 0.0), (0.5, 0.0, 0.0))


def episode_errors(
    env: Any, policy: Callable[[np.ndarray], np.ndarray], command: tuple[float, ...], seed: int
) -> np.ndarray:
    """x-velocity error (body frame) of every decision of one episode."""
    obs, _ = env.reset(seed=seed, options={"command": tuple(command)})
    task = env.unwrapped.task
    errors = []
    while True:
        obs, _, terminated, truncated, _ = env.step(policy(obs))
        errors.append(float(task.base_lin_vel[0]) - command[0])
        if terminated or truncated:
            return np.asarray(errors)


def split(errors: np.ndarray, head: int) -> dict[str, float]:
    """Episode MSE, the share of it from the first ``head`` decisions, and the rest's stats."""
    squared = errors**2
    rest = errors[head:]
    return {
        "x_mse": float(squared.mean()),
        "head_part": float(squared[:head].sum() / len(errors)),
        "rest_mse": float((rest**2).mean()) if rest.size else math.nan,
        "rest_mean_error": float(rest.mean()) if rest.size else math.nan,
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("checkpoints", nargs="+", type=Path)
    parser.add_argument("--commands", nargs=3, type=float, action="append", metavar="V")
    parser.add_argument("--episodes", type=int, default=5)
    parser.add_argument("--head-s", type=float, default=1.0)
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args(argv)
    if args.episodes < 1 or not args.head_s > 0:
        parser.error(f"--episodes={args.episodes} --head-s={args.head_s}: expected >= 1 and > 0")
    for path in args.checkpoints:
        if not path.is_file():
            parser.error(f"checkpoint {str(path)!r}: no such file")
    from chronogym.rl.trainer import load_policy

    commands = [tuple(c) for c in args.commands] if args.commands else list(DEFAULT_COMMANDS)
    env = gym.make("chronogym/Go1Velocity-v0")
    head = max(1, round(args.head_s / env.unwrapped.task.control_dt))
    rows = []
    for path in args.checkpoints:
        policy = load_policy(path)
        for command in commands:
            episodes = [episode_errors(env, policy, command, s) for s in range(args.episodes)]
            parts = [split(errors, head) for errors in episodes]
            mean = {key: float(np.mean([p[key] for p in parts])) for key in parts[0]}
            rows.append({"checkpoint": f"{path.parent.name}/{path.name}", "vx": command[0], **mean})
    env.close()
    columns = [
        Column("checkpoint", 30, align="<", key="checkpoint"),
        Column("vx", 4, "{:.1f}", key="vx"),
        Column("x-MSE", 6, "{:.4f}", key="x_mse"),
        Column(f"first {args.head_s:g} s", 9, "{:.4f}", key="head_part"),
        Column("rest MSE", 8, "{:.4f}", key="rest_mse"),
        Column("rest mean err", 13, "{:+.3f}", key="rest_mean_error"),
    ]
    print(table(columns, rows, rule=True))
    record = {**header("tracking_transient", "torch"), "settings": settings(args)}
    write_json(args.out, {**record, "rows": rows})


if __name__ == "__main__":
    main()
