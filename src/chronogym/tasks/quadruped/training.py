"""Train the Go1 velocity tracker with PPO: its defaults, its vector envs, and the run.

``chronogym train quadruped`` is a thin wrapper over :func:`train_quadruped`, which batches
the task (:func:`make_quadruped_vec_env`), runs the generic trainer (:func:`chronogym.rl.train`)
with the Go1's PPO settings (``QUADRUPED_PPO``) and metric columns (``PROGRESS_METRICS``), and
keeps ``best.pt`` by the walking criterion (:mod:`.evaluation`). torch and RSL-RL are imported
only when a training starts.
"""

from __future__ import annotations

import dataclasses
import os
from pathlib import Path
from typing import Any

import gymnasium as gym

from chronogym.rl.checkpoint import read_checkpoint
from chronogym.rl.config import FINETUNE_PPO, _merge, ppo_train_config
from chronogym.tasks.quadruped.engines import ENV_IDS, check_engine, env_kwargs_for
from chronogym.tasks.quadruped.evaluation import WalkingEvaluator
from chronogym.tasks.quadruped.walking import WalkingCriterion, criterion_for_episode
from chronogym.validation import check_bool, check_int
from chronogym.vector.env_errors import check_env_errors
from chronogym.vector.factory import make_vec

#: The vector backends the Go1 trains on: Ray workers, or all envs in this process.
BACKENDS = ("ray", "serial")

#: The Go1's columns in the trainer's ``progress.csv``: column -> the episode metric of the
#: task's ``info["log"]`` averaged into it (the episode-mean x/y velocity tracking errors).
PROGRESS_METRICS: dict[str, str] = {"x_mse": "/metrics/x_vel_mse", "y_mse": "/metrics/y_vel_mse"}

#: Task settings for training only (what it sees: commands, randomization, initial states;
#: the critic's observation; the reward's weights and kernel widths), left out of the
#: evaluation envs, which run the task as ``chronogym play`` does.
TRAINING_ONLY = (
    "rewards",
    "tracking_sigma",
    "fine_tracking_sigma",
    "privileged_critic",
    "commands",
    "randomization",
    "reset_joint_noise",
    "reset_joint_scale",
    "reset_base_velocity",
)

#: Task settings of the documented Go1 training, under the caller's ``task_kwargs``
#: (:func:`task_settings`), each measured by criterion v2 within 1.5 M env steps
#: (``docs/performance/rl.md``, "time_to_walk.py"):
#:
#: - the policy observes the base's linear velocity (48 observations: the paper's 45, then
#:   that velocity), as legged_gym's, Isaac Lab's and MuJoCo Playground's policies do: with
#:   it 6 of 8 seeds walked, without it none of 5. ``observe_base_lin_vel=False`` trains on
#:   the paper's 45; the checkpoint evaluation runs the task with this setting, and ``play``
#:   and a resumed run read it from the checkpoint (:func:`checkpoint_task_kwargs`);
#: - a second, narrow linear-velocity tracking kernel (``tracking_lin_vel_fine``, width
#:   ``fine_tracking_sigma`` = 0.05) beside the paper's (0.25): with it 8 of 8 seeds walked,
#:   the two that missed the rise time included. ``rewards={"tracking_lin_vel_fine": 0.0}``
#:   trains on the paper's reward.
QUADRUPED_TASK: dict[str, Any] = {
    "observe_base_lin_vel": True,
    "rewards": {"tracking_lin_vel_fine": 1.0},
}


def task_settings(*layers: dict[str, Any] | None) -> dict[str, Any]:
    """Go1 task arguments from ``layers``, each over the ones before. ``rewards`` given as a
    dict changes only the weights it names, a ``RewardWeights`` replaces them all; the
    result's ``rewards``, if any, is a ``RewardWeights``."""
    merged: dict[str, Any] = {}
    for layer in layers:
        for key, value in (layer or {}).items():
            if key == "rewards" and isinstance(value, dict):
                before = merged.get(key) or {}
                if not isinstance(before, dict):  # a RewardWeights
                    before = dataclasses.asdict(before)
                value = {**before, **value}
            merged[key] = value
    rewards = merged.get("rewards")
    if isinstance(rewards, dict):
        from chronogym.tasks.quadruped.config import RewardWeights  # imports MuJoCo

        names = [f.name for f in dataclasses.fields(RewardWeights)]
        unknown = [name for name in rewards if name not in names]
        if unknown:
            raise ValueError(
                f"rewards={rewards!r}: unknown term {unknown[0]!r}; expected RewardWeights' "
                f"fields ({', '.join(names)})"
            )
        merged["rewards"] = RewardWeights(**rewards)
    return merged


#: PPO settings of the documented Go1 run, on top of :func:`ppo_train_config`'s legged_gym
#: defaults. Few envs (32 on a laptop instead of 4096 on a GPU) make each minibatch small and
#: noisy: the default 32 envs x 48 steps keep the batch at ~1.5k samples, a smaller initial
#: action noise keeps the servos from shaking the robot, and a fixed learning rate replaces the
#: adaptive schedule, which drove the rate to its 1e-5 floor within the first iteration. The
#: rate (3e-4) and the entropy bonus (0.001) are MuJoCo Playground's for the Go1 joystick:
#: against 1e-4 and 0.01 they walked 3 of 5 seeds within 1.5 M env steps instead of 1
#: (``docs/performance/rl.md``, "time_to_walk.py"). A checkpoint every 100 iterations is
#: scored for ``best.pt``.
QUADRUPED_PPO: dict[str, Any] = {
    "num_steps_per_env": 48,
    "save_interval": 100,
    "actor": {"distribution_cfg": {"init_std": 0.5}},
    "algorithm": {"schedule": "fixed", "learning_rate": 3e-4, "entropy_coef": 0.001},
}


def quadruped_train_config(**overrides: Any) -> dict[str, Any]:
    """A fresh PPO config for the Go1 task: ``QUADRUPED_PPO`` merged into the defaults, then
    ``overrides`` (same rules as :func:`~chronogym.rl.ppo_train_config`)."""
    ppo_train_config(**overrides)  # rejects unknown keys by name
    return _merge(ppo_train_config(**QUADRUPED_PPO), overrides)


def make_quadruped_vec_env(
    num_envs: int,
    backend: str = "ray",
    *,
    terrain: str = "rigid",
    envs_per_worker: int | None = None,
    address: str | None = None,
    task_kwargs: dict[str, Any] | None = None,
    engine: str = "mujoco",
    **vector_kwargs: Any,
) -> Any:
    """``num_envs`` Go1 envs batched by ``backend`` ("ray" or "serial", the no-Ray baseline),
    with Gymnasium's SAME_STEP autoreset that RSL-RL needs; ``task_kwargs`` reach each
    ``Go1VelocityTask`` (``engine="chrono"``: each ``ChronoGo1VelocityTask``)."""
    if backend not in BACKENDS:
        raise ValueError(f"backend={backend!r}: expected one of {BACKENDS}")
    check_int("num_envs", num_envs, low=1)
    env_id = check_engine(engine, terrain)  # before any Ray worker starts
    kwargs: dict[str, Any] = {
        "autoreset_mode": gym.vector.AutoresetMode.SAME_STEP,
        "env_kwargs": env_kwargs_for(terrain, task_kwargs, engine),
        **vector_kwargs,
    }
    if backend == "ray":
        kwargs.update(envs_per_worker=envs_per_worker, address=address)
    return make_vec(env_id, num_envs, backend=backend, **kwargs)


def train_quadruped(
    out: str | Path,
    *,
    num_envs: int = 32,
    backend: str = "ray",
    iterations: int | None = None,
    minutes: float | None = None,
    resume: str | Path | None = None,
    terrain: str = "rigid",
    finetune: bool = False,
    seed: int = 0,
    envs_per_worker: int | None = None,
    address: str | None = None,
    torch_threads: int = 1,
    train_cfg: dict[str, Any] | None = None,
    progress: bool = True,
    policy_lag: int = 0,
    task_kwargs: dict[str, Any] | None = None,
    update_threads: int | None = None,
    engine: str = "mujoco",
    driver_worker: bool = False,
    eval_episodes: int = 5,
    env_errors: str = "restart",
) -> Any:
    """Train (or, with ``resume``, continue / fine-tune) the Go1 velocity tracker with PPO.

    ``finetune`` swaps in the paper's conservative PPO settings (``FINETUNE_PPO``), as for
    the transfer from rigid to deformable terrain. ``policy_lag=1`` overlaps each PPO update
    with the next rollout (:mod:`chronogym.rl.overlap`). ``update_threads``: torch threads of
    the synchronous update, while the simulations wait (default: every CPU this process may
    use, at most 8; with ``policy_lag=1`` the update runs on ``torch_threads``).
    ``task_kwargs``: further ``Go1VelocityTask`` arguments (e.g. the physics step
    ``{"dt": 0.005, "k": 4}``). ``engine="chrono"`` trains the same task in Project Chrono
    (``chronogym/ChronoGo1Velocity-v0``; a MuJoCo checkpoint resumes there unchanged).
    ``driver_worker`` (Ray only): the training process steps one worker's envs itself
    (``RayVectorEnv(driver_worker=True)``).

    ``env_errors``: what an env's Python exception does during training (see
    :class:`~chronogym.RayVectorEnv`). A training runs unattended for hours, so the default is
    ``"restart"``: the env is rebuilt and its episode truncated (``info["worker_error"]``
    holds the traceback, at most ``max_restarts=3`` times per env), and an env that fails
    again right after its rebuild (a bug at reset) stops the run at once. ``"raise"`` stops
    at the first exception, for debugging a task.

    ``eval_episodes``: at every save point the checkpoint is judged by the walking criterion
    (:class:`~chronogym.tasks.quadruped.walking.WalkingCriterion`, v2: its commands and its
    command switch, this many episodes each, in envs of the training process; the default 5
    is the criterion's own, so ``best.pt`` is chosen on exactly the episodes that say whether
    a policy walks) and the best so far is kept as ``best.pt`` (``best.json`` says why); 0
    evaluates nothing. The groups passed in order and the worst clause's value over its bound
    are ``progress.csv``'s ``eval_commands_passed`` and ``eval_worst_ratio``. Returns
    :class:`~chronogym.rl.TrainResult`.
    """
    # torch and RSL-RL: imported when a training starts, not with this module
    from chronogym.rl.overlap import check_policy_lag
    from chronogym.rl.trainer import Budget, train
    from chronogym.rl.vecenv import RslRlVecEnv

    Budget.of(iterations, minutes)  # checked before any worker starts
    check_policy_lag(policy_lag)
    check_engine(engine, terrain)
    check_bool("driver_worker", driver_worker)
    check_int("eval_episodes", eval_episodes, low=0)
    check_env_errors(env_errors)
    if driver_worker and backend != "ray":
        raise ValueError(f"driver_worker=True with backend={backend!r}: expected backend='ray'")
    if resume is not None and not Path(resume).is_file():
        raise FileNotFoundError(f"resume={str(resume)!r}: no such checkpoint file")
    if update_threads is None:
        update_threads = torch_threads if policy_lag else default_update_threads()
    task_kwargs = training_task_kwargs(task_kwargs, resume)
    cfg = train_cfg if train_cfg is not None else quadruped_train_config()
    if finetune:
        cfg = {**cfg, "algorithm": {**cfg["algorithm"], **FINETUNE_PPO}}
    vec = make_quadruped_vec_env(
        num_envs,
        backend,
        terrain=terrain,
        envs_per_worker=envs_per_worker,
        address=address,
        task_kwargs=task_kwargs,
        engine=engine,
        env_errors=env_errors,
        **({"driver_worker": True} if driver_worker else {}),
    )
    env = RslRlVecEnv(vec, seed=seed)
    evaluator = None
    try:
        if eval_episodes:
            evaluator = walking_evaluator(engine, terrain, task_kwargs, eval_episodes)
        return train(
            env,
            out,
            iterations=iterations,
            minutes=minutes,
            resume=resume,
            train_cfg=cfg,
            torch_threads=torch_threads,
            progress=progress,
            seed=seed,
            policy_lag=policy_lag,
            update_threads=update_threads,
            evaluator=evaluator,
            progress_metrics=PROGRESS_METRICS,
        )
    finally:
        env.close()
        if evaluator is not None:
            evaluator.close()


def training_task_kwargs(
    task_kwargs: dict[str, Any] | None, resume: str | Path | None
) -> dict[str, Any]:
    """``QUADRUPED_TASK`` under ``task_kwargs``; a resumed checkpoint keeps the observations
    it was trained with (:func:`checkpoint_task_kwargs`), unless ``task_kwargs`` sets them."""
    trained = {} if resume is None else checkpoint_task_kwargs(resume, critic=True, name="resume")
    return task_settings(QUADRUPED_TASK, trained, task_kwargs)


def checkpoint_task_kwargs(
    checkpoint: str | Path, critic: bool = False, name: str = "checkpoint"
) -> dict[str, Any]:
    """The task settings that a checkpoint's input sizes tell: ``observe_base_lin_vel``
    (its policy reads 48 observations, not 45) and, with ``critic``, ``privileged_critic``
    (its critic reads more than its policy). Empty where a size is not found. ``name``: the
    argument that gave ``checkpoint``, for the error if it is no checkpoint."""
    from chronogym.tasks.quadruped.config import OBS_DIM  # imports MuJoCo (the Go1 model)

    saved = read_checkpoint(checkpoint, name)
    kwargs: dict[str, Any] = {}
    actor = input_size(saved, "actor_state_dict")
    if actor is not None:
        kwargs["observe_base_lin_vel"] = actor == OBS_DIM + 3
    size = input_size(saved, "critic_state_dict")
    if critic and size is not None:
        kwargs["privileged_critic"] = size > (actor or OBS_DIM)
    return kwargs


def critic_input_size(checkpoint: str | Path) -> int | None:
    """The number of observations the checkpoint's critic reads (None: not found)."""
    return input_size(read_checkpoint(checkpoint, "resume"), "critic_state_dict")


def input_size(saved: dict[str, Any], network: str) -> int | None:
    """The number of inputs of the first layer of ``network`` (``"actor_state_dict"`` or
    ``"critic_state_dict"``) in a checkpoint's dict (None: not found)."""
    state = saved.get(network) or {}
    weight = state.get("mlp.0.weight")
    return int(weight.shape[1]) if weight is not None and weight.ndim == 2 else None


def walking_evaluator(
    engine: str, terrain: str, task_kwargs: dict[str, Any] | None, episodes: int
) -> WalkingEvaluator:
    """A :class:`~chronogym.tasks.quadruped.evaluation.WalkingEvaluator` on the training's
    task as ``chronogym play`` makes it (``QUADRUPED_TASK`` under ``task_kwargs``, the
    ``TRAINING_ONLY`` settings left out): the walking criterion's groups, ``episodes``
    episodes each (seeds 0, 1, ...); in episodes shorter than twice the criterion's switch
    time, the switch comes half-way through."""
    env_id = ENV_IDS[engine]
    trained = task_settings(QUADRUPED_TASK, task_kwargs)
    physics = {k: v for k, v in trained.items() if k not in TRAINING_ONLY}
    kwargs = env_kwargs_for(terrain, physics, engine)
    evaluator = WalkingEvaluator(
        lambda: gym.make(env_id, **kwargs), WalkingCriterion(episodes=episodes)
    )
    env = evaluator.envs[0]
    steps = env.spec.max_episode_steps if env.spec is not None else None  # gym.make's TimeLimit
    task = env.unwrapped.task
    length_s = (steps or task.max_episode_steps) * task.control_dt
    evaluator.criterion = criterion_for_episode(evaluator.criterion, length_s)
    return evaluator


def default_update_threads() -> int:
    """Threads for a synchronous PPO update: the CPUs this process may run on, at most 8."""
    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        usable = os.cpu_count() or 1
    return max(1, min(8, usable))
