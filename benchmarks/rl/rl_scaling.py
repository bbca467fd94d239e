"""The paper's scaling experiment: PPO on Go1 with n_env in {1, 8, 16} through Ray, plus serial.

Every configuration trains from scratch for the same wall-clock budget with the same PPO
settings and seed; the figure has the paper's three panels (mean episode reward, episode-mean
x-velocity MSE and y-velocity MSE against wall time). Writes one CSV per configuration, a JSON
summary and ``rl_scaling.png``.

    python -m benchmarks.rl.rl_scaling                  # short budget: 2 min per configuration
    python -m benchmarks.rl.rl_scaling --full           # 30 min per configuration
    python -m benchmarks.rl.rl_scaling --minutes 5 --configs ray-16 serial-16
    python -m benchmarks.rl.rl_scaling --engine chrono --resume runs/go1/best.pt --finetune
    python -m benchmarks.rl.rl_scaling --engine chrono --minutes 40 --configs ray-16 serial-16 \
        --save-interval 20 --check-walking --pychrono-commit SHA   # from scratch, time to walk
    python -m benchmarks.rl.rl_scaling --engine chrono --merge /tmp/ray16 /tmp/serial16

Configuration names are ``<backend>-<n_env>``; the serial backend steps its envs one after
another in the training process (the paper's "no Ray" baseline, same env code).
``--engine chrono`` trains the same task in Project Chrono (PyChrono needed; results in
``results/rl_scaling_chrono/`` unless ``--out`` says otherwise: the figure from scratch since
Chrono's resets are free of history is ``results/rl_scaling_chrono_fresh_resets/``), the
engine the paper ran its quadruped in; ``--resume CKPT``
starts every configuration from a checkpoint (e.g. a MuJoCo-trained ``best.pt``) instead of
from scratch, with ``--finetune`` under the paper's conservative PPO settings (results in
``results/rl_scaling_chrono_finetune/``, checkpoints in ``runs/rl_scaling_chrono_finetune/``).
Checkpoints are not scored for ``best.pt`` here (``eval_episodes=0``): the budget is all
training.

Each configuration's summary also has the first iteration whose mean episode reward reaches
10, 15 and 20 (wall minutes, env steps, and the minutes as a ratio to the first
configuration's), and whether its reward against env steps is the first's: with the same
seed it is, whatever the backend, so the ratios are those of throughput alone.

``--check-walking`` then judges each configuration's checkpoints (one every ``--save-interval``
iterations) in order, in the same engine, by the walking criteria v2 and v1 (as
``time_to_walk.py`` does) until one walks by each: the wall-clock minutes and env steps to
walk of every configuration, and the ratio of each to the first configuration's, go into the
JSON, and a dotted line marks each on the figure. ``--pychrono-commit`` records the commit
PyChrono was built from in the machine record.

``--iterations N`` also stops each configuration after N PPO iterations (whichever of the two
budgets comes first), e.g. to run a slower configuration exactly to the checkpoint at which
another walked: the same seed gives it the same policy there.

``--merge DIR ...`` only joins the results of invocations run apart (each its own ``--out``,
e.g. one configuration per sitting) into one figure and JSON in ``--out``: the comparisons
are made again against the first folder's first configuration, and each part keeps its date
and machine record (``parts``). The parts must share engine, start, seed, checkpoint interval,
PyChrono commit and task.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import shutil
from pathlib import Path
from typing import Any

from benchmarks.common import RESULTS, Column, header, pyplot, save_figure, table, write_json

DEFAULT_OUT = RESULTS / "rl_scaling"
DEFAULT_RUNS = Path("runs") / "rl_scaling"  # checkpoints and TensorBoard events (not results)
#: ``--engine`` -> (results folder, runs folder) when ``--out`` / ``--runs`` are not given
ENGINE_FOLDERS = {
    "mujoco": (DEFAULT_OUT, DEFAULT_RUNS),
    "chrono": (RESULTS / "rl_scaling_chrono", Path("runs") / "rl_scaling_chrono"),
}
#: appended to both folders' names with ``--resume`` (e.g. ``results/rl_scaling_chrono_finetune/``)
FINETUNE_SUFFIX = "_finetune"
#: mean episode rewards whose first crossing each configuration's summary times
REWARD_LEVELS = (10.0, 15.0, 20.0)
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
    """Train one configuration (``train_kwargs`` go to ``train_quadruped``, e.g. ``resume``
    or an ``iterations`` cap); its summary. Iterations and env steps count this run only,
    also when it resumes."""
    from chronogym.tasks.quadruped.training import QUADRUPED_PPO, train_quadruped

    backend, num_envs = parse_config(name)
    shutil.rmtree(runs / name, ignore_errors=True)  # a fresh progress.csv for the figure
    train_kwargs = {"eval_episodes": 0, **train_kwargs}
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


def reward_milestones(
    rows: list[dict[str, float]], levels: tuple[float, ...] = REWARD_LEVELS
) -> list[dict[str, Any]]:
    """The first iteration whose mean episode reward reaches each of ``levels``: its wall
    minutes and env steps (None: never)."""
    out = []
    for level in levels:
        hit = next((r for r in rows if r["mean_reward"] >= level), None)
        out.append({
            "reward": level,
            "minutes": hit["wall_time"] / 60 if hit else None,
            "env_steps": int(hit["env_steps"]) if hit else None,
        })  # fmt: skip
    return out


def same_curve(rows: list[dict[str, float]], base: list[dict[str, float]]) -> bool | None:
    """Do two runs log the same mean reward at every env-step count both reached (None: no
    count in common)? Same seed and settings give the same numbers on any backend."""
    theirs = {r["env_steps"]: r["mean_reward"] for r in base}
    shared = [(r["mean_reward"], theirs[r["env_steps"]]) for r in rows if r["env_steps"] in theirs]
    if not shared:
        return None
    return all(a == b or (math.isnan(a) and math.isnan(b)) for a, b in shared)


def compare_to_first(summaries: list[dict], out: Path) -> None:
    """Add to each summary its reward milestones (:func:`reward_milestones`), each one's
    minutes as a ratio to the first configuration's, and whether its reward curve against
    env steps is the first's (:func:`same_curve`)."""
    rows = {s["config"]: read_rows(out / s["csv"]) for s in summaries}
    first = summaries[0]
    for summary in summaries:
        mine = summary["reward_milestones"] = reward_milestones(rows[summary["config"]])
        for hit, base in zip(mine, reward_milestones(rows[first["config"]]), strict=True):
            both = hit["minutes"] is not None and base["minutes"]
            hit["minutes_ratio"] = hit["minutes"] / base["minutes"] if both else None
        summary["same_reward_curve_as_first"] = same_curve(
            rows[summary["config"]], rows[first["config"]]
        )


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
    fig, axes = pyplot().subplots(1, 3, figsize=(15, 4.2))
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
            (line,) = axis.plot(minutes_axis, values, label=summary["config"])
            walked = summary.get("minutes_to_walk_v2")
            if walked is not None:  # --check-walking: the first checkpoint that walks (v2)
                axis.axvline(walked, color=line.get_color(), ls=":", lw=1)
    for axis, (key, label) in zip(axes, panels, strict=True):
        axis.set_xlabel("wall-clock time (min)")
        axis.set_ylabel(label)
        axis.grid(alpha=0.3)
        if key != "mean_reward":
            axis.set_yscale("log")
    axes[0].legend(title="backend-n_env")
    fig.suptitle(title)
    save_figure(fig, path)


TABLE_COLUMNS = (
    Column("config", 10, key="config"),
    Column("iters", 6, "{:d}", key="iterations"),
    Column("env steps", 10, "{:d}", key="env_steps"),
    Column("steps/s", 8, "{:.0f}", key="env_steps_per_s"),
    Column("reward", 8, "{:.2f}", key="mean_reward"),
    Column("x_mse", 7, "{:.4f}", key="x_mse"),
    Column("y_mse", 7, "{:.4f}", key="y_mse"),
)


def print_table(summaries: list[dict]) -> None:
    """One row per configuration: iterations, env steps, throughput, last iteration's means."""
    final = ("mean_reward", "x_mse", "y_mse")
    rows = [{**s, **{key: s["final"].get(key, math.nan) for key in final}} for s in summaries]
    print(table(TABLE_COLUMNS, rows, sep=" "))


def write_results(summaries: list[dict], out: Path, name: str, title: str, **fields: Any) -> None:
    """``<name>.png`` (the three panels) and ``<name>.json`` (the header, ``fields`` and the
    configurations' summaries) in ``out``."""
    png = out / f"{name}.png"
    plot(summaries, png, title)
    record = {**header(name, "torch"), **fields, "configs": summaries}
    write_json(out / f"{name}.json", record, f" and {png}")


def add_run_flags(
    parser: argparse.ArgumentParser,
    configs: tuple[str, ...],
    out: Path | None,
    runs: Path | None,
) -> None:
    """``--configs``, ``--seed``, ``--out`` and ``--runs`` (also ``soil_finetune.py``'s)."""
    parser.add_argument("--configs", nargs="+", default=list(configs))
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", type=Path, default=out, help="CSVs, PNG and JSON")
    parser.add_argument("--runs", type=Path, default=runs, help="checkpoints, events")


def check_run_flags(
    parser: argparse.ArgumentParser, args: argparse.Namespace, minutes: float
) -> None:
    """Stop with a usage error on a bad ``--configs`` name or budget."""
    for name in args.configs:
        try:
            parse_config(name)
        except argparse.ArgumentTypeError as error:
            parser.error(str(error))
    if not minutes > 0:
        parser.error(f"--minutes={minutes}: expected > 0")


def run_configs(
    args: argparse.Namespace, minutes: float, what: str, **train_kwargs: Any
) -> list[dict]:
    """Train each configuration (printing ``== <config>: <what>``), print the table; the
    summaries."""
    args.out.mkdir(parents=True, exist_ok=True)
    summaries = []
    for name in args.configs:
        print(f"== {name}: {what}")
        summaries.append(run_config(name, minutes, args.out, args.runs, args.seed, **train_kwargs))
    print_table(summaries)
    return summaries


def time_to_walk(summaries: list[dict], runs: Path, engine: str) -> None:
    """Judge each configuration's checkpoints in order by v2 and v1 in ``engine``; add the
    minutes and env steps to walk by each (None: not by the end) to its summary, and the
    ratio of its minutes to the first configuration's."""
    import gymnasium as gym

    from benchmarks.rl.time_to_walk import evaluate_run
    from chronogym.tasks.quadruped.engines import ENV_IDS, env_kwargs_for
    from chronogym.tasks.quadruped.training import checkpoint_task_kwargs
    from chronogym.tasks.quadruped.walking import WalkingCriterion, WalkingCriterionV1

    for summary in summaries:
        run = runs / summary["config"]
        # the observations the policy was trained on, read from its checkpoint as play does
        kwargs = env_kwargs_for("rigid", checkpoint_task_kwargs(summary["checkpoint"]), engine)
        rows, ends, _ = evaluate_run(
            run,
            [WalkingCriterion(), WalkingCriterionV1()],
            lambda kwargs=kwargs: gym.make(ENV_IDS[engine], **kwargs),
        )
        for suffix, key in (("_v2", "v2_walks"), ("_v1", "walks")):
            walked = [r for r in rows if r[key]]
            summary[f"minutes_to_walk{suffix}"] = walked[0]["wall_time"] / 60 if walked else None
            summary[f"env_steps_to_walk{suffix}"] = walked[0]["env_steps"] if walked else None
        summary["checked"] = [{k: v for k, v in r.items() if k != "run"} for r in rows]
        summary["last"] = ends["last"]
    walk_ratios(summaries)


def walk_ratios(summaries: list[dict]) -> None:
    """Add to each checked summary the ratio of its minutes to walk (v2, v1) to the first
    configuration's (None: either did not walk, or was not checked)."""
    first = summaries[0]
    for summary in summaries:
        for suffix in ("_v2", "_v1"):
            mine = summary.get(f"minutes_to_walk{suffix}")
            base = first.get(f"minutes_to_walk{suffix}")
            summary[f"time_to_walk_ratio{suffix}"] = mine / base if mine and base else None


#: run settings every merged part must share (a figure compares backends, nothing else)
SHARED_FIELDS = ("benchmark", "engine", "start", "seed", "save_interval", "pychrono_commit", "task")


def merge_results(folders: list[Path], out: Path) -> dict[str, Any]:
    """One figure from the results of invocations run apart (e.g. ``ray-16`` in one sitting,
    ``serial-16`` in the next), configurations in the folders' order: their CSVs are copied
    into ``out``, the milestones, same-curve check and walk ratios recomputed against the first
    configuration; each part's date and machine record are kept in ``parts``. The fields of
    the JSON besides the header and ``configs``."""
    records = []
    for folder in folders:
        path = folder / "rl_scaling.json"
        if not path.is_file():
            raise ValueError(f"--merge {folder}: no rl_scaling.json there")
        records.append((folder, json.loads(path.read_text())))
    first = records[0][1]
    for folder, record in records[1:]:
        differ = [k for k in SHARED_FIELDS if record.get(k) != first.get(k)]
        if differ:
            raise ValueError(
                f"--merge {folder}: {', '.join(differ)} differ from {records[0][0]}'s "
                f"({', '.join(f'{k}={record.get(k)!r} vs {first.get(k)!r}' for k in differ)})"
            )
    summaries: list[dict] = []
    for folder, record in records:
        for summary in record["configs"]:
            if any(s["config"] == summary["config"] for s in summaries):
                raise ValueError(f"--merge {folder}: configuration {summary['config']} twice")
            summaries.append(summary)
            if folder.resolve() != out.resolve():
                out.mkdir(parents=True, exist_ok=True)
                shutil.copyfile(folder / summary["csv"], out / summary["csv"])
    compare_to_first(summaries, out)
    walk_ratios(summaries)
    parts = [
        {"configs": [s["config"] for s in record["configs"]], "date": record["date"],
         "machine": record["machine"], "minutes_per_config": record["minutes_per_config"],
         "iterations_cap": record.get("iterations_cap")}
        for _, record in records
    ]  # fmt: skip
    minutes = sorted({part["minutes_per_config"] for part in parts})
    fields = {k: first.get(k) for k in SHARED_FIELDS if k != "benchmark"}
    return {"minutes_per_config": minutes[0] if len(minutes) == 1 else minutes, **fields,
            "configs": summaries, "parts": parts}  # fmt: skip


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--minutes", type=float, default=None, help="budget per configuration")
    parser.add_argument("--full", action="store_true", help=f"{FULL_MINUTES:g} min each")
    parser.add_argument(
        "--iterations",
        type=int,
        help="also stop each configuration after this many PPO iterations (default: no cap)",
    )
    parser.add_argument("--engine", choices=sorted(ENGINE_FOLDERS), default="mujoco")
    parser.add_argument("--resume", type=Path, help="checkpoint to start from (default: scratch)")
    parser.add_argument("--finetune", action="store_true", help="the paper's conservative PPO")
    parser.add_argument("--save-interval", type=int, help="iterations between checkpoints")
    parser.add_argument(
        "--check-walking",
        action="store_true",
        help="then find each configuration's first walking checkpoint (v2, v1)",
    )
    parser.add_argument("--pychrono-commit", help="the commit PyChrono was built from (recorded)")
    parser.add_argument(
        "--merge",
        nargs="+",
        type=Path,
        default=[],
        metavar="DIR",
        help="only merge these result folders (runs made apart) into --out",
    )
    add_run_flags(parser, DEFAULT_CONFIGS, None, None)
    args = parser.parse_args()
    default_out, default_runs = ENGINE_FOLDERS[args.engine]
    if args.resume is not None:  # a fine-tune is another experiment than a run from scratch
        default_out = default_out.with_name(default_out.name + FINETUNE_SUFFIX)
        default_runs = default_runs.with_name(default_runs.name + FINETUNE_SUFFIX)
    args.out = args.out or default_out
    args.runs = args.runs or default_runs
    if args.merge:
        try:
            merged = merge_results(args.merge, args.out)
        except ValueError as error:
            parser.error(str(error))
        summaries = merged.pop("configs")
        cpus = merged["parts"][0]["machine"].get("cpus")
        title = figure_title(merged["engine"], merged["start"], merged["minutes_per_config"], cpus)
        write_results(summaries, args.out, "rl_scaling", title, **merged)
        return
    minutes = args.minutes or (FULL_MINUTES if args.full else SHORT_MINUTES)
    check_run_flags(parser, args, minutes)
    if args.resume is not None and not args.resume.is_file():
        parser.error(f"--resume={args.resume}: no such checkpoint file")
    if args.iterations is not None and args.iterations < 1:
        parser.error(f"--iterations={args.iterations}: expected an integer >= 1")
    if args.save_interval is not None and args.save_interval < 1:
        parser.error(f"--save-interval={args.save_interval}: expected an integer >= 1")
    if args.finetune and args.resume is None:
        parser.error("--finetune: expected --resume CKPT too (fine-tuning needs a policy)")
    try:
        from chronogym.tasks.quadruped.engines import check_engine

        check_engine(args.engine)
    except (ValueError, ImportError) as error:
        parser.error(f"--engine {args.engine}: {error}")
    start = f"fine-tuned from {args.resume}" if args.resume else "from scratch"
    extra: dict[str, Any] = {}
    if args.iterations is not None:
        extra["iterations"] = args.iterations
    if args.save_interval is not None:
        from chronogym.tasks.quadruped.training import quadruped_train_config

        extra["train_cfg"] = quadruped_train_config(save_interval=args.save_interval)
    summaries = run_configs(
        args, minutes, f"{minutes:g} min, {start}", engine=args.engine, resume=args.resume,
        finetune=args.finetune, **extra,
    )  # fmt: skip
    compare_to_first(summaries, args.out)
    if args.check_walking:
        time_to_walk(summaries, args.runs, args.engine)
        for s in summaries:
            print(f"{s['config']}: walks by v2 after "
                  f"{fmt_minutes(s['minutes_to_walk_v2'])}, by v1 after "
                  f"{fmt_minutes(s['minutes_to_walk_v1'])}")  # fmt: skip
    title = figure_title(args.engine, start, minutes, os.cpu_count())
    write_results(
        summaries, args.out, "rl_scaling", title, minutes_per_config=minutes, seed=args.seed,
        engine=args.engine, start=start, save_interval=args.save_interval,
        iterations_cap=args.iterations, pychrono_commit=args.pychrono_commit, task=quadruped_task(),
    )  # fmt: skip


def figure_title(engine: str, start: str, minutes: Any, cpus: int | None) -> str:
    """The figure's title: engine, policy, start, budget per configuration and CPUs."""
    budget = f"{minutes:g}" if isinstance(minutes, float | int) else "/".join(map(str, minutes))
    return (
        f"Go1 velocity tracking in {engine}, PPO [512, 256, 128], {start}, "
        f"{budget} min per configuration, {cpus} CPUs"
    )


def quadruped_task() -> dict[str, Any]:
    """The task settings training adds by default (``QUADRUPED_TASK``), for the record."""
    from chronogym.tasks.quadruped.training import QUADRUPED_TASK

    return dict(QUADRUPED_TASK)


def fmt_minutes(value: float | None) -> str:
    return "- (not by the end)" if value is None else f"{value:.1f} min"


if __name__ == "__main__":
    main()
