"""Scale-out of the vector envs: parallel efficiency E(W), the fixed cost a and per-worker cost b
of a vector step, stragglers, start-up and memory, for W = 1 ... 64 (128) workers.

The workload is ``chronogym/Synthetic-v0`` (:class:`chronogym.testing.SyntheticEnv`): each
env step *sleeps* ``--step-ms`` (constant, or lognormal for the stragglers), which releases
the CPU as a step computing on another core would. On a machine with fewer cores than
workers (this one has 2), W sleeping workers then measure the vector env's own cost as W
grows (the driver's work per worker, the transport, the barrier's wait), not the workers'
compute: what a machine with W cores would show, minus the compute. The driver's CPU time
per vector step (``time.process_time`` of this process, every thread) is measured at any W,
and ``b_cpu``, its slope in W, is the issue's "driver CPU per worker per step". The wall
time's slope ``b`` also holds what 2 cores cannot hide at large W: the workers' own
Python per step (receiving, stepping, answering) queues for the 2 cores, most at 0.1 ms.
``b_thread`` is the same slope of the stepping thread's CPU alone (``time.thread_time``):
the driver's serial work per worker. The process's other threads (Ray's, in the driver)
spend CPU per second, not per step or worker (2-3 ms/s at W = 1, 16 and 64 alike, measured
idle), so on 2 cores, where the step's wall time grows with W, they add to ``b_cpu`` what a
machine with a core per worker would not see; on the paths whose step is a Ray call per
worker or node (``actor``, ``multinode_calls``), Ray's threads do per-call work, and there
``b_cpu`` is the one to read.

    python -m benchmarks.vector.scaling --quick          # smoke run, < 2 min
    python -m benchmarks.vector.scaling                  # the full sweep (see --help)
    python -m benchmarks.vector.scaling --multinode --with-128

Paths, side by side (the same W, envs per worker and step cost, one after another):

- ``socket``: ``RayVectorEnv`` with its default transport, workers on the driver's node
  (Unix sockets; the barrier step through shared memory, :mod:`chronogym.vector.shared_step`);
- ``socket_tree``: the same with the workers woken in groups (a leader per group of 8
  wakes the rest) at every W; the default groups only where each worker has a core
  (:func:`chronogym.vector.shared_step.wants_tree`), never on 2 cores with W > 2;
- ``socket_messages``: the same with ``shared_memory=False``: one socket message each way
  per worker and step (the default before the shared-memory step);
- ``actor``: ``RayVectorEnv(transport="actor")``: one Ray actor call per worker and step,
  the path of workers on other nodes;
- ``driver_worker``: ``RayVectorEnv(driver_worker=True)``: the driver steps the last of the
  W workers' envs itself (W - 1 Ray workers);
- ``fork``: ``RayVectorEnv(transport="fork")``: workers forked from a warm process
  (:mod:`chronogym.vector.fork_transport`), no Ray actors; steps as ``socket``;
- ``async``: Gymnasium's ``AsyncVectorEnv`` with W subprocesses, one env each (it has no
  envs per worker: skipped at envs_per_worker > 1);
- ``multinode`` (``--multinode``): ``RayVectorEnv(scheduling="spread")`` on a loopback
  ``chronogym.testing.LocalCluster`` whose head has no CPUs, so every worker is on another
  node than the driver, after the local paths (it needs its own Ray): each node's relay
  steps its workers through a shared block there, one frame per node and step over a TCP
  line to the driver (:mod:`chronogym.vector.spread_step`,
  :mod:`chronogym.vector.relay_channel`);
- ``multinode_calls``: the same with ``relay_tcp=False``: one Ray call per node and step
  (the default before the TCP lines);
- ``multinode_messages``: the same with ``shared_memory=False``: the relay sends each
  worker its message and returns every answer, which the driver decodes one by one (the
  default before the per-node shared step);
- ``multinode_fork``: ``RayVectorEnv(transport="fork", address=...)`` on the same cluster:
  the workers spread over the nodes by their CPUs, each forked by its node's relay
  (:mod:`chronogym.vector.fork_transport`), not Ray actors; steps as ``multinode``.
  ``--multinode-only`` runs just the multi-node paths (``--multinode-paths`` chooses).

Method. One local Ray for the local paths (``ray.init(num_cpus=--ray-cpus)``, default the
machine's CPUs; RayVectorEnv shares them as fractional ``num_cpus`` per worker, so 64
workers fit on 2). For each W, envs per worker and path, one vector env is built (timed from
the constructor to the first ``reset()``: the start-up time; the driver's RSS before and
after, and each worker's RSS, from ``/proc``), then for each step cost (``set_attr``):
``--warmup`` untimed vector steps and timed ones until ``--seconds`` and ``--min-steps``
are both reached; zero actions. Per setting: wall ms per vector step, driver CPU ms per
step, env-steps/s, E(W) = measured / ideal env-steps/s (ideal: every env stepping back to
back, ``W * epw / (epw * step_ms)``), and E(W) / E(1).

Fits, per path and envs per worker: ``t_step(W) = S + a + b * W`` by least squares with
``S = epw * step_ms`` (the nominal step cost; the sleep's own overshoot, ``sleep_ms`` in the
JSON, lands in ``a``), per step cost and pooled over step costs; and the driver's CPU per
step ``a_cpu + b_cpu * W``. The model's predicted E(W) / E(1) at W = 64 and 256 comes from
the fit at each step cost, and again with the driver's CPU as a floor under the step,
``t(W) = max(S + a + b W, a_cpu + b_cpu W)`` ("bound": a machine with W cores hides the
workers' compute, never the driver's serial work per worker), and ("cores") from the step
measured at W = 1 plus the driver's CPU per further worker, ``t(W) = t(1) + b_cpu (W - 1)``:
what a machine with a core per worker shows when nothing but the driver's serial work grows
with W (the issue's "measure b as the driver process's CPU time"; the wall time's b on 2
cores also holds the workers' own wake-ups queueing for the 2 cores); "thread" is the same
with ``b_thread``. The multi-node paths
make one Ray call per node in use, so W = 1 ... ``--nodes`` also add calls: their fits add
``b_cpu`` over W >= ``--nodes`` and its "cores" predictions (:func:`fits`).

Stragglers (W = ``--straggler-workers``, 10 ms, lognormal CV 0, 0.25, 0.5, on each of
``--straggler-paths``, default the socket path):
the barrier's env-steps/s; ``recv(min_envs=num_envs // 2)`` with every env kept in flight
(each recv returns the workers that answered, at least half the envs, sent again at once);
and EnvPool's batch mode, ``recv(min_envs=k, max_envs=k)`` with ``k = num_envs // 2``:
exactly k envs per recv, the first ready (:func:`run_exact_batch`; skipped in a revision
without ``max_envs``).

``--pin-driver``: the driver's own core. Every process and thread (Ray's daemons, the
workers, the driver's Ray threads) runs on the other cores, and the driver's main thread
moves to the first core for the timed barrier steps only (stragglers and start-up are not
pinned). The driver's CPU per step then holds its own work without the workers running
between its instructions on the same core: what it pays with a core to itself, as on a
machine with a core per worker. Compare ``b_cpu`` with a run without it.

Output: tables, JSON (default ``benchmarks/results/scaling.json``) and a PNG beside it:
E(W) per path and step cost (top), driver CPU per step (bottom), one column per envs per
worker.
"""

from __future__ import annotations

import argparse
import contextlib
import functools
import gc
import importlib.util
import os
import statistics
import sys
import time
import traceback
from collections.abc import Iterator
from dataclasses import dataclass
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
from benchmarks.vector.throughput_timing import start_ray
from chronogym.sizing import (
    StepModel,
    Timed,
    fit_line,
    fit_overhead,
    synthetic_step_s,
    timed_loop,
)

DEFAULT_OUT = RESULTS / "scaling.json"
ENV_ID = "chronogym/Synthetic-v0"
LOCAL_PATHS = (
    "socket",
    "socket_tree",
    "socket_messages",
    "actor",
    "driver_worker",
    "fork",
    "async",
)
MULTINODE_PATHS = ("multinode", "multinode_calls", "multinode_messages", "multinode_fork")
ALL_PATHS = (*LOCAL_PATHS, *MULTINODE_PATHS)
PREDICT_AT = (64, 256)
STRAGGLER_CVS = (0.0, 0.25, 0.5)
STRAGGLER_STEP_MS = 10.0
STRAGGLER_PATHS = ("socket", "fork")  # transports --straggler-paths may name
RAY_FREE_PATHS = ("fork", "async")  # the paths that run where Ray is not installed
RAY_SETTLE_S = 2.0


# -- options --------------------------------------------------------------------------------


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--workers", type=positive_int, nargs="+", default=[1, 2, 4, 8, 16, 32, 64])
    parser.add_argument("--with-128", action="store_true", help="add W = 128 (memory permitting)")
    parser.add_argument("--envs-per-worker", type=positive_int, nargs="+", default=[1, 8])
    parser.add_argument("--step-ms", type=positive_float, nargs="+", default=[0.1, 1.0, 10.0])
    parser.add_argument("--paths", nargs="+", choices=LOCAL_PATHS, default=list(LOCAL_PATHS))
    parser.add_argument(
        "--multinode", action="store_true", help="add the loopback multi-node paths (slow start)"
    )
    parser.add_argument(
        "--multinode-only", action="store_true", help="only the multi-node paths (no stragglers)"
    )
    parser.add_argument(
        "--multinode-paths",
        nargs="+",
        choices=MULTINODE_PATHS,
        default=list(MULTINODE_PATHS),
        help="the multi-node paths to run (default all)",
    )
    parser.add_argument("--nodes", type=positive_int, default=2, help="worker nodes of it")
    parser.add_argument("--seconds", type=positive_float, default=2.0, help="timed per setting")
    parser.add_argument("--min-steps", type=positive_int, default=20, help="timed, at least")
    parser.add_argument("--warmup", type=non_negative_int, default=10, help="untimed vector steps")
    parser.add_argument("--obs-dim", type=positive_int, default=16)
    parser.add_argument("--info-floats", type=non_negative_int, default=0)
    parser.add_argument(
        "--info-scalars",
        type=non_negative_int,
        default=0,
        help="float64 scalars in each step's info (Ant-v5 reports 9; default 0)",
    )
    parser.add_argument("--straggler-workers", type=positive_int, default=16)
    parser.add_argument(
        "--straggler-paths",
        nargs="+",
        choices=STRAGGLER_PATHS,
        default=["socket"],
        help="the transports the straggler runs compare (default socket)",
    )
    parser.add_argument("--no-stragglers", action="store_true")
    parser.add_argument(
        "--ray-cpus", type=positive_int, default=os.cpu_count() or 1, help="ray.init num_cpus"
    )
    parser.add_argument(
        "--quick", action="store_true", help="smoke run: W 1, 2, 8; 1 and 2 envs; 1 ms; short"
    )
    parser.add_argument(
        "--pin-driver",
        action="store_true",
        help="time the barrier with the driver on a core of its own (the rest on the others)",
    )
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="JSON; the PNG beside it")
    args = parser.parse_args(argv)
    args.driver_cpus, args.other_cpus = None, None
    if args.pin_driver:
        cpus = sorted(os.sched_getaffinity(0)) if hasattr(os, "sched_getaffinity") else []
        if len(cpus) < 2:
            parser.error(f"--pin-driver needs at least 2 usable CPUs; this process has {cpus}")
        args.driver_cpus, args.other_cpus = cpus[:1], cpus[1:]
    if args.quick:
        args.workers, args.envs_per_worker, args.step_ms = [1, 2, 8], [1, 2], [1.0]
        args.seconds, args.min_steps, args.warmup = 0.3, 5, 3
        args.straggler_workers = 4
    if args.multinode_only:
        args.multinode, args.paths, args.no_stragglers = True, [], True
    if args.with_128 and 128 not in args.workers:
        args.workers.append(128)
    args.workers = sorted(set(args.workers))
    ray_paths = ray_paths_of(args)
    if ray_paths and importlib.util.find_spec("ray") is None:
        parser.error(
            f"paths {', '.join(ray_paths)} need Ray, which is not importable here; "
            f"expected only {' and '.join(RAY_FREE_PATHS)} (--paths, --straggler-paths or "
            "--no-stragglers), without --multinode"
        )
    return args


def ray_paths_of(args: argparse.Namespace, multinode: bool = True) -> list[str]:
    """The paths of this run that need Ray: every one but fork and async, and with
    ``multinode`` the multi-node ones (their cluster is Ray's)."""
    stragglers = [] if args.no_stragglers else args.straggler_paths
    extra = args.multinode_paths if multinode and args.multinode else []
    paths = [*args.paths, *stragglers, *extra]
    return [p for p in dict.fromkeys(paths) if p not in RAY_FREE_PATHS]


# -- building the vector envs -----------------------------------------------------------------


def rss_mb(pid: int) -> float | None:
    """Resident memory of ``pid``, MiB (None if it is gone)."""
    try:
        for line in Path(f"/proc/{pid}/status").read_text().splitlines():
            if line.startswith("VmRSS:"):
                return int(line.split()[1]) / 1024
    except OSError:
        return None
    return None


def env_kwargs(args: argparse.Namespace, step_ms: float, cv: float = 0.0) -> dict[str, Any]:
    return {
        "step_ms": step_ms,
        "cv": cv,
        "obs_dim": args.obs_dim,
        "info_floats": args.info_floats,
        "info_scalars": args.info_scalars,
        "max_steps": 1_000_000,  # no truncation inside the timed loops
    }


def build(path: str, workers: int, epw: int, kwargs: dict[str, Any], address: str | None) -> Any:
    """The vector env of ``path``: ``workers`` workers of ``epw`` synthetic envs each."""
    from gymnasium.vector import AutoresetMode

    num_envs = workers * epw
    if path == "async":
        import gymnasium as gym

        return gym.make_vec(
            ENV_ID,
            num_envs,
            vectorization_mode="async",
            vector_kwargs={"autoreset_mode": AutoresetMode.NEXT_STEP},
            **kwargs,
        )
    from chronogym import RayVectorEnv

    options: dict[str, Any] = {"envs_per_worker": epw, "env_kwargs": kwargs}
    if path in ("actor", "fork"):
        options["transport"] = path
    elif path == "socket_messages":
        options["shared_memory"] = False
    elif path == "driver_worker":
        options["driver_worker"] = True
    elif path == "multinode_fork":
        options.update(address=address, transport="fork")
    elif path in MULTINODE_PATHS:
        options.update(address=address, scheduling="spread")
        if path == "multinode_calls":
            options["relay_tcp"] = False
        if path == "multinode_messages":
            options["shared_memory"] = False
    vec = RayVectorEnv(ENV_ID, num_envs, **options)
    if path == "socket_tree":
        vec._backend.wake_tree = True  # groups of FANOUT, whatever the cores (first step)
    return vec


def worker_pids(path: str, vec: Any) -> list[int]:
    """The workers' process ids (not the driver's own, which a driver worker lists)."""
    if path == "async":
        return [p.pid for p in vec.processes]
    return [pid for pid in vec.worker_pids() if pid != os.getpid()]


@dataclass
class Built:
    vec: Any
    record: dict[str, Any]  # start-up time and memory


def start(
    path: str, workers: int, epw: int, args: argparse.Namespace, address: str | None
) -> Built:
    """Build and reset one vector env: its start-up time and memory record."""
    gc.collect()
    before = rss_mb(os.getpid())
    t0 = time.perf_counter()
    vec = build(path, workers, epw, env_kwargs(args, args.step_ms[0]), address)
    constructed = time.perf_counter() - t0
    vec.reset(seed=0)
    start_s = time.perf_counter() - t0
    after = rss_mb(os.getpid())
    worker_rss = [m for m in map(rss_mb, worker_pids(path, vec)) if m is not None]
    record = {
        "path": path,
        "workers": workers,
        "envs_per_worker": epw,
        "start_s": start_s,
        "construct_s": constructed,
        "driver_rss_before_mb": before,
        "driver_rss_after_mb": after,
        "driver_rss_growth_mb": (after - before) if before and after else None,
        "worker_rss_mb_mean": statistics.mean(worker_rss) if worker_rss else None,
        "worker_rss_mb_max": max(worker_rss) if worker_rss else None,
        "worker_processes": len(worker_rss),
    }
    return Built(vec, record)


# -- timed loops --------------------------------------------------------------------------------


def zero_actions(vec: Any) -> np.ndarray:
    space = vec.action_space
    return np.zeros(space.shape, dtype=space.dtype)


def run_barrier(vec: Any, args: argparse.Namespace) -> Timed:
    """Barrier ``step``s: vector steps, wall s, the driver's CPU s (process and stepping
    thread); with ``--pin-driver``, the calling thread on the driver's core meanwhile."""
    actions = zero_actions(vec)
    with driver_core(args):
        return timed_loop(lambda: vec.step(actions), args.seconds, args.min_steps, args.warmup)


@contextlib.contextmanager
def driver_core(args: argparse.Namespace) -> Iterator[None]:
    """Move this thread to ``args.driver_cpus`` and back to the other cores (no-op unpinned)."""
    if not args.driver_cpus:
        yield
        return
    os.sched_setaffinity(0, args.driver_cpus)
    try:
        yield
    finally:
        os.sched_setaffinity(0, args.other_cpus)


def run_recv_min_envs(
    vec: Any, seconds: float, batch: int, exact: bool = False
) -> tuple[int, float]:
    """Every env in flight; each ``recv(min_envs=batch)`` returns the workers that answered
    (``exact``: ``max_envs=batch`` too, EnvPool's batch), sent again at once: (env steps,
    seconds). Drains before returning."""
    actions = zero_actions(vec)
    vec.send(actions)
    limit = {"max_envs": batch} if exact else {}
    done, start = 0, time.perf_counter()
    try:
        while time.perf_counter() - start < seconds:
            ids = vec.recv(min_envs=batch, **limit)[5]
            vec.send(actions[: len(ids)], ids)
            done += len(ids)
        return done, time.perf_counter() - start
    finally:
        vec.recv()  # the envs still in flight


def run_exact_batch(vec: Any, seconds: float, batch: int) -> tuple[int, float] | None:
    """EnvPool's batch mode, ``recv(min_envs=batch, max_envs=batch)``: exactly ``batch`` envs
    per recv, the rest staying in flight; None in a revision whose ``recv`` has no
    ``max_envs`` (to compare revisions)."""
    import inspect

    if "max_envs" not in inspect.signature(vec.recv).parameters:
        return None
    return run_recv_min_envs(vec, seconds, batch, exact=True)


def measure(
    built: Built, step_ms: float, args: argparse.Namespace, ideal_steps_s: float
) -> dict[str, Any]:
    """One setting on a built env: the step cost set in place, then the timed barrier."""
    vec = built.vec
    vec.set_attr("step_ms", step_ms)
    vec.set_attr("cv", 0.0)
    timed = run_barrier(vec, args)
    steps, wall = timed.steps, timed.wall_s
    record = built.record
    num_envs = record["workers"] * record["envs_per_worker"]
    rate = steps * num_envs / wall
    return {
        "path": record["path"],
        "workers": record["workers"],
        "envs_per_worker": record["envs_per_worker"],
        "step_ms": step_ms,
        "steps": steps,
        "wall_ms_per_step": 1e3 * wall / steps,
        "driver_cpu_ms_per_step": 1e3 * timed.cpu_s / steps,
        "driver_thread_cpu_ms_per_step": 1e3 * timed.thread_cpu_s / steps,
        "env_steps_per_s": rate,
        "ideal_env_steps_per_s": ideal_steps_s,
        "efficiency": rate / ideal_steps_s,
    }


def ideal_rate(workers: int, epw: int, step_ms: float) -> float:
    """Env-steps/s of every env stepping back to back: W * epw envs at 1 / (epw * step_ms)
    steps/s per worker."""
    return workers * epw / (epw * step_ms / 1e3)


# -- the sweep --------------------------------------------------------------------------------


def prime(paths: list[str], args: argparse.Namespace, address: str | None) -> None:
    """Build, reset and close each path once at W = 1, untimed: the imports and caches of a
    first build stay out of the start-up times and the driver's RSS growth."""
    for path in paths:
        try:
            built = start(path, 1, 1, args, address)
        except Exception as error:
            print(f"  priming {path} failed: {error_text(error)}")
            continue
        built.vec.close()
        del built
        gc.collect()


def sweep(
    paths: list[str],
    args: argparse.Namespace,
    address: str | None,
    runs: list[dict[str, Any]],
    starts: list[dict[str, Any]],
    failures: list[dict[str, Any]],
) -> None:
    """Every W x envs per worker x path x step cost; appends to the lists."""
    for workers in args.workers:
        for epw in args.envs_per_worker:
            for path in paths:
                if path == "async" and epw > 1:
                    continue  # one env per subprocess: no envs per worker
                label = f"{path}, W={workers}, epw={epw}"
                print(f"  {label}: starting ...", flush=True)
                try:
                    built = start(path, workers, epw, args, address)
                except Exception as error:
                    failures.append({"setting": label, "error": error_text(error)})
                    print(f"    failed to start: {error_text(error)}", flush=True)
                    continue
                starts.append(built.record)
                try:
                    for step_ms in args.step_ms:
                        row = measure(built, step_ms, args, ideal_rate(workers, epw, step_ms))
                        runs.append(row)
                        print(
                            f"    {step_ms:g} ms: {row['wall_ms_per_step']:.3f} ms/step, "
                            f"driver CPU {row['driver_cpu_ms_per_step']:.3f} ms, "
                            f"E = {row['efficiency']:.3f}",
                            flush=True,
                        )
                except Exception as error:
                    failures.append(
                        {"setting": label, "error": error_text(error), "tb": traceback.format_exc()}
                    )
                    print(f"    failed: {error_text(error)}", flush=True)
                finally:
                    built.vec.close()
                    del built
                    gc.collect()


def stragglers(args: argparse.Namespace) -> list[dict[str, Any]]:
    """Barrier vs recv(min_envs) (and the exact batch slot) under lognormal step costs."""
    rows = []
    for path in getattr(args, "straggler_paths", ["socket"]):
        rows += stragglers_of(path, args)
    return rows


def stragglers_of(path: str, args: argparse.Namespace) -> list[dict[str, Any]]:
    """:func:`stragglers` on one transport (``path``: ``socket`` or ``fork``)."""
    from chronogym import RayVectorEnv

    workers = args.straggler_workers
    batch = max(1, workers // 2)
    rows = []
    vec = RayVectorEnv(
        ENV_ID,
        workers,
        envs_per_worker=1,
        env_kwargs=env_kwargs(args, STRAGGLER_STEP_MS),
        transport=path,
    )
    try:
        vec.reset(seed=0)
        for cv in STRAGGLER_CVS:
            vec.set_attr("cv", cv)
            timed = run_barrier(vec, args)
            barrier = timed.steps * workers / timed.wall_s
            done, seconds = run_recv_min_envs(vec, args.seconds, batch)
            exact = run_exact_batch(vec, args.seconds, batch)
            row = {
                "path": path,
                "workers": workers,
                "step_ms": STRAGGLER_STEP_MS,
                "cv": cv,
                "batch": batch,
                "barrier_env_steps_per_s": barrier,
                "recv_min_envs_env_steps_per_s": done / seconds,
                "recv_min_envs_x_barrier": done / seconds / barrier,
                "exact_batch_env_steps_per_s": exact[0] / exact[1] if exact else None,
                "exact_batch_x_barrier": exact[0] / exact[1] / barrier if exact else None,
                "exact_batch_note": None if exact else "no exact batch mode in this revision",
                "ideal_env_steps_per_s": ideal_rate(workers, 1, STRAGGLER_STEP_MS),
            }
            rows.append(row)
            exact_text = (
                f", recv(min_envs={batch}, max_envs={batch}) "
                f"{row['exact_batch_env_steps_per_s']:,.0f}"
                if exact
                else ""
            )
            print(
                f"  {path}, CV {cv:g}: barrier {barrier:,.0f}, recv(min_envs={batch}) "
                f"{row['recv_min_envs_env_steps_per_s']:,.0f}{exact_text} env-steps/s",
                flush=True,
            )
    finally:
        vec.close()
    return rows


# -- fits -------------------------------------------------------------------------------------


def add_relative_efficiency(runs: list[dict[str, Any]]) -> None:
    """E(W) / E(1) of each run, against the same path, envs per worker and step cost; and
    ``x_async``, its env-steps/s over AsyncVectorEnv's at the same W and step cost (one env
    per worker only)."""
    first = {}
    for run in runs:
        key = (run["path"], run["envs_per_worker"], run["step_ms"])
        if run["workers"] == 1:
            first[key] = run["efficiency"]
    asynchronous = {
        (r["workers"], r["step_ms"]): r["env_steps_per_s"] for r in runs if r["path"] == "async"
    }
    for run in runs:
        base = first.get((run["path"], run["envs_per_worker"], run["step_ms"]))
        run["efficiency_rel_w1"] = run["efficiency"] / base if base else None
        peer = asynchronous.get((run["workers"], run["step_ms"]))
        same_envs = run["envs_per_worker"] == 1
        run["x_async"] = run["env_steps_per_s"] / peer if peer and same_envs else None


def fit_group(rows: list[dict[str, Any]], epw: int) -> dict[str, Any] | None:
    """a, b (wall), a_cpu, b_cpu (the driver process's CPU) and a_thread, b_thread (its
    stepping thread's CPU) of one group of runs, in µs."""
    if len({r["workers"] for r in rows}) < 2:
        return None
    workers = [r["workers"] for r in rows]
    wall = [r["wall_ms_per_step"] / 1e3 for r in rows]
    busy = [epw * r["step_ms"] / 1e3 for r in rows]
    a, b = fit_overhead(workers, wall, busy)
    a_cpu, b_cpu = fit_line(workers, [r["driver_cpu_ms_per_step"] / 1e3 for r in rows])
    out = {"a_us": a * 1e6, "b_us": b * 1e6, "a_cpu_us": a_cpu * 1e6, "b_cpu_us": b_cpu * 1e6}
    if all("driver_thread_cpu_ms_per_step" in r for r in rows):
        thread = [r["driver_thread_cpu_ms_per_step"] / 1e3 for r in rows]
        a_thread, b_thread = fit_line(workers, thread)
        out.update(a_thread_us=a_thread * 1e6, b_thread_us=b_thread * 1e6)
    return out


def predicted(fit: dict[str, Any], step_ms: float, epw: int, workers: int, bound: bool) -> float:
    """The model's E(W) / E(1): ``t(W) = S + a + b W``; with ``bound``, the driver's CPU caps
    the step: ``t(W) = max(S + a + b W, a_cpu + b_cpu W)`` (a machine with W cores hides the
    workers' compute, not the driver's serial work)."""
    model = StepModel(step_ms / 1e3, fit["a_us"] / 1e6, fit["b_us"] / 1e6)

    def t(w: int) -> float:
        wall = model.t_step(w, epw)
        return max(wall, (fit["a_cpu_us"] + fit["b_cpu_us"] * w) / 1e6) if bound else wall

    return t(1) / t(workers)


def predicted_on_cores(t1_ms: float, b_cpu_us: float, workers: int) -> float:
    """E(W) / E(1) on a machine with a core per worker: the step measured at W = 1, plus the
    driver's serial CPU per further worker, ``t(W) = t(1) + b_cpu (W - 1)`` (the workers'
    own compute and wake-ups run in parallel there; 2 cores cannot show that, so the wall
    time's b here overstates it)."""
    return t1_ms / (t1_ms + b_cpu_us / 1e3 * (workers - 1))


def fits(runs: list[dict[str, Any]], nodes: int = 1) -> list[dict[str, Any]]:
    """Per path and envs per worker: the fit at each step cost (with its predictions) and
    pooled over the step costs. A multi-node path's driver makes one call per node in use,
    so W = 1 ... ``nodes`` also add nodes: its entries add the driver-CPU fit over W >=
    ``nodes`` (every node in use), ``b_cpu_us_every_node``, and the "cores" predictions
    from it, ``t(W) = t(nodes) + b_cpu (W - nodes)`` against ``t(1)``."""
    out = []
    groups = sorted({(r["path"], r["envs_per_worker"]) for r in runs})
    for path, epw in groups:
        rows = [r for r in runs if (r["path"], r["envs_per_worker"]) == (path, epw)]
        costs = sorted({r["step_ms"] for r in rows})
        for step_ms in [*costs, None] if len(costs) > 1 else costs:
            chosen = [r for r in rows if step_ms is None or r["step_ms"] == step_ms]
            fit = fit_group(chosen, epw)
            if fit is None:
                continue
            entry = {"path": path, "envs_per_worker": epw, "step_ms": step_ms, **fit}
            if step_ms is not None:
                one = [r["wall_ms_per_step"] for r in chosen if r["workers"] == 1]
                for w in PREDICT_AT:
                    entry[f"predicted_rel_e_{w}_cores"] = (
                        predicted_on_cores(one[0], fit["b_cpu_us"], w) if one else None
                    )
                    if "b_thread_us" in fit:
                        entry[f"predicted_rel_e_{w}_cores_thread"] = (
                            predicted_on_cores(one[0], fit["b_thread_us"], w) if one else None
                        )
                    entry[f"predicted_rel_e_{w}"] = predicted(fit, step_ms, epw, w, False)
                    entry[f"predicted_rel_e_{w}_driver_bound"] = predicted(
                        fit, step_ms, epw, w, True
                    )
                if path in MULTINODE_PATHS and nodes > 1:
                    entry.update(every_node_fit(chosen, epw, nodes, one[0] if one else None))
            out.append(entry)
    return out


def every_node_fit(
    rows: list[dict[str, Any]], epw: int, nodes: int, t1_ms: float | None
) -> dict[str, Any]:
    """The driver-CPU slope over W >= ``nodes`` and its "cores" predictions (see :func:`fits`)."""
    full = [r for r in rows if r["workers"] >= nodes]
    fit = fit_group(full, epw)
    at_nodes = [r["wall_ms_per_step"] for r in full if r["workers"] == nodes]
    if fit is None or t1_ms is None or not at_nodes:
        return {}
    out: dict[str, Any] = {"b_cpu_us_every_node": fit["b_cpu_us"]}
    for w in PREDICT_AT:
        t_w = at_nodes[0] + fit["b_cpu_us"] / 1e3 * (w - nodes)
        out[f"predicted_rel_e_{w}_cores_every_node"] = t1_ms / t_w
    return out


def memory_fits(starts: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Per path: the driver's RSS growth per worker (slope over W) and start-up at max W."""
    out = []
    for path in dict.fromkeys(s["path"] for s in starts):
        rows = [s for s in starts if s["path"] == path and s["driver_rss_growth_mb"] is not None]
        if len({r["workers"] for r in rows}) < 2:
            continue
        _, slope = fit_line([r["workers"] for r in rows], [r["driver_rss_growth_mb"] for r in rows])
        top = max(rows, key=lambda r: r["workers"])
        out.append(
            {
                "path": path,
                "driver_rss_mb_per_worker": slope,
                "max_workers": top["workers"],
                "start_s_at_max": top["start_s"],
                "worker_rss_mb_mean_at_max": top["worker_rss_mb_mean"],
                **worker_memory(rows),
            }
        )
    return out


def worker_memory(rows: list[dict[str, Any]]) -> dict[str, float | None]:
    """What a worker holds: its RSS at one env (the interpreter, Ray's core worker, the
    imports) and the MB each further env adds (mean over W, most against fewest envs)."""

    def mean_rss(epw: int) -> float | None:
        values = [r["worker_rss_mb_mean"] for r in rows if r["envs_per_worker"] == epw]
        values = [v for v in values if v is not None]
        return statistics.mean(values) if values else None

    epws = sorted({r["envs_per_worker"] for r in rows})
    low, high = mean_rss(epws[0]), mean_rss(epws[-1])
    per_env = (high - low) / (epws[-1] - epws[0]) if low and high and len(epws) > 1 else None
    return {"worker_rss_mb_base": low, "worker_rss_mb_per_env": per_env}


# -- report -----------------------------------------------------------------------------------

RUN_COLUMNS = (
    Column("path", 15, align="<", key="path"),
    Column("W", 4, key="workers"),
    Column("epw", 3, key="envs_per_worker"),
    Column("step ms", 7, "{:g}", key="step_ms"),
    Column("ms/step", 8, "{:.3f}", key="wall_ms_per_step"),
    Column("driver CPU ms", 13, "{:.3f}", key="driver_cpu_ms_per_step"),
    Column("env-steps/s", 11, "{:,.0f}", key="env_steps_per_s"),
    Column("E(W)", 5, "{:.3f}", key="efficiency"),
    Column("E/E(1)", 6, "{:.3f}", key="efficiency_rel_w1"),
    Column("x async", 7, "{:.2f}", key="x_async"),
)
FIT_COLUMNS = (
    Column("path", 15, align="<", key="path"),
    Column("epw", 3, key="envs_per_worker"),
    Column("step ms", 7, "{:g}", key="step_ms"),
    Column("a us", 8, "{:,.0f}", key="a_us"),
    Column("b us", 7, "{:,.1f}", key="b_us"),
    Column("a_cpu us", 8, "{:,.0f}", key="a_cpu_us"),
    Column("b_cpu us", 8, "{:,.1f}", key="b_cpu_us"),
    Column("E64 cores", 9, "{:.2f}", key="predicted_rel_e_64_cores"),
    Column("E256 cores", 10, "{:.2f}", key="predicted_rel_e_256_cores"),
    Column("b_thread us", 11, "{:,.1f}", key="b_thread_us"),
    Column("E256 thread", 11, "{:.2f}", key="predicted_rel_e_256_cores_thread"),
    Column("E64/E1", 6, "{:.2f}", key="predicted_rel_e_64"),
    Column("E256/E1", 7, "{:.2f}", key="predicted_rel_e_256"),
    Column("E64 bound", 9, "{:.2f}", key="predicted_rel_e_64_driver_bound"),
    Column("E256 bound", 10, "{:.2f}", key="predicted_rel_e_256_driver_bound"),
)
START_COLUMNS = (
    Column("path", 15, align="<", key="path"),
    Column("W", 4, key="workers"),
    Column("epw", 3, key="envs_per_worker"),
    Column("start s", 7, "{:.2f}", key="start_s"),
    Column("driver RSS +MB", 14, "{:.1f}", key="driver_rss_growth_mb"),
    Column("worker RSS MB", 13, "{:.0f}", key="worker_rss_mb_mean"),
)
STRAGGLER_COLUMNS = (
    Column("path", 6, align="<", key="path"),
    Column("CV", 4, "{:g}", key="cv"),
    Column("W", 3, key="workers"),
    Column("barrier env-steps/s", 19, "{:,.0f}", key="barrier_env_steps_per_s"),
    Column("recv(min_envs) env-steps/s", 26, "{:,.0f}", key="recv_min_envs_env_steps_per_s"),
    Column("x barrier", 9, "{:.2f}", key="recv_min_envs_x_barrier"),
    Column("exact batch", 11, "{:,.0f}", key="exact_batch_env_steps_per_s"),
    Column("x barrier", 9, "{:.2f}", key="exact_batch_x_barrier"),
)


def fmt(value: float | None, spec: str) -> str:
    return "-" if value is None else format(value, spec)


def with_none(columns: tuple[Column, ...], rows: list[dict[str, Any]]) -> list[dict[str, Any]]:
    """Rows with every column's key present (None where missing)."""
    return [{c.key: row.get(c.key) for c in columns} for row in rows]


def plot(runs: list[dict[str, Any]], path: Path) -> None:
    """E(W) (top) and driver CPU ms per step (bottom) against W, one column per envs per
    worker; a colour per path, a line style per step cost."""
    plt = pyplot()
    epws = sorted({r["envs_per_worker"] for r in runs})
    paths = list(dict.fromkeys(r["path"] for r in runs))
    steps = sorted({r["step_ms"] for r in runs})
    styles = ["-", "--", ":", "-."]
    colors = dict(zip(paths, plt.rcParams["axes.prop_cycle"].by_key()["color"], strict=False))
    fig, axes = plt.subplots(2, len(epws), figsize=(6 * len(epws), 8), squeeze=False)
    for col, epw in enumerate(epws):
        for p in paths:
            for i, step_ms in enumerate(steps):
                rows = sorted(
                    (
                        r
                        for r in runs
                        if (r["path"], r["envs_per_worker"], r["step_ms"]) == (p, epw, step_ms)
                    ),
                    key=lambda r: r["workers"],
                )
                if not rows:
                    continue
                ws = [r["workers"] for r in rows]
                style = {"color": colors[p], "linestyle": styles[i % len(styles)], "marker": "o"}
                axes[0, col].plot(
                    ws, [r["efficiency"] for r in rows], label=f"{p}, {step_ms:g} ms", **style
                )
                axes[1, col].plot(ws, [r["driver_cpu_ms_per_step"] for r in rows], **style)
        for row, ylabel in enumerate(("E(W) = measured / ideal", "driver CPU ms per vector step")):
            ax = axes[row, col]
            ax.set_xscale("log", base=2)
            ticks = sorted({r["workers"] for r in runs})
            ax.set_xticks(ticks, [str(w) for w in ticks])
            ax.set_xlabel("workers W")
            ax.set_ylabel(ylabel)
            ax.grid(alpha=0.3)
        axes[0, col].set_ylim(0, 1.05)
        axes[1, col].set_yscale("log")
        axes[0, col].set_title(f"{epw} env(s) per worker")
        axes[0, col].legend(fontsize=7)
    save_figure(fig, path)
    print(f"wrote {path}")


# -- main ---------------------------------------------------------------------------------


@contextlib.contextmanager
def multinode_cluster(nodes: int, cpus: int) -> Iterator[str]:
    """A loopback cluster whose head has no CPUs (every worker on another node): its address."""
    from chronogym.testing import LocalCluster

    with LocalCluster(workers=nodes, num_cpus=cpus, head_cpus=0) as cluster:
        cluster.connect()
        time.sleep(RAY_SETTLE_S)
        try:
            yield cluster.address
        finally:
            cluster.disconnect()


def sleep_calibration(step_ms: list[float], seconds: float) -> dict[str, float]:
    """What one SyntheticEnv step of each cost takes in this process, ms."""
    return {f"{ms:g}": 1e3 * synthetic_step_s(ms / 1e3, seconds) for ms in step_ms}


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    if args.other_cpus:  # everything started from here on inherits the other cores
        os.sched_setaffinity(0, args.other_cpus)
    wall = time.perf_counter()
    local_ray = bool(ray_paths_of(args, multinode=False))
    runs: list[dict[str, Any]] = []
    starts: list[dict[str, Any]] = []
    failures: list[dict[str, Any]] = []
    record: dict[str, Any] = {**header("vector/scaling"), "settings": settings(args)}
    record["sleep_ms"] = sleep_calibration(args.step_ms, min(args.seconds, 1.0))
    print(f"sleep calibration (ms per step, in process): {record['sleep_ms']}")
    straggler_rows: list[dict[str, Any]] = []
    if local_ray:
        start_ray(args.ray_cpus)
    try:
        prime(args.paths, args, None)
        sweep(args.paths, args, None, runs, starts, failures)
        if not args.no_stragglers:
            print("stragglers:")
            straggler_rows = stragglers(args)
    finally:
        if local_ray:
            import ray

            ray.shutdown()
    if args.multinode:
        print(f"multinode: {args.nodes} worker nodes of {args.ray_cpus} CPUs, head without")
        try:
            with multinode_cluster(args.nodes, args.ray_cpus) as address:
                prime(args.multinode_paths, args, address)
                sweep(args.multinode_paths, args, address, runs, starts, failures)
        except Exception as error:
            failures.append({"setting": "multinode cluster", "error": error_text(error)})
            print(f"  multinode failed: {error_text(error)}")
    add_relative_efficiency(runs)
    record.update(
        runs=runs,
        fits=fits(runs, args.nodes if args.multinode else 1),
        startup=starts,
        memory=memory_fits(starts),
        stragglers=straggler_rows,
        failures=failures,
        seconds_in_all=time.perf_counter() - wall,
    )
    print()
    print(table(RUN_COLUMNS, with_none(RUN_COLUMNS, runs), rule=True))
    print()
    print("fit t_step = S + a + b*W (S = epw x step ms); driver CPU = a_cpu + b_cpu*W;")
    print("E64/E1, E256/E1: the model's E(W)/E(1); bound: the step at least the driver's CPU;")
    print("cores: t(W) = t(1) + b_cpu (W - 1), a core per worker (only the driver's CPU adds)")
    print("b_thread: b_cpu of the stepping thread alone; thread: cores with b_thread")
    print("(step ms '-': fitted over every step cost)")
    print(table(FIT_COLUMNS, with_none(FIT_COLUMNS, record["fits"]), rule=True))
    for entry in record["fits"]:
        if "b_cpu_us_every_node" in entry:
            print(
                f"  {entry['path']}, epw {entry['envs_per_worker']}, {entry['step_ms']:g} ms, "
                f"W >= {args.nodes} (every node in use): b_cpu "
                f"{entry['b_cpu_us_every_node']:.1f} us; cores: E64/E1 "
                f"{entry['predicted_rel_e_64_cores_every_node']:.2f}, E256/E1 "
                f"{entry['predicted_rel_e_256_cores_every_node']:.2f}"
            )
    print()
    print("start-up (constructor to first reset) and memory")
    print(table(START_COLUMNS, with_none(START_COLUMNS, starts), rule=True))
    for entry in record["memory"]:
        print(
            f"  {entry['path']}: driver RSS {entry['driver_rss_mb_per_worker']:.2f} MB per worker; "
            f"W={entry['max_workers']}: start {entry['start_s_at_max']:.1f} s; a worker holds "
            f"{fmt(entry['worker_rss_mb_base'], '.0f')} MB at its fewest envs, "
            f"{fmt(entry['worker_rss_mb_per_env'], '.2f')} MB per further env"
        )
    if straggler_rows:
        print()
        print(f"stragglers: {STRAGGLER_STEP_MS:g} ms lognormal, env-steps/s")
        print(table(STRAGGLER_COLUMNS, with_none(STRAGGLER_COLUMNS, straggler_rows), rule=True))
    figure = functools.partial(plot, runs) if runs else None
    return finish(args.out, record, figure, failures)


if __name__ == "__main__":
    sys.exit(main())
