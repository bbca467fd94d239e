"""Sim-to-sim: a Go1 policy, evaluated in MuJoCo and in Project Chrono, command by command.

Both engines run the same task code (observation, action, reward, termination) on the same
robot numbers (``go1.xml``; the Chrono model is built from it), so any difference is the
physics: contact model, actuator integration, solver. Per standard command (those of
``chronogym play quadruped``) and engine it reports survival and the episode x/y-velocity
MSEs over ``--episodes`` episodes (seeds 0, 1, ...), and each engine's cost per env step (the
wall time of ``env.step``, the policy excluded). Needs PyChrono for the Chrono column.
Prints a table and writes ``results/sim_to_sim.json`` and a PNG.

    python -m benchmarks.chrono.sim_to_sim runs/time_to_walk/ray-32-0-48-s0/model_819.pt
    python -m benchmarks.chrono.sim_to_sim CKPT --configs mujoco-soil chrono-scm \
        --out benchmarks/results/sim_to_sim_soil.json
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from tqdm import tqdm

import chronogym  # noqa: F401  (registers the envs)
from benchmarks.common import (
    RESULTS,
    Column,
    header,
    pyplot,
    save_figure,
    settings,
    table,
    write_json,
)

OUT = RESULTS / "sim_to_sim.json"
#: Configurations: engine and task arguments. Rigid ground: the MuJoCo task and the Chrono task
#: per contact method; deformable ground (``--configs mujoco-soil chrono-scm``): chronogym's SCM
#: under MuJoCo and Chrono's SCMTerrain, both on the ``--soil`` preset.
CONFIGS: dict[str, tuple[str, dict[str, Any]]] = {
    "mujoco": ("mujoco", {}),
    "chrono-nsc": ("chrono", {"contact": "nsc"}),
    "chrono-smc": ("chrono", {"contact": "smc"}),
    "mujoco-soil": ("mujoco", {"terrain": "soil"}),
    "chrono-scm": ("chrono", {"terrain": "scm"}),
}
RIGID = ("mujoco", "chrono-nsc", "chrono-smc")


class StepClock:
    """Wraps an env: counts ``step`` calls and their wall time."""

    def __init__(self, env: Any) -> None:
        self.env, self.steps, self.seconds = env, 0, 0.0

    def __getattr__(self, name: str) -> Any:
        return getattr(self.env, name)

    def step(self, action: np.ndarray) -> Any:
        start = time.perf_counter()
        out = self.env.step(action)
        self.seconds += time.perf_counter() - start
        self.steps += 1
        return out


def evaluate_engine(
    config: str, checkpoint: Path, commands: list, episodes: int, steps: int, soil: str
) -> dict[str, Any]:
    """Summary rows and cost per env step of one configuration."""
    from chronogym.rl.trainer import load_policy
    from chronogym.tasks.quadruped.chrono_model import ChronoGo1Settings
    from chronogym.tasks.quadruped.engines import check_engine
    from chronogym.tasks.quadruped.evaluation import run_episode, summarize

    engine, options = CONFIGS[config]
    terrain = options.get("terrain", "rigid")
    env_id = check_engine(engine, terrain)
    from chronogym.tasks.quadruped.training import checkpoint_task_kwargs

    task_kwargs: dict[str, Any] = checkpoint_task_kwargs(checkpoint)  # its observations
    if terrain != "rigid":
        task_kwargs |= {"terrain": terrain, "soil": soil}
    if "contact" in options:
        task_kwargs["settings"] = ChronoGo1Settings(contact=options["contact"])
    env = StepClock(gym.make(env_id, max_episode_steps=steps, **task_kwargs))
    policy = load_policy(checkpoint)
    runs = [(c, s) for c in commands for s in range(episodes)]
    results = [run_episode(env, policy, c, s) for c, s in tqdm(runs, desc=config, unit="ep")]
    dt, k = env.unwrapped.task.dt, env.unwrapped.task.k
    env.close()
    return {
        "dt": dt,
        "k": k,
        "rows": summarize(results),
        "ms_per_step": 1e3 * env.seconds / env.steps,
        "steps": env.steps,
    }


def plot(commands: list, by_engine: dict[str, dict], path: Path) -> None:
    plt = pyplot()
    fig, axes = plt.subplots(1, 2, figsize=(10, 3.6), sharey=False)
    x = np.arange(len(commands))
    width = 0.8 / len(by_engine)
    for i, (engine, result) in enumerate(by_engine.items()):
        rows = result["rows"]
        axes[0].bar(x + i * width, [r["x_vel_mse"] for r in rows], width, label=engine)
        axes[1].bar(x + i * width, [r["survival"] for r in rows], width, label=engine)
    labels = ["(" + ", ".join(f"{c:g}" for c in command) + ")" for command in commands]
    for ax, title in zip(axes, ("x-velocity MSE (m/s)^2", "survival"), strict=True):
        ax.set_xticks(x + width * (len(by_engine) - 1) / 2, labels, rotation=30, fontsize=8)
        ax.set_title(title)
    axes[0].axhline(0.01, color="grey", lw=0.8, ls="--")
    axes[0].set_yscale("log")
    axes[0].legend()
    fig.suptitle("One Go1 policy in two engines (command vx, vy, yaw rate)")
    save_figure(fig, path)


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("checkpoint", type=Path)
    parser.add_argument("--episodes", type=int, default=3, help="episodes per command")
    parser.add_argument("--seconds", type=float, default=20.0, help="episode length")
    parser.add_argument("--configs", nargs="+", default=list(RIGID), choices=list(CONFIGS))
    parser.add_argument("--soil", default="firm", help="soil preset of the soil configurations")
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args(argv)
    if not args.checkpoint.is_file():
        parser.error(f"checkpoint {str(args.checkpoint)!r}: no such file")
    if args.episodes < 1 or not args.seconds > 0:
        parser.error(f"--episodes={args.episodes} --seconds={args.seconds}: expected >= 1, > 0")
    from chronogym.tasks.quadruped.evaluation import DEFAULT_COMMANDS

    commands = list(DEFAULT_COMMANDS)
    steps = round(args.seconds / 0.02)
    by_engine = {
        config: evaluate_engine(config, args.checkpoint, commands, args.episodes, steps, args.soil)
        for config in args.configs
    }
    rows = []
    for i, command in enumerate(commands):
        row: dict[str, Any] = {"command": "(" + ", ".join(f"{c:+.1f}" for c in command) + ")"}
        for engine, result in by_engine.items():
            summary = result["rows"][i]
            row[f"{engine}_survival"] = summary["survival"]
            row[f"{engine}_x_mse"] = summary["x_vel_mse"]
            row[f"{engine}_y_mse"] = summary["y_vel_mse"]
            row[f"{engine}_vx"] = summary["mean_vx"]
        rows.append(row)
    columns = [Column("command", 20, align="<", key="command")]
    for engine in by_engine:
        columns += [
            Column(f"{engine} surv", len(engine) + 5, "{:.2f}", key=f"{engine}_survival"),
            Column("x-MSE", 7, "{:.4f}", key=f"{engine}_x_mse"),
            Column("y-MSE", 7, "{:.4f}", key=f"{engine}_y_mse"),
            Column("mean vx", 7, "{:+.2f}", key=f"{engine}_vx"),
        ]
    print(table(columns, rows, rule=True))
    for engine, result in by_engine.items():
        print(
            f"{engine}: {result['ms_per_step']:.3f} ms per env step (dt {result['dt']:g} s x "
            f"{result['k']}; {result['steps']} steps)"
        )
    record = {**header("sim_to_sim", "torch", "mujoco"), "settings": settings(args)}
    record["pychrono"] = _pychrono_version()
    record["cost_ms_per_step"] = {e: r["ms_per_step"] for e, r in by_engine.items()}
    record["engines"] = by_engine
    record["rows"] = rows
    write_json(args.out, record)
    plot(commands, by_engine, args.out.with_suffix(".png"))


def _pychrono_version() -> str | None:
    try:
        import pychrono
    except ImportError:
        return None
    return str(getattr(pychrono, "__version__", None) or getattr(pychrono, "CHRONO_VERSION", ""))


if __name__ == "__main__":
    main()
