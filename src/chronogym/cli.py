"""The ``chronogym`` command line."""

from __future__ import annotations

import argparse
import hashlib
import os
import sys
import time
from collections.abc import Sequence

import numpy as np

DEMO_ENV = "chronogym/CartPole-v0"
DEFAULT_STORAGE = "sqlite:///chronogym-optuna.db"
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


CONTROL_PERIOD_S = 0.02  # the demo cart-pole's decision period (50 Hz) at any tick count


def compare_backends(args: argparse.Namespace, ticks: int, steps: int, progress: bool) -> tuple:
    """The demo workload (cart-poles at ``ticks`` physics ticks per step) on Ray and serially:
    (Ray stats, serial stats, workers, envs per worker, CPUs per worker, start-up seconds)."""
    from chronogym import RayVectorEnv, SerialVectorEnv

    env_kwargs = {"k": ticks, "dt": CONTROL_PERIOD_S / ticks}
    started = time.perf_counter()
    vec = RayVectorEnv(
        DEMO_ENV,
        args.num_envs,
        envs_per_worker=args.envs_per_worker,
        address=args.address,
        env_kwargs=env_kwargs,
    )
    layout = (vec.num_workers, vec.envs_per_worker, vec.num_cpus_per_worker)
    ready = time.perf_counter() - started
    try:
        ray_stats = run_episodes(vec, steps, args.seed, args.noise, progress=progress)
    finally:
        vec.close()
    serial = SerialVectorEnv(DEMO_ENV, args.num_envs, env_kwargs=env_kwargs)
    try:
        serial_stats = run_episodes(serial, steps, args.seed, args.noise, progress=False)
    finally:
        serial.close()
    return ray_stats, serial_stats, *layout, ready


def cmd_demo(args: argparse.Namespace) -> int:
    """Run the cart-pole on Ray workers and check the numbers against a serial run."""
    for flag, value, least in (("ticks", args.ticks, 1), ("cheap-ticks", args.cheap_ticks, 0)):
        if value < least:
            raise SystemExit(f"--{flag}={value}: expected an integer >= {least}")
    print(
        f"chronogym demo: {args.num_envs} x {DEMO_ENV} on Ray, {args.ticks} physics ticks "
        f"per step ({args.steps} vector steps, seed {args.seed})"
    )
    ray_stats, serial_stats, workers, per_worker, cpus, ready = compare_backends(
        args, args.ticks, args.steps, progress=True
    )
    print(
        f"  {workers} Ray workers x {per_worker} envs each, {cpus:g} CPU per worker "
        f"(ready in {ready:.1f} s)"
    )
    identical = ray_stats["trajectory_sha256"] == serial_stats["trajectory_sha256"]
    print(
        f"  episodes finished : {ray_stats['episodes']} "
        f"(mean return {ray_stats['mean_return']:.1f} of 500)"
    )
    ray_rate, serial_rate = ray_stats["env_steps_per_s"], serial_stats["env_steps_per_s"]
    print(f"  Ray throughput    : {ray_rate:,.0f} env-steps/s ({ray_rate / serial_rate:.2f}x)")
    print(f"  serial throughput : {serial_rate:,.0f} env-steps/s")
    verdict = "bit-identical" if identical else "DIFFERENT"
    print(
        f"  Ray vs serial     : {verdict} trajectories "
        f"(sha256 {ray_stats['trajectory_sha256'][:16]}...)"
    )
    if args.cheap_ticks:
        cheap_ray, cheap_serial, *_ = compare_backends(
            args, args.cheap_ticks, args.steps, progress=False
        )
        ratio = cheap_ray["env_steps_per_s"] / cheap_serial["env_steps_per_s"]
        side = "slower" if ratio < 1 else "faster"
        print(
            f"  cheap steps ({args.cheap_ticks} ticks, "
            f"{1e6 / cheap_serial['env_steps_per_s']:.0f} us each): Ray is {side} than "
            f"one process ({ratio:.2f}x): a remote step costs more than the physics it runs"
            + ("" if ratio < 1 else "; here it still paid")
        )
    return 0 if identical else 1


def cmd_optimize(args: argparse.Namespace) -> int:
    """Optimize the lander's absorbers with Optuna TPE, trials on parallel Ray workers."""
    import optuna

    from chronogym.optim import open_storage, run_parallel_study
    from chronogym.optim.lander import LanderObjective, describe_design, suggest_lander_design

    for name in ("workers", "trials"):
        if getattr(args, name) < 1:
            raise SystemExit(f"--{name}={getattr(args, name)}: expected an integer >= 1")
    try:  # engine checks (terrain of the engine, PyChrono installed) before Ray starts
        objective = LanderObjective(terrain=args.terrain, seed=args.seed, engine=args.engine)
    except (ValueError, ModuleNotFoundError) as exc:
        raise SystemExit(f"chronogym optimize lander: {exc}") from None
    engine_tag = "" if args.engine == "mujoco" else f"-{args.engine}"
    study_name = args.study or f"lander-{args.terrain}{engine_tag}"
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    sampler = optuna.samplers.TPESampler(
        seed=args.seed,
        multivariate=True,
        constant_liar=not args.no_constant_liar,
        n_startup_trials=args.startup_trials,
    )
    study = optuna.create_study(
        storage=open_storage(args.storage),
        study_name=study_name,
        direction="minimize",
        sampler=sampler,
        load_if_exists=True,
    )
    # studies from before --engine hold MuJoCo trials; a new study takes this run's engine
    study_engine = study.user_attrs.get("engine", "mujoco" if study.trials else args.engine)
    if study_engine != args.engine:
        raise SystemExit(
            f"chronogym optimize lander: study {study_name!r} holds {study_engine} trials; "
            f"--engine {args.engine} needs another --study"
        )
    study.set_user_attr("terrain", args.terrain)
    study.set_user_attr("engine", args.engine)
    print(
        f"chronogym optimize lander: study {study_name!r} in {args.storage} "
        f"({args.terrain} terrain, {args.engine}, {args.workers} parallel workers, "
        f"{args.trials} trials)"
    )
    if args.workers > (os.cpu_count() or 1):
        print(f"  note: {args.workers} workers on {os.cpu_count()} CPUs oversubscribe the machine")
    report = run_parallel_study(
        study,
        suggest_lander_design,
        objective,
        args.trials,
        workers=args.workers,
        backend=args.backend,
        address=args.address,
    )
    print(
        f"  this run: {report.completed} completed, {report.failed} failed, "
        f"{report.retried} retried, {report.recovered} recovered from a stopped run "
        f"in {report.elapsed:.1f} s"
    )
    if report.best_value is None:
        print("  no completed trial yet")
        return 1
    complete = [t for t in study.trials if t.state.name == "COMPLETE"]
    prior = [t.value for t in complete[: args.startup_trials]]
    print(f"  best trial #{report.best_number}: J = {report.best_value:.4f}")
    print(f"    design  : {describe_design(report.best_params)}")
    attrs = report.best_attrs
    print(
        f"    metrics : a_max = {attrs.get('a_max', float('nan')):.2f} m/s^2, "
        f"E_abs/E_init = {attrs.get('E_abs', 0) / max(attrs.get('E_init', 1), 1e-9):.3f}, "
        f"max stroke = {attrs.get('max_stroke', float('nan')):.3f} m, "
        f"bottomed out = {attrs.get('bottomed_out')}, tipped over = {attrs.get('tipped_over')}"
    )
    if prior:
        print(
            f"  median J of the {len(prior)} prior (random start-up) trials: "
            f"{float(np.median(prior)):.4f}"
        )
    print(f"  inspect the study: optuna-dashboard {args.storage}")
    return 0


def cmd_train(args: argparse.Namespace) -> int:
    """Train the Go1 velocity tracker with PPO (RSL-RL) on Ray workers or serially."""
    from chronogym.rl.quadruped import train_quadruped

    if args.num_envs < 1:
        raise SystemExit(f"--num-envs={args.num_envs}: expected an integer >= 1")
    if args.iterations is None and args.minutes is None:
        raise SystemExit("chronogym train: give --iterations I, --minutes M, or both")
    if args.iterations is not None and args.iterations < 1:
        raise SystemExit(f"--iterations={args.iterations}: expected an integer >= 1")
    if args.minutes is not None and not args.minutes > 0:
        raise SystemExit(f"--minutes={args.minutes}: expected a number > 0")
    if args.torch_threads < 1:
        raise SystemExit(f"--torch-threads={args.torch_threads}: expected an integer >= 1")
    if args.update_threads is not None and args.update_threads < 1:
        raise SystemExit(f"--update-threads={args.update_threads}: expected an integer >= 1")
    if args.update_threads is not None and args.policy_lag == 1:
        raise SystemExit(
            f"--update-threads={args.update_threads} with --policy-lag 1: the overlapped update "
            "runs on --torch-threads; leave --update-threads out"
        )
    if args.policy_lag not in (0, 1):
        raise SystemExit(
            f"--policy-lag={args.policy_lag}: expected 0 (synchronous PPO) or 1 (update "
            "overlapped with the next rollout)"
        )
    if args.resume is not None and not os.path.isfile(args.resume):
        raise SystemExit(f"--resume={args.resume}: no such checkpoint file")
    _check_quadruped_engine("train", args)
    print(
        f"chronogym train quadruped: {args.num_envs} envs on the {args.backend} backend, "
        f"{args.terrain} terrain, {args.engine}, writing to {args.out}"
        + (f", resuming {args.resume}" if args.resume else "")
    )
    result = train_quadruped(
        args.out,
        num_envs=args.num_envs,
        backend=args.backend,
        iterations=args.iterations,
        minutes=args.minutes,
        resume=args.resume,
        terrain=args.terrain,
        finetune=args.finetune,
        seed=args.seed,
        envs_per_worker=args.envs_per_worker,
        address=args.address,
        torch_threads=args.torch_threads,
        policy_lag=args.policy_lag,
        update_threads=args.update_threads,
        engine=args.engine,
    )
    row = result.last_row
    print(
        f"  iterations {result.iterations_done}, env steps {result.env_steps}, "
        f"wall time {result.wall_time:.1f} s"
    )
    print(
        f"  last iteration: mean reward {row.get('mean_reward', float('nan')):.3f}, "
        f"x-velocity MSE {row.get('x_mse', float('nan')):.4f}, "
        f"y-velocity MSE {row.get('y_mse', float('nan')):.4f}"
    )
    print(f"  checkpoint {result.checkpoint}; progress {result.csv_path}")
    print(f"  TensorBoard: tensorboard --logdir {args.out}")
    return 0


def cmd_play(args: argparse.Namespace) -> int:
    """Roll a trained policy out for a set of commands; print tracking errors, save a video."""
    from chronogym.rl.evaluate import format_summary
    from chronogym.rl.quadruped import play_quadruped

    if not os.path.isfile(args.checkpoint):
        raise SystemExit(f"checkpoint {args.checkpoint!r}: no such file")
    if args.episodes < 1:
        raise SystemExit(f"--episodes={args.episodes}: expected an integer >= 1")
    if args.steps is not None and args.steps < 1:
        raise SystemExit(f"--steps={args.steps}: expected an integer >= 1")
    if not args.video_seconds > 0:
        raise SystemExit(f"--video-seconds={args.video_seconds}: expected a number > 0")
    if args.video and os.path.splitext(args.video)[1].lower() not in (".mp4", ".gif", ".png"):
        raise SystemExit(f"--video={args.video}: expected a .mp4, .gif or .png path")
    _check_quadruped_engine("play", args)
    commands = [tuple(c) for c in args.command] if args.command else None
    rows = play_quadruped(
        args.checkpoint,
        commands=commands,
        episodes=args.episodes,
        seed=args.seed,
        video=args.video,
        terrain=args.terrain,
        max_episode_steps=args.steps,
        video_seconds=args.video_seconds,
        engine=args.engine,
    )
    print(format_summary(rows))
    if args.video:
        print(f"video: {args.video}")
    return 0


def _check_quadruped_engine(command: str, args: argparse.Namespace) -> None:
    """Engine and terrain checks (Chrono: PyChrono installed) before anything starts."""
    from chronogym.rl.quadruped import check_engine

    try:
        check_engine(args.engine, args.terrain)
    except (ValueError, ModuleNotFoundError) as exc:
        raise SystemExit(f"chronogym {command} quadruped: {exc}") from None


def cmd_envs(args: argparse.Namespace) -> int:
    """List the registered chronogym environment ids."""
    import gymnasium as gym

    import chronogym  # noqa: F401  (registers the ids)

    for env_id in sorted(i for i in gym.registry if i.startswith("chronogym/")):
        print(env_id)
    return 0


QUADRUPED_ENGINES = ["mujoco", "chrono"]
QUADRUPED_ENGINE_HELP = "physics engine (chrono: needs PyChrono; a MuJoCo checkpoint runs there)"
QUADRUPED_TERRAINS = ["rigid", "soil", "scm"]
QUADRUPED_TERRAIN_HELP = (
    "rigid ground; soil: chronogym's SCM (engine mujoco); scm: Chrono's SCMTerrain (engine chrono)"
)


def build_parser() -> argparse.ArgumentParser:
    from chronogym.optim.lander import ENGINES as LANDER_ENGINES
    from chronogym.optim.lander import TERRAINS as LANDER_TERRAINS

    parser = argparse.ArgumentParser(
        prog="chronogym",
        description="High-fidelity simulations as Gymnasium environments, in parallel on Ray.",
    )
    sub = parser.add_subparsers(dest="command", required=True)
    demo = sub.add_parser("demo", help="run a short parallel cart-pole demo on Ray")
    demo.add_argument("--num-envs", type=int, default=8)
    demo.add_argument("--envs-per-worker", type=int, default=None)
    demo.add_argument("--steps", type=int, default=1000)
    demo.add_argument(
        "--ticks", type=int, default=200, help="physics ticks per env step (20 ms of control)"
    )
    demo.add_argument(
        "--cheap-ticks",
        type=int,
        default=10,
        help="also time a cheap workload with this many ticks per step (0: skip)",
    )
    demo.add_argument("--seed", type=int, default=0)
    demo.add_argument("--noise", type=float, default=1.5, help="policy noise std")
    demo.add_argument("--address", default=None, help="Ray cluster address (default: local)")
    demo.set_defaults(func=cmd_demo)
    opt = sub.add_parser("optimize", help="parallel Bayesian optimization of a design")
    opt.add_argument("problem", choices=["lander"])
    opt.add_argument("--workers", type=int, default=2, help="trials evaluated in parallel")
    opt.add_argument("--trials", type=int, default=40, help="finished trials wanted in the study")
    opt.add_argument("--terrain", default="rigid", choices=list(LANDER_TERRAINS))
    opt.add_argument("--storage", default=DEFAULT_STORAGE, help="Optuna storage URL")
    opt.add_argument(
        "--engine",
        default="mujoco",
        choices=list(LANDER_ENGINES),
        help="physics engine (mujoco: rigid, rough, soil; chrono: rigid, scm; needs PyChrono)",
    )
    opt.add_argument(
        "--study", default=None, help="study name (default lander-TERRAIN, +-chrono for Chrono)"
    )
    opt.add_argument("--seed", type=int, default=0)
    opt.add_argument("--startup-trials", type=int, default=10, help="random trials before TPE")
    opt.add_argument("--no-constant-liar", action="store_true")
    opt.add_argument("--backend", default="ray", choices=["ray", "serial"])
    opt.add_argument("--address", default=None, help="Ray cluster address (default: local)")
    opt.set_defaults(func=cmd_optimize)
    tr = sub.add_parser("train", help="train a policy with PPO (RSL-RL) on parallel envs")
    tr.add_argument("problem", choices=["quadruped"])
    tr.add_argument("--num-envs", type=int, default=32)
    tr.add_argument("--backend", default="ray", choices=["ray", "serial"])
    tr.add_argument("--iterations", type=int, default=None, help="PPO iterations to run")
    tr.add_argument("--minutes", type=float, default=None, help="wall-clock budget")
    tr.add_argument("--out", default="runs/quadruped", help="logs, CSV and checkpoints")
    tr.add_argument("--resume", default=None, help="checkpoint to continue from")
    tr.add_argument(
        "--terrain", default="rigid", choices=QUADRUPED_TERRAINS, help=QUADRUPED_TERRAIN_HELP
    )
    tr.add_argument(
        "--engine", default="mujoco", choices=QUADRUPED_ENGINES, help=QUADRUPED_ENGINE_HELP
    )
    tr.add_argument("--finetune", action="store_true", help="conservative PPO (paper's transfer)")
    tr.add_argument("--seed", type=int, default=0)
    tr.add_argument("--envs-per-worker", type=int, default=None)
    tr.add_argument("--torch-threads", type=int, default=1, help="torch CPU threads (learner)")
    tr.add_argument("--address", default=None, help="Ray cluster address (default: local)")
    tr.add_argument(
        "--policy-lag",
        type=int,
        default=0,
        help="0 (default): synchronous PPO, the update on every core while the simulations "
        "wait; 1: run each update while the next rollout is collected, one update stale",
    )
    tr.add_argument(
        "--update-threads",
        type=int,
        default=None,
        help="torch threads of the synchronous update (default: this machine's CPUs, at most 8)",
    )
    tr.set_defaults(func=cmd_train)
    play = sub.add_parser("play", help="roll out a trained policy, print errors, save a video")
    play.add_argument("problem", choices=["quadruped"])
    play.add_argument("checkpoint")
    play.add_argument(
        "--video", default=None, help="MP4 to write (.gif: an animation, .png: a film strip)"
    )
    play.add_argument(
        "--video-seconds", type=float, default=5.0, help="seconds recorded per command"
    )
    play.add_argument("--episodes", type=int, default=1, help="episodes per command")
    play.add_argument(
        "--command",
        nargs=3,
        type=float,
        action="append",
        metavar=("VX", "VY", "WZ"),
        help="a command to evaluate (repeatable; default: a standard set)",
    )
    play.add_argument("--steps", type=int, default=None, help="episode length in steps")
    play.add_argument(
        "--terrain", default="rigid", choices=QUADRUPED_TERRAINS, help=QUADRUPED_TERRAIN_HELP
    )
    play.add_argument(
        "--engine", default="mujoco", choices=QUADRUPED_ENGINES, help=QUADRUPED_ENGINE_HELP
    )
    play.add_argument("--seed", type=int, default=0)
    play.set_defaults(func=cmd_play)
    envs = sub.add_parser("envs", help="list registered environment ids")
    envs.set_defaults(func=cmd_envs)
    return parser


def main(argv: Sequence[str] | None = None) -> int:
    args = build_parser().parse_args(argv)
    steps = getattr(args, "steps", None)
    if steps is not None and steps < 1:
        raise SystemExit(f"--steps={args.steps}: expected an integer >= 1")
    return args.func(args)


if __name__ == "__main__":
    raise SystemExit(main())
