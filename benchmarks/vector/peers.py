"""chronogym's vector envs against their peers, side by side in one run: env-steps/s.

Backends: chronogym's SerialVectorEnv and RayVectorEnv (default settings, plus any
``--ray-configs``), Gymnasium's SyncVectorEnv and AsyncVectorEnv, and EnvPool (sync with 1 and
``os.cpu_count()`` threads, and async with ``batch_size = num_envs / 2``: ``recv`` returns the
first half that is ready and only those envs get their next actions). Every vector env uses
Gymnasium's NEXT_STEP autoreset, as EnvPool does. Workloads: ``Ant-v5`` (Gymnasium MuJoCo),
``chronogym/Go1Velocity-v0`` and ``chronogym/CartPole-v0`` at ``k=10`` (cheap steps; endless
episodes, so every step costs the same physics); with PyChrono, ``--workloads
chronogym/ChronoGo1Velocity-v0`` (the Go1 in Project Chrono). EnvPool runs only the Gymnasium
tasks it ships (Ant-v5); the rest, and every EnvPool row where envpool is not installed, are
skipped with a note.

    python -m benchmarks.vector.peers           # full run, about 4 min on 2 quiet cores
    python -m benchmarks.vector.peers --quick   # smoke run: a few steps, one repeat
    python -m benchmarks.vector.peers --ray-configs "envs_per_worker=8,transport=actor"

Method: one seeded sequence of random actions (uniform over the action space) per workload,
shared by every backend, so each does identical work: vector step ``t`` sends row ``t`` to
every env; EnvPool's async mode sends each env its own next row. Per backend and repeat: build,
reset (seeded), ``--warmup`` untimed vector steps, then ``--steps`` timed ones; then close. The
repeats interleave the backends round-robin (repeat 1 of every backend, then repeat 2, ...), so
drift on a noisy machine hits them all alike, and the table shows the median over repeats.

For each RayVectorEnv configuration a separate short run (``--profile-steps`` vector steps after
the timed ones, in the same env) records ``profile_steps()``: µs per vector step of every phase
``StepProfile.per_step_us()`` reports (kept as is in the JSON), and from them ``round_trip`` =
``wait - compute`` (the barrier beyond the slowest worker's compute) and ``fixed`` = ``driver +
round_trip`` = ``total - compute`` (what a vector step costs beyond the slowest worker's
compute). ``round_trip`` alone can come out negative where the first workers compute while the
driver still submits to the others; ``fixed`` holds all the same.

Output: a table per workload (env-steps/s, ratio to SyncVectorEnv and to chronogym serial), the
JSON (default ``benchmarks/results/peers.json``: settings, per-repeat numbers, medians,
profiles) and a PNG beside it (one panel per workload). A backend that fails is reported with
its error and skipped in later repeats.
"""

from __future__ import annotations

import argparse
import gc
import os
import statistics
import sys
import time
import traceback
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.vector import AutoresetMode

import chronogym
from benchmarks.common import (
    RESULTS,
    Column,
    error_text,
    header,
    non_negative_int,
    positive_int,
    pyplot,
    save_figure,
    settings,
    table,
    write_json,
)
from benchmarks.vector.throughput_timing import start_ray as start_local_ray  # this script's folder

DEFAULT_OUT = RESULTS / "peers.json"
RAY_SETTLE_S = 2.0  # let a fresh Ray cluster's processes finish starting before timing
SYNC_KEY = "gym-sync"
SERIAL_KEY = "chronogym-serial"


@dataclass(frozen=True)
class Workload:
    """One task: its Gymnasium id and the keyword arguments of ``gymnasium.make``."""

    name: str
    env_id: str
    env_kwargs: dict[str, Any] = field(default_factory=dict)


WORKLOADS = {
    w.name: w
    for w in (
        Workload("Ant-v5", "Ant-v5"),
        Workload("chronogym/Go1Velocity-v0", "chronogym/Go1Velocity-v0"),
        Workload("chronogym/CartPole-v0", "chronogym/CartPole-v0", {"k": 10, "terminate": False}),
        Workload("chronogym/ChronoGo1Velocity-v0", "chronogym/ChronoGo1Velocity-v0"),
    )
}
#: Run unless ``--workloads`` names others: the MuJoCo ones (PyChrono is a conda install).
DEFAULT_WORKLOADS = [name for name in WORKLOADS if "Chrono" not in name]


@dataclass(frozen=True)
class Backend:
    """One way of batching envs: a key for the JSON, a label for the table and figure, how it is
    driven (``"step"``: a barrier ``step`` per vector step; ``"envpool-async"``: send / recv),
    its options, and why it does not run (``skip``), if it does not."""

    key: str
    label: str
    build: Callable[[Workload, int, int], Any]  # (workload, num_envs, seed) -> env
    drive: str = "step"
    options: dict[str, Any] = field(default_factory=dict)
    skip: str | None = None

    @property
    def is_ray(self) -> bool:
        return self.key.startswith("chronogym-ray")


# -- options --------------------------------------------------------------------------------


def config_value(text: str) -> Any:
    """A ``--ray-configs`` value: None, a bool, an int, a float, else the text itself."""
    lowered = text.lower()
    if lowered == "none":
        return None
    if lowered in ("true", "false"):
        return lowered == "true"
    for kind in (int, float):
        try:
            return kind(text)
        except ValueError:
            pass
    return text


def parse_ray_config(text: str) -> dict[str, Any]:
    """``"envs_per_worker=8,transport=actor"`` -> ``{"envs_per_worker": 8, "transport":
    "actor"}`` (keyword arguments of RayVectorEnv; an empty text is the default settings)."""
    config: dict[str, Any] = {}
    for part in filter(None, (p.strip() for p in text.split(","))):
        key, sep, value = (s.strip() for s in part.partition("="))
        if not sep or not key.isidentifier() or not value:
            raise argparse.ArgumentTypeError(
                f"--ray-configs {text!r}: expected keyword=value pairs separated by commas, "
                "e.g. 'envs_per_worker=8,transport=actor'"
            )
        config[key] = config_value(value)
    return config


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    """Command-line options; ``--quick`` shrinks the run to a smoke test."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument(
        "--workloads",
        nargs="+",
        choices=tuple(WORKLOADS),
        default=DEFAULT_WORKLOADS,
        help="default: the MuJoCo ones (chronogym/ChronoGo1Velocity-v0 needs PyChrono)",
    )
    parser.add_argument("--num-envs", type=positive_int, default=16, help="envs per vector env")
    parser.add_argument("--steps", type=positive_int, default=1000, help="timed vector steps")
    parser.add_argument("--warmup", type=non_negative_int, default=50, help="untimed vector steps")
    parser.add_argument(
        "--repeats", type=positive_int, default=5, help="runs per backend (median reported)"
    )
    parser.add_argument(
        "--profile-steps",
        type=non_negative_int,
        default=300,
        help="vector steps of each RayVectorEnv's profile_steps() run (0: none)",
    )
    parser.add_argument(
        "--ray-configs",
        nargs="*",
        type=parse_ray_config,
        default=[],
        metavar="KEY=VALUE[,KEY=VALUE]",
        help="extra RayVectorEnv configurations besides the default settings, e.g. "
        '"envs_per_worker=8" "envs_per_worker=8,transport=actor"',
    )
    parser.add_argument("--seed", type=int, default=0, help="seed of the envs and the actions")
    parser.add_argument("--quick", action="store_true", help="smoke run: few steps, 1 repeat")
    parser.add_argument(
        "--out",
        type=Path,
        default=DEFAULT_OUT,
        help=f"JSON output, the PNG beside it (default {DEFAULT_OUT.name})",
    )
    args = parser.parse_args(argv)
    if args.quick:
        args.steps, args.warmup, args.repeats = min(args.steps, 20), min(args.warmup, 3), 1
        args.profile_steps = min(args.profile_steps, 10)
    return args


# -- backends -------------------------------------------------------------------------------


def envpool_tasks() -> tuple[set[str] | None, str | None]:
    """The task ids EnvPool ships, or None and why not (not installed, broken)."""
    try:
        import envpool
    except ImportError as error:
        return None, f"envpool is not importable ({error}); pip install envpool"
    return set(envpool.list_all_envs()), None


def make_envpool(num_threads: int, batch_size: int | None = None) -> Callable[..., Any]:
    """An EnvPool builder with ``num_threads`` threads (``batch_size``: default num_envs)."""

    def build(workload: Workload, num_envs: int, seed: int) -> Any:
        import envpool

        return envpool.make(
            workload.env_id,
            env_type="gymnasium",
            num_envs=num_envs,
            batch_size=batch_size or num_envs,
            num_threads=num_threads,
            seed=seed,
            **workload.env_kwargs,
        )

    return build


def make_gym(mode: str) -> Callable[..., Any]:
    """A Gymnasium SyncVectorEnv / AsyncVectorEnv builder (``mode``: "sync" or "async")."""

    def build(workload: Workload, num_envs: int, seed: int) -> Any:
        return gym.make_vec(
            workload.env_id,
            num_envs,
            vectorization_mode=mode,
            vector_kwargs={"autoreset_mode": AutoresetMode.NEXT_STEP},
            **workload.env_kwargs,
        )

    return build


def build_serial(workload: Workload, num_envs: int, seed: int) -> Any:
    return chronogym.SerialVectorEnv(
        workload.env_id,
        num_envs,
        autoreset_mode=AutoresetMode.NEXT_STEP,
        env_kwargs=dict(workload.env_kwargs),
    )


def make_ray(config: dict[str, Any]) -> Callable[..., Any]:
    """A RayVectorEnv builder with keyword arguments ``config`` (empty: default settings)."""

    def build(workload: Workload, num_envs: int, seed: int) -> Any:
        return chronogym.RayVectorEnv(
            workload.env_id,
            num_envs,
            **{"autoreset_mode": AutoresetMode.NEXT_STEP, **config},
            env_kwargs=dict(workload.env_kwargs),
        )

    return build


def config_text(config: dict[str, Any]) -> str:
    return ",".join(f"{key}={value}" for key, value in config.items())


def backends_for(
    workload: Workload, num_envs: int, ray_configs: list[dict[str, Any]]
) -> list[Backend]:
    """Every backend of one workload, the skipped ones with their reason (the Ray
    configurations once each, the default settings first)."""
    backends = [Backend(SERIAL_KEY, "chronogym serial", build_serial)]
    configs = {config_text(c): c for c in [{}, *ray_configs]}
    for text, config in configs.items():
        backends.append(
            Backend(
                f"chronogym-ray[{text}]" if text else "chronogym-ray",
                f"chronogym Ray ({text})" if text else "chronogym Ray",
                make_ray(config),
                options=config,
            )
        )
    backends += [
        Backend(SYNC_KEY, "Gymnasium Sync", make_gym("sync")),
        Backend("gym-async", "Gymnasium Async", make_gym("async")),
    ]
    tasks, missing = envpool_tasks()
    if missing is None and (
        workload.env_id.startswith("chronogym/") or workload.env_id not in tasks
    ):
        missing = f"EnvPool does not ship {workload.env_id}"
    cpus = os.cpu_count() or 1
    batch = max(1, num_envs // 2)
    for threads in dict.fromkeys((1, cpus)):
        backends.append(
            Backend(
                f"envpool-sync-{threads}t",
                f"EnvPool sync, {threads} thread{'s' if threads > 1 else ''}",
                make_envpool(threads),
                options={"num_threads": threads, "batch_size": num_envs},
                skip=missing,
            )
        )
    backends.append(
        Backend(
            f"envpool-async-{cpus}t-b{batch}",
            f"EnvPool async, {cpus} threads, batch {batch}",
            make_envpool(cpus, batch),
            drive="envpool-async",
            options={"num_threads": cpus, "batch_size": batch},
            skip=missing,
        )
    )
    return backends


# -- actions and timed loops ----------------------------------------------------------------


def action_sequence(workload: Workload, num_envs: int, length: int, seed: int) -> np.ndarray:
    """``length`` rows of random actions for ``num_envs`` envs, uniform over the (bounded Box)
    action space: shape ``(length, num_envs, *action_shape)``."""
    env = gym.make(workload.env_id, **workload.env_kwargs)
    try:
        space = env.action_space
    finally:
        env.close()
    if not isinstance(space, gym.spaces.Box) or not space.is_bounded():
        raise ValueError(f"{workload.env_id}: action space {space}: expected a bounded Box")
    rng = np.random.default_rng(seed)
    size = (length, num_envs, *space.shape)
    return rng.uniform(space.low, space.high, size=size).astype(space.dtype)


def action_dtype(env: Any) -> np.dtype:
    """The dtype of the batched actions ``env`` expects."""
    return np.dtype(env.action_space.dtype)


def run_steps(env: Any, actions: np.ndarray, warmup: int, steps: int) -> tuple[int, float]:
    """On a reset ``env``: ``warmup`` untimed vector steps, then ``steps`` timed ones, row ``t``
    of ``actions`` at vector step ``t``: (env steps, seconds)."""
    actions = actions.astype(action_dtype(env), copy=False)
    step = env.step
    for t in range(warmup):
        step(actions[t])
    start = time.perf_counter()
    for t in range(warmup, warmup + steps):
        step(actions[t])
    return steps * actions.shape[1], time.perf_counter() - start


def run_envpool_async(pool: Any, actions: np.ndarray, warmup: int, steps: int) -> tuple[int, float]:
    """EnvPool send / recv: each answered env gets its own next action row. The first rows
    (the resets of ``async_reset``) fall into the ``warmup`` x num_envs untimed rows; timing
    stops once ``steps`` x num_envs env steps have come back: (env steps, seconds)."""
    actions = actions.astype(action_dtype(pool), copy=False)
    length, num_envs = actions.shape[:2]
    row = np.zeros(num_envs, dtype=np.int64)  # each env's next row of the sequence
    recv, send = pool.recv, pool.send

    def answer() -> int:
        ids = recv()[4]["env_id"]
        send(actions[row[ids] % length, ids], ids)
        row[ids] += 1
        return len(ids)

    pool.async_reset()
    done = 0
    while done < max(warmup, 1) * num_envs:
        done += answer()
    done, start = 0, time.perf_counter()
    while done < steps * num_envs:
        done += answer()
    return done, time.perf_counter() - start


def profile_run(env: Any, actions: np.ndarray, steps: int) -> dict[str, float]:
    """``profile_steps()`` over ``steps`` vector steps: µs per vector step of each phase as
    ``per_step_us()`` reports it, plus ``round_trip`` and ``fixed`` (see the module doc)."""
    actions = actions.astype(action_dtype(env), copy=False)
    profile = env.profile_steps()
    for t in range(steps):
        env.step(actions[t % len(actions)])
    us = {key: float(value) for key, value in profile.per_step_us().items()}
    if "wait" in us and "compute" in us:
        us["round_trip"] = us["wait"] - us["compute"]
        if "driver" in us:
            us["fixed"] = us["driver"] + us["round_trip"]
    return us


def measure(
    backend: Backend, workload: Workload, actions: np.ndarray, args: argparse.Namespace
) -> dict[str, Any]:
    """One repeat of one backend: build, reset, warm up, time, (profile), close."""
    num_envs = actions.shape[1]
    start = time.perf_counter()
    env = backend.build(workload, num_envs, args.seed)
    try:
        build_s = time.perf_counter() - start
        if backend.drive == "envpool-async":
            env_steps, seconds = run_envpool_async(env, actions, args.warmup, args.steps)
        else:
            if backend.key.startswith("envpool"):
                env.reset()  # seeded by envpool.make
            else:
                env.reset(seed=args.seed)
            env_steps, seconds = run_steps(env, actions, args.warmup, args.steps)
        run = {
            "env_steps": env_steps,
            "seconds": seconds,
            "env_steps_per_s": env_steps / seconds,
            "build_s": build_s,
        }
        if backend.is_ray and args.profile_steps:
            run["profile_us"] = profile_run(env, actions, args.profile_steps)
        return run
    finally:
        env.close()
        del env
        gc.collect()


# -- the run --------------------------------------------------------------------------------


def start_ray() -> None:
    """One local Ray cluster for the whole run (``throughput_timing.start_ray``), settled."""
    start_local_ray()
    time.sleep(RAY_SETTLE_S)


def new_entry(backend: Backend) -> dict[str, Any]:
    return {
        "key": backend.key,
        "label": backend.label,
        "options": backend.options,
        "status": "skipped" if backend.skip else "ok",
        "note": backend.skip,
        "runs": [],
    }


def run_workload(
    workload: Workload, args: argparse.Namespace, ray_error: str | None
) -> dict[str, Any]:
    """Every backend of ``workload``, ``args.repeats`` rounds interleaved; medians and ratios."""
    backends = backends_for(workload, args.num_envs, args.ray_configs)
    entries = {b.key: new_entry(b) for b in backends}
    if ray_error:
        for backend in filter(lambda b: b.is_ray, backends):
            entries[backend.key].update(status="failed", note=f"Ray did not start: {ray_error}")
    record: dict[str, Any] = {
        "name": workload.name,
        "env_id": workload.env_id,
        "env_kwargs": workload.env_kwargs,
        "num_envs": args.num_envs,
    }
    try:
        length = args.warmup + max(args.steps, args.profile_steps)
        actions = action_sequence(workload, args.num_envs, length, args.seed)
    except Exception as error:  # the workload cannot run at all (task missing, ...)
        record["error"] = error_text(error)
        for entry in entries.values():
            entry.update(status="failed", note=record["error"])
        return {**record, "backends": list(entries.values())}
    for repeat in range(args.repeats):
        for backend in backends:
            entry = entries[backend.key]
            if entry["status"] != "ok":
                continue
            print(f"  [{workload.name}] repeat {repeat + 1}/{args.repeats}: {backend.label}")
            try:
                entry["runs"].append(
                    {"repeat": repeat, **measure(backend, workload, actions, args)}
                )
            except Exception as error:
                entry.update(status="failed", note=error_text(error))
                entry["traceback"] = traceback.format_exc()
                print(f"    failed: {entry['note']}")
    summarize(entries)
    return {**record, "backends": list(entries.values())}


def median_of(runs: list[dict[str, Any]], key: str) -> float | None:
    values = [run[key] for run in runs if key in run]
    return statistics.median(values) if values else None


def summarize(entries: dict[str, dict[str, Any]]) -> None:
    """Medians over the repeats, the spread, the ratios to Sync and serial, profile medians."""
    for entry in entries.values():
        runs = entry["runs"]
        rates = [run["env_steps_per_s"] for run in runs]
        entry["median_env_steps_per_s"] = statistics.median(rates) if rates else None
        entry["spread_pct"] = (
            100 * (max(rates) - min(rates)) / statistics.median(rates) if rates else None
        )
        profiles = [run["profile_us"] for run in runs if "profile_us" in run]
        if profiles:
            entry["profile_us_median"] = {
                key: median_of(profiles, key)
                for key in dict.fromkeys(k for p in profiles for k in p)
            }
    for base, name in ((SYNC_KEY, "x_sync"), (SERIAL_KEY, "x_serial")):
        reference = entries.get(base, {}).get("median_env_steps_per_s")
        for entry in entries.values():
            rate = entry["median_env_steps_per_s"]
            entry[name] = rate / reference if rate and reference else None


# -- report ---------------------------------------------------------------------------------

RATE_COLUMNS = (
    Column("env-steps/s", 11, "{:,.0f}", key="median_env_steps_per_s"),
    Column("x Sync", 6, "{:.2f}", key="x_sync"),
    Column("x serial", 8, "{:.2f}", key="x_serial"),
    Column("spread %", 8, "{:.1f}", key="spread_pct"),
    Column("note", 4, align="<", key="note"),
)
PROFILE_KEYS = ("total", "driver", "round_trip", "fixed", "compute", "compute_sum", "wait")
PROFILE_TITLE = "profile_steps(), µs per vector step"


def format_workload(record: dict[str, Any], repeats: int) -> str:
    """The rate table of one workload, and the profile table of its RayVectorEnv rows."""
    title = f"{record['name']} {record['env_kwargs'] or ''}".strip()
    lines = [f"{title}: {record['num_envs']} envs, median of {repeats} repeat(s)"]
    width = max(len(PROFILE_TITLE), *(len(e["label"]) for e in record["backends"]))
    rows = [{**e, "note": shorten(e["note"]) if e["note"] else ""} for e in record["backends"]]
    columns = [Column("backend", width, align="<", key="label"), *RATE_COLUMNS]
    lines.append(table(columns, rows, rule=True))
    profiled = [e for e in record["backends"] if e.get("profile_us_median")]
    if profiled:
        columns = [Column(PROFILE_TITLE, width, align="<")]
        columns += [Column(key, max(len(key), 7), "{:,.0f}") for key in PROFILE_KEYS]
        lines += ["", table(columns, [profile_row(e) for e in profiled], rule=True)]
    return "\n".join(lines)


def profile_row(entry: dict[str, Any]) -> list[Any]:
    us = entry["profile_us_median"]
    return [entry["label"], *(us.get(key) for key in PROFILE_KEYS)]


def shorten(text: str, width: int = 90) -> str:
    line = " ".join(text.split())
    return line if len(line) <= width else line[: width - 3] + "..."


def plot(records: list[dict[str, Any]], path: Path) -> None:
    """One horizontal bar panel per workload: median env-steps/s, min-max over repeats (the
    skipped backends left out, the failed ones marked)."""
    plt = pyplot()
    colors = {"chronogym": "tab:blue", "gym": "tab:gray", "envpool": "tab:orange"}
    bars = [sum(e["status"] != "skipped" for e in record["backends"]) for record in records]
    fig, axes = plt.subplots(
        len(records),
        1,
        figsize=(9, 0.3 * sum(bars) + 1.0 * len(records)),
        gridspec_kw={"height_ratios": bars},
        squeeze=False,
    )
    for ax, record in zip(axes[:, 0], records, strict=True):
        entries = [e for e in record["backends"] if e["status"] != "skipped"][::-1]  # first on top
        ys = np.arange(len(entries))
        for y, entry in zip(ys, entries, strict=True):
            rate = entry["median_env_steps_per_s"]
            if rate is None:
                ax.text(0, y, f" {entry['status']}", va="center", fontsize=8, color="tab:red")
                continue
            rates = [run["env_steps_per_s"] for run in entry["runs"]]
            color = colors[entry["key"].split("-")[0]]
            ax.barh(y, rate, color=color, xerr=[[rate - min(rates)], [max(rates) - rate]])
            ax.text(rate, y, f" {rate:,.0f}", va="center", fontsize=8)
        ax.set_yticks(ys, [e["label"] for e in entries], fontsize=8)
        kwargs = ", ".join(f"{key}={value}" for key, value in record["env_kwargs"].items())
        ax.set_title(f"{record['name']} {kwargs}, {record['num_envs']} envs", fontsize=10)
        ax.set_xlabel("env-steps/s (median; bars: min-max over repeats)", fontsize=8)
        ax.margins(x=0.15)
    save_figure(fig, path)
    print(f"wrote {path}")


def main(argv: list[str] | None = None) -> int:
    """Measure every workload, print the tables, write the JSON and the PNG."""
    args = parse_args(argv)
    wall = time.perf_counter()
    ray_error = None
    try:
        start_ray()
    except Exception as error:
        ray_error = error_text(error)
        print(f"Ray did not start: {ray_error}")
    records = []
    try:
        for name in args.workloads:
            records.append(run_workload(WORKLOADS[name], args, ray_error))
            print()
            print(format_workload(records[-1], args.repeats))
            print()
    finally:
        if not ray_error:
            import ray

            ray.shutdown()
    record = {
        **header("peers", "envpool"),
        "settings": {
            **settings(args),
            "cpus": os.cpu_count(),
            "actions": "one seeded sequence per workload, uniform over the action space, "
            "shared by every backend",
            "autoreset_mode": "next_step",
            "profile_us": "per_step_us() of StepProfile; round_trip = wait - compute, "
            "fixed = driver + round_trip",
        },
        "workloads": records,
    }
    write_json(args.out, record, f" ({time.perf_counter() - wall:.0f} s in all)")
    try:
        plot(records, args.out.with_suffix(".png"))
    except Exception as error:
        print(f"no figure: {error_text(error)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
