"""The mesh-free Unitree Go1 MJCF: totals, keyframe, standing, actuator limits, offline load."""

from __future__ import annotations

import shutil
import socket

import mujoco
import numpy as np
import pytest

from chronogym.tasks.quadruped import (
    ACTUATOR_NAMES,
    BASE_BODY_NAME,
    DEFAULT_JOINT_POS,
    FOOT_GEOM_NAMES,
    HOME_BASE_HEIGHT,
    IMU_SITE_NAME,
    JOINT_NAMES,
    KP,
    KV,
    TORQUE_LIMITS,
    go1_xml_path,
    load_go1,
)

# Published Go1 joint ranges (rad) and motor torque limits (N m) per joint type.
JOINT_RANGES = {"hip": (-0.863, 0.863), "thigh": (-0.686, 4.501), "calf": (-2.818, -0.888)}
TORQUE_BY_TYPE = {"hip": 23.7, "thigh": 23.7, "calf": 35.55}


@pytest.fixture(scope="module")
def model() -> mujoco.MjModel:
    return load_go1()[0]


def _joint_type(name: str) -> str:
    return name.split("_")[1]


def test_model_totals(model):
    assert (model.nq, model.nv, model.nu) == (19, 18, 12)
    assert mujoco.mj_getTotalmass(model) == pytest.approx(12.74, rel=0.02)
    assert model.body(BASE_BODY_NAME).id == model.jnt_bodyid[0]
    assert model.jnt_type[0] == mujoco.mjtJoint.mjJNT_FREE
    assert [model.joint(i).name for i in range(1, model.njnt)] == list(JOINT_NAMES)
    assert [model.actuator(i).name for i in range(model.nu)] == list(ACTUATOR_NAMES)
    # Actuator i drives joint i (leg order FR, FL, RR, RL).
    assert list(model.actuator_trnid[:, 0]) == [model.joint(n).id for n in JOINT_NAMES]
    feet = [model.geom(n) for n in FOOT_GEOM_NAMES]
    assert len(feet) == 4
    assert all(f.type[0] == mujoco.mjtGeom.mjGEOM_SPHERE for f in feet)
    assert model.nmesh == 0 and model.nhfield == 0
    model.site(IMU_SITE_NAME)  # raises if missing
    model.camera("track")
    assert model.opt.cone == mujoco.mjtCone.mjCONE_PYRAMIDAL


def test_home_keyframe():
    model, data = load_go1()
    assert data.qpos[2] == pytest.approx(0.27)
    assert data.qpos[2] == pytest.approx(HOME_BASE_HEIGHT)
    np.testing.assert_allclose(data.qpos[3:7], [1.0, 0.0, 0.0, 0.0])
    np.testing.assert_allclose(data.qpos[7:], DEFAULT_JOINT_POS)
    np.testing.assert_allclose(data.ctrl, DEFAULT_JOINT_POS)
    np.testing.assert_allclose(DEFAULT_JOINT_POS, [0.0, 0.9, -1.8] * 4)
    assert np.all(data.qvel == 0.0)
    # Home pose is inside every joint's range.
    lo, hi = model.jnt_range[1:].T
    assert np.all((lo < DEFAULT_JOINT_POS) & (hi > DEFAULT_JOINT_POS))


def test_stands_stably_for_two_seconds():
    model, data = load_go1()
    trunk = model.body(BASE_BODY_NAME).id
    foot_ids = {model.geom(n).id for n in FOOT_GEOM_NAMES}
    floor = model.geom("floor").id
    steps = round(2.0 / model.opt.timestep)
    heights = np.empty(steps)
    for i in range(steps):
        mujoco.mj_step(model, data)
        heights[i] = data.xpos[trunk, 2]
    assert np.all(np.isfinite(data.qpos))
    assert not any(w.number for w in data.warning)
    assert abs(heights[-1] - 0.27) < 0.03
    assert np.all(np.abs(heights[steps // 2 :] - 0.27) < 0.03)
    assert data.xmat[trunk, 8] > 0.99  # trunk z-axis still points up
    assert np.linalg.norm(data.qvel) < 0.05  # settled
    np.testing.assert_allclose(data.qpos[7:], DEFAULT_JOINT_POS, atol=0.15)
    # Only the four feet touch the ground, and all four do.
    touching = set()
    for c in data.contact[: data.ncon]:
        pair = {c.geom1, c.geom2}
        assert floor in pair
        (other,) = pair - {floor}
        assert other in foot_ids, model.geom(other).name
        touching.add(other)
    assert touching == foot_ids


def test_actuator_torque_and_range_limits(model):
    for i, name in enumerate(JOINT_NAMES):
        kind = _joint_type(name)
        act = model.actuator(ACTUATOR_NAMES[i])
        joint = model.joint(name)
        limit = TORQUE_BY_TYPE[kind]
        assert TORQUE_LIMITS[i] == limit
        np.testing.assert_allclose(act.forcerange, [-limit, limit])
        assert model.actuator_forcelimited[i]
        np.testing.assert_allclose(joint.range, JOINT_RANGES[kind])
        np.testing.assert_allclose(act.ctrlrange, joint.range)
        assert model.actuator_ctrllimited[i] and model.jnt_limited[joint.id]
        # Position servo: force = kp * (ctrl - q) - kv * qdot.
        assert act.dyntype[0] == mujoco.mjtDyn.mjDYN_NONE
        assert act.gainprm[0] == KP == 100.0
        np.testing.assert_allclose(act.biasprm[:3], [0.0, -KP, -KV])
    # The clamp really applies: a huge target error yields exactly the limit.
    _, data = load_go1()
    data.ctrl[:] = [r[1] for r in model.actuator_ctrlrange]
    mujoco.mj_forward(model, data)
    np.testing.assert_allclose(np.abs(data.actuator_force), TORQUE_LIMITS)


def test_robot_geoms_only_collide_with_environment(model):
    floor = model.geom("floor").id
    assert model.geom_contype[floor] & 1 and model.geom_conaffinity[floor] & 1
    for g in range(model.ngeom):
        if g == floor:
            continue
        assert model.geom_contype[g] == 0, model.geom(g).name  # no robot-robot pairs
        assert model.geom_conaffinity[g] & model.geom_contype[floor]  # but hits the floor
    assert model.geom_friction[floor][0] == pytest.approx(1.0)


def test_loads_offline_from_the_lone_xml(tmp_path, monkeypatch):
    text = go1_xml_path().read_text()
    assert "file=" not in text and "<include" not in text
    lone = tmp_path / "go1.xml"
    shutil.copy(go1_xml_path(), lone)

    def no_network(*args, **kwargs):
        raise AssertionError("go1.xml must load without network access")

    monkeypatch.setattr(socket, "socket", no_network)
    monkeypatch.setattr(socket, "create_connection", no_network)
    from_file = mujoco.MjModel.from_xml_path(str(lone))
    from_text = mujoco.MjModel.from_xml_string(text, {})  # no asset dictionary at all
    for m in (from_file, from_text):
        assert (m.nq, m.nv, m.nu, m.nmesh) == (19, 18, 12, 0)
        assert mujoco.mj_getTotalmass(m) == pytest.approx(12.74, rel=0.02)
