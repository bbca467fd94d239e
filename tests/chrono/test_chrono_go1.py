"""The Go1 in Project Chrono (``chronogym/ChronoGo1Velocity-v0``): it stands as the MuJoCo Go1
does, its readings are in the same frames, resets reproduce episodes, and Ray gives the same
numbers as Gymnasium's SyncVectorEnv. Skipped without PyChrono (the ``chrono`` fixture)."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest
from local_clusters import driving

from chronogym import RayVectorEnv
from chronogym.engines.mujoco import gl_unavailable
from chronogym.tasks.quadruped import DEFAULT_JOINT_POS, HOME_BASE_HEIGHT
from chronogym.testing import ray_start_available

CHRONO_ID = "chronogym/ChronoGo1Velocity-v0"
MUJOCO_ID = "chronogym/Go1Velocity-v0"
ZERO = np.zeros(12, dtype=np.float32)


def stand(env_id: str, steps: int = 50, **kwargs) -> tuple[gym.Env, list[np.ndarray]]:
    env = gym.make(env_id, reset_joint_noise=0.0, **kwargs)
    obs, _ = env.reset(seed=0, options={"command": (0.0, 0.0, 0.0)})
    rows = [obs]
    for _ in range(steps):
        obs, _, terminated, truncated, _ = env.step(ZERO)
        assert not (terminated or truncated)
        rows.append(obs)
    return env, rows


def test_stands_at_the_mujoco_height_with_the_weight_on_its_feet(chrono):
    chrono_env, _ = stand(CHRONO_ID)
    mujoco_env, _ = stand(MUJOCO_ID)
    task = chrono_env.unwrapped.task
    height = task._base_height()
    assert height == pytest.approx(float(mujoco_env.unwrapped.task.data.qpos[2]), abs=0.01)
    assert abs(height - HOME_BASE_HEIGHT) < 0.03
    assert task.feet_contact_now.all()
    weight = sum(b.GetMass() for b in task.robot.bodies) * 9.81
    carried = sum(float(calf.GetContactForce().z) for calf in task.robot.calves)
    assert carried == pytest.approx(weight, rel=0.05)
    # kp 35 lets the knees sag ~0.14 rad under the weight, in both engines alike
    mujoco_angles = mujoco_env.unwrapped.task.data.qpos[7:]
    np.testing.assert_allclose(task.servos.angles(), mujoco_angles, atol=0.01)
    assert np.abs(mujoco_angles - DEFAULT_JOINT_POS).max() > 0.1
    chrono_env.close()
    mujoco_env.close()


def test_readings_are_in_the_mujoco_frames(chrono):
    env = gym.make(CHRONO_ID, reset_joint_noise=0.0)
    env.reset(seed=0)
    task = env.unwrapped.task
    yaw = 0.7
    task._reset_pose(yaw, None)
    qpos = task.mujoco_qpos()
    np.testing.assert_allclose(qpos[0:3], [0, 0, HOME_BASE_HEIGHT], atol=1e-9)
    np.testing.assert_allclose(qpos[3:7], [math.cos(yaw / 2), 0, 0, math.sin(yaw / 2)], atol=1e-9)
    np.testing.assert_allclose(qpos[7:], DEFAULT_JOINT_POS, atol=1e-9)
    task._kick_base(np.array([1.0, 0.0]))  # 1 m/s along world x
    obs = task.observe()
    np.testing.assert_allclose(task.base_lin_vel, [math.cos(yaw), -math.sin(yaw), 0], atol=1e-9)
    np.testing.assert_allclose(obs[3:6], [0, 0, -1], atol=1e-9)  # projected gravity, upright
    np.testing.assert_allclose(obs[0:3], 0.0, atol=1e-9)
    env.close()


def rollout(env: gym.Env, seed: int, steps: int = 25) -> np.ndarray:
    rng = np.random.default_rng(seed)
    rows = [env.reset(seed=seed)[0]]
    for _ in range(steps):
        obs, reward, terminated, truncated, _ = env.step(rng.normal(size=12).astype(np.float32))
        rows.append(np.concatenate([obs, [reward, terminated, truncated]]))
        if terminated or truncated:
            break
    return np.concatenate(rows)


def test_observes_the_base_velocity_when_asked(chrono):
    env, rows = stand(CHRONO_ID, steps=5, observe_base_lin_vel=True)
    try:
        assert rows[-1].shape == (48,) and env.observation_space.contains(rows[-1])
        velocity = env.unwrapped.task.base_lin_vel
        np.testing.assert_allclose(rows[-1][45:], velocity * 2.0, rtol=1e-6)
    finally:
        env.close()


def test_reset_reproduces_an_episode(chrono):
    env = gym.make(CHRONO_ID)
    first = rollout(env, 3)
    rollout(env, 4)
    np.testing.assert_array_equal(rollout(env, 3), first)
    env.close()


def test_reset_forgets_the_contacts_of_earlier_episodes(chrono):
    # long flailing episodes change Bullet's contact manifolds, broadphase tree and pair
    # cache; an episode after reset must still match the same episode in a fresh env
    env, fresh = gym.make(CHRONO_ID), gym.make(CHRONO_ID)
    for seed in range(10, 14):
        rollout(env, seed, steps=200)
    np.testing.assert_array_equal(rollout(env, 3), rollout(fresh, 3))
    env.close()
    fresh.close()


@pytest.mark.parametrize("transport", ["socket", "fork"])
def test_ray_matches_gymnasium_sync_vector_env_bit_for_bit(chrono, ray_cluster, transport):
    def run(vec) -> list[np.ndarray]:
        rng = np.random.default_rng(0)
        out = [vec.reset(seed=11)[0]]
        for _ in range(20):
            actions = rng.normal(size=(2, 12)).astype(np.float32)
            obs, rewards, terminated, truncated, _ = vec.step(actions)
            out += [obs, rewards, terminated, truncated]
        vec.close()
        return out

    sync = run(gym.vector.SyncVectorEnv([lambda: gym.make(CHRONO_ID)] * 2))
    ray = run(RayVectorEnv(CHRONO_ID, 2, envs_per_worker=1, transport=transport))
    for got, want in zip(ray, sync, strict=True):
        np.testing.assert_array_equal(got, want)


@pytest.mark.skipif(ray_start_available() is not None, reason="`ray start` unavailable")
def test_forked_workers_on_a_cluster_match_gymnasium_sync(chrono):
    """transport="fork" on a 2-node loopback cluster: the other node's relay forks its Chrono
    workers there; the same numbers as SyncVectorEnv."""

    def run(vec) -> list[np.ndarray]:
        rng = np.random.default_rng(0)
        out = [vec.reset(seed=11)[0]]
        for _ in range(15):
            obs, rewards, terminated, truncated, _ = vec.step(
                rng.normal(size=(4, 12)).astype(np.float32)
            )
            out += [obs, rewards, terminated, truncated]
        vec.close()
        return out

    with driving(workers=1, num_cpus=1) as cluster:
        address = cluster.address
        vec = RayVectorEnv(CHRONO_ID, 4, envs_per_worker=1, transport="fork", address=address)
        assert vec._backend.relayed() == [False, False, True, True]
        forked = run(vec)
    sync = run(gym.vector.SyncVectorEnv([lambda: gym.make(CHRONO_ID)] * 4))
    for got, want in zip(forked, sync, strict=True):
        np.testing.assert_array_equal(got, want)


@pytest.mark.skipif(gl_unavailable() is not None, reason=f"no GL: {gl_unavailable()}")
def test_renders_the_chrono_pose_with_the_mujoco_model(chrono):
    env = gym.make(CHRONO_ID, render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (360, 480, 3) and frame.std() > 1.0
    env.close()


def test_passes_gymnasium_env_checker(chrono):
    from gymnasium.utils.env_checker import check_env

    render_mode = "rgb_array" if gl_unavailable() is None else None
    env = gym.make(CHRONO_ID, render_mode=render_mode)
    check_env(env.unwrapped, skip_render_check=render_mode is None)
    env.close()
