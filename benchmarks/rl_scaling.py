"""The paper's scaling experiment: PPO on Go1 with n_env in {1, 8, 16} through Ray, plus serial.

Every configuration trains from scratch for the same wall-clock budget with the same PPO
settings and seed; the figure has the paper's three panels (mean episode reward, episode-mean
x-velocity MSE and y-velocity MSE against wall time). Writes one CSV per configuration, a JSON
summary and ``rl_scaling.png``.

    python benchmarks/rl_scaling.py                  # short budget: 2 min per configuration
    python benchmarks/rl_scaling.py --full           # 30 min per configuration
    python benchmarks/rl_scaling.py --minutes 5 --configs ray-16 serial-16

Configuration names are ``<backend>-<n_env>``; the serial backend steps its envs one after
another in the training process (the paper's "no Ray" baseline, same env code).
"""

from __future__ import annotations

import argparse
import csv
import datetime
import json
import math
import os
import platform
import shutil
from pathlib import Path

DEFAULT_OUT = Path(__file__).resolve().parent / "results" / "rl_scaling"
DEFAULT_RUNS = Path("runs") / "rl_scaling"  # checkpoints and TensorBoard events (not results)
DEFAULT_CONFIGS = ("ray-1", "ray-8", "ray-16", "serial-16")
SHORT_MINUTES = 2.0
FULL_MINUTES = 30.0


def parse_config(name: str) -> tuple[str, int]:
    backend, _, count = name.partition("-")
    if backend not in ("ray", "serial") or not count.isdigit() or int(count) < 1:
        raise argparse.ArgumentTypeError(
            f"config {name!r}: expected '<ray|serial>-<n_env>', e.g. ray-16"
        )
    return backend, int(count)


def run_config(
    name: str, minutes: float, out: Path, runs: Path, seed: int, **train_kwargs: object
) -> dict:
    """Train one configuration (``train_kwargs`` go to ``train_quadruped``, e.g. ``resume``);
    its summary. Iterations and env steps count this run only, also when it resumes."""
    from chronogym.rl.quadruped import QUADRUPED_PPO, train_quadruped

    backend, num_envs = parse_config(name)
    shutil.rmtree(runs / name, ignore_errors=True)  # a fresh progress.csv for the figure
    result = train_quadruped(
        runs / name, num_envs=num_envs, backend=backend, minutes=minutes, seed=seed, **train_kwargs
    )
    csv_path = out / f"{name}.csv"
    shutil.copyfile(result.csv_path, csv_path)
    rows = read_rows(csv_path)
    steps = len(rows) * num_envs * QUADRUPED_PPO["num_steps_per_env"]
    return {
        "config": name,
        "backend": backend,
        "num_envs": num_envs,
        "iterations": len(rows),
        "env_steps": steps,
        "wall_time": result.wall_time,
        "env_steps_per_s": steps / result.wall_time if result.wall_time else math.nan,
        "final": rows[-1] if rows else {},
        "csv": csv_path.name,
        "checkpoint": str(result.checkpoint),
    }


def read_rows(path: Path) -> list[dict[str, float]]:
    with path.open() as handle:
        return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(handle)]


def smoothed(values: list[float], window: int = 5) -> list[float]:
    out = []
    for i in range(len(values)):
        chunk = [v for v in values[max(0, i - window + 1) : i + 1] if math.isfinite(v)]
        out.append(sum(chunk) / len(chunk) if chunk else math.nan)
    return out


def plot(summaries: list[dict], path: Path, title: str) -> None:
    """The paper's three panels (reward, x and y velocity MSE against wall time)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(1, 3, figsize=(15, 4.2))
    panels = (
        ("mean_reward", "mean episode reward"),
        ("x_mse", "episode-mean x-velocity MSE (m/s)²"),
        ("y_mse", "episode-mean y-velocity MSE (m/s)²"),
    )
    for summary in summaries:
        rows = read_rows(path.parent / summary["csv"])
        minutes_axis = [row["wall_time"] / 60 for row in rows]
        for axis, (key, _) in zip(axes, panels, strict=True):
            window = 5 if key == "mean_reward" else 30  # MSEs: a few episodes per iteration
            values = smoothed([row[key] for row in rows], window)
            axis.plot(minutes_axis, values, label=summary["config"])
    for axis, (key, label) in zip(axes, panels, strict=True):
        axis.set_xlabel("wall-clock time (min)")
        axis.set_ylabel(label)
        axis.grid(alpha=0.3)
        if key != "mean_reward":
            axis.set_yscale("log")
    axes[0].legend(title="backend-n_env")
    fig.suptitle(title)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def print_table(summaries: list[dict]) -> None:
    """One row per configuration: iterations, env steps, throughput, last iteration's means."""
    print(
        f"{'config':>10} {'iters':>6} {'env steps':>10} {'steps/s':>8} {'reward':>8} "
        f"{'x_mse':>7} {'y_mse':>7}"
    )
    for s in summaries:
        final = s["final"]
        print(
            f"{s['config']:>10} {s['iterations']:6d} {s['env_steps']:10d} "
            f"{s['env_steps_per_s']:8.0f} {final.get('mean_reward', math.nan):8.2f} "
            f"{final.get('x_mse', math.nan):7.4f} {final.get('y_mse', math.nan):7.4f}"
        )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=None, help="budget per configuration")
    parser.add_argument("--full", action="store_true", help=f"{FULL_MINUTES:g} min each")
    parser.add_argument("--configs", nargs="+", default=list(DEFAULT_CONFIGS))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="CSVs, PNG and JSON")
    parser.add_argument("--runs", type=Path, default=DEFAULT_RUNS, help="checkpoints, events")
    args = parser.parse_args()
    for name in args.configs:
        parse_config(name)
    minutes = args.minutes or (FULL_MINUTES if args.full else SHORT_MINUTES)
    if not minutes > 0:
        parser.error(f"--minutes={minutes}: expected > 0")
    args.out.mkdir(parents=True, exist_ok=True)
    summaries = []
    for name in args.configs:
        print(f"== {name}: {minutes:g} min")
        summaries.append(run_config(name, minutes, args.out, args.runs, args.seed))
    print_table(summaries)
    png = args.out / "rl_scaling.png"
    title = (
        f"Go1 velocity tracking, PPO [512, 256, 128], {minutes:g} min per configuration, "
        f"{os.cpu_count()} CPUs"
    )
    plot(summaries, png, title)
    result = {
        "benchmark": "rl_scaling",
        "date": datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds"),
        "machine": {"platform": platform.platform(), "cpus": os.cpu_count()},
        "minutes_per_config": minutes,
        "seed": args.seed,
        "configs": summaries,
    }
    (args.out / "rl_scaling.json").write_text(json.dumps(result, indent=2))
    print(f"wrote {png} and {args.out / 'rl_scaling.json'}")


if __name__ == "__main__":
    main()
