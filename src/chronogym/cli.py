"""The ``chronogym`` command line."""

from __future__ import annotations

import argparse
import hashlib
import sys
import time
from collections.abc import Sequence

import numpy as np

DEMO_ENV = "chronogym/CartPole-v0"
BALANCE_GAINS = np.array([0.5, 10.0, 1.0, 1.5])  # on (x, angle, x velocity, angular velocity)


def balance_policy(obs: np.ndarray, rng: np.random.Generator, noise: float) -> np.ndarray:
    """A linear balancing controller for the cart-pole plus seeded exploration noise."""
    action = obs @ BALANCE_GAINS + rng.normal(0.0, noise, size=len(obs))
    return np.clip(action, -1.0, 1.0).astype(np.float32)[:, None]


def run_episodes(vec, steps: int, seed: int, noise: float, progress: bool) -> dict[str, float]:
    """Step ``vec`` with the balancing policy; return episode statistics and timing."""
    from tqdm import tqdm

    rng = np.random.default_rng(seed)
    obs, _ = vec.reset(seed=seed)
    digest = hashlib.sha256(obs.tobytes())
    returns = np.zeros(vec.num_envs)
    finished: list[float] = []
    start = time.perf_counter()
    for _ in tqdm(range(steps), desc="vector steps", disable=not progress, file=sys.stderr):
        obs, rewards, terminated, truncated, _ = vec.step(balance_policy(obs, rng, noise))
        returns += rewards
        for array in (obs, rewards, terminated, truncated):
            digest.update(array.tobytes())
        for i in np.flatnonzero(terminated | truncated):
            finished.append(returns[i])
            returns[i] = 0.0
    elapsed = time.perf_counter() - start
    return {
        "episodes": len(finished),
        "mean_return": float(np.mean(finished)) if finished else 0.0,
        "env_steps_per_s": steps * vec.num_envs / elapsed,
        "trajectory_sha256": digest.hexdigest(),
    }


def cmd_demo(args: argparse.Namespace) -> int:
    """Run the cart-pole on Ray workers and check the numbers against a serial run."""
    from chronogym import RayVectorEnv, SerialVectorEnv

    print(
        f"chronogym demo: {args.num_envs} x {DEMO_ENV} on Ray "
        f"({args.steps} vector steps, seed {args.seed})"
    )
    started = time.perf_counter()
    vec = RayVectorEnv(
        DEMO_ENV, args.num_envs, envs_per_worker=args.envs_per_worker, address=args.address
    )
    print(
        f"  {vec.num_workers} Ray workers x {vec.envs_per_worker} envs each, "
        f"{vec.num_cpus_per_worker:g} CPU per worker (ready in "
        f"{time.perf_counter() - started:.1f} s)"
    )
    try:
        ray_stats = run_episodes(vec, args.steps, args.seed, args.noise, progress=True)
    finally:
        vec.close()
    serial = SerialVectorEnv(DEMO_ENV, args.num_envs)
    serial_stats = run_episodes(serial, args.steps, args.seed, args.noise, progress=False)
    serial.close()
    identical = ray_stats["trajectory_sha256"] == serial_stats["trajectory_sha256"]
    print(
        f"  episodes finished : {ray_stats['episodes']} "
        f"(mean return {ray_stats['mean_return']:.1f} of 500)"
    )
    print(f"  Ray throughput    : {ray_stats['env_steps_per_s']:,.0f} env-steps/s")
    print(f"  serial throughput : {serial_stats['env_steps_per_s']:,.0f} env-steps/s")
    verdict = "bit-identical" if identical else "DIFFERENT"
    print(
        f"  Ray vs serial     : {verdict} trajectories "
        f"(sha256 {ray_stats['trajectory_sha256'][:16]}...)"
    )
    return 0 if identical else 1


def cmd_envs(args: argparse.Namespace) -> int:
    """List the registered chronogym environment ids."""
    import gymnasium as gym

    import chronogym  # noqa: F401  (registers the ids)

    for env_id in sorted(i for i in gym.registry if i.startswith("chronogym/")):
        print(env_id)
    return 0


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="chronogym",
        description="High-fidelity simulations as Gymnasium environments, in parallel on Ray.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="run a short parallel cart-pole demo on Ray")
    demo.add_argument("--num-envs", type=int, default=8)
    demo.add_argument("--envs-per-worker", type=int, default=None)
    demo.add_argument("--steps", type=int, default=1000)
    demo.add_argument("--seed", type=int, default=0)
    demo.add_argument("--noise", type=float, default=1.5, help="policy noise std")
    demo.add_argument("--address", default=None, help="Ray cluster address (default: local)")
    demo.set_defaults(func=cmd_demo)
    envs = sub.add_parser("envs", help="list registered environment ids")
    envs.set_defaults(func=cmd_envs)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    if getattr(args, "steps", 1) < 1:
        raise SystemExit(f"--steps={args.steps}: expected an integer >= 1")
    return args.func(args)


if __name__ == "__main__":
    raise SystemExit(main())
