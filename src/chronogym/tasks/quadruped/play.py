"""Play a trained Go1 policy back: roll it out per command, print how well it tracked, film it.

``chronogym play quadruped`` is a thin wrapper over :func:`play_quadruped`; ``--push`` and
``--friction`` become :func:`play_randomization`; ``--video`` first asks
:func:`check_can_render` whether offscreen rendering works here.
"""

from __future__ import annotations

from pathlib import Path
from typing import Any

import gymnasium as gym

import chronogym  # noqa: F401  (registers ids, picks a headless GL backend)
from chronogym.engines.mujoco import check_headless_gl
from chronogym.rl.checkpoint import load_policy
from chronogym.tasks.quadruped.engines import check_engine, env_kwargs_for
from chronogym.tasks.quadruped.evaluation import DEFAULT_COMMANDS, evaluate, summarize
from chronogym.tasks.quadruped.training import checkpoint_task_kwargs
from chronogym.tasks.quadruped.walking import WalkingCriterion, judge, save_traces


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
    check_walking: bool = False,
    traces: str | Path | None = None,
    step_response: str | Path | None = None,
) -> list[dict[str, Any]]:
    """Roll the checkpoint's policy out for each command; return the summary rows
    (:func:`~chronogym.tasks.quadruped.evaluation.summarize`).

    ``check_walking``: run exactly the episodes of the walking criterion
    (:class:`~chronogym.tasks.quadruped.walking.WalkingCriterion`: its commands and its
    command switch, 5 episodes each from seed 0), so that the rows' ``"v2"`` and ``"v1"``
    say whether the policy walks; ``commands``, ``episodes``, ``seed`` and
    ``max_episode_steps`` must then be left at their defaults. ``traces``: save every
    episode's velocity trace to this ``.npz``
    (:func:`~chronogym.tasks.quadruped.walking.load_traces` reads it); ``step_response``:
    draw them into this PNG (:func:`~chronogym.tasks.quadruped.step_response.plot_step_response`).

    ``engine="chrono"`` plays it in Project Chrono (sim-to-sim for a MuJoCo-trained policy);
    the video then shows the Chrono robot's pose drawn with the MuJoCo model.

    ``randomization``: a :class:`~chronogym.tasks.quadruped.config.DomainRandomization` of
    the episodes (pushes, friction, trunk mass), to see how robust the policy is.

    With ``video`` the first ``video_seconds`` of the first episode of every command are
    rendered offscreen (needs an OpenGL backend: EGL, or OSMesa with ``MUJOCO_GL=osmesa``)
    into one MP4, GIF or PNG film strip.
    """
    criterion = WalkingCriterion()
    switch = None
    if check_walking:
        given = {
            "commands": commands is not None,
            "episodes": episodes != 1,
            "seed": seed != 0,
            "max_episode_steps": max_episode_steps is not None,
        }
        if any(given.values()):
            raise ValueError(
                f"check_walking=True with {', '.join(k for k, v in given.items() if v)}: the "
                "walking criterion runs its own commands, episodes and seeds; leave them out"
            )
        commands, episodes, seed = criterion.commands, criterion.episodes, criterion.seed
        switch = criterion.switch
    for name, path, suffix in (
        ("traces", traces, ".npz"),
        ("step_response", step_response, ".png"),
    ):
        if path is not None and Path(path).suffix.lower() != suffix:
            raise ValueError(f"{name}={str(path)!r}: expected a file name ending in {suffix}")
    env_id = check_engine(engine, terrain)
    # the observations the policy was trained on (its input size), unless task_kwargs says
    task_kwargs = {**checkpoint_task_kwargs(checkpoint), **(task_kwargs or {})}
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
            switch=switch,
        )
    finally:
        env.close()
    rows = summarize(results, criterion)
    episode_traces = [r.trace for r in results]
    if traces is not None:
        save_traces(traces, episode_traces)
    if step_response is not None:
        from chronogym.tasks.quadruped.step_response import plot_step_response

        verdict = judge(criterion, episode_traces) if check_walking else None
        plot_step_response(
            episode_traces, step_response, criterion, verdict, "/".join(Path(checkpoint).parts[-2:])
        )
    return rows


def play_randomization(
    push_velocity: float | None = None,
    push_interval_s: float = 5.0,
    friction: tuple[float, float] | None = None,
) -> Any:
    """The ``DomainRandomization`` that ``play --push`` / ``--friction`` evaluate under: pushes
    of up to ``push_velocity`` m/s per axis every ``push_interval_s`` (None: no pushes) and
    per-episode friction in ``friction``; no added mass. None when neither is asked for."""
    from chronogym.tasks.quadruped.config import DomainRandomization  # imports MuJoCo

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
