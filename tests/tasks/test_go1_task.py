"""Go1 velocity tracking: observation layout and scales, reward-term signs, termination, logs."""

from __future__ import annotations

import math

import gymnasium as gym
import mujoco
import numpy as np
import pytest

import chronogym
from chronogym.env import SimEnv
from chronogym.tasks.quadruped import (
    DEFAULT_JOINT_POS,
    OBS_DIM,
    OBS_SCALES,
    OBS_SLICES,
    CommandRanges,
    DomainRandomization,
    Go1VelocityTask,
    RewardWeights,
)

COMMAND = (0.5, -0.2, 0.3)


def _env(**kwargs) -> SimEnv:
    env = SimEnv(Go1VelocityTask(**kwargs))
    env.reset(seed=0, options={"command": COMMAND})
    return env


def _set_state(task: Go1VelocityTask, *, lin_vel=(0, 0, 0), ang_vel=(0, 0, 0), quat=None):
    """Put the base at its home height with the given world velocities, then observe."""
    data = task.data
    if quat is not None:
        data.qpos[3:7] = quat
    data.qvel[0:3] = lin_vel
    data.qvel[3:6] = ang_vel
    task.forward()
    return task.observe()


def _quat_from_yaw(yaw: float) -> np.ndarray:
    return np.array([math.cos(yaw / 2), 0, 0, math.sin(yaw / 2)])


def test_spaces_and_registered_id():
    env = gym.make("chronogym/Go1Velocity-v0")
    assert env.observation_space.shape == (OBS_DIM,) == (45,)
    assert env.observation_space.dtype == np.float32
    assert env.action_space.shape == (12,)
    obs, _ = env.reset(seed=3)
    assert obs.shape == (45,) and obs.dtype == np.float32
    assert env.unwrapped.control_dt == pytest.approx(0.02)
    env.close()


def test_observation_slices_hold_each_scaled_group():
    env = _env(reset_joint_noise=0.0)
    task = env.task
    data = task.data
    data.qpos[7:] = DEFAULT_JOINT_POS + np.linspace(-0.1, 0.1, 12)
    data.qvel[6:] = np.linspace(1.0, 12.0, 12)
    task.last_action[:] = np.arange(12) / 10
    obs = _set_state(task, ang_vel=(0.4, -0.8, 1.2), quat=_quat_from_yaw(0.0))

    def group(name):
        start, stop = OBS_SLICES[name]
        return obs[start:stop]

    np.testing.assert_allclose(group("base_ang_vel"), np.array([0.4, -0.8, 1.2]) * 0.25, rtol=1e-6)
    np.testing.assert_allclose(group("projected_gravity"), [0, 0, -1], atol=1e-6)
    np.testing.assert_allclose(group("command"), np.array(COMMAND) * OBS_SCALES["command"], 1e-6)
    np.testing.assert_allclose(group("joint_pos"), np.linspace(-0.1, 0.1, 12), atol=1e-6)
    np.testing.assert_allclose(group("joint_vel"), np.linspace(1.0, 12.0, 12) * 0.05, rtol=1e-6)
    np.testing.assert_allclose(group("last_action"), np.arange(12) / 10, rtol=1e-6)
    assert sum(stop - start for start, stop in OBS_SLICES.values()) == OBS_DIM


def test_projected_gravity_follows_roll_and_velocity_is_in_body_frame():
    env = _env()
    task = env.task
    roll = 0.3
    quat = np.array([math.cos(roll / 2), math.sin(roll / 2), 0, 0])
    obs = _set_state(task, quat=quat)
    start = OBS_SLICES["projected_gravity"][0]
    np.testing.assert_allclose(obs[start : start + 3], [0, -math.sin(roll), -math.cos(roll)], 1e-6)
    # Heading 90 deg left: a world +y velocity is forward (+x) in the body frame.
    _set_state(task, lin_vel=(0, 0.7, 0), quat=_quat_from_yaw(math.pi / 2))
    np.testing.assert_allclose(task.base_lin_vel, [0.7, 0, 0], atol=1e-9)


def test_action_maps_to_scaled_offsets_from_the_default_pose():
    env = _env(action_scale=0.25)
    action = np.full(12, 0.4, dtype=np.float32)
    env.step(action)
    np.testing.assert_allclose(env.task.data.ctrl, DEFAULT_JOINT_POS + 0.1, rtol=1e-6)
    with pytest.raises(ValueError, match="NaN"):
        env.step(np.full(12, np.nan, dtype=np.float32))


def _terms(task: Go1VelocityTask) -> dict[str, float]:
    """The reward terms of a step ending now: contacts read, terms computed, and the feet's
    state carried over to the next step, as ``reward()`` does."""
    task._update_contacts()
    terms = task.compute_reward_terms()
    task._update_feet_state()
    return terms


def test_tracking_terms_are_positive_and_peak_on_the_command():
    env = _env()
    task = env.task
    _set_state(task, lin_vel=(0.5, -0.2, 0), ang_vel=(0, 0, 0.3), quat=(1, 0, 0, 0))
    on = _terms(task)
    _set_state(task, lin_vel=(-0.5, 0.4, 0), ang_vel=(0, 0, -0.6))
    off = _terms(task)
    dt = task.control_dt
    assert on["tracking_lin_vel"] == pytest.approx(1.0 * dt)
    assert on["tracking_ang_vel"] == pytest.approx(0.5 * dt)
    assert 0 < off["tracking_lin_vel"] < on["tracking_lin_vel"]
    assert 0 < off["tracking_ang_vel"] < on["tracking_ang_vel"]


def test_tracking_sigma_sets_the_width_of_both_kernels():
    lin = {}
    for sigma in (0.25, 0.1):
        task = _env(tracking_sigma=sigma).task
        # 0.1 m/s off the command in x, 0.2 rad/s off in yaw rate
        _set_state(task, lin_vel=(0.6, -0.2, 0), ang_vel=(0, 0, 0.5), quat=(1, 0, 0, 0))
        terms = _terms(task)
        dt = task.control_dt
        assert terms["tracking_lin_vel"] == pytest.approx(1.0 * dt * math.exp(-0.01 / sigma))
        assert terms["tracking_ang_vel"] == pytest.approx(0.5 * dt * math.exp(-0.04 / sigma))
        lin[sigma] = terms["tracking_lin_vel"]
    assert lin[0.1] < lin[0.25]


def test_fine_tracking_kernel_is_off_by_default_and_narrower_when_on():
    assert RewardWeights().tracking_lin_vel_fine == 0.0
    # last in the term vector, so that rewards with it off are bit for bit those from before it
    assert list(RewardWeights().__dataclass_fields__)[-1] == "tracking_lin_vel_fine"
    assert "tracking_lin_vel_fine" not in _terms(_env().task)
    rewards = RewardWeights(tracking_lin_vel_fine=2.0)
    for sigma in (0.05, 0.02):
        task = _env(rewards=rewards, fine_tracking_sigma=sigma).task
        _set_state(task, lin_vel=(0.6, -0.2, 0), quat=(1, 0, 0, 0))  # 0.1 m/s off in x
        terms = _terms(task)
        dt = task.control_dt
        assert terms["tracking_lin_vel_fine"] == pytest.approx(2.0 * dt * math.exp(-0.01 / sigma))
        assert terms["tracking_lin_vel_fine"] / 2.0 < terms["tracking_lin_vel"]


@pytest.mark.parametrize(
    ("term", "state"),
    [
        ("lin_vel_z", {"lin_vel": (0, 0, 0.5)}),
        ("ang_vel_xy", {"ang_vel": (1.0, -1.0, 0)}),
        ("orientation", {"quat": (math.cos(0.15), math.sin(0.15), 0, 0)}),
    ],
)
def test_penalties_are_negative_when_violated_and_zero_at_rest(term, state):
    env = _env(reset_joint_noise=0.0)
    task = env.task
    _set_state(task, quat=(1, 0, 0, 0))
    assert _terms(task)[term] == pytest.approx(0.0, abs=1e-12)
    _set_state(task, **state)
    assert _terms(task)[term] < 0


def test_height_posture_action_rate_and_torque_penalties():
    env = _env(reset_joint_noise=0.0)
    task = env.task
    task.data.qpos[2] = task.base_height_target
    _set_state(task)
    rest = _terms(task)
    assert rest["base_height"] == pytest.approx(0.0, abs=1e-12)
    assert rest["joint_posture"] == pytest.approx(0.0, abs=1e-12)
    task.data.qpos[2] = task.base_height_target - 0.1
    task.data.qpos[7:] = DEFAULT_JOINT_POS + 0.2
    task.prev_action[:] = 0.0
    task.last_action[:] = 1.0
    mujoco.mj_step(task.model, task.data)  # actuator forces for the new targets
    _set_state(task)
    moved = _terms(task)
    assert moved["base_height"] < 0
    assert moved["joint_posture"] < 0
    assert moved["action_rate"] == pytest.approx(task.weights.action_rate * 12 * task.control_dt)
    assert moved["torques"] < 0


def test_feet_air_time_rewards_long_swings_and_ignores_standing_commands():
    env = _env(reset_joint_noise=0.0)
    task = env.task
    task._update_contacts()
    assert task.feet_contact_now.all(), "all four feet touch the ground at home"
    task.feet_contact[:] = False
    task.feet_air_time[:] = 0.5  # swung for 0.5 s, longer than the 0.25 s threshold
    assert _terms(task)["feet_air_time"] > 0
    task.feet_contact[:] = False
    task.feet_air_time[:] = 0.05  # a shuffle
    assert _terms(task)["feet_air_time"] < 0
    env.reset(seed=0, options={"command": (0.0, 0.0, 0.5)})
    task.feet_contact[:] = False
    task.feet_air_time[:] = 0.5
    assert _terms(task)["feet_air_time"] == 0.0


def test_zero_weight_switches_a_term_off():
    env = _env(rewards=RewardWeights(torques=0.0, feet_air_time=0.0))
    _, _, _, _, _ = env.step(np.zeros(12, dtype=np.float32))
    assert "torques" not in env.task.reward_terms
    assert "tracking_lin_vel" in env.task.reward_terms


def test_reward_is_never_negative_unless_asked():
    env = _env()
    task = env.task
    _set_state(task, lin_vel=(-1.0, 1.0, 1.0), ang_vel=(3.0, 3.0, 0))
    assert sum(_terms(task).values()) < 0
    assert task.reward(np.zeros(12), task.observe()) == 0.0
    raw = _env(only_positive_rewards=False)
    _set_state(raw.task, lin_vel=(-1.0, 1.0, 1.0), ang_vel=(3.0, 3.0, 0))
    assert raw.task.reward(np.zeros(12), raw.task.observe()) < 0


def test_tipped_robot_terminates_and_logs_its_episode():
    env = _env()
    roll = 1.3  # past the 1.0 rad tilt limit
    env.task.data.qpos[3:7] = (math.cos(roll / 2), math.sin(roll / 2), 0, 0)
    env.task.forward()
    _, _, terminated, truncated, info = env.step(np.zeros(12, dtype=np.float32))
    assert terminated and not truncated
    assert info["log"]["/metrics/survived"] == 0.0
    assert info["log"]["/metrics/episode_length_s"] == pytest.approx(0.02)


def test_base_on_the_ground_terminates():
    env = _env()
    env.task.data.qpos[2] = 0.03  # trunk resting on the floor
    env.task.forward()
    _, _, terminated, _, _ = env.step(np.zeros(12, dtype=np.float32))
    assert terminated


def test_standing_still_survives_and_reports_episode_means_at_the_time_limit():
    env = SimEnv(Go1VelocityTask(max_episode_steps=25, reset_joint_noise=0.0))
    env.reset(seed=1, options={"command": (0.0, 0.0, 0.0)})
    for step in range(25):
        _, reward, terminated, truncated, info = env.step(np.zeros(12, dtype=np.float32))
        assert not terminated
        assert reward >= 0
        assert ("log" in info) == (step == 24)
    assert truncated
    log = info["log"]
    assert log["/metrics/survived"] == 1.0
    # the soft servos (kp 35) let the base sag ~3 cm while it settles: a small drift, no walk
    assert log["/metrics/x_vel_mse"] < 0.05 and log["/metrics/y_vel_mse"] < 0.05
    assert log["/reward/tracking_lin_vel"] > 0.9 * 25 * 0.02
    assert {f"/reward/{name}" for name in RewardWeights().active()} <= set(log)


def test_commands_come_from_the_configured_ranges():
    env = SimEnv(Go1VelocityTask(commands=CommandRanges(vx=(0.4, 0.6), vy=(0, 0), yaw_rate=(0, 0))))
    for seed in range(5):
        env.reset(seed=seed)
        assert 0.4 <= env.task.command[0] <= 0.6
        assert env.task.command[1] == 0 and env.task.command[2] == 0
    with pytest.raises(ValueError, match="command"):
        env.reset(options={"command": (1.0, 2.0)})


def test_commands_are_resampled_at_the_interval_unless_fixed():
    ranges = CommandRanges(resample_s=0.06)  # every 3 decisions of 20 ms
    env = SimEnv(Go1VelocityTask(commands=ranges))
    env.reset(seed=0)
    seen = [env.task.command.copy()]
    for _ in range(7):
        env.step(np.zeros(12, dtype=np.float32))
        seen.append(env.task.command.copy())
    changes = [i for i in range(1, 8) if not np.array_equal(seen[i], seen[i - 1])]
    assert changes == [3, 6]
    assert all(-0.5 <= c[0] <= 1.0 and -0.3 <= c[1] <= 0.3 for c in seen)
    env.reset(seed=0, options={"command": COMMAND})
    for _ in range(7):
        env.step(np.zeros(12, dtype=np.float32))
    assert tuple(env.task.command) == COMMAND
    assert CommandRanges().resample_s is None


def test_domain_randomization_is_off_by_default_and_stays_in_range():
    plain = _env()
    floor = plain.task.model.geom("floor").id
    assert plain.task.model.geom_friction[floor, 0] == 1.0
    randomized = SimEnv(Go1VelocityTask(randomization=DomainRandomization(friction=(0.5, 0.6))))
    trunk_mass = []
    for seed in range(3):
        randomized.reset(seed=seed)
        model = randomized.task.model
        assert 0.5 <= model.geom_friction[model.geom("floor").id, 0] <= 0.6
        trunk_mass.append(float(model.body_mass[model.body("trunk").id]))
    assert len(set(trunk_mass)) == 3 and all(4.2 <= m <= 6.3 for m in trunk_mass)


def test_pushes_kick_the_base_at_the_interval():
    dr = DomainRandomization(friction=None, added_base_mass=None, push_interval_s=0.04)
    env = SimEnv(Go1VelocityTask(randomization=dr))
    env.reset(seed=0, options={"command": (0, 0, 0)})
    env.step(np.zeros(12, dtype=np.float32))
    before = env.task.data.qvel[0:2].copy()
    env.step(np.zeros(12, dtype=np.float32))  # step 2 = 0.04 s: pushed
    assert np.abs(env.task.data.qvel[0:2] - before).max() > 0.05


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"action_scale": 0.0}, "action_scale"),
        ({"max_tilt": float("nan")}, "max_tilt"),
        ({"cone": "round"}, "cone"),
        ({"reset_joint_noise": 2.0}, "reset_joint_noise"),
        ({"kp": -1.0}, r"kp=-1.0: expected None"),
        ({"terrain": "mud"}, r"terrain='mud': expected one of rigid, soil"),
        ({"terrain": "soil", "soil": "clay"}, r"soil preset 'clay'"),
        ({"terrain": "soil", "soil_window": 0.1}, "soil_window=0.1"),
        ({"terrain": "soil", "soil_resolution": 0.0}, "soil_resolution=0.0"),
    ],
)
def test_bad_settings_name_the_value(kwargs, message):
    with pytest.raises(ValueError, match=message):
        Go1VelocityTask(**kwargs)


def test_servo_gains_can_be_overridden():
    stiff, soft = _env(kp=None, kd=None).task, _env(kp=40.0, kd=0.5).task
    assert stiff.model.actuator_gainprm[0, 0] == pytest.approx(100.0)
    assert soft.model.actuator_gainprm[:, 0] == pytest.approx(np.full(12, 40.0))
    assert soft.model.actuator_biasprm[:, 1:3] == pytest.approx(np.tile([-40.0, -0.5], (12, 1)))
    for task in (stiff, soft):  # the same target error gives a force proportional to kp
        task.data.qpos[7:] = DEFAULT_JOINT_POS
        task.data.qvel[:] = 0.0
        task.data.ctrl[:] = DEFAULT_JOINT_POS + 0.05
        mujoco.mj_forward(task.model, task.data)
    assert soft.data.actuator_force[0] == pytest.approx(40.0 * 0.05)
    assert stiff.data.actuator_force[0] == pytest.approx(100.0 * 0.05)


def test_bad_config_values_name_the_field():
    with pytest.raises(ValueError, match="vx"):
        CommandRanges(vx=(1.0, -1.0))
    with pytest.raises(ValueError, match="resample_s=0"):
        CommandRanges(resample_s=0)
    with pytest.raises(ValueError, match="torques"):
        RewardWeights(torques=float("inf"))
    with pytest.raises(ValueError, match="friction"):
        DomainRandomization(friction=(0.0, 1.0))


def _soil_env(**kwargs) -> SimEnv:
    env = SimEnv(Go1VelocityTask(terrain="soil", reset_joint_noise=0.0, **kwargs))
    env.reset(seed=0, options={"command": (0.0, 0.0, 0.0)})
    return env


def test_soil_carries_the_standing_robot_and_reset_restores_it():
    env = _soil_env()
    task = env.task
    assert (task.dt, task.k) == (0.002, 10)
    assert task.advanceables[0] is task.soil
    for _ in range(50):
        env.step(np.zeros(12, dtype=np.float32))
    forces = task.soil.body_forces
    assert task.feet_contact_now.all()  # every leg stands on the soil
    assert forces[:, 2].sum() == pytest.approx(task.model.body_subtreemass[1] * 9.81, rel=0.1)
    assert task.data.ncon == 0  # the floor no longer touches the legs
    ruts = task.soil.plastic_sinkage.max()
    assert 0.005 < ruts < 0.1  # Chrono's "firm" soil: a few cm under a 12 kg robot
    assert 0.15 < task.data.qpos[2] < task.base_height_target
    env.reset(seed=0, options={"command": (0.0, 0.0, 0.0)})
    assert task.soil.plastic_sinkage.max() == 0.0 and task.soil.grid.offset == (0, 0)


def test_the_soil_window_follows_the_trunk():
    env = _soil_env(soil_window=1.0)
    task = env.task
    task.data.qpos[0] += 2.0  # carry the robot 2 m along x, off the first window
    task.forward()
    for _ in range(30):
        env.step(np.zeros(12, dtype=np.float32))
    assert abs(task.soil.grid.center[0] - task.data.qpos[0]) <= 0.25
    assert task.feet_contact_now.all() and task.data.qpos[2] > 0.15  # still on the soil


def _ray_matches_gymnasium(num_envs: int, envs_per_worker: int, steps: int, **kwargs) -> None:
    """RayVectorEnv == Gymnasium's SyncVectorEnv bit for bit (SAME_STEP, random actions), and
    some episode was truncated and restarted on the way."""
    from gymnasium.utils.env_checker import data_equivalence

    same_step = gym.vector.AutoresetMode.SAME_STEP
    ray_vec = chronogym.make_vec(
        "chronogym/Go1Velocity-v0", num_envs, backend="ray", envs_per_worker=envs_per_worker,
        autoreset_mode=same_step, env_kwargs=kwargs,
    )  # fmt: skip
    sync_vec = gym.make_vec(
        "chronogym/Go1Velocity-v0", num_envs, vectorization_mode="sync",
        vector_kwargs={"autoreset_mode": same_step}, **kwargs,
    )  # fmt: skip
    rng_actions = np.random.default_rng(1).normal(0, 1, (steps, num_envs, 12)).astype(np.float32)
    try:
        results = []
        for vec in (ray_vec, sync_vec):
            obs, _ = vec.reset(seed=5)
            trajectory = [obs]
            for actions in rng_actions:
                obs, reward, terminated, truncated, infos = vec.step(actions)
                trajectory.append((obs, reward, terminated, truncated, infos.get("final_obs")))
            results.append(trajectory)
        assert data_equivalence(results[0], results[1], exact=True)
        assert any(step[3].any() for step in results[0][1:])  # episodes ended and restarted
    finally:
        ray_vec.close()
        sync_vec.close()


def test_same_seed_same_trajectory_on_ray_and_in_gymnasium(ray_cluster):
    """Go1 with every randomization on: RayVectorEnv (2 workers) == Gymnasium's SyncVectorEnv."""
    randomization = DomainRandomization(push_interval_s=0.1)
    _ray_matches_gymnasium(3, 2, 30, randomization=randomization, max_episode_steps=12)


def test_same_seed_same_trajectory_on_soil_on_ray_and_in_gymnasium(ray_cluster):
    """Go1 on soil (fresh soil after each reset): Ray (2 workers) == SyncVectorEnv."""
    _ray_matches_gymnasium(2, 1, 20, terrain="soil", max_episode_steps=8)


def test_feet_slip_penalizes_feet_that_slide_on_the_ground_only():
    env = _env(reset_joint_noise=0.0, rewards=RewardWeights(feet_slip=-0.25))
    task = env.task
    assert _terms(task)["feet_slip"] == pytest.approx(0.0, abs=1e-12)  # nothing moved yet
    task.data.qpos[0] += 0.01  # the whole robot, feet on the ground, slid 1 cm in one step
    mujoco.mj_forward(task.model, task.data)
    expected = -0.25 * 4 * (0.01 / task.control_dt) ** 2 * task.control_dt
    assert _terms(task)["feet_slip"] == pytest.approx(expected, rel=1e-6)
    assert _terms(task)["feet_slip"] == pytest.approx(0.0, abs=1e-12)  # and then stood still
    task.data.qpos[2] += 0.2  # lifted off the ground: no foot is in contact
    task.data.qpos[0] += 0.01
    mujoco.mj_forward(task.model, task.data)
    assert _terms(task)["feet_slip"] == pytest.approx(0.0, abs=1e-12)


def test_feet_slip_is_off_by_default():
    assert RewardWeights().feet_slip == 0.0
    assert "feet_slip" not in _env().task.reward_terms
