"""The paper's transfer experiment: fine-tune a rigid-ground Go1 policy on deformable soil.

Every configuration resumes the same rigid-terrain checkpoint on SCM soil (the Go1 task's
``terrain="soil"``: Chrono's "firm" soil under the lower legs, 2 ms physics step) with the
paper's conservative PPO settings (``FINETUNE_PPO``: learning rate 1e-5, clip 0.02, desired KL
0.001, max grad norm 0.5) for the same wall-clock budget and seed: the serial baseline and Ray
with n_env in {8, 16}. Writes one CSV per configuration (``progress.csv`` of the run), the
paper's three panels against wall time (``soil_finetune.png``) and a JSON summary. Then the
deterministic policy (action mean) of the checkpoint before and of each run after is rolled
out on soil for a few fixed commands, and the table shows their velocity-tracking errors.

    python -m benchmarks.rl.soil_finetune                    # 3 min per configuration
    python -m benchmarks.rl.soil_finetune --minutes 20 --checkpoint runs/go1-rigid/latest.pt

Without a rigid checkpoint (``--checkpoint``, default ``runs/go1-rigid/latest.pt``, written by
``chronogym train quadruped --out runs/go1-rigid``), one is trained first for
``--rigid-minutes`` (serial, 32 envs).
"""

from __future__ import annotations

import argparse
import math
import os
from pathlib import Path

from benchmarks.common import RESULTS
from benchmarks.rl.rl_scaling import (  # this script's folder
    add_run_flags,
    check_run_flags,
    run_configs,
    write_results,
)

DEFAULT_OUT = RESULTS / "soil_finetune"
DEFAULT_RUNS = Path("runs") / "soil_finetune"  # checkpoints and TensorBoard events
DEFAULT_CHECKPOINT = Path("runs") / "go1-rigid" / "latest.pt"
DEFAULT_CONFIGS = ("serial-16", "ray-8", "ray-16")
SHORT_MINUTES = 3.0
EVAL_COMMANDS = ((0.5, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 0.5, 0.0), (0.0, 0.0, 1.0))


def rigid_checkpoint(path: Path, minutes: float, seed: int) -> Path:
    """``path`` if it exists, else a rigid policy trained for ``minutes`` (serial, 32 envs)."""
    if path.is_file():
        return path
    from chronogym.tasks.quadruped.training import train_quadruped

    print(f"== no rigid checkpoint at {path}: training one for {minutes:g} min (serial, 32 envs)")
    result = train_quadruped(path.parent, num_envs=32, backend="serial", minutes=minutes, seed=seed)
    return Path(result.checkpoint)


def evaluate_on_soil(checkpoint: str | Path, episodes: int, seed: int) -> dict[str, float]:
    """Mean survival and x/y velocity MSE of the deterministic policy over ``EVAL_COMMANDS``."""
    from chronogym.tasks.quadruped.play import play_quadruped

    rows = play_quadruped(
        checkpoint, commands=EVAL_COMMANDS, episodes=episodes, seed=seed, terrain="soil",
        progress=False,
    )  # fmt: skip
    mean = {key: sum(row[key] for row in rows) / len(rows) for key in ("survival",)}
    for key in ("x_vel_mse", "y_vel_mse"):
        values = [row[key] for row in rows if math.isfinite(row[key])]
        mean[key] = sum(values) / len(values) if values else math.nan
    return mean


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=SHORT_MINUTES, help="per configuration")
    parser.add_argument("--checkpoint", type=Path, default=DEFAULT_CHECKPOINT)
    parser.add_argument("--rigid-minutes", type=float, default=10.0)
    parser.add_argument("--eval-episodes", type=int, default=2, help="per command (0: skip)")
    add_run_flags(parser, DEFAULT_CONFIGS, DEFAULT_OUT, DEFAULT_RUNS)
    args = parser.parse_args()
    check_run_flags(parser, args, args.minutes)  # before a rigid checkpoint is trained
    checkpoint = rigid_checkpoint(args.checkpoint, args.rigid_minutes, args.seed)
    what = f"fine-tune on soil for {args.minutes:g} min from {checkpoint}"
    kwargs = {"resume": checkpoint, "terrain": "soil", "finetune": True}
    summaries = run_configs(args, args.minutes, what, **kwargs)
    evaluation = {}
    if args.eval_episodes > 0:
        print(f"deterministic policy on soil, {args.eval_episodes} episode(s) per command:")
        print(f"{'policy':>10} {'survival':>8} {'x_mse':>7} {'y_mse':>7}")
        policies = [("rigid", checkpoint)] + [(s["config"], s["checkpoint"]) for s in summaries]
        for label, path in policies:
            evaluation[label] = evaluate_on_soil(path, args.eval_episodes, args.seed)
            e = evaluation[label]
            print(f"{label:>10} {e['survival']:8.2f} {e['x_vel_mse']:7.4f} {e['y_vel_mse']:7.4f}")
    title = (
        f"Go1 fine-tuned from rigid ground onto SCM soil (firm), conservative PPO, "
        f"{args.minutes:g} min per configuration, {os.cpu_count()} CPUs"
    )
    write_results(
        summaries,
        args.out,
        "soil_finetune",
        title,
        minutes_per_config=args.minutes,
        seed=args.seed,
        rigid_checkpoint=str(checkpoint),
        evaluation_on_soil={"commands": EVAL_COMMANDS, "policies": evaluation},
    )


if __name__ == "__main__":
    main()
