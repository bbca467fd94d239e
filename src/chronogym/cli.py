"""The ``chronogym`` command line: ``demo``, ``optimize``, ``train``, ``play``, ``envs`` and
``bench``.

Its options are in :mod:`chronogym.cli_parser`; how it reports errors (a line for bad input,
a traceback for a bug) is in :mod:`chronogym.cli_errors`.
"""

from __future__ import annotations

import argparse
import hashlib
import math
import os
import sys
import time
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from tqdm import tqdm

import chronogym  # noqa: F401  (registers the ids, picks a headless GL backend)
from chronogym.cli_errors import UsageError, first_line, run_command
from chronogym.cli_parser import build_parser
from chronogym.optim import open_storage, run_parallel_study
from chronogym.optim.lander import LanderObjective, describe_design, suggest_lander_design
from chronogym.rl.checkpoint import read_checkpoint
from chronogym.tasks.quadruped.engines import check_engine
from chronogym.tasks.quadruped.evaluation import format_summary
from chronogym.tasks.quadruped.play import check_can_render, play_quadruped
from chronogym.tasks.quadruped.play import play_randomization as quadruped_randomization
from chronogym.tasks.quadruped.training import train_quadruped
from chronogym.vector.ray_vector_env import RayVectorEnv
from chronogym.vector.serial import SerialVectorEnv

DEMO_ENV = "chronogym/CartPole-v0"
BALANCE_GAINS = np.array([0.5, 10.0, 1.0, 1.5])  # on (x, angle, x velocity, angular velocity)


def balance_policy(obs: np.ndarray, rng: np.random.Generator, noise: float) -> np.ndarray:
    """A linear balancing controller for the cart-pole plus seeded exploration noise."""
    action = obs @ BALANCE_GAINS + rng.normal(0.0, noise, size=len(obs))
    return np.clip(action, -1.0, 1.0).astype(np.float32)[:, None]


def run_episodes(vec, steps: int, seed: int, noise: float, progress: bool) -> dict[str, float]:
    """Step ``vec`` with the balancing policy; return episode statistics and timing."""
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


def compare_backends(
    args: argparse.Namespace, ticks: int, steps: int, progress: bool, driver_worker: bool = False
) -> tuple:
    """The demo workload (cart-poles at ``ticks`` physics ticks per step) on Ray and serially:
    (Ray stats, serial stats, workers, envs per worker, CPUs per worker, start-up seconds)."""
    env_kwargs = {"k": ticks, "dt": CONTROL_PERIOD_S / ticks}
    started = time.perf_counter()
    vec = RayVectorEnv(
        DEMO_ENV,
        args.num_envs,
        envs_per_worker=args.envs_per_worker,
        address=args.address,
        env_kwargs=env_kwargs,
        driver_worker=driver_worker,
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
        own, own_serial, *_ = compare_backends(
            args, args.cheap_ticks, args.steps, progress=False, driver_worker=True
        )
        same = own["trajectory_sha256"] == own_serial["trajectory_sha256"]
        print(
            "  the same with driver_worker=True (the driver steps one worker's envs itself): "
            f"{own['env_steps_per_s'] / own_serial['env_steps_per_s']:.2f}x"
            + ("" if same else " -- TRAJECTORIES DIFFER")
        )
        identical = identical and same
    return 0 if identical else 1


def cmd_optimize(args: argparse.Namespace) -> int:
    """Optimize the lander's absorbers with Optuna TPE, trials on parallel Ray workers.

    A study runs unattended, so an evaluation that raises is recorded as a FAIL trial (its
    traceback in the trial's ``fail_reason``) and the study goes on; a worker that dies is
    replaced and its trial retried. The summary counts the failed trials and quotes the end
    of the newest one's reason."""
    import optuna  # the optim extra

    if args.backend == "serial" and args.workers != 1:
        raise UsageError(
            f"--workers={args.workers} with --backend serial: the serial backend runs one trial "
            "at a time; give --workers 1"
        )
    # engine checks (terrain of the engine, PyChrono installed) before the storage and Ray
    objective = LanderObjective(terrain=args.terrain, seed=args.seed, engine=args.engine)
    engine_tag = "" if args.engine == "mujoco" else f"-{args.engine}"
    study_name = args.study or f"lander-{args.terrain}{engine_tag}"
    optuna.logging.set_verbosity(optuna.logging.WARNING)
    sampler = optuna.samplers.TPESampler(
        seed=args.seed,
        multivariate=True,
        constant_liar=not args.no_constant_liar,
        n_startup_trials=args.startup_trials,
    )
    study = open_study(args.storage, study_name, sampler)
    # studies from before --engine hold MuJoCo trials; a new study takes this run's engine
    study_engine = study.user_attrs.get("engine", "mujoco" if study.trials else args.engine)
    if study_engine != args.engine:
        raise UsageError(
            f"study {study_name!r} holds {study_engine} trials; "
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
    if report.failed:  # an evaluation that raised is a FAIL trial and the study goes on
        print(f"  a failed trial's reason (user attribute fail_reason): {last_fail_reason(study)}")
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


def last_fail_reason(study: Any, lines: int = 3) -> str:
    """The end of the newest FAIL trial's ``fail_reason``: its last ``lines`` lines."""
    failed = [t for t in study.trials if t.state.name == "FAIL"]
    reason = failed[-1].user_attrs.get("fail_reason", "") if failed else ""
    return "\n    ".join(["", *str(reason).strip().splitlines()[-lines:]]) or "none recorded"


def train_task_options(args: argparse.Namespace) -> dict[str, Any] | None:
    """The Go1 task arguments ``train`` options set over the training's defaults (None: none)."""
    options: dict[str, Any] = {}
    if args.observe_base_lin_vel is not None:
        options["observe_base_lin_vel"] = args.observe_base_lin_vel
    if args.fine_tracking_weight is not None:
        options["rewards"] = {"tracking_lin_vel_fine": args.fine_tracking_weight}
    return options or None


def cmd_train(args: argparse.Namespace) -> int:
    """Train the Go1 velocity tracker with PPO (RSL-RL) on Ray workers or serially.

    The library checks the rest (engine and terrain, thread counts) before anything starts;
    these checks name the command's flags where the library's message would name arguments."""
    if args.iterations is None and args.minutes is None:
        raise UsageError("give --iterations I, --minutes M, or both")
    if args.update_threads is not None and args.policy_lag == 1:
        raise UsageError(
            f"--update-threads={args.update_threads} with --policy-lag 1: the overlapped update "
            "runs on --torch-threads; leave --update-threads out"
        )
    if args.resume is not None and not os.path.exists(args.resume):
        raise UsageError(f"--resume={args.resume}: no such checkpoint file")
    if args.resume is not None:
        check_checkpoint(args.resume, "--resume")
    check_out_folder(args.out)
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
        driver_worker=args.driver_worker,
        eval_episodes=args.eval_episodes,
        env_errors=args.env_errors,
        task_kwargs=train_task_options(args),
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
    if result.best:
        print(f"  {result.best}")
    print(f"  TensorBoard: tensorboard --logdir {args.out}")
    return 0


def cmd_play(args: argparse.Namespace) -> int:
    """Roll a trained policy out for a set of commands; print tracking errors, save a video."""
    randomization = play_randomization(args)
    commands = [tuple(c) for c in args.command] if args.command else None
    if args.check_walking:
        given = [
            flag
            for flag, value, default in (
                ("--command", commands, None),
                ("--steps", args.steps, None),
                ("--episodes", args.episodes, 1),
                ("--seed", args.seed, 0),
            )
            if value != default
        ]
        if given:
            raise UsageError(
                f"--check-walking with {', '.join(given)}: the walking criterion runs its own "
                "commands, episodes, seeds and 20 s episodes; leave them out"
            )
    for flag, path, suffix in (
        ("--traces", args.traces, ".npz"),
        ("--step-response", args.step_response, ".png"),
    ):
        if path and os.path.splitext(path)[1].lower() != suffix:
            raise UsageError(f"{flag}={path}: expected a {suffix} path")
    if not os.path.exists(args.checkpoint):
        raise UsageError(f"checkpoint {args.checkpoint!r}: no such file")
    if args.video and os.path.splitext(args.video)[1].lower() not in (".mp4", ".gif", ".png"):
        raise UsageError(f"--video={args.video}: expected a .mp4, .gif or .png path")
    check_engine(args.engine, args.terrain)  # a missing PyChrono before reading the checkpoint
    check_checkpoint(args.checkpoint, "checkpoint")
    if args.video:
        try:
            check_can_render()
        except RuntimeError as error:  # no GL library: a setup the user can change
            raise UsageError(f"--video={args.video}: {first_line(error)}") from error
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
        randomization=randomization,
        check_walking=args.check_walking,
        traces=args.traces,
        step_response=args.step_response,
    )
    if randomization is not None:
        print(f"randomization: {describe_randomization(randomization)}")
    print(format_summary(rows))
    if args.check_walking:
        print(walking_verdicts(rows))
    for what, path in (("video", args.video), ("traces", args.traces),
                       ("step response", args.step_response)):  # fmt: skip
        if path:
            print(f"{what}: {path}")
    return 0


def walking_verdicts(rows: list[dict[str, Any]]) -> str:
    """``play --check-walking``'s verdicts: walks by v2 (else each failed clause on a line of
    its own) and by v1."""
    failures = [f"  {row['label']}: {f}" for row in rows for f in row["failures"]]
    v1 = "yes" if all(row["v1"] for row in rows if row["v1"] is not None) else "no"
    lines = ["walks by criterion v2: " + ("yes" if not failures else "no, because"), *failures]
    return "\n".join([*lines, f"walks by criterion v1 (whole-episode MSE): {v1}"])


def open_study(url: str, study_name: str, sampler: Any) -> Any:
    """The Optuna study ``study_name`` in the storage at ``url`` (created if new); a URL that
    does not open (unknown scheme, missing driver, unreachable server) is a UsageError."""
    import optuna  # the optim extra (with SQLAlchemy)
    import sqlalchemy.exc

    try:
        storage = open_storage(url)
    except (ValueError, ImportError, OSError, sqlalchemy.exc.SQLAlchemyError) as error:
        raise UsageError(
            f"--storage={url}: cannot open this Optuna storage ({type(error).__name__}: "
            f"{first_line(error)}); expected sqlite:///FILE.db, journal:FILE.log or an RDB URL"
        ) from error
    try:
        return optuna.create_study(
            storage=storage,
            study_name=study_name,
            direction="minimize",
            sampler=sampler,
            load_if_exists=True,
        )
    except sqlalchemy.exc.SQLAlchemyError as error:  # e.g. a database file that is read-only
        raise UsageError(
            f"--study={study_name}: cannot create or load it in {url} "
            f"({type(error).__name__}: {first_line(error)})"
        ) from error


def play_randomization(args: argparse.Namespace) -> Any:
    """The ``DomainRandomization`` of ``play --push`` / ``--friction`` (None: neither)."""
    friction = None
    if args.friction is not None:
        low, high = args.friction
        if not (math.isfinite(low) and math.isfinite(high) and 0 < low <= high):
            raise UsageError(
                f"--friction {low:g} {high:g}: expected 0 < LO <= HI (friction coefficients)"
            )
        friction = (low, high)
    return quadruped_randomization(
        args.push_velocity if args.push else None, args.push_interval, friction
    )


def describe_randomization(dr: Any) -> str:
    """One line: the pushes and the friction range of ``play``'s randomization."""
    parts = []
    if dr.push_interval_s is not None:
        parts.append(
            f"pushes up to {dr.push_velocity:g} m/s per axis every {dr.push_interval_s:g} s"
        )
    if dr.friction is not None:
        parts.append(f"friction uniform in [{dr.friction[0]:g}, {dr.friction[1]:g}]")
    return "; ".join(parts)


def check_checkpoint(path: str, name: str) -> None:
    """Reject ``path`` (given as ``name``) unless it holds a checkpoint with an actor, before
    any env or Ray worker starts (read with ``weights_only=True``: nothing is unpickled)."""
    saved = read_checkpoint(path, name)  # a ValueError naming the file when it is not one
    if "actor_state_dict" not in saved:
        keys = ", ".join(map(str, list(saved)[:8]))
        raise UsageError(
            f"{name}={path!r}: expected a checkpoint that `chronogym train` wrote; this dict "
            f"has no 'actor_state_dict' (keys: {keys})"
        )


def check_out_folder(out: str) -> None:
    """Create the output folder ``out`` now, so that a path that cannot be one fails before
    any env starts."""
    try:
        os.makedirs(out, exist_ok=True)
    except OSError as error:
        raise UsageError(f"--out={out}: cannot create this folder ({error.strerror})") from error


def cmd_envs(args: argparse.Namespace) -> int:
    """List the registered chronogym environment ids; with an id, describe that environment."""
    if args.env_id is None:
        for env_id in sorted(i for i in gym.registry if i.startswith("chronogym/")):
            print(env_id)
        return 0
    try:
        spec = gym.spec(args.env_id)
    except gym.error.Error as error:
        raise UsageError(f"{args.env_id}: {error} (`chronogym envs` lists the ids)") from error
    env = gym.make(spec)
    try:
        print(spec.id)
        print(f"  observation space: {env.observation_space}")
        print(f"  action space     : {env.action_space}")
        steps = env.spec.max_episode_steps if env.spec is not None else None
        print(f"  episode steps    : {steps if steps is not None else 'no limit'}")
    finally:
        env.close()
    return 0


def cmd_bench(args: argparse.Namespace) -> int:
    """Size a parallel run of ``args.env_id`` (:mod:`chronogym.sizing`)."""
    import json

    from chronogym.sizing import format_report, run_bench

    try:
        env_kwargs = json.loads(args.env_kwargs)
    except json.JSONDecodeError as error:
        raise UsageError(f"--env-kwargs={args.env_kwargs}: not JSON ({error})") from error
    if not isinstance(env_kwargs, dict):
        raise UsageError(f"--env-kwargs={args.env_kwargs}: expected a JSON object, e.g. '{{}}'")
    if args.target > 1:
        raise UsageError(f"--target={args.target}: expected an efficiency in (0, 1]")
    try:
        gym.spec(args.env_id)
    except gym.error.Error as error:
        raise UsageError(f"{args.env_id}: {error} (`chronogym envs` lists the ids)") from error
    report = run_bench(
        args.env_id,
        env_kwargs,
        seconds=args.seconds,
        max_workers=args.max_workers,
        address=args.address,
        cores=args.cores,
        target=args.target,
        check=not args.no_check,
        transport=args.transport,
    )
    print()
    print(format_report(report))
    return 0


#: Each subcommand: its function and the ``chronogym[...]`` extra that it needs.
COMMANDS: dict[str, tuple[Callable[[argparse.Namespace], int], str | None]] = {
    "demo": (cmd_demo, None),
    "optimize": (cmd_optimize, "optim"),
    "train": (cmd_train, "rl"),
    "play": (cmd_play, "rl"),
    "envs": (cmd_envs, None),
    "bench": (cmd_bench, None),
}


def main(argv: Sequence[str] | None = None) -> int:
    """Run ``chronogym`` with ``argv`` (default: ``sys.argv[1:]``); return the exit status.

    A user error raises ``SystemExit`` with its message (:mod:`chronogym.cli_errors`)."""
    args = build_parser().parse_args(argv)
    command, extra = COMMANDS[args.subcommand]
    prog = " ".join(["chronogym", args.subcommand, getattr(args, "problem", "")]).strip()
    return run_command(command, args, prog, extra)


if __name__ == "__main__":
    raise SystemExit(main())
