"""Robustness of a Go1 policy: survival and tracking under pushes and friction randomization.

Plays one checkpoint, as ``chronogym play quadruped --push`` / ``--friction LO HI`` do, on the
standard commands (5 episodes each, the walking criterion's seeds) under each condition of
:data:`CONDITIONS`: nominal, base pushes of growing size (the task's ``DomainRandomization``:
a random horizontal velocity kick of up to ``v`` m/s per axis every ``interval`` s; legged_gym
trains with 1 m/s every 15 s) and foot-ground friction drawn per episode from a range.
Prints a table and writes ``robustness.json`` (every command's row per condition) and
``robustness.png``.

    python -m benchmarks.rl.robustness runs/time_to_walk/serial-32-0-48-s0/best.pt
"""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

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

OUT = RESULTS / "robustness"

#: name -> (push velocity m/s or None, push interval s, friction range or None)
CONDITIONS: dict[str, tuple[float | None, float, tuple[float, float] | None]] = {
    "nominal": (None, 0.0, None),
    "push 0.5 m/s / 5 s": (0.5, 5.0, None),
    "push 1.0 m/s / 15 s": (1.0, 15.0, None),
    "push 1.0 m/s / 5 s": (1.0, 5.0, None),
    "push 1.5 m/s / 5 s": (1.5, 5.0, None),
    "friction 0.2-0.4": (None, 0.0, (0.2, 0.4)),
    "friction 0.4-0.8": (None, 0.0, (0.4, 0.8)),
    "friction 0.5-1.25": (None, 0.0, (0.5, 1.25)),
    "friction 1.0-2.0": (None, 0.0, (1.0, 2.0)),
}


def main(argv: list[str] | None = None) -> None:
    from chronogym.tasks.quadruped.play import play_quadruped, play_randomization

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("checkpoint", type=Path)
    parser.add_argument("--episodes", type=int, default=5, help="per command and condition")
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args(argv)
    if not args.checkpoint.is_file():
        parser.error(f"checkpoint {args.checkpoint}: no such file")
    if args.episodes < 1:
        parser.error(f"--episodes={args.episodes}: expected an integer >= 1")
    results = []
    for name, (push, interval, friction) in CONDITIONS.items():
        rows = play_quadruped(
            args.checkpoint,
            episodes=args.episodes,
            progress=False,
            randomization=play_randomization(push, interval, friction),
        )
        results.append({
            "condition": name, "push_velocity": push, "push_interval_s": interval or None,
            "friction": friction,
            "survival": min(r["survival"] for r in rows),
            "mean_survival": sum(r["survival"] for r in rows) / len(rows),
            "worst_mse": max(max(r["x_vel_mse"], r["y_vel_mse"]) for r in rows),
            "commands_passed": sum(bool(r["v1"]) for r in rows),  # whole-episode MSE (v1)
            "commands_passed_v2": sum(r["v2"] for r in rows),
            "commands": [{**r, "command": list(r["command"])} for r in rows],
        })  # fmt: skip
        print(f"  {name}: done", flush=True)
    columns = [
        Column("condition", 22, align="<", key="condition"),
        Column("episodes survived", 17, "{:.0%}", key="mean_survival"),
        Column("worst command survival", 22, "{:.0%}", key="survival"),
        Column("worst x/y MSE", 13, "{:.4f}", key="worst_mse"),
        Column("commands passing v1", 19, key="commands_passed"),
        Column("v2", 3, key="commands_passed_v2"),
    ]
    print(table(columns, results, rule=True))
    plot(results, args.out / "robustness.png")
    write_json(args.out / "robustness.json", {
        **header("robustness", "torch", "rsl-rl-lib"), "settings": settings(args),
        "commands": len(results[0]["commands"]), "conditions": results,
    })  # fmt: skip


def plot(results: list[dict[str, Any]], path: Path) -> None:
    fig, (left, right) = pyplot().subplots(1, 2, figsize=(12, 4.2))
    names = [r["condition"] for r in results]
    ys = range(len(names))
    left.barh(ys, [100 * r["mean_survival"] for r in results], color="tab:blue")
    left.set_xlabel("episodes survived (%)")
    right.barh(ys, [r["worst_mse"] for r in results], color="tab:orange")
    right.axvline(0.01, color="k", lw=0.8, ls="--")
    right.set_xscale("log")
    right.set_xlabel("worst command's x/y velocity MSE (m/s)²")
    for axis in (left, right):
        axis.set_yticks(list(ys), names)
        axis.invert_yaxis()
        axis.grid(alpha=0.3, axis="x")
    right.set_yticklabels([])
    fig.suptitle("Go1 policy under pushes and friction (standard commands, 5 episodes each)")
    save_figure(fig, path)


if __name__ == "__main__":
    main()
