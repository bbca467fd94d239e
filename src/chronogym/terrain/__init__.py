"""Deformable terrain: Project Chrono's Soil Contact Model (SCM) for MuJoCo bodies.

``SoilParameters`` and the presets need only NumPy; ``MujocoSoil`` imports MuJoCo when it is
first stepped. See ``chronogym.terrain.mujoco_soil`` for the coupling and ``scm`` for the model.
"""

from chronogym.terrain.mujoco_soil import MujocoSoil, exclude_ground_contacts
from chronogym.terrain.params import SOIL_PRESETS, SoilParameters, soil_preset
from chronogym.terrain.scm import ScmLaw, SoilGrid, patch_inverse_width

__all__ = [
    "SOIL_PRESETS",
    "MujocoSoil",
    "ScmLaw",
    "SoilGrid",
    "SoilParameters",
    "exclude_ground_contacts",
    "patch_inverse_width",
    "soil_preset",
]
