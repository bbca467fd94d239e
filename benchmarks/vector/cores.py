"""Scale-out on real cores: real workloads with W = 1 ... N workers, against EnvPool's threads.

``scaling.py`` times a synthetic env that sleeps, so 2 cores can stand in for W: it measures
what the vector env costs, not what W cores deliver on real physics. This script runs the real
workloads (``Ant-v5`` and the Go1, ``chronogym/Go1Velocity-v0``) on a machine with many cores,
W by W, side by side:

- ``fork``: ``RayVectorEnv(transport="fork")``, W workers of ``--envs-per-worker`` envs (no Ray);
- ``socket``: ``RayVectorEnv`` with its default transport (Ray workers; skipped, with a note,
  where Ray is not importable);
- ``async``: Gymnasium's ``AsyncVectorEnv``, W subprocesses of one env (only at 1 env per
  worker: it has no envs per worker);
- ``envpool``: EnvPool, sync, ``W x envs per worker`` envs on W threads (the tasks it ships:
  ``Ant-v5``); ``--envpool-threads`` adds thread counts beyond the W list (the machine's CPUs
  by default, where that is not in it).

E(W) is env-steps/s over ``W x`` what one process stepping the same envs serially reaches
(``serial``: Gymnasium's SyncVectorEnv of ``envs per worker`` envs in this process, measured
first at each setting), so E(1) < 1 is the cost of the transport itself. The driver's CPU per
vector step is measured too, and ``b_cpu``, its slope in W, is fitted per path.

With ``--model JSON ...`` (``scaling.py`` runs on the same machine), the synthetic model's
prediction is set beside each measured E(W) / E(1): ``t(W) = t(1) + b_cpu (W - 1)``, with
``t(1)`` this run's step at W = 1 and ``b_cpu`` the synthetic fit of the same path and envs per
worker at the step cost nearest ``t(1)`` ("cores" in ``scaling.py``), from the run whose
``--info-scalars`` is nearest the workload's own (Ant-v5 reports nine scalar infos a step, the
Go1 none; infos cost the driver Python per worker).

    python -m benchmarks.vector.cores                    # W = 1, 2, 4, ... up to the CPUs
    python -m benchmarks.vector.cores --quick            # smoke run: W = 1, 2, short
    python -m benchmarks.vector.cores --model benchmarks/results/scaling.json

Method: random actions (one seeded sequence per workload and setting, cycled), zero-copy where
the vector env allows; per setting, build, reset (seeded), ``--warmup`` untimed vector steps,
timed ones until ``--seconds`` and ``--min-steps`` are both reached, close. Output: a table,
the JSON (default ``benchmarks/results/cores.json``) and a PNG of E(W) beside it.
"""

from __future__ import annotations

import argparse
import functools
import gc
import importlib.util
import json
import os
import sys
import time
import traceback
from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import (
    RESULTS,
    Column,
    error_text,
    finish,
    header,
    non_negative_int,
    positive_float,
    positive_int,
    pyplot,
    save_figure,
    settings,
    table,
)
from benchmarks.vector.peers import WORKLOADS, Workload, action_sequence, envpool_tasks
from chronogym.sizing import fit_line, measure_env, timed_loop

DEFAULT_OUT = RESULTS / "cores.json"
PATHS = ("fork", "socket", "async", "envpool")
DEFAULT_WORKLOADS = ("Ant-v5", "chronogym/Go1Velocity-v0")
ACTION_ROWS = 64  # rows of the cycled action sequence


def default_workers(cpus: int) -> list[int]:
    """1, 2, 4, ... below ``cpus``, and ``cpus - 1`` (a core left to the driver)."""
    workers, w = [], 1
    while w < cpus:
        workers.append(w)
        w *= 2
    return sorted({*workers, max(1, cpus - 1)})


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    cpus = os.cpu_count() or 1
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--workloads", nargs="+", choices=tuple(WORKLOADS), default=list(DEFAULT_WORKLOADS)
    )
    parser.add_argument(
        "--workers",
        type=positive_int,
        nargs="+",
        default=default_workers(cpus),
        help="W (default: 1, 2, 4, ... and the CPUs less one)",
    )
    parser.add_argument("--envs-per-worker", type=positive_int, nargs="+", default=[1, 8])
    parser.add_argument("--paths", nargs="+", choices=PATHS, default=list(PATHS))
    parser.add_argument(
        "--envpool-threads",
        type=positive_int,
        nargs="*",
        default=[cpus],
        help="EnvPool thread counts besides --workers (default: the machine's CPUs)",
    )
    parser.add_argument("--seconds", type=positive_float, default=1.5, help="timed per setting")
    parser.add_argument("--min-steps", type=positive_int, default=20, help="timed, at least")
    parser.add_argument("--warmup", type=non_negative_int, default=10, help="untimed steps")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--model",
        type=Path,
        nargs="*",
        default=[],
        help="scaling.py JSONs of this machine; each workload takes the one whose "
        "--info-scalars is nearest its own info's scalars",
    )
    parser.add_argument("--quick", action="store_true", help="smoke run: W = 1, 2, short")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="JSON; the PNG beside it")
    args = parser.parse_args(argv)
    args.workers = sorted(set(args.workers))
    for model in args.model:
        if not model.is_file():
            parser.error(f"--model {model}: no such file (expected a scaling.py JSON)")
    if args.quick:
        args.workers, args.envpool_threads = [w for w in (1, 2) if w <= cpus] or [1], []
        args.seconds, args.min_steps, args.warmup = 0.3, 5, 2
    return args


# -- building -------------------------------------------------------------------------------


def skip_reason(path: str, workload: Workload, epw: int, envpool_ids: set[str] | None) -> str:
    """Why ``path`` does not run this setting here ("" if it does)."""
    if path == "socket" and importlib.util.find_spec("ray") is None:
        return "Ray is not importable"
    if path == "async" and epw > 1:
        return "AsyncVectorEnv has one env per process"
    if path == "envpool":
        if envpool_ids is None:
            return "envpool is not importable"
        if workload.env_id not in envpool_ids:
            return f"EnvPool does not ship {workload.env_id}"
    return ""


def builder(path: str, workload: Workload, seed: int) -> Callable[[int, int], Any]:
    """``(W, envs per worker) -> vector env`` for ``path`` (``serial``: W is ignored)."""
    import gymnasium as gym
    from gymnasium.vector import AutoresetMode

    kwargs = dict(workload.env_kwargs)

    def build(workers: int, epw: int) -> Any:
        if path == "serial":
            return gym.make_vec(workload.env_id, epw, vectorization_mode="sync", **kwargs)
        if path == "async":
            return gym.make_vec(workload.env_id, workers, vectorization_mode="async", **kwargs)
        if path == "envpool":
            import envpool

            return envpool.make(
                workload.env_id,
                env_type="gymnasium",
                num_envs=workers * epw,
                num_threads=workers,
                seed=seed,
                **kwargs,
            )
        from chronogym import RayVectorEnv

        options: dict[str, Any] = {"envs_per_worker": epw, "env_kwargs": kwargs}
        if path == "fork":
            options["transport"] = "fork"
        return RayVectorEnv(
            workload.env_id,
            workers * epw,
            autoreset_mode=AutoresetMode.NEXT_STEP,
            **options,
        )

    return build


# -- one setting ----------------------------------------------------------------------------


def measure(
    path: str, workload: Workload, workers: int, epw: int, args: argparse.Namespace
) -> dict[str, Any]:
    """Build, reset, time, close one vector env: env-steps/s and the driver's CPU per step."""
    num_envs = epw if path == "serial" else workers * epw
    actions = action_sequence(workload, num_envs, ACTION_ROWS, args.seed + workers)
    gc.collect()
    t0 = time.perf_counter()
    vec = builder(path, workload, args.seed)(workers, epw)
    try:
        if path == "envpool":
            vec.reset()  # seeded by envpool.make
        else:
            vec.reset(seed=args.seed)
        start_s = time.perf_counter() - t0
        actions = actions.astype(np.dtype(vec.action_space.dtype), copy=False)
        row, vec_step = iter(range(1 << 62)), vec.step

        def step() -> None:
            vec_step(actions[next(row) % ACTION_ROWS])

        timed = timed_loop(step, args.seconds, args.min_steps, args.warmup)
    finally:
        vec.close()
        del vec
        gc.collect()
    return {
        "workload": workload.name,
        "path": path,
        "workers": workers,
        "envs_per_worker": epw,
        "num_envs": num_envs,
        "steps": timed.steps,
        "start_s": start_s,
        "wall_ms_per_step": 1e3 * timed.wall_s / timed.steps,
        "driver_cpu_ms_per_step": 1e3 * timed.cpu_s / timed.steps,
        "env_steps_per_s": timed.steps * num_envs / timed.wall_s,
    }


# -- the run --------------------------------------------------------------------------------


def run_workload(
    workload: Workload,
    args: argparse.Namespace,
    envpool_ids: set[str] | None,
    skipped: list[dict[str, Any]],
    failures: list[dict[str, Any]],
) -> list[dict[str, Any]]:
    """The serial references, then every path W by W; appends skips and failures."""
    rows: list[dict[str, Any]] = []

    def attempt(path: str, workers: int, epw: int) -> None:
        setting = f"{workload.name} {path} W={workers} epw={epw}"
        print(f"  {setting}")
        try:
            rows.append(measure(path, workload, workers, epw, args))
        except Exception as error:
            failures.append(
                {"setting": setting, "error": error_text(error), "trace": traceback.format_exc()}
            )
            print(f"    failed: {error_text(error)}")

    for epw in args.envs_per_worker:
        attempt("serial", 1, epw)
    for workers, epw in ((w, e) for w in args.workers for e in args.envs_per_worker):
        for path in args.paths:  # W ascending: a failure late in the run costs the large W only
            reason = skip_reason(path, workload, epw, envpool_ids)
            if reason:
                note = {"workload": workload.name, "path": path, "envs_per_worker": epw}
                if {**note, "reason": reason} not in skipped:
                    skipped.append({**note, "reason": reason})
                continue
            attempt(path, workers, epw)
    if "envpool" in args.paths:
        for threads in (t for t in args.envpool_threads if t not in args.workers):
            for epw in args.envs_per_worker:
                if not skip_reason("envpool", workload, epw, envpool_ids):
                    attempt("envpool", threads, epw)
    return rows


def add_efficiency(rows: list[dict[str, Any]]) -> None:
    """E(W) against W x the serial rate of the same workload and envs per worker, and
    E(W) / E(1) against the same path's W = 1."""
    serial = {
        (r["workload"], r["envs_per_worker"]): r["env_steps_per_s"]
        for r in rows
        if r["path"] == "serial"
    }
    for row in rows:
        reference = serial.get((row["workload"], row["envs_per_worker"]))
        row["efficiency"] = (
            row["env_steps_per_s"] / (row["workers"] * reference) if reference else None
        )
    ones = {
        (r["workload"], r["path"], r["envs_per_worker"]): r["efficiency"]
        for r in rows
        if r["workers"] == 1
    }
    for row in rows:
        one = ones.get((row["workload"], row["path"], row["envs_per_worker"]))
        row["rel_e"] = row["efficiency"] / one if row["efficiency"] and one else None


def fits(rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per workload, path and envs per worker: the driver's CPU per step ``a_cpu + b_cpu W``
    (not EnvPool's: its threads, the workers, run in this process)."""
    groups: dict[tuple[str, str, int], list[dict[str, Any]]] = {}
    for row in rows:
        if row["path"] not in ("serial", "envpool"):
            key = (row["workload"], row["path"], row["envs_per_worker"])
            groups.setdefault(key, []).append(row)
    out = []
    for (workload, path, epw), group in groups.items():
        if len({r["workers"] for r in group}) < 2:
            continue
        a, b = fit_line(
            [r["workers"] for r in group], [1e3 * r["driver_cpu_ms_per_step"] for r in group]
        )
        out.append(
            {
                "workload": workload,
                "path": path,
                "envs_per_worker": epw,
                "a_cpu_us": a,
                "b_cpu_us": b,
            }
        )
    return out


def model_b_cpu(model: dict[str, Any], path: str, epw: int, step_ms: float) -> float | None:
    """The synthetic run's ``b_cpu`` (µs) of ``path`` at ``epw``, at the step cost nearest
    ``step_ms`` (its per-step-cost fits only)."""
    candidates = [
        f
        for f in model.get("fits", [])
        if f.get("path") == path
        and f.get("envs_per_worker") == epw
        and isinstance(f.get("step_ms"), (int, float))
        and f.get("b_cpu_us") is not None
    ]
    if not candidates:
        return None
    nearest = min(candidates, key=lambda f: abs(np.log(f["step_ms"] * epw / step_ms)))
    return float(nearest["b_cpu_us"])


def models_by_nearness(models: dict[str, dict[str, Any]], info_scalars: int) -> list[str]:
    """The models (file names), the one whose synthetic env's ``info_scalars`` is nearest the
    given first."""
    return sorted(
        models,
        key=lambda name: abs(models[name]["settings"].get("info_scalars", 0) - info_scalars),
    )


def add_predictions(
    rows: list[dict[str, Any]], models: dict[str, dict[str, Any]], info_scalars: dict[str, int]
) -> None:
    """The synthetic model's E(W) / E(1) beside each measured one (see the module doc), from
    the model (of ``models``, by file name) nearest each workload's ``info_scalars`` that
    has a fit of the row's path and envs per worker."""
    ones = {(r["workload"], r["path"], r["envs_per_worker"]): r for r in rows if r["workers"] == 1}
    for row in rows:
        one = ones.get((row["workload"], row["path"], row["envs_per_worker"]))
        if row["path"] == "serial" or one is None:
            continue
        t1 = one["wall_ms_per_step"]
        for name in models_by_nearness(models, info_scalars.get(row["workload"], 0)):
            b_cpu = model_b_cpu(models[name], row["path"], row["envs_per_worker"], t1)
            if b_cpu is not None:
                break
        else:
            continue
        row["model"], row["model_b_cpu_us"] = name, b_cpu
        growth = 1e-3 * max(0.0, b_cpu) * (row["workers"] - 1)  # a slope below 0 is noise
        row["predicted_rel_e"] = t1 / (t1 + growth)


# -- report ---------------------------------------------------------------------------------

COLUMNS = (
    Column("workload", 24, align="<", key="workload"),
    Column("path", 8, align="<", key="path"),
    Column("W", 3, key="workers"),
    Column("epw", 3, key="envs_per_worker"),
    Column("env-steps/s", 11, "{:,.0f}", key="env_steps_per_s"),
    Column("E(W)", 6, "{:.3f}", key="efficiency"),
    Column("E(W)/E(1)", 9, "{:.3f}", key="rel_e"),
    Column("model", 6, "{:.3f}", key="predicted_rel_e"),
    Column("step ms", 8, "{:.3f}", key="wall_ms_per_step"),
    Column("driver CPU ms", 13, "{:.3f}", key="driver_cpu_ms_per_step"),
    Column("start s", 7, "{:.2f}", key="start_s"),
)


def plot(rows: list[dict[str, Any]], path: Path) -> None:
    """E(W) per workload (panels) and path (lines), one line style per envs per worker."""
    plt = pyplot()
    workloads = list(dict.fromkeys(r["workload"] for r in rows))
    fig, axes = plt.subplots(1, len(workloads), figsize=(5.5 * len(workloads), 4), squeeze=False)
    for ax, workload in zip(axes[0], workloads, strict=True):
        lines: dict[tuple[str, int], list[dict[str, Any]]] = {}
        for row in rows:
            if row["workload"] == workload and row["path"] != "serial" and row["efficiency"]:
                lines.setdefault((row["path"], row["envs_per_worker"]), []).append(row)
        for (name, epw), line in sorted(lines.items()):
            line.sort(key=lambda r: r["workers"])
            ax.plot(
                [r["workers"] for r in line],
                [r["efficiency"] for r in line],
                "o-" if epw == 1 else "s--",
                label=f"{name}, {epw} env{'s' if epw > 1 else ''}/worker",
            )
        ax.set(title=workload, xlabel="workers (EnvPool: threads)", ylabel="E(W) vs serial")
        ax.set_xscale("log", base=2)
        ax.set_ylim(bottom=0)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    save_figure(fig, path)


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    wall = time.perf_counter()
    envpool_ids, envpool_missing = envpool_tasks()
    if envpool_missing and "envpool" in args.paths:
        print(f"EnvPool skipped: {envpool_missing}")
    record: dict[str, Any] = {**header("vector/cores"), "settings": settings(args)}
    rows: list[dict[str, Any]] = []
    skipped: list[dict[str, Any]] = []
    failures: list[dict[str, Any]] = []
    for name in args.workloads:
        print(f"{name}:")
        rows += run_workload(WORKLOADS[name], args, envpool_ids, skipped, failures)
    add_efficiency(rows)
    info_scalars = {
        name: measure_env(WORKLOADS[name].env_id, WORKLOADS[name].env_kwargs, 0.05).info_scalars
        for name in args.workloads
    }
    record["info_scalars"] = info_scalars
    if args.model:
        models = {str(path): json.loads(path.read_text()) for path in args.model}
        add_predictions(rows, models, info_scalars)
    record.update(
        runs=rows,
        fits=fits(rows),
        skipped=skipped,
        failures=failures,
        seconds_in_all=time.perf_counter() - wall,
    )
    print()
    print(table(COLUMNS, [{c.key: r.get(c.key) for c in COLUMNS} for r in rows], rule=True))
    for fit in record["fits"]:
        print(
            f"  {fit['workload']}, {fit['path']}, epw {fit['envs_per_worker']}: driver CPU "
            f"{fit['a_cpu_us']:.0f} + {fit['b_cpu_us']:.1f} us x W per step"
        )
    for skip in skipped:
        print(
            f"  skipped {skip['workload']} {skip['path']} epw {skip['envs_per_worker']}: "
            f"{skip['reason']}"
        )
    figure = functools.partial(plot, rows) if rows else None
    return finish(args.out, record, figure, failures)


if __name__ == "__main__":
    sys.exit(main())
