"""SyntheticEnv: spaces, seeded durations and observations, the lognormal's mean and CV, its
argument checks, the registered id, and the same numbers in RayVectorEnv as serially."""

from __future__ import annotations

import time

import gymnasium as gym
import numpy as np
import pytest

from chronogym import RayVectorEnv, SerialVectorEnv
from chronogym.testing import SyntheticEnv
from chronogym.testing.synthetic import ENV_ID, lognormal_parameters


def durations(env: SyntheticEnv, seed: int, count: int) -> np.ndarray:
    env.reset(seed=seed)
    return np.array([env.draw_duration_ms() for _ in range(count)])


def test_spaces_observation_and_info_sizes():
    env = SyntheticEnv(step_ms=0, obs_dim=7, info_floats=3, action_dim=4, max_steps=2)
    assert env.observation_space == gym.spaces.Box(-np.inf, np.inf, (7,), np.float32)
    assert env.action_space == gym.spaces.Box(-1.0, 1.0, (4,), np.float32)
    obs, info = env.reset(seed=0)
    assert obs.shape == (7,) and obs.dtype == np.float32 and env.observation_space.contains(obs)
    assert info["payload"].shape == (3,) and info["payload"].dtype == np.float32
    obs, reward, terminated, truncated, info = env.step(np.full(4, 0.5, np.float32))
    assert reward == pytest.approx(-1.0) and not terminated and not truncated
    assert obs[1:].tolist() == [1.0] * 6 and info["payload"].tolist() == [1.0] * 3
    assert env.step(env.action_space.sample())[3]  # max_steps=2: the second step truncates
    assert SyntheticEnv(step_ms=0, info_floats=0).reset(seed=0)[1] == {}


def test_info_scalars_are_float64_scalars_like_mujoco_tasks_report():
    env = SyntheticEnv(step_ms=0, info_scalars=3)
    env.reset(seed=0)
    info = env.step(env.action_space.sample())[4]
    assert list(info) == ["info_0", "info_1", "info_2"]
    assert all(type(v) is np.float64 and v == 1.0 for v in info.values())


def test_same_seed_same_durations_and_observations():
    env = SyntheticEnv(step_ms=2.0, cv=0.5)
    first, again = durations(env, 3, 50), durations(env, 3, 50)
    other = durations(env, 4, 50)
    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(first, other)
    obs = [SyntheticEnv(step_ms=0, obs_dim=3).reset(seed=s)[0] for s in (7, 7, 8)]
    np.testing.assert_array_equal(obs[0], obs[1])
    assert obs[0][0] != obs[2][0]


def test_constant_durations_when_cv_is_zero():
    assert set(durations(SyntheticEnv(step_ms=1.5, cv=0), 0, 20)) == {1.5}


@pytest.mark.parametrize("cv", [0.25, 0.5, 1.0])
def test_lognormal_mean_and_cv(cv):
    drawn = durations(SyntheticEnv(step_ms=10.0, cv=cv), 1, 200_000)
    assert drawn.mean() == pytest.approx(10.0, rel=0.02)
    assert drawn.std() / drawn.mean() == pytest.approx(cv, rel=0.05)
    mu, sigma = lognormal_parameters(10.0, cv)
    assert np.log(drawn).mean() == pytest.approx(mu, abs=0.01)
    assert np.log(drawn).std() == pytest.approx(sigma, rel=0.02)


def test_step_sleeps_without_using_the_cpu():
    env = SyntheticEnv(step_ms=20.0)
    env.reset(seed=0)
    cpu, wall = time.process_time(), time.perf_counter()
    for _ in range(3):
        env.step(env.action_space.sample())
    wall, cpu = time.perf_counter() - wall, time.process_time() - cpu
    assert wall >= 0.05  # three 20 ms steps (a learned lead may shorten each by <= 0.1 ms)
    assert cpu < wall / 2


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"step_ms": -1}, r"step_ms=-1: expected milliseconds >= 0"),
        ({"step_ms": float("nan")}, r"step_ms=nan"),
        ({"cv": -0.1}, r"cv=-0.1: expected a coefficient of variation >= 0"),
        ({"obs_dim": 0}, r"obs_dim=0: expected an integer >= 1"),
        ({"obs_dim": 2.5}, r"obs_dim=2.5"),
        ({"info_floats": -1}, r"info_floats=-1: expected an integer >= 0"),
        ({"info_scalars": -1}, r"info_scalars=-1: expected an integer >= 0"),
        ({"action_dim": 0}, r"action_dim=0"),
        ({"max_steps": 0}, r"max_steps=0"),
        ({"reset_ms": -2}, r"reset_ms=-2"),
        ({"precise_sleep": 1}, r"precise_sleep=1: expected True or False"),
        ({"step_ms": True}, r"step_ms=True"),
    ],
)
def test_bad_arguments_are_rejected_by_name(kwargs, message):
    with pytest.raises(ValueError, match=message):
        SyntheticEnv(**kwargs)


def test_registered_id_takes_the_kwargs():
    env = gym.make(ENV_ID, step_ms=0, obs_dim=5, info_floats=2)
    try:
        assert env.observation_space.shape == (5,)
        assert env.reset(seed=0)[1]["payload"].shape == (2,)
    finally:
        env.close()
    with pytest.raises(ValueError, match="cv=-1"):
        gym.make(ENV_ID, cv=-1)


def rollout(vec, steps: int = 6) -> list[np.ndarray]:
    obs, info = vec.reset(seed=11)
    arrays = [obs, info["payload"]]
    actions = np.random.default_rng(0).uniform(-1, 1, (steps, vec.num_envs, 2))
    for t in range(steps):
        obs, reward, terminated, truncated, info = vec.step(actions[t].astype(np.float32))
        arrays += [obs, reward, terminated, truncated, info["payload"]]
    vec.close()
    return arrays


def test_ray_vector_env_matches_serial(ray_cluster):
    kwargs = {"step_ms": 0.2, "cv": 0.5, "obs_dim": 4, "info_floats": 2, "max_steps": 4}
    ray_run = rollout(RayVectorEnv(ENV_ID, 4, envs_per_worker=2, env_kwargs=kwargs))
    serial_run = rollout(SerialVectorEnv(ENV_ID, 4, env_kwargs=kwargs))
    assert any(t.any() for t in serial_run[5::5])  # a truncation (max_steps=4) was compared
    assert len(ray_run) == len(serial_run)
    for got, expected in zip(ray_run, serial_run, strict=True):
        np.testing.assert_array_equal(got, expected)
    assert len({float(x) for x in serial_run[2][:, 0]}) == 4  # each env drew its own durations


def test_vector_entry_point_builds_serial():
    vec = gym.make_vec(
        ENV_ID, 3, vectorization_mode="vector_entry_point", backend="serial", step_ms=0
    )
    assert isinstance(vec, SerialVectorEnv) and vec.observation_space.shape == (3, 16)
    vec.close()


def test_step_cost_can_be_changed_in_place():
    env = SyntheticEnv(step_ms=1.0)
    env.step_ms, env.cv = 4.0, 0.5
    drawn = durations(env, 0, 20_000)
    assert drawn.mean() == pytest.approx(4.0, rel=0.05) and drawn.std() > 1.0
    with pytest.raises(ValueError, match="step_ms=-3"):
        env.step_ms = -3
    vec = SerialVectorEnv(ENV_ID, 2, env_kwargs={"step_ms": 0})
    vec.set_attr("step_ms", 0.5)
    assert vec.get_attr("step_ms") == (0.5, 0.5)
    vec.close()
