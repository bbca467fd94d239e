"""Quadruped tasks: a mesh-free MuJoCo model of the Unitree Go1 (12 DoF).

``load_go1()`` compiles the bundled ``go1.xml`` and returns ``(model, data)`` at the ``home``
keyframe; the constants describe its joint order (FR, FL, RR, RL; hip, thigh, calf per leg).
"""

from chronogym.tasks.quadruped.model import *  # noqa: F403  (re-exported names)
from chronogym.tasks.quadruped.model import __all__ as __all__
