"""Where one PPO iteration's time goes on Go1: the driver, the simulations and the update.

Each configuration runs in its own subprocess (its own local Ray for the Ray backend) the
synchronous (``policy_lag=0``) loop of ``chronogym.rl.trainer.train`` with every phase timed:

- ``act``: the policy's forward pass, sampling and the transition it stores (driver);
- ``vec step``: the vector env's barrier ``step``; for Ray split into ``compute`` (the
  slowest worker's time in its envs' ``step``, the critical path) and ``transport`` (the rest:
  sending actions, waking workers, gathering results);
- ``adapter``: the NumPy <-> torch conversion of ``RslRlVecEnv.step`` around it;
- ``storage``: RSL-RL's ``process_env_step`` and the episode logger;
- ``update``: returns and the PPO update (on ``train_quadruped``'s update threads).

``workers busy`` is the share of the iteration in which the Ray workers step simulations
(their summed compute over workers x iteration time); the rest they wait for the driver.
Prints a table (ms per iteration, medians over the iterations after ``--warmup``) and writes
``results/train_breakdown.json``.

    python -m benchmarks.rl.train_breakdown                       # ray:32:0 and serial:32:0
    python -m benchmarks.rl.train_breakdown --configs ray:16:0 ray:64:0:24 --iterations 20
    python -m benchmarks.rl.train_breakdown --configs ray:32:0 ray:32:0+dw serial:32:0

Configurations are ``train_throughput.py``'s, synchronous only (policy lag 0); a ``+dw`` suffix
on a Ray configuration sets ``RayVectorEnv(driver_worker=True)``.
"""

from __future__ import annotations

import argparse
import contextlib
import io
import json
import statistics
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

from benchmarks.common import RESULTS, Column, child_env, header, settings, table, write_json
from benchmarks.rl.train_throughput import TrainConfig, parse_config

DEFAULT_CONFIGS = ("ray:32:0", "serial:32:0")
DRIVER_WORKER = "+dw"  # config suffix: the driver steps one worker's envs (Ray only)


def parse(text: str) -> tuple[TrainConfig, bool]:
    """A configuration and whether it asks for ``driver_worker=True``."""
    driver_worker = text.endswith(DRIVER_WORKER)
    config = parse_config(text.removesuffix(DRIVER_WORKER))
    if driver_worker and config.backend != "ray":
        raise argparse.ArgumentTypeError(f"config {text!r}: {DRIVER_WORKER} needs the Ray backend")
    return config, driver_worker


OUT = RESULTS / "train_breakdown.json"
PHASES = ("act", "vec_step", "compute", "transport", "adapter", "storage", "update", "other")


class TimedVecEnv:
    """A vector env whose ``step`` wall time is summed into ``step_s`` (all else forwarded)."""

    def __init__(self, vec_env: Any) -> None:
        self.vec_env = vec_env
        self.step_s = 0.0

    def __getattr__(self, name: str) -> Any:
        return getattr(self.vec_env, name)

    def step(self, actions: Any) -> Any:
        start = time.perf_counter()
        out = self.vec_env.step(actions)
        self.step_s += time.perf_counter() - start
        return out


def measure(
    config: TrainConfig, iterations: int, warmup: int, driver_worker: bool = False
) -> list[dict[str, float]]:
    """Run ``iterations`` timed PPO iterations of ``config``; seconds per phase, per iteration."""
    import torch
    from rsl_rl.runners import OnPolicyRunner

    from chronogym.rl.vecenv import RslRlVecEnv
    from chronogym.tasks.quadruped.training import (
        default_update_threads,
        make_quadruped_vec_env,
        quadruped_train_config,
    )

    extra = {"driver_worker": True} if driver_worker else {}
    vec = make_quadruped_vec_env(
        config.num_envs, config.backend, task_kwargs=config.task_kwargs(), **extra
    )
    timed = TimedVecEnv(vec)
    env = RslRlVecEnv(timed, seed=0)
    cfg = quadruped_train_config(**({"num_steps_per_env": config.steps} if config.steps else {}))
    with contextlib.redirect_stdout(io.StringIO()):
        runner = OnPolicyRunner(env, cfg, log_dir=None, device="cpu")
    update_threads = config.update_threads or default_update_threads()
    alg, logger = runner.alg, runner.logger
    torch.set_num_threads(1)
    torch.manual_seed(0)
    alg.train_mode()
    obs = env.get_observations()
    workers = getattr(vec, "num_workers", 1)
    rows = []
    try:
        for it in range(iterations):
            profile = vec.profile_steps() if config.backend == "ray" else None
            timed.step_s = 0.0
            act = env_s = storage = 0.0
            start = time.perf_counter()
            with torch.inference_mode():
                for _ in range(int(cfg["num_steps_per_env"])):
                    t0 = time.perf_counter()
                    actions = alg.act(obs)
                    t1 = time.perf_counter()
                    obs, rewards, dones, extras = env.step(actions)
                    t2 = time.perf_counter()
                    alg.process_env_step(obs, rewards, dones, extras)
                    logger.process_env_step(rewards, dones, extras, None)
                    t3 = time.perf_counter()
                    act, env_s, storage = act + t1 - t0, env_s + t2 - t1, storage + t3 - t2
                t4 = time.perf_counter()
                alg.compute_returns(obs)
            torch.set_num_threads(update_threads)
            alg.update()
            torch.set_num_threads(1)
            end = time.perf_counter()
            row = {
                "iteration": end - start,
                "act": act,
                "vec_step": timed.step_s,
                "adapter": env_s - timed.step_s,
                "storage": storage,
                "update": end - t4,
            }
            row["other"] = row["iteration"] - sum(row[k] for k in PHASES if k in row)
            if profile is not None and profile.steps:
                row["compute"] = profile.compute
                row["transport"] = timed.step_s - profile.compute
                row["workers_busy"] = profile.compute_sum / (workers * row["iteration"])
            if it >= warmup:
                rows.append(row)
    finally:
        if config.backend == "ray":
            vec.profile_steps(False)
        env.close()
    return rows


def run_config(text: str, iterations: int, warmup: int) -> dict[str, Any]:
    """Measure one configuration in a subprocess; medians (ms) of its phases."""
    done = subprocess.run(
        [sys.executable, "-m", "benchmarks.rl.train_breakdown", "--one", text,
         "--iterations", str(iterations), "--warmup", str(warmup)],
        capture_output=True, text=True, check=False, env=child_env(),
    )  # fmt: skip
    if done.returncode != 0:
        raise RuntimeError(f"{text} failed:\n{done.stderr[-3000:]}")
    rows = json.loads(done.stdout.strip().splitlines()[-1])
    config, _ = parse(text)
    samples = (config.steps or 48) * config.num_envs
    summary: dict[str, Any] = {"config": text}
    for key in ("iteration", *PHASES):
        values = [row[key] for row in rows if key in row]
        summary[f"{key}_ms"] = statistics.median(values) * 1e3 if values else None
    busy = [row["workers_busy"] for row in rows if "workers_busy" in row]
    summary["workers_busy"] = statistics.median(busy) if busy else None
    summary["env_steps_per_s"] = samples / (summary["iteration_ms"] / 1e3)
    summary["iterations"] = rows
    return summary


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--configs", nargs="+", default=list(DEFAULT_CONFIGS))
    parser.add_argument("--iterations", type=int, default=25)
    parser.add_argument("--warmup", type=int, default=5, help="iterations left out")
    parser.add_argument("--out", type=Path, default=OUT)
    parser.add_argument("--one", help=argparse.SUPPRESS)  # subprocess mode: one config
    args = parser.parse_args(argv)
    if args.iterations < args.warmup + 1:
        parser.error(f"--iterations={args.iterations}: expected >= --warmup + 1")
    if args.one is not None:
        config, driver_worker = parse(args.one)
        print(json.dumps(measure(config, args.iterations, args.warmup, driver_worker)))
        return
    for text in args.configs:
        try:
            config, _ = parse(text)
        except argparse.ArgumentTypeError as error:
            parser.error(str(error))
        if config.policy_lag != 0:
            parser.error(f"config {text!r}: expected policy lag 0 (the synchronous loop)")
    summaries = []
    for text in args.configs:
        summaries.append(run_config(text, args.iterations, args.warmup))
        print(f"{text}: {summaries[-1]['env_steps_per_s']:,.0f} env-steps/s", flush=True)
    columns = [
        Column("config", 18, align="<", key="config"),
        Column("steps/s", 7, "{:,.0f}", key="env_steps_per_s"),
        Column("iter", 5, "{:.0f}", key="iteration_ms"),
        Column("act", 4, "{:.0f}", key="act_ms"),
        Column("vec step", 8, "{:.0f}", key="vec_step_ms"),
        Column("compute", 7, "{:.0f}", key="compute_ms"),
        Column("transport", 9, "{:.0f}", key="transport_ms"),
        Column("adapter", 7, "{:.0f}", key="adapter_ms"),
        Column("storage", 7, "{:.0f}", key="storage_ms"),
        Column("update", 6, "{:.0f}", key="update_ms"),
        Column("other", 5, "{:.0f}", key="other_ms"),
        Column("workers busy", 12, "{:.0%}", key="workers_busy"),
    ]
    print("\nms per PPO iteration (medians)")
    print(table(columns, summaries, rule=True))
    record = {**header("train_breakdown", "torch", "rsl-rl-lib"), "settings": settings(args)}
    write_json(args.out, {**record, "rows": summaries})


if __name__ == "__main__":
    main()
