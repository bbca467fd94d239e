"""``observe_base_lin_vel``: the policy's observation ends with the base's linear velocity."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import chronogym  # noqa: F401
from chronogym.tasks.quadruped.config import LIN_VEL_SCALE, OBS_DIM, Go1TaskConfig

ENV_ID = "chronogym/Go1Velocity-v0"


def rollout(steps: int = 25, **kwargs) -> tuple[list[np.ndarray], np.ndarray]:
    """The observations of a short scripted episode, and the base velocity at its end."""
    env = gym.make(ENV_ID, **kwargs)
    try:
        obs, _ = env.reset(seed=3)
        seen = [obs]
        for i in range(steps):
            obs, *_ = env.step(np.full(12, 0.3 * np.sin(i), dtype=np.float32))
            seen.append(obs)
        assert env.observation_space.contains(obs)
        return seen, env.unwrapped.task.base_lin_vel.copy()
    finally:
        env.close()


def test_the_velocity_is_appended_and_the_rest_unchanged():
    plain, _ = rollout()
    with_velocity, velocity = rollout(observe_base_lin_vel=True)
    assert with_velocity[-1].shape == (OBS_DIM + 3,) and with_velocity[-1].dtype == np.float32
    for a, b in zip(plain, with_velocity, strict=True):
        np.testing.assert_array_equal(b[:OBS_DIM], a)  # same physics, same first 45
    np.testing.assert_allclose(with_velocity[-1][OBS_DIM:], velocity * LIN_VEL_SCALE, rtol=1e-6)
    assert np.abs(velocity).max() > 1e-3  # the scripted steps moved the base


def test_off_by_default():
    plain, _ = rollout(steps=1)
    assert plain[-1].shape == (OBS_DIM,)


def test_bad_value_is_named():
    with pytest.raises(ValueError, match="observe_base_lin_vel=1: expected True or False"):
        Go1TaskConfig(observe_base_lin_vel=1)


def test_play_and_resume_read_it_from_the_checkpoint(tmp_path):
    pytest.importorskip("rsl_rl")
    from chronogym.tasks.quadruped.play import play_quadruped
    from chronogym.tasks.quadruped.training import (
        checkpoint_task_kwargs,
        quadruped_train_config,
        train_quadruped,
        training_task_kwargs,
    )

    cfg = quadruped_train_config(num_steps_per_env=4, save_interval=1)
    task = {"max_episode_steps": 20, "observe_base_lin_vel": True}
    result = train_quadruped(
        tmp_path, iterations=1, num_envs=2, backend="serial", train_cfg=cfg,
        task_kwargs=task, eval_episodes=0, progress=False,
    )  # fmt: skip
    assert checkpoint_task_kwargs(result.checkpoint) == {"observe_base_lin_vel": True}
    assert training_task_kwargs({}, result.checkpoint)["observe_base_lin_vel"] is True
    # what the caller says wins over what the checkpoint tells
    assert training_task_kwargs({"observe_base_lin_vel": False}, result.checkpoint)[
        "observe_base_lin_vel"
    ] is False  # fmt: skip
    rows = play_quadruped(
        result.checkpoint, commands=[(0.5, 0.0, 0.0)], max_episode_steps=10, progress=False
    )  # no task_kwargs: play builds the 48-observation env the policy needs
    assert len(rows) == 1 and np.isfinite(rows[0]["x_vel_mse"])
