"""Quadruped tasks: a mesh-free MuJoCo model of the Unitree Go1 (12 DoF).

``load_go1()`` compiles the bundled ``go1.xml`` and returns ``(model, data)`` at the ``home``
keyframe; the constants describe its joint order (FR, FL, RR, RL; hip, thigh, calf per leg).
"""

from chronogym.tasks.quadruped.model import (
    ACTUATOR_NAMES,
    BASE_BODY_NAME,
    CAMERA_NAME,
    DEFAULT_JOINT_POS,
    FOOT_GEOM_NAMES,
    FOOT_SITE_NAMES,
    HOME_BASE_HEIGHT,
    HOME_KEYFRAME,
    IMU_SITE_NAME,
    JOINT_NAMES,
    JOINT_VELOCITY_LIMITS,
    KP,
    KV,
    LEG_NAMES,
    TORQUE_LIMITS,
    go1_xml_path,
    load_go1,
)

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
