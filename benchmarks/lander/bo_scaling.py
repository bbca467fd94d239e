"""Lander design optimization: best J vs wall-clock time for several levels of parallelism.

For each terrain, each number of parallel workers W and each seed, a fresh Optuna study
(TPE, multivariate, constant liar, the same trial budget) runs through
``chronogym.optim.run_parallel_study`` on Ray workers. At the largest W the same runs are
repeated without the constant liar, to measure what it buys. Writes, per terrain, a CSV of
every finished trial and a PNG (best J vs wall-clock and vs trial index), plus a JSON
summary, and prints time-to-target ratios.

Wall-clock counts from the first trial (worker start-up is reported apart). The target J
is the worst of the final best values of all constant-liar runs, so every run reaches it.

    python -m benchmarks.lander.bo_scaling                  # W in {1, 2, 4, 8}, 2 seeds, rigid
    python -m benchmarks.lander.bo_scaling --quick          # smoke run
    python -m benchmarks.lander.bo_scaling --terrain rigid rough --seeds 3 --address auto
    python -m benchmarks.lander.bo_scaling --terrain soil   # SCM soil: ~2 s a landing (rigid 0.3)
    python -m benchmarks.lander.bo_scaling --engine chrono --terrain scm --workers 1 2 --seeds 1 \
        --trials 16 --skip-liar-check --out-dir benchmarks/results/bo_scaling_chrono_scm
        # Chrono's SCMTerrain (needs PyChrono with its vehicle module): ~16 s a landing
"""

from __future__ import annotations

import argparse
import csv
import os
import statistics
import sys
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np
from tqdm import tqdm

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
from chronogym.optim.lander import (
    ENGINES,
    TERRAINS,
    LanderObjective,
    check_engine,
    suggest_lander_design,
)
from chronogym.ray_runtime import ensure_ray

DEFAULT_OUT = RESULTS


@dataclass
class Run:
    """One optimization run and its trial-by-trial history."""

    terrain: str
    workers: int
    seed: int
    liar: bool
    startup: float
    elapsed: float
    history: list[tuple[float, int, float | None, float | None]]

    @property
    def final_best(self) -> float:
        return min(h[3] for h in self.history if h[3] is not None)

    def time_to(self, target: float) -> float:
        return next(h[0] for h in self.history if h[3] is not None and h[3] <= target)

    def trials_to(self, target: float) -> int:
        return next(
            i + 1 for i, h in enumerate(self.history) if h[3] is not None and h[3] <= target
        )


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2, 4, 8])
    parser.add_argument("--trials", type=int, default=48, help="trial budget of every run")
    parser.add_argument("--seeds", type=int, default=2, help="repetitions per level")
    parser.add_argument("--terrain", nargs="+", default=["rigid"], choices=list(TERRAINS))
    parser.add_argument("--engine", default="mujoco", choices=list(ENGINES))
    parser.add_argument("--startup-trials", type=int, default=10)
    parser.add_argument("--skip-liar-check", action="store_true")
    parser.add_argument("--quick", action="store_true", help="smoke run (about a minute)")
    parser.add_argument("--address", default=None, help="Ray cluster (default: local)")
    parser.add_argument("--out-dir", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    if args.quick:
        args.workers, args.trials, args.seeds, args.startup_trials = [1, 2], 12, 1, 4
    if min(args.workers) < 1 or args.trials < 2 or args.seeds < 1:
        parser.error("expected --workers >= 1, --trials >= 2 and --seeds >= 1")
    for terrain in args.terrain:
        try:
            check_engine(args.engine, terrain)
        except (ValueError, ModuleNotFoundError) as exc:
            parser.error(str(exc))
    return args


def run_once(terrain: str, workers: int, seed: int, liar: bool, args: argparse.Namespace) -> Run:
    """One fresh in-memory study with ``args.trials`` trials on ``workers`` Ray workers."""
    import optuna

    from chronogym.optim import run_parallel_study

    sampler = optuna.samplers.TPESampler(
        seed=seed, multivariate=True, constant_liar=liar, n_startup_trials=args.startup_trials
    )
    study = optuna.create_study(sampler=sampler)
    report = run_parallel_study(
        study,
        suggest_lander_design,
        LanderObjective(terrain=terrain, seed=0, engine=args.engine),
        args.trials,
        workers=workers,
        address=args.address,
        progress=False,
    )
    return Run(terrain, workers, seed, liar, report.startup, report.elapsed, report.history)


def summarize(runs: list[Run], levels: list[int]) -> dict:
    """Per W: median wall time, final best J, time and trials to the common target."""
    liar_runs = [r for r in runs if r.liar]
    target = max(r.final_best for r in liar_runs)
    rows = {}
    for w in levels:
        group = [r for r in liar_runs if r.workers == w]
        rows[w] = {
            "wall_s": statistics.median(r.elapsed for r in group),
            "startup_s": statistics.median(r.startup for r in group),
            "best_J": statistics.median(r.final_best for r in group),
            "time_to_target_s": statistics.median(r.time_to(target) for r in group),
            "trials_to_target": statistics.median(r.trials_to(target) for r in group),
        }
    base = rows[levels[0]]["time_to_target_s"]
    for row in rows.values():
        row["speedup_vs_first"] = (
            base / row["time_to_target_s"] if row["time_to_target_s"] else None
        )
    no_liar = [r for r in runs if not r.liar]
    liar_check = None
    if no_liar:
        w = no_liar[0].workers
        with_liar = [r for r in liar_runs if r.workers == w]
        liar_check = {
            "workers": w,
            "best_J_liar": statistics.median(r.final_best for r in with_liar),
            "best_J_no_liar": statistics.median(r.final_best for r in no_liar),
        }
    return {"target_J": target, "levels": rows, "constant_liar": liar_check}


def step_curve(run: Run, grid: np.ndarray) -> np.ndarray:
    """Best J so far at each time of ``grid`` (NaN before the first completed trial)."""
    times = np.array([h[0] for h in run.history if h[3] is not None])
    bests = np.array([h[3] for h in run.history if h[3] is not None])
    index = np.searchsorted(times, grid, side="right") - 1
    return np.where(index >= 0, bests[np.clip(index, 0, None)], np.nan)


def plot(runs: list[Run], terrain: str, levels: list[int], target: float, path: Path) -> None:
    """Two panels: best J vs wall-clock (median, min-max band) and vs trial index."""
    plt = pyplot()
    warnings.filterwarnings("ignore", "All-NaN slice", RuntimeWarning)

    fig, (ax_t, ax_n) = plt.subplots(1, 2, figsize=(12, 4.5))
    colors = plt.get_cmap("viridis")(np.linspace(0, 0.85, len(levels)))
    t_max = max(r.history[-1][0] for r in runs)
    grid = np.linspace(0, t_max, 400)
    for color, w in zip(colors, levels, strict=True):
        for liar, style in ((True, "-"), (False, "--")):
            group = [r for r in runs if r.workers == w and r.liar == liar]
            if not group:
                continue
            curves = np.array([step_curve(r, grid) for r in group])
            label = f"W={w}" + ("" if liar else " (no constant liar)")
            ax_t.plot(grid, np.nanmedian(curves, axis=0), style, color=color, label=label)
            if liar and len(group) > 1:
                ax_t.fill_between(
                    grid, np.nanmin(curves, 0), np.nanmax(curves, 0), color=color, alpha=0.15
                )
            by_trial = np.array([[h[3] for h in r.history] for r in group], dtype=float)
            ax_n.plot(
                np.arange(1, by_trial.shape[1] + 1),
                np.nanmedian(by_trial, axis=0),
                style,
                color=color,
                label=label,
            )
    for ax in (ax_t, ax_n):
        ax.axhline(target, color="grey", lw=0.8, ls=":", label="target J")
        ax.set_ylabel("best J so far (median over seeds)")
        ax.set_yscale("log")
        ax.grid(alpha=0.3)
    ax_t.set_xlabel("wall-clock time since the first trial [s]")
    ax_n.set_xlabel("finished trials")
    ax_t.legend(fontsize=8)
    fig.suptitle(
        f"Lander design optimization, {terrain} terrain: TPE on W parallel Ray workers "
        f"({os.cpu_count()} CPUs)"
    )
    save_figure(fig, path)


def write_csv(runs: list[Run], path: Path) -> None:
    with path.open("w", newline="") as handle:
        writer = csv.writer(handle)
        writer.writerow(
            [
                "terrain",
                "workers",
                "seed",
                "constant_liar",
                "elapsed_s",
                "trial",
                "value",
                "best_so_far",
            ]
        )
        for r in runs:
            for elapsed, number, value, best in r.history:
                writer.writerow(
                    [r.terrain, r.workers, r.seed, r.liar, f"{elapsed:.4f}", number, value, best]
                )


TABLE_COLUMNS = (
    Column("W", 3, key="W"),
    Column("wall s", 8, "{:.1f}", key="wall_s"),
    Column("start s", 8, "{:.1f}", key="startup_s"),
    Column("best J", 8, "{:.4f}", key="best_J"),
    Column("t->target s", 12, "{:.2f}", key="time_to_target_s"),
    Column("trials->tgt", 12, "{:.0f}", key="trials_to_target"),
    Column("speed-up", 9, "{:.2f}x", key="speedup_vs_first"),
)


def format_table(terrain: str, summary: dict) -> str:
    rows = [{"W": w, **row} for w, row in summary["levels"].items()]
    lines = [
        f"\n{terrain} terrain: target J = {summary['target_J']:.4f} "
        "(the worst final best over all constant-liar runs)",
        table(TABLE_COLUMNS, rows, sep=" "),
    ]
    check = summary["constant_liar"]
    if check:
        lines.append(
            f"constant liar at W={check['workers']}: median final best J {check['best_J_liar']:.4f}"
            f" with, {check['best_J_no_liar']:.4f} without"
        )
    return "\n".join(lines)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    import optuna

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    ensure_ray(args.address)
    args.out_dir.mkdir(parents=True, exist_ok=True)
    levels = sorted(set(args.workers))
    plan = [(t, w, s, True) for t in args.terrain for w in levels for s in range(args.seeds)]
    if not args.skip_liar_check:
        plan += [(t, levels[-1], s, False) for t in args.terrain for s in range(args.seeds)]
    runs = [
        run_once(t, w, s, liar, args) for t, w, s, liar in tqdm(plan, desc="runs", file=sys.stderr)
    ]
    summaries = {}
    for terrain in args.terrain:
        mine = [r for r in runs if r.terrain == terrain]
        summaries[terrain] = summarize(mine, levels)
        write_csv(mine, args.out_dir / f"bo_scaling_{terrain}.csv")
        plot(
            mine,
            terrain,
            levels,
            summaries[terrain]["target_J"],
            args.out_dir / f"bo_scaling_{terrain}.png",
        )
        print(format_table(terrain, summaries[terrain]))
    cpus = os.cpu_count() or 1
    if max(levels) > cpus:
        print(
            f"\nNOTE: this machine has {cpus} CPUs; W > {cpus} oversubscribes the cores, so "
            f"speed-ups beyond {cpus}x are not expected here (run with --address on a cluster)."
        )
    record = {**header("bo_scaling", "optuna"), "args": settings(args), "summary": summaries}
    write_json(args.out_dir / "bo_scaling.json", record, " and bo_scaling_*.csv, *.png beside it")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
