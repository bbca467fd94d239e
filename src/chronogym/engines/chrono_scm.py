"""Chrono's own SCM terrain (``pychrono.vehicle.SCMTerrain``) driven by a chronogym soil preset.

One :class:`~chronogym.terrain.SoilParameters` drives both engines: its fields are Chrono's
``SCMTerrain::SetSoilParameters`` arguments, in that order, so ``--terrain soil`` (chronogym's
SCM under MuJoCo bodies) and ``--terrain scm`` (Chrono's under Chrono bodies) use the same
numbers. :class:`ChronoSCM` is an advanceable (``Synchronize(t)`` + ``Advance(dt)``, listed
before the system), and resets by putting every node it touched back at the flat level.

``SCMTerrain`` lives in PyChrono's vehicle module (Chrono built with
``CH_ENABLE_MODULE_VEHICLE``; the conda package has it). Nothing here imports PyChrono at
module import.
"""

from __future__ import annotations

import math
from collections.abc import Sequence
from typing import Any

import numpy as np

from chronogym.engines.chrono import INSTALL_HINT, import_pychrono, vec3
from chronogym.terrain.params import SoilParameters
from chronogym.validation import is_number

__all__ = ["ChronoSCM", "chrono_soil_arguments", "import_chrono_vehicle"]


def chrono_soil_arguments(params: SoilParameters) -> tuple[float, ...]:
    """``SCMTerrain.SetSoilParameters`` arguments of a chronogym soil: (Kphi, Kc, n, cohesion,
    friction angle [deg], Janosi shear [m], elastic stiffness [Pa/m], damping [Pa s/m])."""
    return (
        params.Kphi,
        params.Kc,
        params.n,
        params.cohesion,
        params.friction_angle,
        params.janosi_shear,
        params.elastic_stiffness,
        params.damping,
    )


def import_chrono_vehicle() -> Any:
    """``pychrono.vehicle``, or ModuleNotFoundError naming what is missing and what to do."""
    import_pychrono()
    try:
        import pychrono.vehicle as vehicle
    except ImportError as exc:
        raise ModuleNotFoundError(
            f"Chrono's SCM terrain needs PyChrono's vehicle module, but `import pychrono.vehicle` "
            f"failed ({exc}); build Chrono with CH_ENABLE_MODULE_VEHICLE=ON, or {INSTALL_HINT} "
            "(the conda package includes it)",
            name="pychrono.vehicle",
        ) from exc
    return vehicle


def _positive(value: Any) -> bool:
    return is_number(value) and math.isfinite(value) and value > 0


class ChronoSCM:
    """A flat patch of Chrono SCM soil at z = 0 under some bodies of a Chrono system.

    The soil finds the bodies by casting a ray from each grid node into the system's collision
    system, so that system shapes the footprint: Chrono's default single-precision Bullet
    returns hits up to ~1 cm off a moving shape, and its collision envelope widens footprints
    (``RayHit`` corrects only the depth). For small shapes use a small envelope, and Chrono's
    multicore collision system (spheres, boxes) or Bullet built with
    ``CH_USE_BULLET_DOUBLE=ON`` (``benchmarks/soil/soil_cross_check.py``).

    Args:
        system: the ``ChSystem`` (with a collision system already set).
        params: the soil (a chronogym preset or ``SoilParameters``).
        size: (x, y) extent of the patch [m], centred on the origin.
        resolution: grid spacing [m].
        domains: ``(body, centre, dims)`` active domains: oriented boxes moving with the
            body (centre in the body frame, full side lengths) where the soil looks for the
            body's collision shapes; outside them it does no work.
    """

    def __init__(
        self,
        system: Any,
        params: SoilParameters,
        size: tuple[float, float],
        resolution: float,
        domains: Sequence[tuple[Any, Sequence[float], Sequence[float]]],
    ) -> None:
        if not isinstance(params, SoilParameters):
            raise ValueError(f"params={params!r}: expected a chronogym SoilParameters")
        if len(size) != 2 or not all(_positive(s) for s in size):
            raise ValueError(f"size={size!r}: expected (x, y) extents > 0 in m")
        if not _positive(resolution) or resolution > min(size) / 2:
            raise ValueError(
                f"resolution={resolution!r}: expected a grid spacing > 0 and at most half the "
                f"patch's smaller side ({min(size) / 2:g} m)"
            )
        chrono = import_pychrono()
        vehicle = import_chrono_vehicle()
        self.params = params
        self.chrono = chrono
        self.vehicle = vehicle
        self.terrain = vehicle.SCMTerrain(system, False)  # no visualization mesh
        self.terrain.SetReferenceFrame(chrono.ChCoordsysd(chrono.ChVector3d(0.0, 0.0, 0.0)))
        self.terrain.SetSoilParameters(*chrono_soil_arguments(params))
        self.terrain.Initialize(float(size[0]), float(size[1]), float(resolution))
        for body, centre, dims in domains:
            self.terrain.AddActiveDomain(
                body, chrono.ChVector3d(*map(float, centre)), chrono.ChVector3d(*map(float, dims))
            )
        self._force = chrono.ChVector3d(0.0, 0.0, 0.0)
        self._torque = chrono.ChVector3d(0.0, 0.0, 0.0)

    def Synchronize(self, time: float) -> None:
        self.terrain.Synchronize(time)

    def Advance(self, dt: float) -> None:
        self.terrain.Advance(dt)

    def reset(self) -> None:
        """Put every node the soil has touched back at the flat level, with no history."""
        touched = self.terrain.GetModifiedNodes(True)
        flat = self.vehicle.ChSCMTerrainNodeLevelList()
        for node in touched:
            flat.append(self.vehicle.ChSCMTerrainNodeLevel(node[0], 0.0))
        if len(flat):
            self.terrain.SetModifiedNodes(flat)

    def deepest(self) -> float:
        """Depth of the deepest node the soil has touched [m] (0 when untouched)."""
        levels = [node[1] for node in self.terrain.GetModifiedNodes(True)]
        return max(0.0, -min(levels)) if levels else 0.0

    def force_on(self, body: Any) -> tuple[np.ndarray, np.ndarray]:
        """Force and torque [N, N m] the soil applied to ``body`` in the last step (world)."""
        if not self.terrain.GetContactForceBody(body, self._force, self._torque):
            return np.zeros(3), np.zeros(3)
        return vec3(self._force), vec3(self._torque)

    def height(self, x: float, y: float) -> float:
        """The soil surface's height at (x, y) [m] (0 where untouched)."""
        point = self.chrono.ChVector3d(float(x), float(y), 0.0)
        return float(self.terrain.GetHeight(point))
