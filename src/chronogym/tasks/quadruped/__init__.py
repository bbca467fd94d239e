"""Quadruped tasks: a mesh-free MuJoCo model of the Unitree Go1 (12 DoF) and velocity tracking.

``load_go1()`` compiles the bundled ``go1.xml`` and returns ``(model, data)`` at the ``home``
keyframe; the constants describe its joint order (FR, FL, RR, RL; hip, thigh, calf per leg).
``Go1VelocityTask`` (Gymnasium id ``chronogym/Go1Velocity-v0``) is the paper's locomotion task;
``ChronoGo1VelocityTask`` (``chronogym/ChronoGo1Velocity-v0``, needs PyChrono) is the same task
in Project Chrono, sharing ``Go1VelocityBase``'s code and its settings, ``Go1TaskConfig``.
"""

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
from chronogym.tasks.quadruped.model import *  # noqa: F403  (re-exported names)
from chronogym.tasks.quadruped.model import __all__ as _model_names
from chronogym.tasks.quadruped.task import Go1VelocityTask
from chronogym.tasks.quadruped.velocity import Go1VelocityBase

__all__ = [
    *_model_names,
    "OBS_DIM",
    "OBS_SCALES",
    "OBS_SLICES",
    "ChronoGo1Settings",
    "ChronoGo1VelocityTask",
    "CommandRanges",
    "DomainRandomization",
    "Go1TaskConfig",
    "Go1VelocityBase",
    "Go1VelocityTask",
    "RewardWeights",
]
