"""The Soil Contact Model (SCM) of Project Chrono: a height grid of soil nodes and its force law.

This module knows nothing about MuJoCo: :class:`SoilGrid` holds the per-node state and
:class:`ScmLaw` turns the sinkage and the body-point velocity at a block of nodes into
pressure, shear stress and the updated node state. ``mujoco_soil`` does the geometry.

Per-node state (flat arrays over a padded grid)
    ``level0``: the level the sinkage is measured from (the reset level, raised by
    bulldozed soil);
    ``plastic``: plastic sinkage ``zp`` below ``level0`` (the rut depth, never decreases);
    ``shear``: accumulated shear displacement ``j`` (0 out of contact).

Elastic/plastic rule (Wong's repetitive-loading model, as in Chrono)
    With ``s`` the sinkage of the body's lower surface below ``level0`` at a node,
    the static pressure is ``sigma = min(E * (s - zp), B(s))``, where
    ``B(s) = (Kc / b + Kphi) * s**n`` is Bekker's virgin loading curve and ``E`` the elastic
    stiffness. While ``E * (s - zp) > B(s)`` the node yields: the pressure follows Bekker's
    curve and ``zp`` moves to ``s - B(s) / E`` (it only ever grows), so unloading from a
    sinkage ``s_y`` follows ``sigma = sigma_y - E * (s_y - s)`` and the node is out of contact
    once ``s <= zp``: the rut stays. Bekker's ``z`` is thus the sinkage on the virgin curve
    (total sinkage at yield), as in Chrono and Wong; the rut left is ``z - sigma / E``.
    Damping adds ``-R * v_z`` (``v_z`` upward velocity of the body point) and the sum is
    clipped at 0: the soil never pulls.

Shear
    ``tau = (c + sigma * tan(phi)) * (1 - exp(-j / K))`` opposes the tangential slip
    velocity; ``j`` is the path length slipped while the node stays in contact (``|v_t| dt``
    per tick, the value at the start of the tick is used) and is reset when it leaves contact.

Where it runs
    :class:`ScmLaw` holds the law's constants and :meth:`ScmLaw.update` is its NumPy form (the
    reference the tests check the compiled tick against). The per-tick hot path of
    ``MujocoSoil`` is compiled with numba (``_kernels``): each tick touches tens (feet) to a few
    thousand (plates, wheels) nodes, and as NumPy array operations a tick was ~70 calls of
    0.4-1 us fixed overhead each whatever the block size (60-80 us for the Go1's four feet,
    4x a rigid ``mj_step``); compiled loops visit each node once, in tens of ns (4-6 us per
    Go1 tick, plus ~2 us of MuJoCo kinematics).

Units
    :class:`ScmLaw` works in force per node (pressure x node area), folded into its constants.
"""

from __future__ import annotations

import math
from collections.abc import Sequence

import numpy as np

from chronogym.terrain.archive import TileArchive
from chronogym.terrain.params import SoilParameters
from chronogym.validation import check_int, check_positive

__all__ = ["ScmLaw", "SoilGrid", "patch_inverse_width"]

#: Level of the inert padding nodes around the grid: far below anything, never in contact.
PAD_LEVEL = -1e30
_MAX_NODES = 50_000_000


def _positive(name: str, value: float) -> float:
    return check_positive(name, value, "a finite float > 0")


def _pair(name: str, value: Sequence[float], positive: bool = False) -> tuple[float, float]:
    expected = "two finite floats > 0 (x, y)" if positive else "two finite floats (x, y)"
    try:
        a, b = (float(v) for v in value)
    except (TypeError, ValueError):
        raise ValueError(f"{name}={value!r}: expected {expected}") from None
    if not (math.isfinite(a) and math.isfinite(b)) or (positive and not (a > 0 and b > 0)):
        raise ValueError(f"{name}={value!r}: expected {expected}")
    return a, b


class SoilGrid:
    """A regular ``nx x ny`` grid of soil nodes with spacing ``resolution`` (m).

    Nodes span ``extent`` (m, x and y) centred on ``center``; node ``(i, j)`` sits at
    ``origin + (i, j) * resolution``. ``level`` is the initial surface height: a float or an
    ``(nx, ny)`` array. The state arrays are stored flat with ``margin`` inert nodes on each
    side (level ``PAD_LEVEL``), so blocks of up to ``margin`` nodes may hang over the edge.
    """

    def __init__(
        self,
        extent: Sequence[float],
        resolution: float,
        center: Sequence[float] = (0.0, 0.0),
        level: float | np.ndarray = 0.0,
        margin: int = 0,
    ) -> None:
        self.resolution = _positive("resolution", resolution)
        lx, ly = _pair("extent", extent, positive=True)
        cx, cy = _pair("center", center)
        nx = round(lx / self.resolution) + 1
        ny = round(ly / self.resolution) + 1
        if nx * ny > _MAX_NODES:
            raise ValueError(
                f"extent={tuple(extent)!r} at resolution={resolution!r} gives {nx} x {ny} nodes; "
                f"expected at most {_MAX_NODES} (coarser resolution or smaller extent)"
            )
        margin = check_int("margin", margin, 0, expected="an int >= 0")
        self.shape = (nx, ny)
        self.margin = margin
        self.stride = ny + 2 * margin
        self.origin = (cx - 0.5 * (nx - 1) * self.resolution, cy - 0.5 * (ny - 1) * self.resolution)
        self.node_area = self.resolution**2
        padded = (nx + 2 * margin, self.stride)
        reset_level = np.full(padded, PAD_LEVEL)
        reset_level[margin : margin + nx, margin : margin + ny] = self._check_level(level)
        self._reset_level = reset_level.reshape(-1)
        self._reset_level.setflags(write=False)
        #: ``(3, N)``: rows ``level0``, ``plastic``, ``shear`` (one array for the compiled tick).
        self.state = np.zeros((3, self._reset_level.size))
        self.level0, self.plastic, self.shear = self.state
        np.copyto(self.level0, self._reset_level)
        self.top = float(self.interior(self.level0).max())
        level_array = np.asarray(level)
        #: The reset level when it is one number (a window can then move: :meth:`shift`).
        self.uniform_level = float(level_array) if level_array.ndim == 0 else None
        self._origin0 = self.origin
        #: Global index of node ``(0, 0)``: 0 until the window moves.
        self.offset = (0, 0)
        self.archive: TileArchive | None = None

    def _check_level(self, level: float | np.ndarray) -> np.ndarray:
        array = np.asarray(level, dtype=np.float64)
        if array.ndim == 0:
            array = np.full(self.shape, float(array))
        if array.shape != self.shape:
            raise ValueError(
                f"level of shape {array.shape}: expected a float or an array of shape {self.shape}"
            )
        if not np.isfinite(array).all():
            raise ValueError("level holds NaN or Inf: expected finite heights (m)")
        return array

    def interior(self, flat: np.ndarray) -> np.ndarray:
        """The ``(nx, ny)`` view of a flat padded per-node array."""
        m, (nx, ny) = self.margin, self.shape
        return flat.reshape(nx + 2 * m, self.stride)[m : m + nx, m : m + ny]

    @property
    def x(self) -> np.ndarray:
        """Node x coordinates, shape ``(nx,)``."""
        return self.origin[0] + self.resolution * np.arange(self.shape[0])

    @property
    def y(self) -> np.ndarray:
        """Node y coordinates, shape ``(ny,)``."""
        return self.origin[1] + self.resolution * np.arange(self.shape[1])

    @property
    def reset_level(self) -> np.ndarray:
        """The initial surface heights, ``(nx, ny)`` (read-only)."""
        return self.interior(self._reset_level)

    def shift(self, di: int, dj: int) -> int:
        """Move the window by ``(di, dj)`` nodes; returns the change of a node's flat index.

        Nodes leaving the window are kept in :attr:`archive` where they are deformed; nodes
        entering it come from there or are fresh soil. Shear displacement moves with the nodes
        that stay (out of the window it is 0: only nodes in contact have any). Needs a uniform
        reset level (``uniform_level``).
        """
        if self.uniform_level is None:
            raise ValueError("shift() needs a uniform level: expected level to be a float")
        if self.archive is None:
            self.archive = TileArchive((self.uniform_level, 0.0))
        di, dj = int(di), int(dj)
        rows = [self.interior(self.level0), self.interior(self.plastic)]
        self.archive.store(rows, self.offset)
        shear = self.interior(self.shear)
        kept = shear.copy()
        shear.fill(0.0)
        nx, ny = self.shape
        if abs(di) < nx and abs(dj) < ny:  # new node (i, j) was old node (i + di, j + dj)
            shear[max(-di, 0) : nx - max(di, 0), max(-dj, 0) : ny - max(dj, 0)] = kept[
                max(di, 0) : nx + min(di, 0), max(dj, 0) : ny + min(dj, 0)
            ]
        self.offset = (self.offset[0] + di, self.offset[1] + dj)
        self.archive.load(rows, self.offset)
        self.origin = (
            self._origin0[0] + self.offset[0] * self.resolution,
            self._origin0[1] + self.offset[1] * self.resolution,
        )
        self.top = float(rows[0].max())
        return di * self.stride + dj

    @property
    def center(self) -> tuple[float, float]:
        """Centre of the window (m)."""
        half = 0.5 * self.resolution
        return (
            self.origin[0] + half * (self.shape[0] - 1),
            self.origin[1] + half * (self.shape[1] - 1),
        )

    def reset(self) -> None:
        """Restore the initial levels and clear plastic sinkage and shear, in place (and put a
        moved window back where it started, forgetting the soil it archived)."""
        self.offset, self.origin = (0, 0), self._origin0
        if self.archive is not None:
            self.archive.clear()
        np.copyto(self.level0, self._reset_level)
        self.plastic.fill(0.0)
        self.shear.fill(0.0)
        self.top = float(self.interior(self.level0).max())


def patch_inverse_width(contact: np.ndarray, resolution: float) -> np.ndarray:
    """Bekker's ``1/b`` of each patch in a ``(G, Wi, Wj)`` block: perimeter / (2 area).

    As Chrono estimates it from the grid: area = nodes x cell area, perimeter = boundary
    nodes (in contact with a 4-neighbour that is not) x resolution. 0 for an empty patch.
    """
    g, wi, wj = contact.shape
    pad = np.zeros((g, wi + 2, wj + 2), dtype=bool)
    pad[:, 1:-1, 1:-1] = contact
    inner = contact & pad[:, :-2, 1:-1]
    inner &= pad[:, 2:, 1:-1]
    inner &= pad[:, 1:-1, :-2]
    inner &= pad[:, 1:-1, 2:]
    nodes = np.count_nonzero(contact.reshape(g, -1), axis=1)
    boundary = nodes - np.count_nonzero(inner.reshape(g, -1), axis=1)
    return boundary / (2.0 * resolution * np.maximum(nodes, 1))


class ScmLaw:
    """SCM pressure-sinkage and shear law over blocks of nodes of area ``node_area``.

    Works in force per node (N): pressures are multiplied by ``node_area`` once, in the
    constants, which saves array operations in the per-tick hot path.
    """

    def __init__(self, params: SoilParameters, node_area: float) -> None:
        if not isinstance(params, SoilParameters):
            raise ValueError(f"params={params!r}: expected a SoilParameters (or a preset name)")
        area = _positive("node_area", node_area)
        self.params = params
        self.node_area = area
        self.n = params.n
        self.Kc_area = params.Kc * area
        self.Kphi_area = params.Kphi * area
        self.elastic_area = params.elastic_stiffness * area
        self.inv_elastic_area = 1.0 / self.elastic_area
        self.neg_damping_area = -params.damping * area
        self.cohesion_area = params.cohesion * area
        self.tan_phi = params.tan_phi
        self.neg_inv_janosi = -1.0 / params.janosi_shear
        self.needs_width = params.Kc != 0.0

    def modulus_area(self, inv_b: np.ndarray | float) -> np.ndarray | float:
        """``(Kc / b + Kphi) * node_area``."""
        return self.Kc_area * inv_b + self.Kphi_area

    def update(
        self,
        sinkage: np.ndarray,
        elastic: np.ndarray,
        plastic: np.ndarray,
        shear: np.ndarray,
        contact: np.ndarray,
        v_up: np.ndarray,
        v_slip: np.ndarray,
        modulus_area: np.ndarray | float,
        dt: float,
        out: np.ndarray | None = None,
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """One tick at a block of nodes (all arrays of one shape, or broadcastable).

        ``sinkage``: ``s``, the body surface's depth below ``level0``; ``elastic``:
        ``s - plastic`` (> 0 exactly where in contact); ``plastic``, ``shear``: node state;
        ``contact``: 1.0 in contact, 0.0 elsewhere; ``v_up``: upward velocity of the body
        point; ``v_slip``: its tangential speed; ``modulus_area``: see :meth:`modulus_area`.
        Returns ``(normal, shear_force, plastic_new, shear_new, static)``: normal force per
        node (N, written to ``out`` if given), shear force along the slip direction (N, <= 0:
        it opposes the slip), the new plastic sinkage (unchanged out of contact), the new
        shear displacement (0 out of contact) and the static part of the normal force.
        """
        bekker = np.maximum(sinkage, 0.0)
        if self.n != 1.0:
            np.power(bekker, self.n, out=bekker)
        bekker *= modulus_area
        static = np.multiply(elastic, self.elastic_area)
        np.minimum(static, bekker, out=static)
        plastic_new = np.multiply(bekker, self.inv_elastic_area, out=bekker)
        np.subtract(sinkage, plastic_new, out=plastic_new)
        np.maximum(plastic_new, plastic, out=plastic_new)
        normal = np.multiply(v_up, self.neg_damping_area, out=out)
        normal += static
        np.maximum(normal, 0.0, out=normal)
        normal *= contact
        grip = np.multiply(shear, self.neg_inv_janosi)
        np.expm1(grip, out=grip)  # -(1 - exp(-j / K))
        if self.cohesion_area:
            strength = normal * self.tan_phi
            strength += self.cohesion_area
            strength *= contact
        else:
            strength = normal * self.tan_phi
        grip *= strength
        shear_new = np.multiply(v_slip, dt)
        shear_new += shear
        shear_new *= contact
        return normal, grip, plastic_new, shear_new, static
