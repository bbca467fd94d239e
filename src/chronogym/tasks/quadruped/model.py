"""Loader and constants for the mesh-free Unitree Go1 model in ``go1.xml``.

Leg order everywhere is FR, FL, RR, RL; per leg the joints are hip (abduction), thigh (hip
pitch) and calf (knee). Arrays below follow that order, which is also the order of the model's
joints, actuators and ``qpos[7:]``. See the header of ``go1.xml`` for where the figures come from.
"""

from __future__ import annotations

import pathlib

import mujoco
import numpy as np

__all__ = [
    "ACTUATOR_NAMES",
    "BASE_BODY_NAME",
    "CAMERA_NAME",
    "DEFAULT_JOINT_POS",
    "FOOT_GEOM_NAMES",
    "FOOT_SITE_NAMES",
    "HOME_BASE_HEIGHT",
    "HOME_KEYFRAME",
    "IMU_SITE_NAME",
    "JOINT_NAMES",
    "JOINT_VELOCITY_LIMITS",
    "KP",
    "KV",
    "LEG_NAMES",
    "TORQUE_LIMITS",
    "go1_xml_path",
    "load_go1",
]


def _frozen(values: list[float]) -> np.ndarray:
    array = np.array(values, dtype=np.float64)
    array.setflags(write=False)
    return array


LEG_NAMES: tuple[str, ...] = ("FR", "FL", "RR", "RL")
_PARTS: tuple[str, ...] = ("hip", "thigh", "calf")

JOINT_NAMES: tuple[str, ...] = tuple(f"{leg}_{part}_joint" for leg in LEG_NAMES for part in _PARTS)
ACTUATOR_NAMES: tuple[str, ...] = tuple(
    f"{leg}_{part}_motor" for leg in LEG_NAMES for part in _PARTS
)
FOOT_GEOM_NAMES: tuple[str, ...] = tuple(f"{leg}_foot" for leg in LEG_NAMES)
FOOT_SITE_NAMES: tuple[str, ...] = FOOT_GEOM_NAMES  # sites share the geoms' names
BASE_BODY_NAME = "trunk"
IMU_SITE_NAME = "imu"
CAMERA_NAME = "track"
HOME_KEYFRAME = "home"
HOME_BASE_HEIGHT = 0.27  # m, base (trunk origin) height in the home keyframe

#: Home joint targets (rad), (hip, thigh, calf) = (0, 0.9, -1.8) for each leg.
DEFAULT_JOINT_POS: np.ndarray = _frozen([0.0, 0.9, -1.8] * 4)
#: Motor torque limits (N m): 23.7 for hip and thigh, 35.55 for the knee (1.5x linkage).
TORQUE_LIMITS: np.ndarray = _frozen([23.7, 23.7, 35.55] * 4)
#: Published joint speed limits (rad/s). Not enforced by the model; for the task to use.
JOINT_VELOCITY_LIMITS: np.ndarray = _frozen([30.1, 30.1, 20.06] * 4)
#: Position-servo gains of every actuator (N m/rad and N m s/rad).
KP = 100.0
KV = 2.0


def go1_xml_path() -> pathlib.Path:
    """Path of the self-contained Go1 MJCF (no meshes, no asset files)."""
    return pathlib.Path(__file__).resolve().with_name("go1.xml")


def load_go1() -> tuple[mujoco.MjModel, mujoco.MjData]:
    """Compile ``go1.xml`` and return ``(model, data)`` with data at the ``home`` keyframe.

    ``data.ctrl`` holds the home joint targets and ``mj_forward`` has been run, so positions,
    contacts and sensors are current.
    """
    model = mujoco.MjModel.from_xml_path(str(go1_xml_path()))
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key(HOME_KEYFRAME).id)
    mujoco.mj_forward(model, data)
    return model, data
