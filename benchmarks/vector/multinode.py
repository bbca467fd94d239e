"""RayVectorEnv on one Ray node vs a 3-node loopback cluster, and the equality checks.

Both clusters are started with ``chronogym.testing.LocalCluster`` (``ray start``
subprocesses) with the same total CPUs: one node with 3 CPUs, or a head and two
worker nodes with 1 CPU each. On them it times Go1 env-steps/s of RayVectorEnv
(3 workers, one per CPU) and checks that

* the trajectories of a seeded rollout are bit-identical to SerialVectorEnv's;
* ``train_quadruped`` (2 short PPO iterations) gives the same progress.csv and the
  same policy weights as the serial backend (3-node cluster only);
* a 6-trial lander study with 2 spread workers gives the same trials (design,
  J) as a serial study with the same sampler seed (3-node cluster only).

All nodes share this machine's cores: this measures the overhead of crossing
raylets (object transfers between nodes' stores, remote scheduling), not a
speed-up.

    python -m benchmarks.vector.multinode [--quick] [--steps 400] [--out PATH]

Prints a table and writes ``benchmarks/results/multinode.json``.
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import RESULTS, header, write_json
from chronogym.optim.lander import LanderObjective, suggest_lander_design
from chronogym.testing import LocalCluster

DEFAULT_OUT = RESULTS / "multinode.json"
GO1 = "chronogym/Go1Velocity-v0"
NUM_ENVS = 6
ENVS_PER_WORKER = 2


def rollout(vec: Any, steps: int, seed: int = 5) -> tuple[str, float]:
    """sha256 of every array of a seeded random-action rollout, and env-steps/s."""
    obs, _ = vec.reset(seed=seed)
    rng = np.random.default_rng(seed)
    digest = hashlib.sha256(obs.tobytes())
    for _ in range(10):  # warm-up, hashed as well
        obs, *rest, _ = vec.step(rng.uniform(-1, 1, (vec.num_envs, 12)).astype(np.float32))
        for array in (obs, *rest):
            digest.update(array.tobytes())
    start = time.perf_counter()
    for _ in range(steps):
        obs, *rest, _ = vec.step(rng.uniform(-1, 1, (vec.num_envs, 12)).astype(np.float32))
        for array in (obs, *rest):
            digest.update(array.tobytes())
    return digest.hexdigest(), steps * vec.num_envs / (time.perf_counter() - start)


def serial_reference(steps: int) -> tuple[str, float]:
    from chronogym.vector.serial import SerialVectorEnv

    vec = SerialVectorEnv(GO1, NUM_ENVS)
    try:
        return rollout(vec, steps)
    finally:
        vec.close()


def ray_rollout(cluster: Any, steps: int) -> dict[str, Any]:
    """Throughput and digest of RayVectorEnv (3 workers x 1 CPU, spread) on ``cluster``."""
    from chronogym.vector.ray_vector_env import RayVectorEnv

    vec = RayVectorEnv(
        GO1,
        NUM_ENVS,
        envs_per_worker=ENVS_PER_WORKER,
        num_cpus=1,
        address=cluster.address,
        scheduling="spread",
    )
    try:
        nodes = [cluster.node_of_pid(pid) for pid in vec.worker_pids()]
        digest, rate = rollout(vec, steps)
    finally:
        vec.close()
    return {"worker_nodes": nodes, "sha256": digest, "env_steps_per_s": rate}


def train_check(address: str, out: Path) -> dict[str, Any]:
    """train_quadruped for 2 iterations on the cluster and serially: same numbers?"""
    import torch

    from chronogym.tasks.quadruped.training import quadruped_train_config, train_quadruped

    results = {}
    for backend, addr in (("ray", address), ("serial", None)):
        cfg = quadruped_train_config(num_steps_per_env=16, save_interval=100)
        result = train_quadruped(
            out / backend,
            num_envs=4,
            backend=backend,
            iterations=2,
            seed=3,
            address=addr,
            train_cfg=cfg,
            progress=False,
        )
        with open(result.csv_path) as handle:
            rows = [
                {k: v for k, v in row.items() if k not in ("wall_time", "collect_s", "learn_s")}
                for row in csv.DictReader(handle)
            ]
        actor = torch.load(result.checkpoint, map_location="cpu", weights_only=True)
        results[backend] = (rows, actor["actor_state_dict"])
    (ray_rows, ray_actor), (serial_rows, serial_actor) = results["ray"], results["serial"]
    same_weights = all(torch.equal(ray_actor[k], serial_actor[k]) for k in serial_actor)
    return {
        "progress_rows_equal": ray_rows == serial_rows,
        "policy_weights_equal": same_weights,
        "env_steps": [int(r["env_steps"]) for r in ray_rows],
    }


def lander_check(address: str, out: Path) -> dict[str, Any]:
    """6 lander trials on 2 spread Ray workers vs serially, same sampler seed."""
    import optuna

    from chronogym.optim import open_storage, run_parallel_study

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    trials = {}
    for name, workers, backend in (("cluster", 2, "ray"), ("serial", 1, "serial")):
        sampler = optuna.samplers.TPESampler(seed=7, n_startup_trials=6, constant_liar=True)
        study = optuna.create_study(
            storage=open_storage(f"sqlite:///{out}/{name}.db"), study_name=name, sampler=sampler
        )
        run_parallel_study(
            study,
            suggest_lander_design,
            LanderObjective("rigid", seed=0),
            6,
            workers=workers,
            backend=backend,
            address=address if backend == "ray" else None,
            scheduling="spread" if backend == "ray" else "default",
            progress=False,
        )
        trials[name] = {t.number: (t.params, t.value, t.state.name) for t in study.trials}
    return {
        "trials": len(trials["cluster"]),
        "complete": sum(s == "COMPLETE" for _, _, s in trials["cluster"].values()),
        "trials_equal": trials["cluster"] == trials["serial"],
        "values": [trials["cluster"][n][1] for n in sorted(trials["cluster"])],
    }


def run_cluster(label: str, workers: int, head_cpus: int, steps: int, checks: bool) -> dict:
    started = time.perf_counter()
    with LocalCluster(workers=workers, num_cpus=1, head_cpus=head_cpus) as cluster:
        start_s = time.perf_counter() - started
        cluster.connect()
        row: dict[str, Any] = {"cluster": label, "nodes": workers + 1, "start_s": start_s}
        row.update(ray_rollout(cluster, steps))
        if checks:
            with tempfile.TemporaryDirectory() as tmp:
                row["train"] = train_check(cluster.address, Path(tmp))
                row["lander"] = lander_check(cluster.address, Path(tmp))
    return row


def print_table(rows: list[dict], serial: dict) -> None:
    print(f"{'run':<22}{'nodes':>6}{'start s':>9}{'steps/s':>10}  worker nodes / checks")
    print(f"{'serial (no Ray)':<22}{'-':>6}{'-':>9}{serial['env_steps_per_s']:>10.0f}")
    for row in rows:
        same = "bit-identical" if row["sha256"] == serial["sha256"] else "DIFFERENT"
        print(
            f"{row['cluster']:<22}{row['nodes']:>6}{row['start_s']:>9.1f}"
            f"{row['env_steps_per_s']:>10.0f}  {row['worker_nodes']} {same} to serial"
        )
        if "train" in row:
            t, lander = row["train"], row["lander"]
            print(
                f"{'':<47}train_quadruped: csv equal {t['progress_rows_equal']}, weights "
                f"equal {t['policy_weights_equal']}; lander: {lander['complete']}/"
                f"{lander['trials']} complete, trials equal {lander['trials_equal']}"
            )


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--steps", type=int, default=400, help="timed vector steps")
    parser.add_argument("--quick", action="store_true", help="100 steps (smoke run)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args()
    steps = 100 if args.quick else args.steps
    serial_sha, serial_rate = serial_reference(steps)
    serial = {"sha256": serial_sha, "env_steps_per_s": serial_rate}
    rows = [
        run_cluster("1 node x 3 CPUs", 0, 3, steps, checks=False),
        run_cluster("3 nodes x 1 CPU", 2, 1, steps, checks=True),
    ]
    print_table(rows, serial)
    for row in rows:
        row["identical_to_serial"] = row["sha256"] == serial_sha
    report = {
        **header("multinode", "torch", "optuna"),
        "env": GO1,
        "num_envs": NUM_ENVS,
        "envs_per_worker": ENVS_PER_WORKER,
        "timed_steps": steps,
        "serial": serial,
        "results": rows,
        "note": "all nodes share one machine: overhead of crossing raylets, not a speed-up",
    }
    write_json(args.out, report)


if __name__ == "__main__":
    main()
