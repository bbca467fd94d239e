"""Everything about the Unitree Go1 (12 DoF): its model, its velocity-tracking task in two
engines, and how a policy for it is trained, evaluated and played back.

``load_go1()`` compiles the bundled ``go1.xml`` and returns ``(model, data)`` at the ``home``
keyframe; the constants describe its joint order (FR, FL, RR, RL; hip, thigh, calf per leg).
``Go1VelocityTask`` (Gymnasium id ``chronogym/Go1Velocity-v0``) is the paper's locomotion task;
``ChronoGo1VelocityTask`` (``chronogym/ChronoGo1Velocity-v0``, needs PyChrono) is the same task
in Project Chrono, sharing ``Go1VelocityBase``'s code and its settings, ``Go1TaskConfig``.

The modules, one job each:

* ``model.py`` -- the MJCF model and its constants; ``chrono_model.py`` -- the same robot
  built in Chrono.
* ``config.py`` -- the task's settings (``Go1TaskConfig``) and observation layout.
* ``engines.py`` -- which engine runs which terrain, under which Gymnasium id.
* ``velocity.py`` -- the engine-independent task (``Go1VelocityBase``); ``task.py`` (MuJoCo)
  and ``chrono_task.py`` (Chrono) implement its engine hooks.
* ``training.py`` -- PPO defaults, vector envs and ``train_quadruped``
  (``chronogym train quadruped``).
* ``evaluation.py`` -- rollouts, the summary table and the walking criterion that picks
  ``best.pt``; ``play.py`` -- ``play_quadruped`` (``chronogym play quadruped``).

Names are imported lazily: ``import chronogym.tasks.quadruped`` imports no MuJoCo, PyChrono
or torch until one of its names is used.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from chronogym._lazy import lazy_exports

_MODEL = "chronogym.tasks.quadruped.model"
_CONFIG = "chronogym.tasks.quadruped.config"

_EXPORTS = {
    **dict.fromkeys(
        (
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
        ),
        _MODEL,
    ),
    **dict.fromkeys(("OBS_DIM", "OBS_SCALES", "OBS_SLICES"), _CONFIG),
    "ChronoGo1Settings": "chronogym.tasks.quadruped.chrono_model",
    "ChronoGo1VelocityTask": "chronogym.tasks.quadruped.chrono_task",
    "CommandRanges": _CONFIG,
    "DomainRandomization": _CONFIG,
    "Go1TaskConfig": _CONFIG,
    "Go1VelocityBase": "chronogym.tasks.quadruped.velocity",
    "Go1VelocityTask": "chronogym.tasks.quadruped.task",
    "RewardWeights": _CONFIG,
}

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
    "OBS_DIM",
    "OBS_SCALES",
    "OBS_SLICES",
    "TORQUE_LIMITS",
    "ChronoGo1Settings",
    "ChronoGo1VelocityTask",
    "CommandRanges",
    "DomainRandomization",
    "Go1TaskConfig",
    "Go1VelocityBase",
    "Go1VelocityTask",
    "RewardWeights",
    "go1_xml_path",
    "load_go1",
]

if TYPE_CHECKING:
    from chronogym.tasks.quadruped.chrono_model import ChronoGo1Settings
    from chronogym.tasks.quadruped.chrono_task import ChronoGo1VelocityTask
    from chronogym.tasks.quadruped.config import (
        OBS_DIM,
        OBS_SCALES,
        OBS_SLICES,
        CommandRanges,
        DomainRandomization,
        Go1TaskConfig,
        RewardWeights,
    )
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
    from chronogym.tasks.quadruped.task import Go1VelocityTask
    from chronogym.tasks.quadruped.velocity import Go1VelocityBase

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
