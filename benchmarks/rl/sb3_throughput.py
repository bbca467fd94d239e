"""SB3 PPO ``learn()`` on HalfCheetah-v5: DummyVecEnv, SubprocVecEnv and RayVecEnv side by side.

Each backend builds its vector env with SB3's ``make_vec_env(..., vec_env_cls=...)`` (so every
env is in SB3's ``Monitor``), then trains PPO from scratch for ``--steps`` env steps, in its own
subprocess (RayVecEnv starts its own local Ray there); the backends alternate round by round,
so machine noise falls on all of them. Reported per backend (medians over the rounds):

- env-steps/s of ``learn()`` and its wall-clock (building the vector env is apart:
  ``build s``);
- where the time goes: ``collect s`` (SB3's ``collect_rollouts``: from each rollout's start
  to its end), split into ``env s`` (``vec_env.step``, timed by a thin ``VecEnvWrapper``
  under PPO) and ``policy s`` (the rest: the policy's forward pass, the rollout buffer,
  callbacks); ``update s`` is everything else in ``learn()`` (SB3's ``train()``: the
  gradient epochs, plus logging);
- ``env us``: microseconds per ``vec_env.step`` of all envs.

PPO settings are SB3's defaults except ``n_steps`` (``--n-steps`` per env and rollout); torch
uses one thread (``torch.set_num_threads(1)``), as chronogym's training does on small machines.

    python -m benchmarks.rl.sb3_throughput               # 3 rounds of 32,768 steps per backend
    python -m benchmarks.rl.sb3_throughput --quick       # smoke run (JSON to a temporary file)
    python -m benchmarks.rl.sb3_throughput --backends subproc ray --rounds 5
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

from benchmarks.common import RESULTS, Column, child_env, header, settings, table, write_json

BACKENDS = ("dummy", "subproc", "ray")
ENV_ID = "HalfCheetah-v5"
OUT = RESULTS / "sb3_throughput.json"

# Runs in the subprocess: one PPO learn() with the timing wrapper and callback, as JSON.
CHILD = r"""
import json, sys
from benchmarks.rl import sb3_throughput
print(json.dumps(sb3_throughput.train_once(**json.loads(sys.argv[1]))))
"""


def train_once(
    backend: str,
    num_envs: int,
    steps: int,
    n_steps: int,
    seed: int,
    envs_per_worker: int | None,
) -> dict[str, float]:
    """Build ``num_envs`` HalfCheetah envs with ``backend`` and time one PPO ``learn(steps)``."""
    import torch
    from stable_baselines3 import PPO
    from stable_baselines3.common.callbacks import BaseCallback
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv, SubprocVecEnv, VecEnvWrapper

    from chronogym.integrations.sb3 import RayVecEnv

    torch.set_num_threads(1)

    class StepTimer(VecEnvWrapper):
        """Adds up the seconds spent in the wrapped env's ``step`` (async + wait)."""

        def __init__(self, venv: Any) -> None:
            super().__init__(venv)
            self.step_s, self.steps, self._start = 0.0, 0, 0.0

        def reset(self) -> Any:
            return self.venv.reset()

        def step_async(self, actions: Any) -> None:
            self._start = time.perf_counter()
            self.venv.step_async(actions)

        def step_wait(self) -> Any:
            out = self.venv.step_wait()
            self.step_s += time.perf_counter() - self._start
            self.steps += 1
            return out

    class RolloutTimer(BaseCallback):
        """Adds up the seconds from each rollout's start to its end (``collect_rollouts``)."""

        def __init__(self) -> None:
            super().__init__()
            self.collect_s, self._start = 0.0, 0.0

        def _on_rollout_start(self) -> None:
            self._start = time.perf_counter()

        def _on_rollout_end(self) -> None:
            self.collect_s += time.perf_counter() - self._start

        def _on_step(self) -> bool:
            return True

    classes = {"dummy": DummyVecEnv, "subproc": SubprocVecEnv, "ray": RayVecEnv}
    use_workers = backend == "ray" and envs_per_worker is not None
    vec_env_kwargs = {"envs_per_worker": envs_per_worker} if use_workers else {}
    start = time.perf_counter()
    venv = make_vec_env(
        ENV_ID,
        n_envs=num_envs,
        seed=seed,
        vec_env_cls=classes[backend],
        vec_env_kwargs=vec_env_kwargs,
    )
    build_s = time.perf_counter() - start
    timer, rollouts = StepTimer(venv), RolloutTimer()
    try:
        model = PPO("MlpPolicy", timer, n_steps=n_steps, seed=seed, device="cpu")
        start = time.perf_counter()
        model.learn(steps, callback=rollouts)
        learn_s = time.perf_counter() - start
    finally:
        venv.close()
    done = int(model.num_timesteps)
    return {
        "env_steps": done,
        "learn_s": learn_s,
        "env_steps_per_s": done / learn_s,
        "build_s": build_s,
        "collect_s": rollouts.collect_s,
        "env_s": timer.step_s,
        "policy_s": rollouts.collect_s - timer.step_s,
        "update_s": learn_s - rollouts.collect_s,
        "env_us": 1e6 * timer.step_s / max(timer.steps, 1),
    }


def run_once(backend: str, args: argparse.Namespace) -> dict[str, float]:
    """``train_once`` for ``backend`` in a fresh Python process."""
    kwargs = {
        "backend": backend,
        "num_envs": args.num_envs,
        "steps": args.steps,
        "n_steps": args.n_steps,
        "seed": args.seed,
        "envs_per_worker": args.envs_per_worker,
    }
    done = subprocess.run(
        [sys.executable, "-c", CHILD, json.dumps(kwargs)],
        capture_output=True,
        text=True,
        check=False,
        env=child_env(),
    )
    if done.returncode != 0:
        raise RuntimeError(f"{backend} failed:\n{done.stderr[-3000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def parse_args(argv: list[str] | None) -> argparse.Namespace:
    """Command-line options; ``--quick`` shrinks the run to a smoke test."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--backends", nargs="+", choices=BACKENDS, default=list(BACKENDS))
    parser.add_argument("--num-envs", type=int, default=8)
    parser.add_argument("--steps", type=int, default=32_768, help="env steps per learn()")
    parser.add_argument("--n-steps", type=int, default=256, help="PPO steps per env and rollout")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument(
        "--envs-per-worker", type=int, default=None, help="RayVecEnv (default: spread on CPUs)"
    )
    parser.add_argument("--out", type=Path, default=None, help=f"JSON path (default {OUT})")
    parser.add_argument("--quick", action="store_true", help="smoke run: 2,048 steps, 1 round")
    args = parser.parse_args(argv)
    if args.quick:
        args.steps, args.n_steps, args.rounds = 2_048, 64, 1
        if args.out is None:
            args.out = Path(tempfile.gettempdir()) / "sb3_throughput_quick.json"
    if args.out is None:
        args.out = OUT
    if min(args.num_envs, args.steps, args.n_steps, args.rounds) < 1:
        parser.error(
            f"--num-envs={args.num_envs} --steps={args.steps} --n-steps={args.n_steps} "
            f"--rounds={args.rounds}: expected integers >= 1"
        )
    return args


COLUMNS = [
    Column("backend", 8, align="<", key="backend"),
    Column("env-steps/s", 11, "{:,.0f}", key="env_steps_per_s"),
    Column("x subproc", 9, "{:.2f}", key="vs_subproc"),
    Column("learn s", 7, "{:.1f}", key="learn_s"),
    Column("collect s", 9, "{:.1f}", key="collect_s"),
    Column("env s", 6, "{:.1f}", key="env_s"),
    Column("policy s", 8, "{:.1f}", key="policy_s"),
    Column("update s", 8, "{:.1f}", key="update_s"),
    Column("env us", 7, "{:,.0f}", key="env_us"),
    Column("build s", 7, "{:.1f}", key="build_s"),
]


def main(argv: list[str] | None = None) -> int:
    """Run every backend ``--rounds`` times, print the table, write the JSON."""
    args = parse_args(argv)
    wall = time.perf_counter()
    runs: dict[str, list[dict[str, float]]] = {b: [] for b in args.backends}
    for r in range(args.rounds):
        order = args.backends if r % 2 == 0 else list(reversed(args.backends))
        for backend in order:
            runs[backend].append(run_once(backend, args))
            last = runs[backend][-1]
            print(
                f"round {r + 1}/{args.rounds} {backend}: {last['env_steps_per_s']:,.0f} "
                f"env-steps/s ({last['learn_s']:.1f} s)",
                flush=True,
            )
    rows = []
    for backend, samples in runs.items():
        med = {k: statistics.median(x[k] for x in samples) for k in samples[0]}
        rows.append({"backend": backend, **med, "rounds": samples})
    base = next((row for row in rows if row["backend"] == "subproc"), None)
    for row in rows:
        row["vs_subproc"] = row["env_steps_per_s"] / base["env_steps_per_s"] if base else None
    print()
    print(
        f"SB3 PPO learn() on {ENV_ID}, {args.num_envs} envs, {rows[0]['env_steps']:,} env "
        f"steps, n_steps={args.n_steps}; medians of {args.rounds} round(s)"
    )
    print(table(COLUMNS, rows, rule=True))
    record = {
        **header("sb3_throughput", "torch", "stable-baselines3"),
        "settings": settings(args),
        "env_id": ENV_ID,
        "rows": rows,
    }
    write_json(args.out, record, f" ({time.perf_counter() - wall:.0f} s in all)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
