"""``privileged_critic``: the critic sees the base's velocity and height, the policy does not."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import chronogym  # noqa: F401
from chronogym.tasks.quadruped.config import Go1TaskConfig

ENV_ID = "chronogym/Go1Velocity-v0"


def test_critic_obs_is_the_observation_then_velocity_and_height():
    env = gym.make(ENV_ID, privileged_critic=True)
    try:
        obs, info = env.reset(seed=0)
        np.testing.assert_array_equal(info["critic_obs"][:45], obs)
        for _ in range(30):
            obs, _, _, _, info = env.step(np.full(12, 0.3, dtype=np.float32))
        task = env.unwrapped.task
        critic = info["critic_obs"]
        assert critic.shape == (49,) and critic.dtype == np.float32
        np.testing.assert_array_equal(critic[:45], obs)
        np.testing.assert_allclose(critic[45:48], task.base_lin_vel * 2.0, rtol=1e-6)
        assert critic[48] == pytest.approx(
            (task._base_height() - task.config.base_height_target) * 10.0, rel=1e-6
        )
        assert env.observation_space.shape == (45,)  # the policy's interface is unchanged
    finally:
        env.close()


def test_off_by_default():
    env = gym.make(ENV_ID)
    try:
        _, info = env.reset(seed=0)
        _, _, _, _, info = env.step(np.zeros(12, dtype=np.float32))
        assert "critic_obs" not in info
    finally:
        env.close()


def test_the_rsl_rl_adapter_feeds_it_to_the_critic():
    pytest.importorskip("rsl_rl")
    import torch

    from chronogym.rl.vecenv import RslRlVecEnv
    from chronogym.tasks.quadruped.training import make_quadruped_vec_env

    env = RslRlVecEnv(make_quadruped_vec_env(2, "serial", task_kwargs={"privileged_critic": True}))
    try:
        for _ in range(3):
            obs, *_ = env.step(torch.zeros(2, 12))
        assert obs["policy"].shape == (2, 45) and obs["critic"].shape == (2, 49)
        torch.testing.assert_close(obs["critic"][:, :45], obs["policy"])
    finally:
        env.close()


def test_bad_value_is_named():
    with pytest.raises(ValueError, match="privileged_critic='yes': expected True or False"):
        Go1TaskConfig(privileged_critic="yes")
