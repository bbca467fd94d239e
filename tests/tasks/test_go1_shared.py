"""The Go1 task's engine-independent parts, tested without PyChrono: the code both engines
share, the Chrono model's layout read off the MJCF, the servo law against MuJoCo's
actuators, and the engine checks of the CLI."""

from __future__ import annotations

import subprocess
import sys

import mujoco
import numpy as np
import pytest

from chronogym.env import SimEnv
from chronogym.tasks.quadruped import JOINT_NAMES, TORQUE_LIMITS, Go1VelocityTask, go1_xml_path
from chronogym.tasks.quadruped.chrono_model import (
    ChronoGo1Settings,
    go1_layout,
    limit_torque,
    quat_to_matrix,
    servo_torque,
)
from chronogym.tasks.quadruped.chrono_task import ChronoGo1VelocityTask
from chronogym.tasks.quadruped.velocity import Go1VelocityBase

COMMAND = (0.5, 0.0, 0.0)
SHARED = (
    "reset",
    "apply_action",
    "observe",
    "reward",
    "terminated",
    "info",
    "compute_reward_terms",
    "_raw_terms",
    "_draw_command",
)


@pytest.mark.parametrize("name", SHARED)
def test_both_engines_run_the_same_task_code(name):
    shared = getattr(Go1VelocityBase, name)
    assert getattr(Go1VelocityTask, name) is shared
    assert getattr(ChronoGo1VelocityTask, name) is shared


def test_layout_keeps_the_mjcf_masses_inertias_and_joints():
    model = mujoco.MjModel.from_xml_path(str(go1_xml_path()))
    layout = go1_layout()
    assert [b.name for b in layout.bodies][:4] == ["trunk", "FR_hip", "FR_thigh", "FR_calf"]
    assert sum(b.mass for b in layout.bodies) == pytest.approx(float(model.body_mass.sum()))
    for joint in layout.joints:
        j = model.joint(joint.name).id
        body = layout.bodies[joint.child]
        rot = quat_to_matrix(body.quat)  # principal axes in the world
        axis = rot.T @ joint.axis
        principal = model.body_inertia[model.jnt_bodyid[j]]
        # the armature is added about the joint axis, nowhere else
        added = body.inertia - np.diag(principal)
        np.testing.assert_allclose(
            added, model.dof_armature[model.jnt_dofadr[j]] * np.outer(axis, axis)
        )
        # the joint frame's z is the joint axis
        np.testing.assert_allclose(quat_to_matrix(joint.quat)[:, 2], joint.axis, atol=1e-12)
        assert layout.bodies[joint.parent].mujoco_id == model.body_parentid[body.mujoco_id]
    assert [j.name for j in layout.joints] == list(JOINT_NAMES)
    np.testing.assert_array_equal(layout.joint_ranges, [model.joint(n).range for n in JOINT_NAMES])
    kinds = sorted((s.kind, s.foot) for s in layout.shapes)
    assert kinds.count(("sphere", True)) == 4  # the feet; calf capsules are left out
    assert {k for k, _ in kinds} == {"box", "cylinder", "capsule", "sphere"}
    assert np.all(layout.joint_inertia > np.tile([0.00448, 0.00448, 0.01008], 4))


def test_servo_law_matches_mujocos_position_actuators():
    env = SimEnv(Go1VelocityTask())  # kp 35, kd 0.5
    env.reset(seed=0)
    task = env.task
    model, data = task.model, task.data
    rng = np.random.default_rng(1)
    ranges = np.array([model.joint(n).range for n in JOINT_NAMES])
    for _ in range(20):
        data.qpos[7:] = rng.uniform(ranges[:, 0], ranges[:, 1])
        data.qvel[6:] = rng.normal(scale=5.0, size=12)
        data.ctrl[:] = rng.uniform(ranges[:, 0] - 1, ranges[:, 1] + 1)
        mujoco.mj_forward(model, data)
        targets = np.clip(data.ctrl, ranges[:, 0], ranges[:, 1])  # MuJoCo clamps ctrl
        ours = servo_torque(data.qpos[7:], data.qvel[6:], targets, 35.0, 0.5)
        np.testing.assert_allclose(ours, data.actuator_force, rtol=1e-12, atol=1e-12)
    assert np.abs(ours).max() <= TORQUE_LIMITS.max()
    env.close()


def test_joint_limit_only_pushes_back_into_the_range():
    low, high = np.array([-1.0, -1.0, -1.0]), np.array([1.0, 1.0, 1.0])
    k, b = np.full(3, 100.0), np.full(3, 10.0)
    q = np.array([0.5, 1.1, -1.2])
    torque = limit_torque(q, np.zeros(3), low, high, k, b)
    np.testing.assert_allclose(torque, [0.0, -10.0, 20.0])
    # moving back inward fast: the damper does not pull the joint outward
    torque = limit_torque(q, np.array([0.0, -5.0, 5.0]), low, high, k, b)
    np.testing.assert_array_equal(torque, [0.0, 0.0, 0.0])


def test_chrono_go1_envelope_depends_on_the_ground_unless_set():
    """Bullet's envelope finds rigid contacts early but widens what SCM's ray casts see, so the
    default is 5 mm on rigid ground and 0.1 mm on soil; a value set by hand is kept."""
    default = ChronoGo1Settings()
    assert default.collision_margins(rigid_ground=True) == (0.005, 0.002)
    assert default.collision_margins(rigid_ground=False) == (1e-4, 1e-4)
    chosen = ChronoGo1Settings(envelope=0.003, margin=0.001)
    assert chosen.collision_margins(rigid_ground=False) == (0.003, 0.001)
    with pytest.raises(ValueError, match=r"envelope=0: expected None or a finite float > 0"):
        ChronoGo1Settings(envelope=0)


def test_chrono_task_rejects_bad_input_before_building():
    with pytest.raises(ValueError, match=r"terrain='soil'.*chronogym/Go1Velocity-v0"):
        ChronoGo1VelocityTask(terrain="soil")
    with pytest.raises(ValueError, match=r"terrain='sand': expected one of rigid, scm"):
        ChronoGo1VelocityTask(terrain="sand")
    with pytest.raises(ValueError, match=r"contact='penalty': expected one of nsc, smc"):
        ChronoGo1Settings(contact="penalty")
    with pytest.raises(ValueError, match=r"friction=-1: expected None or a float > 0"):
        ChronoGo1Settings(friction=-1)
    with pytest.raises(ValueError, match=r"collision='gpu': expected one of bullet, multicore"):
        ChronoGo1Settings(collision="gpu")
    multicore = ChronoGo1Settings(collision="multicore")
    with pytest.raises(ValueError, match=r"collision='multicore' on terrain='rigid'.*'scm'"):
        ChronoGo1VelocityTask(terrain="rigid", settings=multicore)
    with pytest.raises(ValueError, match=r"action_scale=0: expected a finite float > 0"):
        ChronoGo1VelocityTask(action_scale=0)
    with pytest.raises(ValueError, match=r"terrain='scm'.*ChronoGo1Velocity-v0"):
        Go1VelocityTask(terrain="scm")


NO_PYCHRONO_CLI = """
import sys
sys.modules["pychrono"] = None  # as if PyChrono were not installed
from chronogym.cli import main
try:
    main(sys.argv[1:])
except SystemExit as exc:
    print("EXIT:", exc)
import ray
print("RAY_STARTED:", ray.is_initialized())
"""


@pytest.mark.parametrize(
    ("argv", "expected"),
    [
        (["train", "quadruped", "--engine", "chrono", "--iterations", "1"], "conda install"),
        (["play", "quadruped", "README.md", "--engine", "chrono"], "conda install"),
        (
            ["train", "quadruped", "--engine", "chrono", "--terrain", "soil", "--iterations", "1"],
            "terrain='soil': expected one of rigid, scm on engine 'chrono' (terrain 'soil' "
            "runs on engine 'mujoco')",
        ),
    ],
)
def test_cli_engine_chrono_fails_clearly_before_ray_starts(argv, expected):
    result = subprocess.run(
        [sys.executable, "-c", NO_PYCHRONO_CLI, *argv],
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert result.returncode == 0, result.stderr
    assert "EXIT: chronogym" in result.stdout and expected in result.stdout
    assert "RAY_STARTED: False" in result.stdout


def test_run_episode_reports_errors_under_a_shorter_time_limit():
    """``gym.make(..., max_episode_steps=N)`` ends episodes before the task logs its metrics
    (``chronogym play --steps``, ``sim_to_sim.py``): the errors come out the same."""
    import gymnasium as gym

    from chronogym.tasks.quadruped.evaluation import run_episode

    def policy(obs):
        return np.zeros(12, dtype=np.float32)

    task_horizon = run_episode(SimEnv(Go1VelocityTask(max_episode_steps=50)), policy, COMMAND, 0)
    wrapper = gym.make("chronogym/Go1Velocity-v0", max_episode_steps=50)
    time_limit = run_episode(wrapper, policy, COMMAND, 0)
    assert task_horizon.survived and time_limit.survived
    assert time_limit.x_vel_mse == pytest.approx(task_horizon.x_vel_mse, rel=1e-12)
    assert time_limit.y_vel_mse == pytest.approx(task_horizon.y_vel_mse, rel=1e-12)
    assert task_horizon.x_vel_mse > 0.1  # standing still against a 0.5 m/s command


def test_one_soil_preset_gives_chronos_scm_arguments_in_order():
    from chronogym.engines.chrono_scm import chrono_soil_arguments
    from chronogym.terrain import soil_preset

    assert chrono_soil_arguments(soil_preset("mars")) == (
        0.82e6,
        1.4e3,
        1.0,
        170.0,
        35.0,
        0.0178,
        2e8,
        3e4,
    )


def test_chrono_scm_rejects_bad_geometry_before_importing_pychrono():
    from chronogym.engines.chrono_scm import ChronoSCM
    from chronogym.terrain import soil_preset

    firm = soil_preset("firm")
    with pytest.raises(ValueError, match=r"params='firm': expected a chronogym SoilParameters"):
        ChronoSCM(None, "firm", (1.0, 1.0), 0.01, [])
    with pytest.raises(ValueError, match=r"size=\(1.0, -1.0\): expected \(x, y\) extents > 0"):
        ChronoSCM(None, firm, (1.0, -1.0), 0.01, [])
    with pytest.raises(ValueError, match=r"resolution=0.8: expected a grid spacing > 0 and at"):
        ChronoSCM(None, firm, (1.0, 1.0), 0.8, [])
