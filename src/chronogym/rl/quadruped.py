"""Case study 1 end to end: train the Go1 velocity tracker with PPO, then play it back.

``chronogym train quadruped`` and ``chronogym play quadruped`` are thin wrappers over
:func:`make_quadruped_vec_env`, :func:`train_quadruped` and :func:`play_quadruped`.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

from chronogym.validation import check_bool, check_int

ENV_ID = "chronogym/Go1Velocity-v0"
TERRAINS = ("rigid", "soil")
BACKENDS = ("ray", "serial")
#: Gymnasium id of the Go1 task per engine; both share observation, action and reward.
ENV_IDS: dict[str, str] = {
    "mujoco": ENV_ID,
    "chrono": "chronogym/ChronoGo1Velocity-v0",
}
#: Terrains of the Go1 task per engine.
ENGINE_TERRAINS: dict[str, tuple[str, ...]] = {"mujoco": TERRAINS, "chrono": ("rigid", "scm")}

#: Task settings for training only (what it sees: commands, randomization, initial states;
#: the critic's observation; the reward's kernel width), left out of the evaluation envs,
#: which run the task as ``chronogym play`` does.
TRAINING_ONLY = (
    "tracking_sigma",
    "privileged_critic",
    "commands",
    "randomization",
    "reset_joint_noise",
    "reset_joint_scale",
    "reset_base_velocity",
)

#: Task settings of the documented Go1 training, under the caller's ``task_kwargs``
#: (training only: ``play`` and the checkpoint evaluation run the task as it is).
QUADRUPED_TASK: dict[str, Any] = {}

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
    from chronogym.rl.config import _merge, ppo_train_config

    ppo_train_config(**overrides)  # rejects unknown keys by name
    return _merge(ppo_train_config(**QUADRUPED_PPO), overrides)


def check_engine(engine: str, terrain: str = "rigid") -> str:
    """The Gymnasium id for ``engine``, after checking that it runs ``terrain`` and, for
    Chrono, that PyChrono imports (ValueError / ModuleNotFoundError naming what to do)."""
    if engine not in ENV_IDS:
        raise ValueError(f"engine={engine!r}: expected one of {', '.join(ENV_IDS)}")
    terrains = ENGINE_TERRAINS[engine]
    if terrain not in terrains:
        others = [e for e, ts in ENGINE_TERRAINS.items() if terrain in ts]
        hint = f" (terrain {terrain!r} runs on engine {others[0]!r})" if others else ""
        raise ValueError(
            f"terrain={terrain!r}: expected one of {', '.join(terrains)} on engine {engine!r}{hint}"
        )
    if engine == "chrono":
        from chronogym.engines.chrono import import_pychrono

        import_pychrono()
    return ENV_IDS[engine]


def env_kwargs_for(
    terrain: str, task_kwargs: dict[str, Any] | None = None, engine: str = "mujoco"
) -> dict[str, Any]:
    """Keyword arguments of the task for a terrain name, plus ``task_kwargs`` (other
    ``Go1VelocityTask`` arguments, e.g. ``{"dt": 0.005, "k": 4}``)."""
    terrains = ENGINE_TERRAINS.get(engine, TERRAINS)
    if terrain not in terrains:
        raise ValueError(f"terrain={terrain!r}: expected one of {terrains} on engine {engine!r}")
    extra = dict(task_kwargs or {})
    if "terrain" in extra:
        raise ValueError(
            f"task_kwargs={task_kwargs!r}: give the terrain as terrain=..., not in task_kwargs"
        )
    return {**({} if terrain == "rigid" else {"terrain": terrain}), **extra}


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
    import gymnasium as gym

    from chronogym.vector.factory import make_vec

    if backend not in BACKENDS:
        raise ValueError(f"backend={backend!r}: expected one of {BACKENDS}")
    if isinstance(num_envs, bool) or not isinstance(num_envs, int) or num_envs < 1:
        raise ValueError(f"num_envs={num_envs!r}: expected an integer >= 1")
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
    eval_episodes: int = 2,
) -> Any:
    """Train (or, with ``resume``, continue / fine-tune) the Go1 velocity tracker with PPO.

    ``finetune`` swaps in the paper's conservative PPO settings (``FINETUNE_PPO``), as for
    the transfer from rigid to deformable terrain. ``policy_lag=1`` overlaps each PPO update
    with the next rollout (:mod:`chronogym.rl.collection`). ``update_threads``: torch threads of
    the synchronous update, while the simulations wait (default: every CPU this process may
    use, at most 8; with ``policy_lag=1`` the update runs on ``torch_threads``).
    ``task_kwargs``: further ``Go1VelocityTask`` arguments (e.g. the physics step
    ``{"dt": 0.005, "k": 4}``). ``engine="chrono"`` trains the same task in Project Chrono
    (``chronogym/ChronoGo1Velocity-v0``; a MuJoCo checkpoint resumes there unchanged).
    ``driver_worker`` (Ray only): the training process steps one worker's envs itself
    (``RayVectorEnv(driver_worker=True)``).

    ``eval_episodes``: at every save point the checkpoint is scored on the walking criterion
    of ``chronogym play`` (:class:`~chronogym.rl.evaluate.WalkingCriterion`'s commands, this
    many episodes each, in envs of the training process) and the best so far is kept as
    ``best.pt`` (``best.json`` says why); 0 evaluates nothing. Returns
    :class:`~chronogym.rl.TrainResult`.
    """
    from chronogym.rl.config import FINETUNE_PPO
    from chronogym.rl.overlap import check_policy_lag
    from chronogym.rl.trainer import Budget, train
    from chronogym.rl.vecenv import RslRlVecEnv

    Budget.of(iterations, minutes)  # checked before any worker starts
    check_policy_lag(policy_lag)
    check_engine(engine, terrain)
    check_bool("driver_worker", driver_worker)
    check_int("eval_episodes", eval_episodes, low=0)
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
        )
    finally:
        env.close()
        if evaluator is not None:
            evaluator.close()


def training_task_kwargs(
    task_kwargs: dict[str, Any] | None, resume: str | Path | None
) -> dict[str, Any]:
    """``QUADRUPED_TASK`` under ``task_kwargs``; a resumed checkpoint keeps the critic
    observation it was trained with (``privileged_critic`` read from its critic's input
    size), unless ``task_kwargs`` sets it."""
    from chronogym.tasks.quadruped.config import OBS_DIM

    kwargs = {**QUADRUPED_TASK, **(task_kwargs or {})}
    if resume is not None and "privileged_critic" not in (task_kwargs or {}):
        size = critic_input_size(resume)
        if size is not None:
            kwargs["privileged_critic"] = size > OBS_DIM
    return kwargs


def critic_input_size(checkpoint: str | Path) -> int | None:
    """The number of observations the checkpoint's critic reads (None: not found)."""
    from chronogym.rl.checkpoint import read_checkpoint

    critic = read_checkpoint(checkpoint, "resume").get("critic_state_dict") or {}
    weight = critic.get("mlp.0.weight")
    return int(weight.shape[1]) if weight is not None and weight.ndim == 2 else None


def walking_evaluator(
    engine: str, terrain: str, task_kwargs: dict[str, Any] | None, episodes: int
) -> Any:
    """A :class:`~chronogym.rl.evaluate.WalkingEvaluator` on the training's task as
    ``chronogym play`` makes it (the ``TRAINING_ONLY`` settings left out): the
    standard commands, ``episodes`` episodes each (seeds 0, 1, ...)."""
    import gymnasium as gym

    from chronogym.rl.evaluate import WalkingCriterion, WalkingEvaluator

    env_id = ENV_IDS[engine]
    physics = {k: v for k, v in (task_kwargs or {}).items() if k not in TRAINING_ONLY}
    kwargs = env_kwargs_for(terrain, physics, engine)
    return WalkingEvaluator(lambda: gym.make(env_id, **kwargs), WalkingCriterion(episodes=episodes))


def default_update_threads() -> int:
    """Threads for a synchronous PPO update: the CPUs this process may run on, at most 8."""
    import os

    try:
        usable = len(os.sched_getaffinity(0))
    except AttributeError:  # not on Linux
        usable = os.cpu_count() or 1
    return max(1, min(8, usable))


def play_quadruped(
    checkpoint: str | Path,
    *,
    commands: Any = None,
    episodes: int = 1,
    seed: int = 0,
    video: str | Path | None = None,
    terrain: str = "rigid",
    max_episode_steps: int | None = None,
    progress: bool = True,
    video_seconds: float = 5.0,
    engine: str = "mujoco",
    task_kwargs: dict[str, Any] | None = None,
    randomization: Any = None,
) -> list[dict[str, Any]]:
    """Roll the checkpoint's policy out for each command; return the summary rows.

    ``engine="chrono"`` plays it in Project Chrono (sim-to-sim for a MuJoCo-trained policy);
    the video then shows the Chrono robot's pose drawn with the MuJoCo model.

    ``randomization``: a :class:`~chronogym.tasks.quadruped.config.DomainRandomization` of
    the episodes (pushes, friction, trunk mass), to see how robust the policy is.

    With ``video`` the first ``video_seconds`` of the first episode of every command are
    rendered offscreen (needs an OpenGL backend: EGL, or OSMesa with ``MUJOCO_GL=osmesa``)
    into one MP4, GIF or PNG film strip.
    """
    import gymnasium as gym

    import chronogym  # noqa: F401  (registers ids, picks a headless GL backend)
    from chronogym.rl.checkpoint import load_policy
    from chronogym.rl.evaluate import DEFAULT_COMMANDS, evaluate, summarize

    env_id = check_engine(engine, terrain)
    render_mode = "rgb_array" if video is not None else None
    if video is not None:
        check_can_render()
    env = gym.make(
        env_id,
        render_mode=render_mode,
        max_episode_steps=max_episode_steps,
        **{
            **env_kwargs_for(terrain, task_kwargs, engine),
            **({"randomization": randomization} if randomization is not None else {}),
        },
    )
    try:
        policy = load_policy(checkpoint, env.observation_space.shape[0], env.action_space.shape[0])
        results = evaluate(
            env,
            policy,
            commands=commands or DEFAULT_COMMANDS,
            episodes=episodes,
            seed=seed,
            video=video,
            progress=progress,
            video_seconds=video_seconds,
        )
    finally:
        env.close()
    return summarize(results)


def play_randomization(
    push_velocity: float | None = None,
    push_interval_s: float = 5.0,
    friction: tuple[float, float] | None = None,
) -> Any:
    """The ``DomainRandomization`` that ``play --push`` / ``--friction`` evaluate under: pushes
    of up to ``push_velocity`` m/s per axis every ``push_interval_s`` (None: no pushes) and
    per-episode friction in ``friction``; no added mass. None when neither is asked for."""
    from chronogym.tasks.quadruped.config import DomainRandomization

    if push_velocity is None and friction is None:
        return None
    return DomainRandomization(
        friction=friction,
        added_base_mass=None,
        push_interval_s=push_interval_s if push_velocity is not None else None,
        push_velocity=push_velocity or 0.0,
    )


def check_can_render() -> None:
    """Raise RuntimeError naming the GL backends to install when offscreen rendering fails."""
    import mujoco

    from chronogym.engines.mujoco import check_headless_gl

    check_headless_gl()
    try:
        model = mujoco.MjModel.from_xml_string("<mujoco><worldbody/></mujoco>")
        with mujoco.Renderer(model, 8, 8) as renderer:
            renderer.render()
    except Exception as error:  # GL context creation fails in many library-specific ways
        raise RuntimeError(
            f"offscreen rendering is unavailable ({type(error).__name__}: {error}); "
            "install EGL (apt install libegl1 libgl1-mesa-dri) or OSMesa "
            "(apt install libosmesa6, then MUJOCO_GL=osmesa), or run without --video"
        ) from error
