"""Chaos under load: SIGKILL Ray workers (and a whole node) during PPO training and a
lander study on a 3-node loopback cluster, then prove that nothing was lost.

The cluster is ``chronogym.testing.LocalCluster`` (head + 2 worker nodes, 1 CPU each,
``ray start`` subprocesses). A killer thread with its own seeded RNG picks a random
worker process of *this* cluster (``ray::SocketWorker`` or ``ray::ActorGroup`` during
training, ``ray::TrialWorker`` during the study; other Ray clusters on the machine are never
touched) at random intervals and SIGKILLs it, and once per phase kills every process of one
worker node (raylet, agents, actors).

1. Training: ``train`` (RSL-RL PPO) on ``make_quadruped_vec_env`` (8 Go1 envs, 2 Ray
   workers of 4, spread). Counted from the vector env's steps: episodes finished,
   episodes truncated by worker restarts, worker restarts; per iteration the driver's
   RSS and the cluster's object-store bytes in use. Checked: the run reaches the
   requested iterations with one progress.csv row each; memory growth per iteration
   (least squares over the second half of the run) stays under ``--rss-bound-mib``.
2. Study: ``run_parallel_study`` (TPE, 2 spread workers, SQLite storage), repeated until
   the study holds ``--trials`` COMPLETE trials (a trial whose worker died twice is told
   FAIL; parallel.py retries a lost trial once). Checked from the SQLite file: every
   trial is COMPLETE or FAIL, every FAIL has a ``fail_reason``, none is left RUNNING.

    python -m benchmarks.vector.chaos [--short] [--seed 0] [--out PATH]

Prints a table and writes ``benchmarks/results/chaos.json``; exits 1 if a check fails.
"""

from __future__ import annotations

import argparse
import csv
import os
import signal
import sys
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

from benchmarks.common import RESULTS, header, proc_cmdline, write_json
from chronogym.optim.lander import LanderObjective, suggest_lander_design
from chronogym.testing import LocalCluster

DEFAULT_OUT = RESULTS / "chaos.json"
#: Process titles of RayVectorEnv's workers: the socket transport's actor class is SocketWorker
#: (an EnvGroup), the actor transport's EnvGroup.
ENV_WORKERS = ("ray::ActorGroup", "ray::SocketWorker")


@dataclass(frozen=True)
class Settings:
    iterations: int
    steps_per_env: int
    kill_every: tuple[float, float]  # seconds between worker kills, uniform
    trials: int
    trial_kill_every: tuple[float, float]
    study_node_after: int  # COMPLETE trials in storage when a worker node is killed


FULL = Settings(
    iterations=120,
    steps_per_env=48,
    kill_every=(8, 20),
    trials=24,
    trial_kill_every=(4, 10),
    study_node_after=8,
)
SHORT = Settings(
    iterations=12,
    steps_per_env=24,
    kill_every=(3, 6),
    trials=8,
    trial_kill_every=(3, 6),
    study_node_after=3,
)


# -- chaos ---------------------------------------------------------------------------------
def process_title(pid: int) -> str:
    """What ``ps`` shows for ``pid`` (Ray actors rename themselves ``ray::Class.method``)."""
    return " ".join(proc_cmdline(pid))


def cluster_actors(cluster: Any, prefix: str | tuple[str, ...]) -> list[tuple[int, str]]:
    """(pid, node) of this cluster's processes whose title starts with ``prefix`` (or one of)."""
    found = []
    for node in cluster.nodes:
        for pid in node.pids():
            if process_title(pid).startswith(prefix):
                found.append((pid, node.name))
    return found


class Killer(threading.Thread):
    """SIGKILLs a random ``prefix`` actor of ``cluster`` every ``every`` s (seeded); once
    ``node_when()`` turns true, kills the live worker node hosting most of them."""

    def __init__(
        self,
        cluster: Any,
        prefix: str | tuple[str, ...],
        every: tuple[float, float],
        seed: int,
        node_when: Callable[[], bool] | None = None,
    ) -> None:
        super().__init__(daemon=True)
        self.cluster, self.prefix, self.every = cluster, prefix, every
        self.node_when = node_when
        self.rng = np.random.default_rng(seed)
        self.events: list[dict[str, Any]] = []
        self.halt = threading.Event()
        self.start_time = time.perf_counter()
        self.node_killed = False

    def run(self) -> None:
        next_kill = self.rng.uniform(*self.every)
        while not self.halt.wait(0.1):
            now = time.perf_counter() - self.start_time
            if not self.node_killed and self.node_when is not None and self.node_when():
                self.kill_node(now)
            if now >= next_kill:
                self.kill_one(now)
                next_kill = now + self.rng.uniform(*self.every)

    def kill_one(self, now: float) -> None:
        targets = cluster_actors(self.cluster, self.prefix)
        if not targets:
            return
        pid, node = targets[self.rng.integers(len(targets))]
        try:
            os.kill(pid, signal.SIGKILL)
        except ProcessLookupError:
            return
        self.events.append({"t": round(now, 2), "kind": "worker", "pid": pid, "node": node})

    def kill_node(self, now: float) -> None:
        self.node_killed = True
        hosts = [node for _, node in cluster_actors(self.cluster, self.prefix)]
        workers = [n.name for n in self.cluster.nodes[1:] if n.process.poll() is None]
        candidates = [n for n in workers if n in hosts] or workers
        if not candidates:
            return
        name = max(candidates, key=hosts.count)
        pids = self.cluster.kill_node(name)
        self.events.append({"t": round(now, 2), "kind": "node", "node": name, "pids": len(pids)})

    def stop(self) -> None:
        self.halt.set()
        self.join(timeout=10)


# -- memory --------------------------------------------------------------------------------
def driver_rss_mib() -> float:
    for line in Path("/proc/self/status").read_text().splitlines():
        if line.startswith("VmRSS:"):
            return int(line.split()[1]) / 1024
    return float("nan")


def object_store_used(address: str) -> tuple[float, int]:
    """(MiB in use, objects) of the object stores of all alive nodes."""
    from ray._private.internal_api import get_memory_info_reply, get_state_from_address

    state = get_state_from_address(address)
    try:
        stats = get_memory_info_reply(state, timeout_seconds=10).store_stats
    finally:
        state.disconnect()
    return stats.object_store_bytes_used / 2**20, int(stats.num_local_objects)


def growth_per_iteration(values: list[float]) -> float:
    """Least-squares slope of ``values`` over their second half (after warm-up)."""
    tail = np.asarray(values[len(values) // 2 :], dtype=float)
    if len(tail) < 2:
        return 0.0
    return float(np.polyfit(np.arange(len(tail)), tail, 1)[0])


# -- training ------------------------------------------------------------------------------
class ChaosCounter(gym.vector.VectorWrapper):
    """Counts episodes and restarts from every step, and samples memory once per iteration."""

    def __init__(self, env: Any, steps_per_iteration: int, address: str) -> None:
        super().__init__(env)
        self.steps_per_iteration = steps_per_iteration
        self.address = address
        self.steps = 0
        self.episodes = 0
        self.restart_truncations = 0
        self.worker_restarts = 0
        self.memory: list[dict[str, float]] = []

    @property
    def iteration(self) -> int:
        return self.steps // self.steps_per_iteration

    def step(self, actions: Any) -> Any:
        if self.steps % self.steps_per_iteration == 0:
            self.sample_memory()
        obs, rewards, terminated, truncated, infos = self.env.step(actions)
        self.steps += 1
        self.episodes += int(np.count_nonzero(terminated | truncated))
        restarted = np.asarray(infos.get("worker_restarted", np.zeros(0)), dtype=bool)
        mask = np.asarray(infos.get("_worker_restarted", restarted), dtype=bool)
        flags = restarted & mask if restarted.size else restarted
        self.restart_truncations += int(np.count_nonzero(flags))
        per_worker = self.env.unwrapped.envs_per_worker
        self.worker_restarts += len({int(i) // per_worker for i in np.flatnonzero(flags)})
        return obs, rewards, terminated, truncated, infos

    def sample_memory(self) -> None:
        used, objects = object_store_used(self.address)
        self.memory.append(
            {
                "iteration": self.iteration,
                "driver_rss_mib": driver_rss_mib(),
                "object_store_mib": used,
                "objects": objects,
            }
        )


def chaos_training(cluster: Any, settings: Settings, seed: int, out: Path) -> dict[str, Any]:
    from chronogym.rl.trainer import train
    from chronogym.rl.vecenv import RslRlVecEnv
    from chronogym.tasks.quadruped.training import make_quadruped_vec_env, quadruped_train_config

    vec = make_quadruped_vec_env(
        8,
        "ray",
        envs_per_worker=4,
        address=cluster.address,
        num_cpus=0.5,
        scheduling="spread",
        max_restarts=-1,
    )
    counter = ChaosCounter(vec, settings.steps_per_env, cluster.address)
    horizon = int(vec.get_attr("max_episode_steps")[0])  # the wrapper hides it from the adapter
    env = RslRlVecEnv(counter, seed=seed, max_episode_length=horizon)
    node_at = max(2, settings.iterations // 3)
    killer = Killer(
        cluster,
        ENV_WORKERS,
        settings.kill_every,
        seed,
        node_when=lambda: counter.iteration >= node_at,
    )
    killer.start()
    started = time.perf_counter()
    try:
        cfg = quadruped_train_config(num_steps_per_env=settings.steps_per_env)
        result = train(
            env, out, iterations=settings.iterations, train_cfg=cfg, seed=seed, progress=False
        )
    finally:
        killer.stop()
        env.close()
    with open(result.csv_path) as handle:
        rows = list(csv.DictReader(handle))
    rss = [m["driver_rss_mib"] for m in counter.memory]
    store = [m["object_store_mib"] for m in counter.memory]
    return {
        "iterations_requested": settings.iterations,
        "iterations_done": result.iterations_done,
        "csv_rows": len(rows),
        "csv_iterations": [int(r["iteration"]) for r in rows],
        "env_steps": result.env_steps,
        "wall_s": time.perf_counter() - started,
        "max_iteration_s": max(float(r["collect_s"]) + float(r["learn_s"]) for r in rows),
        "episodes": counter.episodes,
        "episodes_truncated_by_restarts": counter.restart_truncations,
        "worker_restarts": counter.worker_restarts,
        "env_restarts_recorded": len(vec.restarts),
        "kills": killer.events,
        "memory": counter.memory,
        "driver_rss_growth_mib_per_it": growth_per_iteration(rss),
        "object_store_growth_mib_per_it": growth_per_iteration(store),
        "object_store_max_mib": max(store) if store else 0.0,
    }


# -- study ---------------------------------------------------------------------------------
def chaos_study(cluster: Any, settings: Settings, seed: int, db: Path) -> dict[str, Any]:
    import optuna

    from chronogym.optim import open_storage, run_parallel_study
    from chronogym.optim.parallel import finished_trials

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    url = f"sqlite:///{db}"
    sampler = optuna.samplers.TPESampler(seed=seed, n_startup_trials=8, constant_liar=True)
    study = optuna.create_study(storage=open_storage(url), study_name="chaos", sampler=sampler)
    runs: list[dict[str, Any]] = []
    started = time.perf_counter()
    killer = Killer(
        cluster,
        "ray::TrialWorker",
        settings.trial_kill_every,
        seed + 1,
        node_when=lambda: _complete(study) >= settings.study_node_after,
    )
    killer.start()
    crashes: list[str] = []
    try:
        while _complete(study) < settings.trials and len(runs) + len(crashes) < 6:
            want = finished_trials(study) + settings.trials - _complete(study)
            try:
                report = run_parallel_study(
                    study,
                    suggest_lander_design,
                    LanderObjective("rigid", seed=0),
                    want,
                    workers=2,
                    address=cluster.address,
                    num_cpus=0.5,
                    scheduling="spread",
                    progress=False,
                )
            except Exception as error:  # the driver died: running it again resumes the study
                crashes.append(f"{type(error).__name__}: {str(error).splitlines()[0]}")
                continue
            runs.append(
                {"completed": report.completed, "failed": report.failed, "retried": report.retried}
            )
    finally:
        killer.stop()
    return {
        "wall_s": time.perf_counter() - started,
        "runs": runs,
        "driver_crashes": crashes,
        "kills": killer.events,
        **account_trials(url, settings.trials),
    }


def _complete(study: Any) -> int:
    return sum(t.state.name == "COMPLETE" for t in study.get_trials(deepcopy=False))


def account_trials(url: str, target: int) -> dict[str, Any]:
    """Read the study back from its SQLite file: is every trial accounted for?"""
    import optuna

    trials = optuna.load_study(study_name="chaos", storage=url).trials
    states = [t.state.name for t in trials]
    fails = [t for t in trials if t.state.name == "FAIL"]
    return {
        "trials_in_storage": len(trials),
        "complete": states.count("COMPLETE"),
        "failed": len(fails),
        "other_states": sorted({s for s in states if s not in ("COMPLETE", "FAIL")}),
        "fail_reasons": [str(t.user_attrs.get("fail_reason", ""))[-160:] for t in fails],
        "every_fail_has_reason": all(t.user_attrs.get("fail_reason") for t in fails),
        "target_reached": states.count("COMPLETE") >= target,
    }


# -- report --------------------------------------------------------------------------------
def checks(training: dict[str, Any], study: dict[str, Any], rss_bound: float) -> dict[str, bool]:
    wanted = list(range(training["iterations_requested"]))
    return {
        "training reached its iterations": training["iterations_done"]
        == training["iterations_requested"],
        "one CSV row per iteration": training["csv_iterations"] == wanted,
        "workers were killed during training": any(
            k["kind"] == "worker" for k in training["kills"]
        ),
        "a node was killed during training": any(k["kind"] == "node" for k in training["kills"]),
        "restarts were reported as truncations": training["episodes_truncated_by_restarts"] > 0,
        f"driver RSS growth < {rss_bound} MiB/it": training["driver_rss_growth_mib_per_it"]
        < rss_bound,
        "object store growth < 0.1 MiB/it": training["object_store_growth_mib_per_it"] < 0.1,
        "study reached its COMPLETE trials": study["target_reached"],
        "study driver never had to be rerun": not study["driver_crashes"],
        "every trial COMPLETE or FAIL": not study["other_states"],
        "every FAIL has a reason": study["every_fail_has_reason"],
        "workers were killed during the study": any(k["kind"] == "worker" for k in study["kills"]),
        "a node was killed during the study": any(k["kind"] == "node" for k in study["kills"]),
    }


def print_report(training: dict[str, Any], study: dict[str, Any], results: dict[str, bool]) -> None:
    t, s = training, study
    worker_kills = sum(k["kind"] == "worker" for k in t["kills"])
    node_kills = [k["node"] for k in t["kills"] if k["kind"] == "node"]
    print("training (8 Go1 envs, 2 Ray workers)")
    print(
        f"  iterations            {t['iterations_done']}/{t['iterations_requested']}"
        f" ({t['csv_rows']} CSV rows, {t['env_steps']} env steps, {t['wall_s']:.0f} s)"
    )
    print(f"  kills                 {worker_kills} workers, node {node_kills}")
    print(f"  worker restarts       {t['worker_restarts']}")
    print(
        f"  episodes              {t['episodes']} finished, "
        f"{t['episodes_truncated_by_restarts']} truncated by restarts"
    )
    print(f"  slowest iteration     {t['max_iteration_s']:.1f} s")
    print(
        f"  driver RSS            {t['memory'][0]['driver_rss_mib']:.0f} -> "
        f"{t['memory'][-1]['driver_rss_mib']:.0f} MiB, "
        f"{t['driver_rss_growth_mib_per_it']:+.3f} MiB/it (second half)"
    )
    print(
        f"  object store          max {t['object_store_max_mib']:.2f} MiB, "
        f"{t['object_store_growth_mib_per_it']:+.4f} MiB/it"
    )
    worker_kills = sum(k["kind"] == "worker" for k in s["kills"])
    node_kills = [k["node"] for k in s["kills"] if k["kind"] == "node"]
    retried = sum(r["retried"] for r in s["runs"])
    print("lander study (2 Ray workers, SQLite)")
    print(f"  kills                 {worker_kills} workers, node {node_kills}")
    print(
        f"  trials                {s['complete']} complete, {s['failed']} failed, "
        f"{retried} retried, {s['trials_in_storage']} in storage "
        f"({len(s['runs'])} runs, {s['wall_s']:.0f} s)"
    )
    for crash in s["driver_crashes"]:
        print(f"  driver crashed, rerun: {crash[:110]}")
    print("checks")
    for name, ok in results.items():
        print(f"  {'ok  ' if ok else 'FAIL'}  {name}")


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--short", action="store_true", help="smoke run (about 2 min)")
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--rss-bound-mib", type=float, default=1.0, help="allowed driver RSS growth per iteration"
    )
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args()
    settings = SHORT if args.short else FULL

    with tempfile.TemporaryDirectory() as tmp, LocalCluster(workers=2, num_cpus=1) as cluster:
        cluster.connect()
        training = chaos_training(cluster, settings, args.seed, Path(tmp) / "train")
        study = chaos_study(cluster, settings, args.seed, Path(tmp) / "chaos.db")
    results = checks(training, study, args.rss_bound_mib)
    print_report(training, study, results)
    report = {
        **header("chaos", "torch", "optuna"),
        "mode": "short" if args.short else "full",
        "seed": args.seed,
        "settings": settings.__dict__,
        "training": training,
        "study": study,
        "checks": results,
    }
    write_json(args.out, report)
    return 0 if all(results.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
