"""The ground under the lander, for every engine: :class:`Terrain` (rigid plane, slope, rocks
or soil) and :func:`terrain_params` (the time step soil needs).

Each engine builds what it supports: the MuJoCo model (:mod:`.mujoco.model`) the inclined
plane, the rocks and (with ``chronogym.terrain.MujocoSoil``) the soil; the Chrono lander
flat ground, rigid or Chrono's own SCM soil with the same preset
(:func:`.chrono.model.check_chrono_terrain`).
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

import numpy as np

from chronogym.tasks.lander.design import LanderParams
from chronogym.terrain.params import SoilParameters, soil_preset
from chronogym.validation import check_positive

__all__ = ["Terrain", "terrain_params"]


@dataclass(frozen=True)
class Terrain:
    """Ground under the lander.

    Attributes:
        slope: inclination of the ground plane [rad], downhill towards world +x
            (0: flat).  Must be in [0, 20 deg] (landing-site slope requirements are
            typically <= 15 deg).
        n_rocks: number of rocks (0: none).  Rocks are spheres and boxes, partly buried
            (top 1.2 sizes above the plane), scattered by the landing's ``seed``
            uniformly over the ring where pads can land for any design in
            :data:`DESIGN_BOUNDS` (0.3 m inside the innermost to 0.3 m outside the
            outermost pad position), so the same seed gives the same terrain for every
            design.
        rock_size: (min, max) rock radius / box half-size [m].
        soil: ``None`` (rigid ground) or the SCM soil under the pads and the chassis: a
            preset name of ``chronogym.terrain.SOIL_PRESETS`` or a ``SoilParameters``.
            Level ground only (``slope`` 0); rocks stay rigid.
        soil_extent: side of the square soil patch centred under the lander [m].  The
            pads land at most 2.78 m from the axis (pad rim, ``alpha2`` = 50 deg); 7 m
            leaves 0.7 m for sliding or a horizontal touchdown speed.
        soil_resolution: soil grid spacing [m].  On ``"mars"`` soil the default design's
            sinkage, ``E_abs`` and ``a_max`` change by < 0.5 % from 2 cm to 1 cm (1.6 %
            at 3 cm); 2 cm puts about 180 nodes under each 0.3 m pad.
    """

    slope: float = 0.0
    n_rocks: int = 0
    rock_size: tuple[float, float] = (0.05, 0.15)
    soil: SoilParameters | str | None = None
    soil_extent: float = 7.0
    soil_resolution: float = 0.02

    def __post_init__(self) -> None:
        if not 0.0 <= self.slope <= math.radians(20.0):
            raise ValueError(f"slope={self.slope!r} rad must be in [0, {math.radians(20):.4f}]")
        if self.soil is not None:
            self._check_soil()
        if self.n_rocks < 0:
            raise ValueError(f"n_rocks={self.n_rocks!r} must be >= 0")
        lo, hi = self.rock_size
        if not 0 < lo <= hi:
            raise ValueError(f"rock_size={self.rock_size!r} must satisfy 0 < min <= max")

    def _check_soil(self) -> None:
        """Validate the soil fields: preset name or parameters, level ground, grid size."""
        if isinstance(self.soil, str):
            soil_preset(self.soil)  # raises naming the preset and the valid names
        elif not isinstance(self.soil, SoilParameters):
            raise ValueError(
                f"soil={self.soil!r}: expected None, a soil preset name or a SoilParameters"
            )
        if self.slope != 0.0:
            raise ValueError(
                f"slope={self.slope!r} with soil={self.soil!r}: expected slope=0 (the soil "
                "patch is level)"
            )
        for name in ("soil_extent", "soil_resolution"):
            value = getattr(self, name)
            check_positive(name, value, "a finite number > 0 (m)")
        if self.soil_resolution > self.soil_extent / 10:
            raise ValueError(
                f"soil_resolution={self.soil_resolution!r}: expected at most soil_extent / 10 "
                f"= {self.soil_extent / 10:g} m"
            )

    def plane_height(self, x: np.ndarray | float) -> np.ndarray | float:
        """Height of the (inclined) plane at world ``x`` [m]."""
        return -math.tan(self.slope) * np.asarray(x)


def terrain_params(params: LanderParams, terrain: Terrain) -> LanderParams:
    """``params`` with the time step ``terrain`` needs: ``min(timestep, soil_timestep)`` on
    soil (see ``LanderParams.soil_timestep``), unchanged on rigid ground."""
    if terrain.soil is None or params.timestep <= params.soil_timestep:
        return params
    return dataclasses.replace(params, timestep=params.soil_timestep)
