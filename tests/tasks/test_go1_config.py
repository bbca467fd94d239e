"""One Go1TaskConfig for the MuJoCo and the Chrono Go1, and reward terms computed by name
without side effects."""

from __future__ import annotations

import dataclasses

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence

from chronogym.env import SimEnv
from chronogym.tasks.quadruped import (
    CommandRanges,
    DomainRandomization,
    Go1TaskConfig,
    Go1VelocityBase,
    Go1VelocityTask,
    RewardWeights,
)
from chronogym.tasks.quadruped.chrono_task import ChronoGo1VelocityTask
from chronogym.tasks.quadruped.velocity import REWARD_TERMS

COMMAND = (0.5, -0.2, 0.3)


def _rollout(env: SimEnv, steps: int) -> list:
    obs, _ = env.reset(seed=3)
    actions = np.random.default_rng(0).normal(0, 0.5, (steps, 12)).astype(np.float32)
    trajectory = [obs]
    for action in actions:
        obs, reward, terminated, truncated, info = env.step(action)
        trajectory.append((obs, reward, terminated, truncated, info))
        if terminated or truncated:
            trajectory.append(env.reset()[0])
    return trajectory


def test_keywords_and_config_make_the_same_task():
    options = {
        "max_episode_steps": 20,
        "randomization": DomainRandomization(push_interval_s=0.1),
        "rewards": RewardWeights(feet_slip=-0.1),
        "max_tilt": 0.9,
    }
    config = Go1TaskConfig(**options)
    by_keywords = SimEnv(Go1VelocityTask(**options))
    by_config = SimEnv(Go1VelocityTask(config=config))
    assert by_keywords.task.config == by_config.task.config == config
    assert data_equivalence(_rollout(by_keywords, 40), _rollout(by_config, 40), exact=True)


def test_keywords_replace_the_fields_of_a_given_config():
    base = Go1TaskConfig(max_tilt=0.8, action_scale=0.3)
    task = Go1VelocityTask(config=base, action_scale=0.2, dt=0.005, k=4)
    assert task.config == dataclasses.replace(base, action_scale=0.2)
    assert (task.dt, task.k) == (0.005, 4)  # the engine's own settings stay its own
    assert base.action_scale == 0.3  # the given config is untouched
    env = gym.make("chronogym/Go1Velocity-v0", config=base, max_tilt=0.7)
    assert env.unwrapped.task.config == dataclasses.replace(base, max_tilt=0.7)
    env.close()


def test_both_engines_build_one_config_from_the_same_keywords():
    options = {"commands": CommandRanges(vx=(0.0, 0.5)), "kp": 40.0, "reset_joint_noise": 0.0}
    mujoco_task = Go1VelocityTask(**options)
    chrono_task = ChronoGo1VelocityTask(**options)  # no PyChrono needed before init()
    assert mujoco_task.config == chrono_task.config == Go1TaskConfig(**options)
    assert Go1VelocityTask().config == ChronoGo1VelocityTask().config == Go1TaskConfig()


def test_none_for_commands_or_rewards_means_the_default():
    task = Go1VelocityTask(commands=None, rewards=None, randomization=None)
    assert task.config == Go1TaskConfig()


def test_the_tasks_shorthands_read_the_config():
    config = Go1TaskConfig(rewards=RewardWeights(torques=0.0), action_scale=0.3)
    task = Go1VelocityTask(config=config)
    assert task.weights is config.rewards
    assert (task.action_scale, task.base_height_target) == (0.3, config.base_height_target)
    assert task.max_episode_steps == 1000
    with pytest.raises(AttributeError):
        task.action_scale = 0.5


@pytest.mark.parametrize("task_class", [Go1VelocityTask, ChronoGo1VelocityTask])
def test_an_unknown_keyword_is_a_type_error_naming_it(task_class):
    name = task_class.__name__
    with pytest.raises(TypeError, match=rf"{name}\(\) got an unexpected keyword argument 'tilt'"):
        task_class(tilt=0.5)
    with pytest.raises(ValueError, match=r"config=\{'max_tilt': 0.5\}: expected a Go1TaskConfig"):
        task_class(config={"max_tilt": 0.5})


@pytest.mark.parametrize(
    ("fields", "message"),
    [
        ({"max_episode_steps": 0}, r"max_episode_steps=0: expected None or an integer >= 1"),
        ({"commands": (0.0, 1.0)}, r"commands=\(0.0, 1.0\): expected a CommandRanges"),
        ({"rewards": {"torques": 0.0}}, r"rewards=\{'torques': 0.0\}: expected a RewardWeights"),
        ({"randomization": True}, r"randomization=True: expected None or a DomainRandomization"),
        ({"action_clip": -1.0}, r"action_clip=-1.0: expected a finite float > 0"),
        ({"base_height_target": True}, r"base_height_target=True: expected a finite float > 0"),
        ({"kd": float("nan")}, r"kd=nan: expected None \(the model's\) or a float >= 0"),
        ({"tracking_sigma": 0.0}, r"tracking_sigma=0.0: expected a finite float > 0"),
        ({"fine_tracking_sigma": -1.0}, r"fine_tracking_sigma=-1.0: expected a finite float > 0"),
        ({"air_time_threshold": 5.0}, r"air_time_threshold=5.0: expected in \[0, 5\) s"),
        ({"only_positive_rewards": "yes"}, r"only_positive_rewards='yes': expected True or"),
    ],
)
def test_bad_config_fields_are_named(fields, message):
    with pytest.raises(ValueError, match=message):
        Go1TaskConfig(**fields)
    with pytest.raises(ValueError, match=message):
        Go1VelocityTask(**fields)


def test_config_is_frozen_and_hashable():
    config = Go1TaskConfig()
    with pytest.raises(dataclasses.FrozenInstanceError):
        config.max_tilt = 0.5  # type: ignore[misc]
    assert hash(config) == hash(Go1TaskConfig())


def test_every_reward_term_is_a_method_named_after_its_weight():
    assert tuple(f.name for f in dataclasses.fields(RewardWeights)) == REWARD_TERMS
    for name in REWARD_TERMS:
        assert callable(getattr(Go1VelocityBase, f"_reward_{name}"))


def test_terms_are_looked_up_by_name_not_position():
    class TallerTask(Go1VelocityTask):
        def _reward_lin_vel_z(self, motion):
            return 7.0

    plain, taller = SimEnv(Go1VelocityTask()), SimEnv(TallerTask())
    for env in (plain, taller):
        env.reset(seed=0, options={"command": COMMAND})
        env.step(np.zeros(12, dtype=np.float32))
    changed = taller.task.reward_terms
    expected = dict(plain.task.reward_terms, lin_vel_z=7.0 * -1.0 * taller.task.control_dt)
    assert changed == expected


def _carried_state(task: Go1VelocityTask) -> list:
    return [
        task.feet_air_time.copy(),
        task.feet_contact.copy(),
        task.feet_contact_now.copy(),
        task._feet_xy_before.copy(),
        task._episode_sum.copy(),
        list(task._sq_err),
        task._weighted.copy(),
    ]


def test_compute_reward_terms_changes_nothing():
    env = SimEnv(Go1VelocityTask(rewards=RewardWeights(feet_slip=-0.25), reset_joint_noise=0.0))
    env.reset(seed=0, options={"command": COMMAND})
    task = env.task
    for _ in range(3):
        env.step(np.zeros(12, dtype=np.float32))
    task.feet_contact[:] = False  # every foot touches down now, after 0.5 s in the air
    task.feet_air_time[:] = 0.5
    task.data.qpos[0] += 0.01  # and slid 1 cm
    task.forward()
    before = _carried_state(task)
    first, second = task.compute_reward_terms(), task.compute_reward_terms()
    assert first == second
    assert first["feet_air_time"] > 0 and first["feet_slip"] < 0
    for was, now in zip(before, _carried_state(task), strict=True):
        np.testing.assert_array_equal(was, now)


def test_the_step_carries_air_time_and_contacts_over_after_the_reward():
    env = SimEnv(Go1VelocityTask(reset_joint_noise=0.0))
    env.reset(seed=0, options={"command": COMMAND})
    task = env.task
    task.feet_contact[:] = False  # as if every foot had been in the air for 0.5 s
    task.feet_air_time[:] = 0.5
    task.data.qpos[2] += 0.05  # lift the robot: it comes down onto its feet within the step
    task.forward()
    for _ in range(8):
        env.step(np.zeros(12, dtype=np.float32))
        if task.feet_contact_now.any():
            break
    landed = task.feet_contact_now
    assert landed.any()
    assert task.reward_terms["feet_air_time"] > 0  # the touchdown, rewarded in this step
    np.testing.assert_array_equal(task.feet_contact, landed)  # carried over after the reward
    assert (task.feet_air_time[landed] == 0).all()
    assert (task.feet_air_time[~landed] > 0.5).all()
