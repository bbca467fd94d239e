"""The Go1's initial-state noise and command shaping: off by default, each does what it says."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest

import chronogym  # noqa: F401
from chronogym.tasks.quadruped.config import CommandRanges, Go1TaskConfig
from chronogym.tasks.quadruped.model import DEFAULT_JOINT_POS

ENV_ID = "chronogym/Go1Velocity-v0"


def commands_drawn(seeds, **ranges):
    env = gym.make(ENV_ID, commands=CommandRanges(**ranges))
    try:
        drawn = []
        for seed in seeds:
            env.reset(seed=seed)
            drawn.append(env.unwrapped.task.command.copy())
        return np.array(drawn)
    finally:
        env.close()


def test_shaping_off_keeps_the_uniform_draws():
    plain = commands_drawn(range(20))
    zeroed = commands_drawn(range(20), single_axis_share=0.0, standing_share=0.0, zero_below=0.0)
    np.testing.assert_array_equal(plain, zeroed)
    assert np.count_nonzero(plain) == plain.size  # uniform draws are never exactly 0


def test_standing_share_one_stands_every_episode():
    assert not commands_drawn(range(10), standing_share=1.0).any()


def test_single_axis_keeps_exactly_one_component():
    drawn = commands_drawn(range(30), single_axis_share=1.0)
    assert (np.count_nonzero(drawn, axis=1) == 1).all()
    assert set(np.nonzero(drawn)[1]) == {0, 1, 2}  # each axis is chosen sometimes


def test_zero_below_zeroes_slow_planar_commands_only():
    plain = commands_drawn(range(60))
    shaped = commands_drawn(range(60), zero_below=0.4)
    slow = np.hypot(plain[:, 0], plain[:, 1]) < 0.4
    assert slow.any() and (~slow).any()
    np.testing.assert_array_equal(shaped[slow, :2], 0.0)
    np.testing.assert_array_equal(shaped[~slow], plain[~slow])
    np.testing.assert_array_equal(shaped[:, 2], plain[:, 2])  # yaw rate is kept


def first_state(**config):
    env = gym.make(ENV_ID, **config)
    try:
        env.reset(seed=3)
        data = env.unwrapped.task.data
        return data.qpos[7:].copy(), data.qvel[:2].copy()
    finally:
        env.close()


def test_joint_scale_multiplies_the_home_pose_per_joint():
    joints, _ = first_state(reset_joint_noise=0.0, reset_joint_scale=(0.5, 1.5))
    moving = DEFAULT_JOINT_POS != 0  # the hips' abduction is 0 at home: scaled, it stays 0
    ratio = joints[moving] / DEFAULT_JOINT_POS[moving]
    assert ((ratio >= 0.5) & (ratio <= 1.5)).all()
    assert np.ptp(ratio) > 0.1  # a factor per joint, not one for all
    home, _ = first_state(reset_joint_noise=0.0)
    np.testing.assert_array_equal(home, DEFAULT_JOINT_POS)


def test_base_velocity_starts_within_the_bound():
    _, still = first_state()
    _, moving = first_state(reset_base_velocity=0.5)
    np.testing.assert_array_equal(still, 0.0)
    assert (np.abs(moving) <= 0.5).all() and np.abs(moving).max() > 0.05


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"reset_joint_scale": (1.5, 0.5)}, r"reset_joint_scale=\(1.5, 0.5\): expected"),
        ({"reset_joint_scale": (-0.5, 1.0)}, r"within \[0, 2\]"),
        ({"reset_base_velocity": -0.1}, r"reset_base_velocity=-0.1: expected in \[0, 2\] m/s"),
    ],
)
def test_bad_reset_settings_are_named(fields, message):
    with pytest.raises(ValueError, match=message):
        Go1TaskConfig(**fields)


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"standing_share": 1.5}, r"standing_share=1.5: expected a probability in \[0, 1\]"),
        ({"single_axis_share": -0.1}, r"single_axis_share=-0.1: expected a probability"),
        ({"zero_below": float("nan")}, r"zero_below=nan: expected a speed >= 0"),
    ],
)
def test_bad_command_shaping_is_named(fields, message):
    with pytest.raises(ValueError, match=message):
        CommandRanges(**fields)
