"""Time-to-walk: wall-clock from the start of PPO training to the first walking checkpoint.

Each configuration trains the Go1 from scratch, once per seed, for ``--minutes``, saving a
checkpoint every ``--save-interval`` iterations. After all training (so evaluation never
slows it), each run's checkpoints are checked in order with the walking criterion of
``chronogym play``'s standard commands (``WalkingCriterion``: 5 episodes per command with
fixed seeds, survival 100 %, x- and y-velocity MSE <= 0.01 (m/s)² for every command), until
the first that passes; its wall time (from the run's ``progress.csv``) is the run's
time-to-walk. Writes ``time_to_walk.json``, ``time_to_walk.csv`` (every checkpoint checked)
and ``time_to_walk.png`` (commands passed and worst MSE against wall clock, one line per run).

    python benchmarks/rl/time_to_walk.py --configs serial:32:0:48:5:1 ray:32:0 --seeds 0 1
    python benchmarks/rl/time_to_walk.py --evaluate-only      # re-check the runs already there
    python benchmarks/rl/time_to_walk.py --configs ray:32:0:48 --seeds 2 --keep   # add a seed

A configuration is as in ``train_throughput.py``
(``<ray|serial>:<num_envs>:<policy_lag>[:<steps_per_env>[:<physics_ms>[:<update_threads>]]]``);
``serial:32:0:48:5:1`` is serial, synchronous PPO at 5 ms physics with a 1-thread update;
``ray:32:0:48`` is the default of ``chronogym train quadruped``.
``--keep`` keeps the runs (configuration and seed) already in ``--out`` that this invocation
does not run; a configuration's settings then list every seed it has, and the machine record
(with its date) of the invocation that ran a kept configuration stays in ``earlier_machines``.
"""

from __future__ import annotations

import argparse
import csv
import math
import statistics
import sys
from pathlib import Path
from typing import Any

sys.path.insert(0, str(Path(__file__).resolve().parents[1]))  # benchmarks/: common
from common import RESULTS, header, pyplot, save_figure, settings, write_json
from train_throughput import parse_config

OUT = RESULTS / "time_to_walk"
RUNS = Path("runs") / "time_to_walk"


def run_name(config: str, seed: int) -> str:
    return f"{config.replace(':', '-')}-s{seed}"


def train_run(config: str, seed: int, minutes: float, save_interval: int, runs: Path) -> Path:
    """Train one run from scratch; its folder (``progress.csv``, ``model_<it>.pt``)."""
    import shutil

    from chronogym.rl.quadruped import quadruped_train_config, train_quadruped

    c = parse_config(config)
    out = runs / run_name(config, seed)
    shutil.rmtree(out, ignore_errors=True)
    overrides: dict[str, Any] = {"save_interval": save_interval}
    if c.steps:
        overrides["num_steps_per_env"] = c.steps
    train_quadruped(
        out, num_envs=c.num_envs, backend=c.backend, minutes=minutes, seed=seed,
        policy_lag=c.policy_lag, train_cfg=quadruped_train_config(**overrides),
        task_kwargs=c.task_kwargs(), update_threads=c.update_threads,
    )  # fmt: skip
    return out


def checkpoints(run: Path) -> list[tuple[int, float, int, Path]]:
    """(iteration, wall seconds, env steps, path) of each saved checkpoint, in order."""
    with (run / "progress.csv").open(newline="") as handle:
        rows = {int(r["iteration"]): r for r in csv.DictReader(handle)}
    found = []
    for path in run.glob("model_*.pt"):
        it = int(path.stem.split("_")[1])
        if it in rows:
            found.append((it, float(rows[it]["wall_time"]), int(rows[it]["env_steps"]), path))
    return sorted(found)


def evaluate_run(run: Path, criterion: Any, config: str) -> list[dict[str, Any]]:
    """Check the run's checkpoints in order until one walks, on the physics step the run
    trained with; one row per checkpoint."""
    import gymnasium as gym

    import chronogym  # noqa: F401
    from chronogym.rl.evaluate import check_walking
    from chronogym.rl.quadruped import ENV_ID
    from chronogym.rl.trainer import load_policy

    env = gym.make(ENV_ID, **parse_config(config).task_kwargs())
    rows = []
    try:
        for it, wall, steps, path in checkpoints(run):
            walks, summary = check_walking(env, load_policy(path), criterion)
            passed = sum(criterion.passes(r) for r in summary)
            worst = max(max(r["x_vel_mse"], r["y_vel_mse"]) for r in summary)
            rows.append({
                "run": run.name, "iteration": it, "wall_time": wall, "env_steps": steps,
                "commands_passed": passed, "worst_mse": worst, "walks": walks,
            })  # fmt: skip
            print(f"  {run.name} it {it:5d} {wall / 60:6.2f} min: {passed} commands pass"
                  f"{' -> WALKS' if walks else ''}", flush=True)  # fmt: skip
            if walks:
                break
    finally:
        env.close()
    return rows


def plot(rows: list[dict[str, Any]], criterion: Any, path: Path) -> None:
    fig, (left, right) = pyplot().subplots(1, 2, figsize=(12, 4.2))
    configs = list(dict.fromkeys(r["config"] for r in rows))
    colors = pyplot().get_cmap("tab10")
    styles = ("-", "--", ":", "-.", (0, (6, 2, 1, 2, 1, 2)))  # colour: config; style: seed
    for run in dict.fromkeys(r["run"] for r in rows):
        mine = [r for r in rows if r["run"] == run]
        minutes = [r["wall_time"] / 60 for r in mine]
        color = colors(configs.index(mine[0]["config"]) % 10)
        style = styles[int(mine[0]["seed"]) % len(styles)]
        for axis, key in ((left, "commands_passed"), (right, "worst_mse")):
            values = [r[key] for r in mine]
            axis.plot(minutes, values, marker=".", color=color, ls=style, label=run)
    left.set_ylabel(f"commands passed (of {len(criterion.commands)})")
    right.set_ylabel("worst episode-mean x/y velocity MSE (m/s)²")
    right.axhline(criterion.max_x_mse, color="k", lw=0.8, ls="--")
    right.set_yscale("log")
    for axis in (left, right):
        axis.set_xlabel("wall-clock time since training started (min)")
        axis.grid(alpha=0.3)
    left.legend(fontsize=8)
    fig.suptitle("Go1 time-to-walk (commands evaluated in order until one fails)")
    save_figure(fig, path)


def main(argv: list[str] | None = None) -> None:
    from chronogym.rl.evaluate import WalkingCriterion

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--configs", nargs="+", default=["serial:32:0:48:5:1", "ray:32:0:48"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1])
    parser.add_argument("--minutes", type=float, default=12.0, help="training budget per run")
    parser.add_argument("--save-interval", type=int, default=40, help="iterations")
    parser.add_argument("--max-mse", type=float, default=0.01, help="(m/s)², x and y")
    parser.add_argument("--evaluate-only", action="store_true")
    parser.add_argument(
        "--keep",
        action="store_true",
        help="keep the runs (config and seed) already in --out that this invocation does not run",
    )
    parser.add_argument("--runs", type=Path, default=RUNS)
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args(argv)
    for config in args.configs:
        parse_config(config)
    if not args.minutes > 0 or args.save_interval < 1:
        parser.error(f"--minutes={args.minutes} --save-interval={args.save_interval}: "
                     "expected minutes > 0 and an interval >= 1")  # fmt: skip
    try:
        criterion = WalkingCriterion(max_x_mse=args.max_mse, max_y_mse=args.max_mse)
    except ValueError as error:
        parser.error(f"--max-mse: {error}")
    runs = [(c, s) for c in args.configs for s in args.seeds]
    if not args.evaluate_only:
        for config, seed in runs:
            print(f"training {config} seed {seed} for {args.minutes} min", flush=True)
            train_run(config, seed, args.minutes, args.save_interval, args.runs)
    rows: list[dict[str, Any]] = []
    summary = []
    for config, seed in runs:
        checked = evaluate_run(args.runs / run_name(config, seed), criterion, config)
        rows += [{"config": config, "seed": seed, **r} for r in checked]
        walked = [r for r in checked if r["walks"]]
        summary.append({
            "config": config, "seed": seed,
            "time_to_walk_min": walked[0]["wall_time"] / 60 if walked else None,
            "env_steps": walked[0]["env_steps"] if walked else None,
            "trained_min": checkpoints(args.runs / run_name(config, seed))[-1][1] / 60,
        })  # fmt: skip
    earlier = load_earlier(args.out, set(runs)) if args.keep else {"rows": [], "runs": []}
    rows = earlier["rows"] + rows
    summary = earlier["runs"] + summary
    configs = list(dict.fromkeys([s["config"] for s in summary]))
    medians = {}
    for config in configs:
        times = [s["time_to_walk_min"] for s in summary if s["config"] == config]
        # a run that never walked counts as longer than its budget
        ranked = [t if t is not None else math.inf for t in times]
        medians[config] = statistics.median(ranked)
        shown = ", ".join("-" if t is None else f"{t:.1f}" for t in times)
        print(f"{config:<16} time-to-walk (min): median {medians[config]:.1f}; runs {shown}")
    args.out.mkdir(parents=True, exist_ok=True)
    with (args.out / "time_to_walk.csv").open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]) if rows else ["config"])
        writer.writeheader()
        writer.writerows(rows)
    plot(rows, criterion, args.out / "time_to_walk.png")
    record = {
        **header("time_to_walk", "torch", "rsl-rl-lib"),
        "settings": {**earlier.get("settings", {}),
                     **{config: merged_settings(args, earlier.get("settings", {}).get(config))
                        for config in args.configs}},
        "criterion": {"max_x_mse": criterion.max_x_mse, "max_y_mse": criterion.max_y_mse,
                      "episodes": criterion.episodes, "commands": criterion.commands},
        "median_min": {k: (None if math.isinf(v) else v) for k, v in medians.items()},
        "runs": summary,
    }  # fmt: skip
    if earlier.get("machines"):
        record["earlier_machines"] = earlier["machines"]
    write_json(args.out / "time_to_walk.json", record)


def ppo_settings() -> dict[str, Any]:
    """The PPO settings the runs trained with (``quadruped_train_config``'s algorithm and
    initial action noise)."""
    from chronogym.rl.quadruped import quadruped_train_config

    cfg = quadruped_train_config()
    return {**cfg["algorithm"], "init_std": cfg["actor"]["distribution_cfg"]["init_std"]}


def merged_settings(args: argparse.Namespace, earlier: dict[str, Any] | None) -> dict[str, Any]:
    """This invocation's settings of a configuration, with the seeds of its kept runs."""
    current = {**settings(args), "ppo": ppo_settings()}
    if earlier:
        current["seeds"] = sorted(set(earlier.get("seeds", [])) | set(args.seeds))
        if earlier.get("note"):
            current["note"] = earlier["note"]
    return current


def load_earlier(out: Path, running: set[tuple[str, int]]) -> dict[str, Any]:
    """The rows, run summaries, settings and machine records in ``out`` of the runs
    (configuration, seed) that are not in ``running``."""
    path = out / "time_to_walk.json"
    if not path.exists():
        return {"rows": [], "runs": []}
    import json

    record = json.loads(path.read_text())
    kept = [r for r in record.get("runs", []) if (r["config"], int(r["seed"])) not in running]
    names = {r["config"] for r in kept}
    pairs = {(r["config"], str(r["seed"])) for r in kept}
    with (out / "time_to_walk.csv").open(newline="") as handle:
        rows = [r for r in csv.DictReader(handle) if (r["config"], r["seed"]) in pairs]
    for row in rows:  # CSV text back to numbers
        for key in ("seed", "iteration", "env_steps", "commands_passed"):
            row[key] = int(row[key])
        for key in ("wall_time", "worst_mse"):
            row[key] = float(row[key])
        row["walks"] = row["walks"] == "True"
    machines = {**record.get("earlier_machines", {})}
    for name in names:
        machines.setdefault(name, {"date": record.get("date"), **record.get("machine", {})})
    settings_kept = {k: v for k, v in record.get("settings", {}).items() if k in names}
    return {"rows": rows, "runs": kept, "settings": settings_kept, "machines": machines}


if __name__ == "__main__":
    main()
