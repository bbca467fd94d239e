"""Time-to-walk: env steps from the start of PPO training to the first walking checkpoint.

Each configuration trains the Go1 from scratch, once per seed, for ``--env-steps`` (or
``--minutes``), saving a checkpoint every ``--save-interval`` iterations (50: every 76,800
env steps at 32 envs x 48 steps). After training, each run's checkpoints are checked in order
with the walking criterion of ``chronogym play``'s standard commands (``WalkingCriterion``:
5 episodes per command with fixed seeds, survival 100 %, x- and y-velocity MSE <= 0.01 (m/s)²
for every command) until the first that passes; its env steps (from the run's
``progress.csv``) are the run's time-to-walk, with the minutes it took on this machine beside
them (minutes differ ~1.5x between machines of one kind; env steps do not). The run's
``best.pt`` (kept during training from a smaller evaluation at each save point) and its last
checkpoint are then checked with the whole criterion too.

Writes ``time_to_walk.json`` (per configuration: settings, PPO settings, the median env
steps; per run: env steps and minutes to walk, best and last checkpoint), ``time_to_walk.csv``
(every checkpoint checked) and ``time_to_walk.png`` (commands passed and worst MSE against
env steps, one line per run).

    python -m benchmarks.rl.time_to_walk                      # the default, seeds 0-4
    python -m benchmarks.rl.time_to_walk --configs ray:32:0:48+ent1e-3 --seeds 1 2 --keep
    python -m benchmarks.rl.time_to_walk --evaluate-only --keep   # re-check the runs there
    python -m benchmarks.rl.time_to_walk --merge /tmp/a /tmp/b --keep   # invocations run apart

A configuration is as in ``train_throughput.py``
(``<ray|serial>:<num_envs>:<policy_lag>[:<steps_per_env>[:<physics_ms>[:<update_threads>]]]``)
plus ``+lever`` suffixes from :data:`VARIANTS` (PPO overrides and task arguments measured
against the default, e.g. ``ray:32:0:48+init_noise``); ``ray:32:0:48`` is the default of
``chronogym train quadruped``. ``serial:32:0:48`` trains number for number the same
(same envs, same update threads) and is how two runs share 2 cores side by side.
``--keep`` keeps the runs (configuration and seed) already in ``--out`` that this invocation
does not run; ``--merge DIR ...`` adds the runs of other invocations' ``--out`` folders
(later folders win) without training or checking anything. A configuration's settings list
every seed it has, and the machine record of an invocation that ran a kept configuration
stays in ``earlier_machines``.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import shutil
import statistics
from pathlib import Path
from typing import Any

import gymnasium as gym

import chronogym  # noqa: F401
from benchmarks.common import RESULTS, header, pyplot, save_figure, settings, write_json
from benchmarks.rl.train_throughput import parse_config

OUT = RESULTS / "time_to_walk"
#: Every seed of the default should walk within this many env steps (median <= 1.2 M).
GOAL_ENV_STEPS = 1.5e6
RUNS = Path("runs") / "time_to_walk"


def run_name(config: str, seed: int) -> str:
    return f"{config.replace(':', '-')}-s{seed}"


#: Levers measured against the default, added to a configuration as ``+name`` (several may
#: be chained: ``ray:32:0:48+ppo_anchor+init_noise``): PPO overrides and task arguments.
VARIANTS: dict[str, dict[str, Any]] = {
    "ppo_anchor": {"ppo": {"algorithm": {"learning_rate": 3e-4, "entropy_coef": 0.001}}},
    "lr3e-4": {"ppo": {"algorithm": {"learning_rate": 3e-4}}},
    "ppo_before": {"ppo": {"algorithm": {"learning_rate": 1e-4, "entropy_coef": 0.01}}},
    "lr1e-4": {"ppo": {"algorithm": {"learning_rate": 1e-4}}},
    "ent1e-2": {"ppo": {"algorithm": {"entropy_coef": 0.01}}},
    "lr5e-4": {"ppo": {"algorithm": {"learning_rate": 5e-4}}},
    "pushes": {"task": {"randomization": {"push_interval_s": 15.0, "push_velocity": 1.0}}},
    "critic": {"task": {"privileged_critic": True}},
    "mb8": {"ppo": {"algorithm": {"num_mini_batches": 8}}},
    "init_noise": {"task": {"reset_joint_scale": (0.5, 1.5), "reset_base_velocity": 0.5}},
    "vx1.5": {"task": {"commands": {"vx": (-0.5, 1.5)}}},
    "zero_cmd": {"task": {"commands": {"zero_below": 0.2, "standing_share": 0.1}}},
    "axis_cmd": {"task": {"commands": {"single_axis_share": 0.3, "standing_share": 0.1}}},
    "sigma0.15": {"task": {"tracking_sigma": 0.15}},
    "sigma0.1": {"task": {"tracking_sigma": 0.1}},
    # 10 s training episodes. Training's own evaluation (for best.pt) then runs 10 s episodes
    # too, where that of the committed runs ran 20 s ones; this script's check runs 20 s.
    "ep10s": {"task": {"max_episode_steps": 500}},
}


def split_config(text: str) -> tuple[str, list[str]]:
    """``"ray:32:0:48+a+b"`` -> ``("ray:32:0:48", ["a", "b"])``, checking both parts."""
    base, *variants = text.split("+")
    parse_config(base)
    for name in variants:
        if name not in VARIANTS:
            raise argparse.ArgumentTypeError(
                f"config {text!r}: unknown variant {name!r}; expected one of {sorted(VARIANTS)}"
            )
    return base, variants


def variant_settings(text: str) -> tuple[dict[str, Any], dict[str, Any]]:
    """The PPO overrides and task arguments of a configuration's variants."""
    from chronogym.rl.config import _merge

    base, variants = split_config(text)
    ppo: dict[str, Any] = {}
    task: dict[str, Any] = dict(parse_config(base).task_kwargs())
    for name in variants:
        _merge(ppo, VARIANTS[name].get("ppo", {}))
        _merge(task, VARIANTS[name].get("task", {}))
    from chronogym.tasks.quadruped.config import CommandRanges, DomainRandomization

    if "commands" in task:
        task["commands"] = CommandRanges(**task["commands"])
    if "randomization" in task:
        task["randomization"] = DomainRandomization(**task["randomization"])
    return ppo, task


def train_run(
    config: str, seed: int, budget: dict[str, float], save_interval: int, runs: Path
) -> Path:
    """Train one run from scratch; its folder (``progress.csv``, ``model_<it>.pt``).
    ``budget``: ``{"env_steps": n}`` or ``{"minutes": m}``."""
    from chronogym.tasks.quadruped.training import quadruped_train_config, train_quadruped

    c = parse_config(split_config(config)[0])
    ppo, task = variant_settings(config)
    out = runs / run_name(config, seed)
    shutil.rmtree(out, ignore_errors=True)
    overrides: dict[str, Any] = {**ppo, "save_interval": save_interval}
    if c.steps:
        overrides["num_steps_per_env"] = c.steps
    cfg = quadruped_train_config(**overrides)
    if "env_steps" in budget:
        per_iteration = c.num_envs * cfg["num_steps_per_env"]
        limit = {"iterations": math.ceil(budget["env_steps"] / per_iteration)}
    else:
        limit = {"minutes": budget["minutes"]}
    train_quadruped(
        out, num_envs=c.num_envs, backend=c.backend, seed=seed, policy_lag=c.policy_lag,
        train_cfg=cfg, task_kwargs=task, update_threads=c.update_threads, **limit,
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


def check(env: Any, path: Path, criterion: Any) -> tuple[bool, int, float]:
    """Whether the checkpoint at ``path`` walks, the commands it passes in order, and the worst
    x/y MSE over the commands checked (stopping at the first that fails)."""
    from chronogym.rl.checkpoint import load_policy
    from chronogym.tasks.quadruped.evaluation import check_walking

    walks, summary = check_walking(env, load_policy(path), criterion)
    passed = sum(criterion.passes(r) for r in summary)
    worst = max(max(r["x_vel_mse"], r["y_vel_mse"]) for r in summary)
    return walks, passed, worst


def evaluate_run(run: Path, criterion: Any, config: str) -> tuple[list[dict[str, Any]], dict]:
    """Check the run's checkpoints in order until one walks, on the physics step the run
    trained with (one row per checkpoint); then its ``best.pt`` and last checkpoint."""
    from chronogym.rl.best import read_best
    from chronogym.tasks.quadruped.engines import ENV_ID

    env = gym.make(ENV_ID, **parse_config(split_config(config)[0]).task_kwargs())
    rows = []
    found = checkpoints(run)
    try:
        for it, wall, steps, path in found:
            walks, passed, worst = check(env, path, criterion)
            rows.append({
                "run": run.name, "iteration": it, "wall_time": wall, "env_steps": steps,
                "commands_passed": passed, "worst_mse": worst, "walks": walks,
            })  # fmt: skip
            print(f"  {run.name} it {it:5d} {steps / 1e6:5.2f} M steps: {passed} commands pass"
                  f"{' -> WALKS' if walks else ''}", flush=True)  # fmt: skip
            if walks:
                break
        ends = {"last": {"iteration": found[-1][0], "env_steps": found[-1][2]}}
        ends["last"]["walks"] = check(env, found[-1][3], criterion)[0]
        best = read_best(run)
        if best is not None:
            ends["best"] = {**best, "walks": check(env, run / "best.pt", criterion)[0]}
    finally:
        env.close()
    return rows, ends


def plot(
    rows: list[dict[str, Any]], summary: list[dict[str, Any]], criterion: Any, path: Path
) -> None:
    """Commands passed and worst MSE against env steps (a line per run; colour: configuration,
    style: seed), and each configuration's env steps to walk (a dot per seed; an open triangle
    at the last checkpoint checked for a run that did not walk)."""
    fig, (left, middle, right) = pyplot().subplots(
        1, 3, figsize=(17, 4.6), gridspec_kw={"width_ratios": [1, 1, 1.1]}
    )
    configs = list(dict.fromkeys(s["config"] for s in summary))
    colors = pyplot().get_cmap("tab10")
    styles = ("-", "--", ":", "-.", (0, (6, 2, 1, 2, 1, 2)))
    for run in dict.fromkeys(r["run"] for r in rows):
        mine = [r for r in rows if r["run"] == run]
        steps = [r["env_steps"] / 1e6 for r in mine]
        color = colors(configs.index(mine[0]["config"]) % 10)
        style = styles[int(mine[0]["seed"]) % len(styles)]
        for axis, key in ((left, "commands_passed"), (middle, "worst_mse")):
            axis.plot(steps, [r[key] for r in mine], marker=".", ms=3, lw=1, color=color, ls=style)
    left.set_ylabel(f"commands passed in order (of {len(criterion.commands)})")
    middle.set_ylabel("worst episode-mean x/y velocity MSE (m/s)²")
    middle.axhline(criterion.max_x_mse, color="k", lw=0.8, ls="--")
    middle.set_yscale("log")
    for axis in (left, middle):
        axis.set_xlabel("env steps since training started (millions)")
        axis.grid(alpha=0.3)
    for y, config in enumerate(configs):
        mine = [s for s in summary if s["config"] == config]
        walked = [s["env_steps_to_walk"] / 1e6 for s in mine if s["env_steps_to_walk"]]
        failed = [
            (s.get("trained_env_steps") or 0) / 1e6 for s in mine if not s["env_steps_to_walk"]
        ]
        right.scatter(walked, [y] * len(walked), color=colors(y % 10), zorder=3)
        right.scatter(failed, [y] * len(failed), marker=">", facecolors="none",
                      edgecolors=colors(y % 10), zorder=3)  # fmt: skip
    right.axvline(GOAL_ENV_STEPS / 1e6, color="k", lw=0.8, ls="--")
    right.set_yticks(range(len(configs)), [f"{c} ({medians_label(summary, c)})" for c in configs])
    right.invert_yaxis()
    right.yaxis.tick_right()
    right.set_xlabel("env steps to the first walking checkpoint (millions; > : not by then)")
    right.grid(alpha=0.3, axis="x")
    fig.suptitle("Go1 time-to-walk: checkpoints checked in order until one walks")
    save_figure(fig, path)


def medians_label(summary: list[dict[str, Any]], config: str) -> str:
    """``"walked 4/5"`` for a configuration's runs."""
    mine = [s for s in summary if s["config"] == config]
    return f"walked {sum(bool(s['env_steps_to_walk']) for s in mine)}/{len(mine)}"


def summarize_run(config: str, seed: int, rows: list[dict[str, Any]], ends: dict, run: Path):
    """The JSON record of one run."""
    walked = [r for r in rows if r["walks"]]
    last = checkpoints(run)[-1]
    return {
        "config": config, "seed": seed,
        "env_steps_to_walk": walked[0]["env_steps"] if walked else None,
        "minutes_to_walk": walked[0]["wall_time"] / 60 if walked else None,
        "iteration_to_walk": walked[0]["iteration"] if walked else None,
        "trained_env_steps": last[2], "trained_min": last[1] / 60, **ends,
    }  # fmt: skip


def medians(summary: list[dict[str, Any]]) -> dict[str, dict[str, Any]]:
    """Per configuration: runs that walked, median env steps and minutes to walk (a run that
    never walked counts as longer than any that did; None if that is the median)."""
    out = {}
    for config in dict.fromkeys(s["config"] for s in summary):
        mine = [s for s in summary if s["config"] == config]
        med = {}
        for key in ("env_steps_to_walk", "minutes_to_walk"):
            value = statistics.median(math.inf if s[key] is None else s[key] for s in mine)
            med[key] = None if math.isinf(value) else value
        walked = sum(s["env_steps_to_walk"] is not None for s in mine)
        out[config] = {"walked": f"{walked}/{len(mine)}", **med}
        shown = ", ".join(
            f"s{s['seed']}: " + ("-" if s["env_steps_to_walk"] is None
                                 else f"{s['env_steps_to_walk'] / 1e6:.2f} M")
            for s in mine
        )  # fmt: skip
        steps = med["env_steps_to_walk"]
        print(f"{config:<28} walked {walked}/{len(mine)}; median "
              f"{'-' if steps is None else f'{steps / 1e6:.2f} M'} env steps; {shown}")  # fmt: skip
    return out


def main(argv: list[str] | None = None) -> None:
    from chronogym.tasks.quadruped.evaluation import WalkingCriterion

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--configs", nargs="+", default=["ray:32:0:48"])
    parser.add_argument("--seeds", nargs="+", type=int, default=[0, 1, 2, 3, 4])
    parser.add_argument("--env-steps", type=float, default=1.5e6, help="training budget per run")
    parser.add_argument("--minutes", type=float, help="training budget instead of --env-steps")
    parser.add_argument("--save-interval", type=int, default=50, help="iterations")
    parser.add_argument("--max-mse", type=float, default=0.01, help="(m/s)², x and y")
    parser.add_argument("--evaluate-only", action="store_true")
    parser.add_argument(
        "--keep",
        action="store_true",
        help="keep the runs (config and seed) already in --out that this invocation does not run",
    )
    parser.add_argument("--merge", nargs="+", type=Path, default=[], metavar="DIR",
                        help="only merge these result folders into --out")  # fmt: skip
    parser.add_argument("--runs", type=Path, default=RUNS)
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args(argv)
    try:
        for config in args.configs:
            split_config(config)
    except argparse.ArgumentTypeError as error:
        parser.error(str(error))
    budget = {"minutes": args.minutes} if args.minutes else {"env_steps": args.env_steps}
    if not next(iter(budget.values())) > 0 or args.save_interval < 1:
        parser.error(f"budget {budget}, --save-interval={args.save_interval}: expected a "
                     "budget > 0 and an interval >= 1")  # fmt: skip
    try:
        criterion = WalkingCriterion(max_x_mse=args.max_mse, max_y_mse=args.max_mse)
    except ValueError as error:
        parser.error(f"--max-mse: {error}")
    missing = [str(d) for d in args.merge if not (d / "time_to_walk.json").is_file()]
    if missing:
        parser.error(f"--merge: no time_to_walk.json in {', '.join(missing)}")
    runs = [] if args.merge else [(c, s) for c in args.configs for s in args.seeds]
    if not args.evaluate_only:
        for config, seed in runs:
            print(f"training {config} seed {seed} for {budget}", flush=True)
            train_run(config, seed, budget, args.save_interval, args.runs)
    rows: list[dict[str, Any]] = []
    summary = []
    for config, seed in runs:
        run = args.runs / run_name(config, seed)
        checked, ends = evaluate_run(run, criterion, config)
        rows += [{"config": config, "seed": seed, **r} for r in checked]
        summary.append(summarize_run(config, seed, checked, ends, run))
    sources = ([args.out] if args.keep else []) + list(args.merge)
    earlier = load_earlier(sources, set(runs))
    rows = earlier["rows"] + rows
    order = list(dict.fromkeys(s["config"] for s in earlier["runs"] + summary))
    summary = sorted(earlier["runs"] + summary, key=lambda s: (order.index(s["config"]), s["seed"]))
    per_config = medians(summary)
    args.out.mkdir(parents=True, exist_ok=True)
    with (args.out / "time_to_walk.csv").open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=list(rows[0]) if rows else ["config"])
        writer.writeheader()
        writer.writerows(rows)
    plot(rows, summary, criterion, args.out / "time_to_walk.png")
    ran = {c: merged_settings(args, c, earlier["settings"].get(c)) for c in args.configs if runs}
    record = {
        **header("time_to_walk", "torch", "rsl-rl-lib"),
        "settings": {**earlier["settings"], **ran},
        "criterion": {"max_x_mse": criterion.max_x_mse, "max_y_mse": criterion.max_y_mse,
                      "episodes": criterion.episodes, "commands": criterion.commands},
        "configs": per_config,
        "runs": summary,
    }  # fmt: skip
    if earlier["machines"]:
        record["earlier_machines"] = earlier["machines"]
    write_json(args.out / "time_to_walk.json", record)


def ppo_settings(config: str) -> dict[str, Any]:
    """The PPO settings a configuration trains with (``quadruped_train_config``'s algorithm
    with the configuration's overrides, and the initial action noise)."""
    from chronogym.tasks.quadruped.training import quadruped_train_config

    cfg = quadruped_train_config(**variant_settings(config)[0])
    return {**cfg["algorithm"], "init_std": cfg["actor"]["distribution_cfg"]["init_std"]}


def merged_settings(
    args: argparse.Namespace, config: str, earlier: dict[str, Any] | None
) -> dict[str, Any]:
    """This invocation's settings of ``config``, with the seeds of its kept runs."""
    current = {**settings(args), "ppo": ppo_settings(config)}
    current["task"] = {k: repr(v) for k, v in variant_settings(config)[1].items()}
    if earlier:
        current["seeds"] = sorted(set(earlier.get("seeds", [])) | set(args.seeds))
        if earlier.get("note"):
            current["note"] = earlier["note"]
    return current


def load_earlier(sources: list[Path], running: set[tuple[str, int]]) -> dict[str, Any]:
    """The rows, run summaries, settings and machine records in the result folders
    ``sources`` (a later folder's run replaces an earlier one's) of the runs (configuration,
    seed) that are not in ``running``."""
    found: dict[tuple[str, int], dict[str, Any]] = {}
    settings_kept: dict[str, Any] = {}
    machines: dict[str, Any] = {}
    for out in sources:
        path = out / "time_to_walk.json"
        if not path.exists():
            continue
        record = json.loads(path.read_text())
        with (out / "time_to_walk.csv").open(newline="") as handle:
            rows = list(csv.DictReader(handle))
        for run in record.get("runs", []):
            key = (run["config"], int(run["seed"]))
            if key in running:
                continue
            mine = [r for r in rows if (r["config"], int(r["seed"])) == key]
            found[key] = {"run": run, "rows": [as_numbers(r) for r in mine]}
            if run["config"] in record.get("settings", {}):
                kept = settings_kept.setdefault(run["config"], record["settings"][run["config"]])
                kept["seeds"] = sorted(set(kept.get("seeds", [])) | {key[1]})
            name = run["config"]
            machines[name] = record.get("earlier_machines", {}).get(
                name, {"date": record.get("date"), **record.get("machine", {})}
            )
    return {
        "rows": [r for v in found.values() for r in v["rows"]],
        "runs": [v["run"] for v in found.values()],
        "settings": settings_kept,
        "machines": machines,
    }


def as_numbers(row: dict[str, str]) -> dict[str, Any]:
    """A ``time_to_walk.csv`` row with its numbers read back."""
    out: dict[str, Any] = dict(row)
    for key in ("seed", "iteration", "env_steps", "commands_passed"):
        out[key] = int(row[key])
    for key in ("wall_time", "worst_mse"):
        out[key] = float(row[key])
    out["walks"] = row["walks"] == "True"
    return out


if __name__ == "__main__":
    main()
