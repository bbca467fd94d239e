"""SCM soil under MuJoCo bodies: an advanceable that writes the soil wrench to ``xfrc_applied``.

Use it before ``mj_step`` in a task's advanceables::

    calves = ["FR_calf", "FL_calf", "RR_calf", "RL_calf"]   # calf capsule + foot sphere each
    soil = MujocoSoil(model, data, "soft", bodies=calves, extent=(8, 8), resolution=0.01)
    soil.exclude_ground("floor")      # the rigid floor no longer touches the soil's geoms
    task.advanceables = [soil, (model, data)]

Order of one tick (``Advance(dt)``), for the state ``mj_step`` is about to integrate:

1. ``mj_kinematics`` (then ``mj_comPos`` + ``mj_comVel`` if any geom is near the soil): poses
   and velocities of the current ``qpos``/``qvel`` (after ``mj_step`` MuJoCo's derived fields
   describe the previous state);
2. active region: per geom whose lowest point is below the highest soil node, a square block
   of nodes around the part of it that can touch the soil, and the height of the geom's lower
   surface over each node (closed form for sphere, capsule, ellipsoid, cylinder and box, any
   orientation; what a ray cast up from below the node would hit first);
3. contact where that surface is below the node's current surface (``level0 - plastic``,
   which holds the plastic flow of every earlier tick); a node under two geoms belongs to the
   one whose surface is lower there;
4. SCM law (``scm.ScmLaw``) at the contact nodes: pressure, shear, plastic sinkage and shear
   displacement; the grid is updated in place (and, with ``bulldozing``, the displaced volume
   is put on the rim of each patch);
5. per body, the node forces and their moments about the body's centre of mass
   (``data.xipos``) are summed into the body's row of ``data.xfrc_applied``, which the soil
   overwrites every tick: apply other external forces on these bodies after the soil.

The force law is explicit, as Chrono's SCM: forces come from the state at the start of the
step and are held during it. Two consequences:

* The shear force is Coulomb-like (``tau`` opposes the slip velocity); below ~``mass / dt``
  of viscosity it would flip direction every tick, so per geom it is scaled down to at most
  what stops the slip in one tick (``body mass / dt``), which keeps it dissipative and stable.
* The elastic branch is a spring of stiffness ``E * contact area``: a body resting on it is
  explicit-stable when ``sqrt(E * area / mass) * dt < 2`` and passive tick by tick when
  ``dt < 2 R / E``. Chrono's presets (``E`` = 2e8) need ``dt`` <= 1 ms for light bodies (Go1
  feet); at 5 ms use a softer ``E`` (e.g. ``soil_preset("firm", elastic_stiffness=2e7)``).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from typing import Any

import numpy as np

from chronogym.terrain.params import SoilParameters, soil_preset
from chronogym.terrain.scm import ScmLaw, SoilGrid, patch_inverse_width

__all__ = ["MujocoSoil", "exclude_ground_contacts"]

# mjtGeom values (stable in MuJoCo's C API).
_SPHERE, _CAPSULE, _ELLIPSOID, _CYLINDER, _BOX = 2, 3, 4, 5, 6
_KIND_NAMES = {_SPHERE: "sphere", _CAPSULE: "capsule", _ELLIPSOID: "ellipsoid"}
_KIND_NAMES |= {_CYLINDER: "cylinder", _BOX: "box"}
_TYPE_NAMES = {0: "plane", 1: "hfield", 7: "mesh", 8: "sdf"}
_EPS = 1e-12
_SLIP_EPS = 1e-4  # m/s; below this slip speed the shear force fades out linearly
_MISS = -1e6  # "below" of a vertical line that misses a geom: finite, never in contact

# Om (3 x 4) = [v | skew(w)] from a MuJoCo 6D velocity [wx wy wz vx vy vz]: v(p) = Om @ [1, r].
_OM_SRC = np.array([3, 0, 2, 1, 4, 2, 0, 0, 5, 1, 0, 0])
_OM_SIGN = np.array([1.0, 0, -1, 1, 1, 1, 0, -1, 1, -1, 1, 0])
# Fm = sum of f r^T with r = [1, rx, ry, rz] (3 x 4, flattened) -> [force, torque]: Fm @ _TO_WRENCH.
_TO_WRENCH = np.zeros((12, 6))
for _row, _col, _sign in [(0, 0, 1), (4, 1, 1), (8, 2, 1), (10, 3, 1), (7, 3, -1), (3, 4, 1)]:
    _TO_WRENCH[_row, _col] = _sign
for _row, _col, _sign in [(9, 4, -1), (5, 5, 1), (2, 5, -1)]:
    _TO_WRENCH[_row, _col] = _sign
_SWAP = np.array([3, 4, 5, 0, 1, 2])  # MuJoCo [w, v] -> [v, w], to pair with a wrench [f, t]


# --------------------------------------------------------------------------------------------
# Lower surface of each geom type over a block of vertical lines. ``offsets`` (G, 2, W): node x
# and y minus the geom centre's; ``mat`` (G, 9): row-major rotation (None for spheres);
# ``group.size`` (G, 3): MuJoCo geom_size; ``out``: a (G, W, W) buffer the kernel may use.
# Returns ``below`` (G, W, W): centre height minus the height of the geom's lowest point on the
# vertical line, or _MISS where the line misses it.
# --------------------------------------------------------------------------------------------


def _sphere_below(offsets, mat, group, out):
    square = offsets * offsets
    rem = group.r2 - square[:, 0, :, None] - square[:, 1, None, :]
    out.fill(_MISS)
    return np.sqrt(rem, out=out, where=rem > 0.0)


def _ellipsoid_below(offsets, mat, group, out=None):
    rows = mat.reshape(-1, 3, 3)
    inv2 = 1.0 / group.size**2  # (G, 3)
    dx, dy = offsets[:, 0, :, None, None], offsets[:, 1, None, :, None]
    # local coordinates of the line's point at the centre height, and of the line's direction
    u0 = dx * rows[:, None, None, 0, :] + dy * rows[:, None, None, 1, :]  # (G, W, W, 3)
    up = rows[:, None, None, 2, :]
    a = (up * up * inv2[:, None, None, :]).sum(axis=3)
    b = (u0 * up * inv2[:, None, None, :]).sum(axis=3)
    c = (u0 * u0 * inv2[:, None, None, :]).sum(axis=3) - 1.0
    disc = b * b - a * c
    hit = disc > 0.0
    return np.where(hit, (b + np.sqrt(np.maximum(disc, 0.0))) / a, _MISS)


def _axis(mat):
    return mat[:, 2, None, None], mat[:, 5, None, None], mat[:, 8, None, None]


def _side_below(dx3, dy3, ax, ay, az, r, hl):
    """Lower crossing of the infinite cylinder of radius r around the axis, within |t| <= hl."""
    e = dx3 * ax + dy3 * ay
    a = 1.0 - az * az
    c = dx3 * dx3 + dy3 * dy3 - e * e - r * r
    disc = e * e * az * az - a * c
    slanted = a > _EPS
    dz = (e * az - np.sqrt(np.maximum(disc, 0.0))) / np.where(slanted, a, 1.0)
    ok = slanted & (disc > 0.0) & (np.abs(e + dz * az) <= hl)
    return np.where(ok, -dz, -np.inf), e


def _capsule_below(offsets, mat, group, out=None):
    ax, ay, az = _axis(mat)
    r, hl = group.size[:, 0, None, None], group.size[:, 1, None, None]
    dx3, dy3 = offsets[:, 0, :, None], offsets[:, 1, None, :]
    below, _ = _side_below(dx3, dy3, ax, ay, az, r, hl)
    for sign in (1.0, -1.0):
        ex, ey = dx3 - sign * hl * ax, dy3 - sign * hl * ay
        rem = r * r - ex * ex - ey * ey
        cap = np.where(rem > 0.0, np.sqrt(np.maximum(rem, 0.0)) - sign * hl * az, -np.inf)
        below = np.maximum(below, cap)
    return np.where(np.isfinite(below), below, _MISS)


def _cylinder_below(offsets, mat, group, out=None):
    ax, ay, az = _axis(mat)
    r, hl = group.size[:, 0, None, None], group.size[:, 1, None, None]
    dx3, dy3 = offsets[:, 0, :, None], offsets[:, 1, None, :]
    below, e = _side_below(dx3, dy3, ax, ay, az, r, hl)
    tilted = np.abs(az) > _EPS
    safe_az = np.where(tilted, az, 1.0)
    for t in (hl, -hl):
        dz = (t - e) / safe_az
        radial2 = dx3 * dx3 + dy3 * dy3 + dz * dz - t * t
        below = np.maximum(below, np.where(tilted & (radial2 <= r * r), -dz, -np.inf))
    return np.where(np.isfinite(below), below, _MISS)


def _box_below(offsets, mat, group, out=None):
    dx3, dy3 = offsets[:, 0, :, None], offsets[:, 1, None, :]
    entry = np.full(np.broadcast_shapes(dx3.shape, dy3.shape), -np.inf)
    leave = np.full_like(entry, np.inf)
    for k in range(3):
        cx, cy, cz = mat[:, k, None, None], mat[:, 3 + k, None, None], mat[:, 6 + k, None, None]
        h = group.size[:, k, None, None]
        e = dx3 * cx + dy3 * cy
        level = np.abs(cz) <= _EPS  # face normal horizontal: the slab does not depend on z
        inside = np.abs(e) <= h
        safe = np.where(level, 1.0, cz)
        t1, t2 = (-h - e) / safe, (h - e) / safe
        lo = np.where(level, np.where(inside, -np.inf, np.inf), np.minimum(t1, t2))
        hi = np.where(level, np.where(inside, np.inf, -np.inf), np.maximum(t1, t2))
        np.maximum(entry, lo, out=entry)
        np.minimum(leave, hi, out=leave)
    hit = (entry <= leave) & np.isfinite(entry)
    return np.where(hit, -entry, _MISS)


# Where each (non-sphere) geom type reaches at its current pose: (centre (G, 3), mat (G, 9),
# size (G, 3), top) -> (lowest (G,), lo (G, 2), hi (G, 2)): the height of its lowest point and the
# horizontal box that holds the part of it below the height ``top`` (the highest soil node).


def _box_extent(mat, size):
    return (np.abs(mat.reshape(-1, 3, 3)) * size[:, None, :]).sum(axis=2)


def _ellipsoid_extent(mat, size):
    return np.sqrt(np.square(mat.reshape(-1, 3, 3) * size[:, None, :]).sum(axis=2))


def _extent_span(extent_fn):
    def span(centre, mat, size, top):
        extent = extent_fn(mat, size)
        return (
            centre[:, 2] - extent[:, 2],
            centre[:, :2] - extent[:, :2],
            centre[:, :2] + extent[:, :2],
        )

    return span


def _segment_span(centre, mat, size, top, down, pad):
    """Around the part of the axis segment whose cross-section (reaching ``down`` below the axis
    and ``pad`` (G, 2) sideways) dips below ``top``."""
    hl = size[:, 1]
    axis = mat[:, 2::3]  # third column of R: the geom's z axis in world, (G, 3)
    az = axis[:, 2]
    up = az > _EPS
    dips = az < -_EPS
    limit = (top + down - centre[:, 2]) / np.where(up | dips, az, 1.0)
    t0 = np.where(dips, np.maximum(-hl, limit), -hl)
    t1 = np.where(up, np.minimum(hl, limit), hl)
    ends0 = centre[:, :2] + t0[:, None] * axis[:, :2]
    ends1 = centre[:, :2] + t1[:, None] * axis[:, :2]
    lowest = centre[:, 2] - np.abs(az) * hl - down
    return lowest, np.minimum(ends0, ends1) - pad, np.maximum(ends0, ends1) + pad


def _capsule_span(centre, mat, size, top):
    r = size[:, 0]
    return _segment_span(centre, mat, size, top, r, r[:, None])


def _cylinder_span(centre, mat, size, top):
    # A disk of radius r across the axis a reaches r * sqrt(1 - a_i^2) along world axis i.
    rim = size[:, 0, None] * np.sqrt(np.maximum(1.0 - np.square(mat[:, 2::3]), 0.0))
    return _segment_span(centre, mat, size, top, rim[:, 2], rim[:, :2])


def _horizontal_reach(kind: int, size: np.ndarray) -> float:
    """Largest horizontal half-extent over all orientations."""
    if kind == _SPHERE:
        return float(size[0])
    if kind == _ELLIPSOID:
        return float(size.max())
    if kind == _CAPSULE:
        return float(size[0] + size[1])
    if kind == _CYLINDER:
        return float(math.hypot(size[0], size[1]))
    return float(np.linalg.norm(size))


_SHAPES = {
    _SPHERE: (_sphere_below, None),
    _ELLIPSOID: (_ellipsoid_below, _extent_span(_ellipsoid_extent)),
    _CAPSULE: (_capsule_below, _capsule_span),
    _CYLINDER: (_cylinder_below, _cylinder_span),
    _BOX: (_box_below, _extent_span(_box_extent)),
}


# --------------------------------------------------------------------------------------------
# Model lookups.
# --------------------------------------------------------------------------------------------


def _object_id(model: Any, kind: str, key: str | int, count: int) -> int:
    import mujoco

    if isinstance(key, (int, np.integer)) and not isinstance(key, bool):
        if 0 <= int(key) < count:
            return int(key)
        raise ValueError(f"{kind} id {key!r}: expected an int in [0, {count})")
    if isinstance(key, str):
        obj = mujoco.mjtObj.mjOBJ_GEOM if kind == "geom" else mujoco.mjtObj.mjOBJ_BODY
        index = mujoco.mj_name2id(model, obj, key)
        if index >= 0:
            return index
        raise ValueError(f"{kind} {key!r}: no {kind} of that name in the model")
    raise ValueError(f"{kind} {key!r}: expected a name (str) or an id (int)")


def _geom_label(model: Any, geom: int) -> str:
    name = model.geom(geom).name
    return repr(name) if name else f"#{geom}"


def _resolve_geoms(
    model: Any, bodies: Sequence[str | int] | None, geoms: Sequence[str | int] | None
) -> tuple[list[int], list[int]]:
    """(soil geoms, skipped geoms of the given bodies whose type SCM cannot handle)."""
    if bodies is None and geoms is None:
        raise ValueError("bodies=None and geoms=None: expected the bodies or geoms the soil holds")
    for label, seq in (("bodies", bodies), ("geoms", geoms)):
        if seq is not None and (isinstance(seq, (str, bytes)) or not isinstance(seq, Iterable)):
            raise ValueError(f"{label}={seq!r}: expected a list of names or ids")
    chosen: set[int] = set()
    skipped: list[int] = []
    for key in geoms or ():
        geom = _object_id(model, "geom", key, model.ngeom)
        kind = int(model.geom_type[geom])
        if kind not in _SHAPES:
            name = _TYPE_NAMES.get(kind, str(kind))
            raise ValueError(
                f"geom {_geom_label(model, geom)} has type {name}: expected one of "
                f"{', '.join(_KIND_NAMES.values())} (planes, height fields and meshes are not "
                "supported)"
            )
        chosen.add(geom)
    for key in bodies or ():
        body = _object_id(model, "body", key, model.nbody)
        start, count = int(model.body_geomadr[body]), int(model.body_geomnum[body])
        usable = [g for g in range(start, start + count) if int(model.geom_type[g]) in _SHAPES]
        skipped += [g for g in range(start, start + count) if g not in usable]
        if not usable:
            raise ValueError(
                f"body {key!r} has no sphere, capsule, ellipsoid, cylinder or box geom: "
                "expected at least one for the soil to act on"
            )
        chosen.update(usable)
    for geom in chosen:
        if int(model.geom_bodyid[geom]) == 0:
            raise ValueError(
                f"geom {_geom_label(model, geom)} belongs to the world body: expected geoms of "
                "moving bodies (the soil applies forces to bodies)"
            )
    return sorted(chosen), skipped


def exclude_ground_contacts(model: Any, ground: str | int, geoms: Iterable[str | int]) -> int:
    """Stop MuJoCo contacts between the ``ground`` geom and ``geoms``; keep every other pair.

    MuJoCo collides two geoms when ``contype1 & conaffinity2`` or ``contype2 & conaffinity1``
    is non-zero. The ground gets a contype/conaffinity bit no geom uses; every geom that used
    to collide with it, except ``geoms``, gets that bit in its conaffinity. So the ground still
    holds everything else (a fallen trunk, obstacles) and no other pair changes. Edits the
    model in place and returns the bit. Raises ``ValueError`` when no bit is free or an explicit
    ``<pair>`` joins the ground to one of ``geoms`` (remove it from the MJCF instead).
    """
    g = _object_id(model, "geom", ground, model.ngeom)
    excluded = {_object_id(model, "geom", key, model.ngeom) for key in geoms}
    contype = model.geom_contype.astype(np.int64)
    conaffinity = model.geom_conaffinity.astype(np.int64)
    used = int(np.bitwise_or.reduce(contype | conaffinity)) if model.ngeom else 0
    free = [bit for bit in range(31) if not used >> bit & 1]
    if not free:
        raise ValueError("every contype/conaffinity bit is in use: expected one free bit")
    for a, b in zip(model.pair_geom1, model.pair_geom2, strict=True):
        if {int(a), int(b)} & {g} and {int(a), int(b)} & excluded:
            raise ValueError(
                f"explicit <pair> between geoms {int(a)} and {int(b)} joins the ground to a soil "
                "geom: expected no such pair (explicit pairs ignore contype/conaffinity)"
            )
    bit = 1 << free[0]
    for h in range(model.ngeom):
        if h == g or h in excluded:
            continue
        if contype[g] & conaffinity[h] or contype[h] & conaffinity[g]:
            model.geom_conaffinity[h] |= bit
    model.geom_contype[g] = bit
    model.geom_conaffinity[g] = bit
    return free[0]


# --------------------------------------------------------------------------------------------
# The soil.
# --------------------------------------------------------------------------------------------


class _Group:
    """Geoms of one type processed together each tick, each over a square block of nodes.

    Spheres use a fixed block (their diameter); other types a block sized each tick to the part
    of the geom below the highest soil node (e.g. the low end of a tilted capsule).
    """

    def __init__(
        self, kind: int, geoms: np.ndarray, model: Any, body: np.ndarray, nbody: int, width: int
    ):
        self.kind = kind
        self.geoms = geoms
        self.count = len(geoms)
        self.size = np.array(model.geom_size[geoms], dtype=np.float64)
        self.body = body  # index into MujocoSoil.body_ids, per geom
        self.body_identity = np.array_equal(body, np.arange(nbody))
        self.below, self.span = _SHAPES[kind]
        self.sphere = kind == _SPHERE
        self.radius = self.size[:, 0].copy()
        self.r2 = (self.radius**2)[:, None, None]
        self.reach_xy = np.array([_horizontal_reach(kind, size) for size in self.size])
        self.max_width = width
        # Body mass shared among the body's soil geoms (for the shear-stability limit).
        self.mass_share = np.ones(self.count)
        self.last_index: np.ndarray | None = None
        self._buffers: dict[int, tuple] = {}

    def setup(self, grid: SoilGrid, rim: int) -> None:
        """Bind to the grid; ``rim`` extra nodes around each block (for bulldozed soil)."""
        self.grid = grid
        self.rim = rim
        self.reach_cells = (self.radius / grid.resolution + rim)[:, None]
        self.fixed = self.buffers(self.max_width + 2 * rim) if self.sphere else None

    def buffers(self, width: int) -> tuple:
        """(width, node steps, flat index offsets, moments, weights, below) for a block width."""
        found = self._buffers.get(width)
        if found is None:
            grid = self.grid
            steps = np.arange(width)
            flat = (steps[:, None] * grid.stride + steps).reshape(-1)
            flat += grid.margin * grid.stride + grid.margin
            g, n = self.count, width * width
            moments = np.ones((4, g, n))  # [1, x, y, z] of each node's body point minus the CoM
            weights = np.empty((3, g, n))  # node forces
            below = np.empty((g, width, width))
            found = (
                width,
                steps * grid.resolution,
                flat.astype(np.float64),
                moments,
                weights,
                below,
            )
            self._buffers[width] = found
        return found

    def locate(self, soil: MujocoSoil, top: float) -> tuple | None:
        """This tick's node blocks and contacts, or None when every geom is above the soil."""
        centre = soil._geom_xpos[self.geoms]
        grid = soil.grid
        if self.sphere:
            if min((centre[:, 2] - self.radius).tolist()) >= top:
                return None
            mat, buffers = None, self.fixed
            cells = centre[:, :2] - soil._origin
            cells *= soil._inv_res
            first = np.ceil(cells - self.reach_cells)
        else:
            mat = soil._geom_xmat[self.geoms]
            lowest, lo, hi = self.span(centre, mat, self.size, top)
            if min(lowest.tolist()) >= top:
                return None
            first = np.ceil((lo - soil._origin) * soil._inv_res)
            last = np.floor((hi - soil._origin) * soil._inv_res)
            width = min(max(int((last - first).max()) + 1, 1), self.max_width)
            first -= self.rim
            buffers = self.buffers(width + 2 * self.rim)
            cells = centre[:, :2] - soil._origin
            cells *= soil._inv_res
        np.maximum(first, soil._clip_lo, out=first)
        np.minimum(first, soil._clip_hi, out=first)
        rel = first - cells
        rel *= grid.resolution
        offsets = rel[:, :, None] + buffers[1]  # (G, 2, W): node x and y minus the geom's
        index = (first @ soil._index_scale)[:, None] + buffers[2]
        index = index.astype(np.intp)
        below = self.below(offsets, mat, self, buffers[5]).reshape(self.count, -1)
        sinkage = grid.level0[index] - centre[:, 2, None]
        sinkage += below  # depth of the geom's lower surface below level0
        plastic = grid.plastic[index]
        elastic = sinkage - plastic
        contact = np.heaviside(elastic, 0.0)
        return (
            self,
            centre,
            buffers,
            offsets,
            index,
            below,
            sinkage,
            elastic,
            plastic,
            contact,
            first,
        )

    def solve(self, block: tuple, soil: MujocoSoil, om: np.ndarray, com: np.ndarray, dt: float):
        """SCM law at the block's nodes; returns (geom wrench (G, 6), record for accessors)."""
        _, centre, buffers, offsets, index, below, sinkage, elastic, plastic, contact, _ = block
        grid, law = soil.grid, soil.law
        width, _, _, moments, weights, _ = buffers
        g = self.count
        if not self.body_identity:
            om, com = om[self.body], com[self.body]
        # Node points relative to the body CoM, and their velocities (3, G, N).
        arm = centre - com
        rows = moments.reshape(4, g, width, width)
        np.add(offsets[:, 0, :, None], arm[:, 0, None, None], out=rows[1])
        np.add(offsets[:, 1, None, :], arm[:, 1, None, None], out=rows[2])
        np.subtract(arm[:, 2, None], below, out=moments[3])
        velocity = np.matmul(om, moments.transpose(1, 0, 2))
        velocity = np.ascontiguousarray(velocity.transpose(1, 0, 2))
        slip = np.hypot(velocity[0], velocity[1])
        if law.needs_width:
            inv_b = patch_inverse_width(contact.reshape(g, width, width) > 0.0, grid.resolution)
            modulus = law.modulus_area(inv_b)[:, None]
        else:
            modulus = law.Kphi_area
        shear = grid.shear[index]
        normal, tau, plastic_new, shear_new, static = law.update(
            sinkage,
            elastic,
            plastic,
            shear,
            contact,
            velocity[2],
            slip,
            modulus,
            dt,
            out=weights[2],
        )
        grid.plastic[index] = plastic_new
        if self.rim:
            self.bulldoze(grid, index, contact, plastic, plastic_new, width)
        if self.last_index is not None:
            grid.shear[self.last_index] = 0.0
        grid.shear[index] = shear_new
        self.last_index = index
        # Shear force f = coef * v_t (coef <= 0: along -v_t / |v_t|). At low slip speed this is a
        # viscous force sum(-coef) * v_t; where that viscosity would reverse the slip within one
        # tick (> mass / dt, the explicit limit), it is scaled down to stop the slip instead.
        coef = np.maximum(slip, _SLIP_EPS)
        np.divide(tau, coef, out=coef)
        viscosity = coef.sum(axis=1)
        viscosity *= -dt
        np.maximum(viscosity, self.mass_share, out=viscosity)
        np.divide(self.mass_share, viscosity, out=viscosity)
        coef *= viscosity[:, None]
        np.multiply(velocity[:2], coef, out=weights[:2])
        fm = np.matmul(weights.transpose(1, 0, 2), moments.transpose(1, 2, 0)).reshape(g, 12)
        return fm @ _TO_WRENCH, (index, contact, centre, below, normal, tau, static)

    def bulldoze(self, grid, index, contact, plastic, plastic_new, width) -> None:
        """Move the soil pressed down this tick onto the nodes just outside each patch."""
        g = self.count
        removed = ((plastic_new - plastic) * contact).sum(axis=1)
        inside = contact.reshape(g, width, width) > 0.0
        ring = inside.copy()
        ring[:, 1:] |= inside[:, :-1]
        ring[:, :-1] |= inside[:, 1:]
        ring[:, :, 1:] |= inside[:, :, :-1]
        ring[:, :, :-1] |= inside[:, :, 1:]
        ring &= ~inside
        ring = ring.reshape(g, -1)
        count = np.count_nonzero(ring, axis=1)
        rise = np.broadcast_to((removed / np.maximum(count, 1))[:, None], ring.shape)
        nodes = index[ring]
        if nodes.size:
            np.add.at(grid.level0, nodes, rise[ring])
            grid.top = max(grid.top, float(grid.level0[nodes].max()))


class MujocoSoil:
    """Deformable SCM soil under some MuJoCo bodies; an advanceable stepped before ``mj_step``.

    ``params``: a :class:`SoilParameters` or a preset name (``SOIL_PRESETS``). ``bodies``: the
    bodies whose sphere/capsule/ellipsoid/cylinder/box geoms touch the soil (other geom types
    of these bodies are skipped and listed in ``skipped_geoms``); ``geoms``: individual geoms
    (any other type raises ``ValueError``); both may be given. ``extent`` (m), ``resolution``
    (m), ``center`` and ``level`` (m, or an ``(nx, ny)`` array) define the grid. Each tick
    only the nodes within a geom's horizontal reach are processed, and only for geoms whose
    lowest point is below the highest soil node, so a large field costs memory, not time.
    ``bulldozing``: the volume pressed down under a geom each tick is spread evenly over the
    nodes just outside its patch (a rim that conserves the soil volume; no erosion or flow).
    """

    def __init__(
        self,
        model: Any,
        data: Any,
        params: SoilParameters | str,
        *,
        bodies: Sequence[str | int] | None = None,
        geoms: Sequence[str | int] | None = None,
        extent: Sequence[float] = (4.0, 4.0),
        resolution: float = 0.02,
        center: Sequence[float] = (0.0, 0.0),
        level: float | np.ndarray = 0.0,
        bulldozing: bool = False,
    ) -> None:
        if type(model).__name__ != "MjModel" or type(data).__name__ != "MjData":
            raise ValueError(
                f"model={type(model).__name__}, data={type(data).__name__}: expected a "
                "mujoco.MjModel and its mujoco.MjData"
            )
        if (
            isinstance(resolution, bool)
            or not isinstance(resolution, (int, float))
            or not 0 < resolution < math.inf
        ):
            raise ValueError(f"resolution={resolution!r}: expected a finite float > 0 (m)")
        res = float(resolution)
        self.model, self.data = model, data
        self.params = soil_preset(params) if isinstance(params, str) else params
        if not isinstance(self.params, SoilParameters):
            raise ValueError(f"params={params!r}: expected a SoilParameters or a preset name")
        self.geom_ids, skipped = _resolve_geoms(model, bodies, geoms)
        self.skipped_geoms = [model.geom(g).name or f"#{g}" for g in skipped]
        geom_bodies = np.array([int(model.geom_bodyid[g]) for g in self.geom_ids])
        self.body_ids = np.unique(geom_bodies)
        body_pos = {int(b): i for i, b in enumerate(self.body_ids)}
        members: dict[tuple[int, int], list[int]] = {}
        for g in self.geom_ids:
            kind = int(model.geom_type[g])
            width = math.floor(2 * _horizontal_reach(kind, model.geom_size[g]) / res) + 1
            members.setdefault((kind, width), []).append(g)
        self._groups: list[_Group] = []
        widths = []
        for (kind, width), geom_list in sorted(members.items()):
            geom_array = np.array(geom_list)
            body = np.array([body_pos[int(model.geom_bodyid[g])] for g in geom_list])
            group = _Group(kind, geom_array, model, body, len(self.body_ids), width)
            owners = model.geom_bodyid[geom_array]
            share = model.body_mass[owners] / [np.count_nonzero(geom_bodies == b) for b in owners]
            group.mass_share = np.maximum(share, 1e-9)
            self._groups.append(group)
            widths.append(width)
        if not isinstance(bulldozing, bool):
            raise ValueError(f"bulldozing={bulldozing!r}: expected True or False")
        self.bulldozing = bulldozing
        rim = 1 if bulldozing else 0
        self.grid = SoilGrid(extent, res, center, level, margin=max(widths) + 2 * rim)
        for group in self._groups:
            group.setup(self.grid, rim)
        self.law = ScmLaw(self.params, self.grid.node_area)
        # Views of MjData arrays (attribute access on MjData costs about a microsecond).
        self._geom_xpos, self._geom_xmat = data.geom_xpos, data.geom_xmat
        self._xipos = data.xipos
        self._body_velocity = np.zeros((len(self.body_ids), 6))  # [w, v at the CoM], world
        self._velocity_rows = [
            (self._body_velocity[i], int(b)) for i, b in enumerate(self.body_ids)
        ]
        self._xfrc = data.xfrc_applied
        self._origin = np.array(self.grid.origin)
        self._inv_res = 1.0 / res
        self._clip_lo = -float(self.grid.margin)
        self._clip_hi = np.array(self.grid.shape, dtype=np.float64)
        self._index_scale = np.array([float(self.grid.stride), 1.0])
        self._wrench = np.zeros((len(self.body_ids), 6))
        self._direct = len(self._groups) == 1 and self._groups[0].body_identity
        self._claim: np.ndarray | None = None  # per-node scratch, allocated on first use
        self._stamp = 0
        self._zmin: np.ndarray | None = None
        self._owner: np.ndarray | None = None
        self._last: list[tuple] = []
        self._dirty = False
        self._object_velocity: Any = None
        self._last_dt = 0.0
        self._obj_body: Any = None
        self.energy_dissipated = 0.0

    # ---------------------------------------------------------------------------- stepping
    def Advance(self, dt: float) -> None:
        """Compute the soil wrench on every soil body for the current state into xfrc_applied."""
        import mujoco

        model, data, grid = self.model, self.data, self.grid
        if self._object_velocity is None:
            self._object_velocity = mujoco.mj_objectVelocity
            self._obj_body = mujoco.mjtObj.mjOBJ_BODY
        mujoco.mj_kinematics(model, data)
        top = grid.top
        blocks = []
        for group in self._groups:
            block = group.locate(self, top)
            if block is not None:
                blocks.append(block)
            elif group.last_index is not None:
                grid.shear[group.last_index] = 0.0
                group.last_index = None
        self._last = []
        if not blocks and not self._dirty:
            return
        mujoco.mj_comPos(model, data)
        mujoco.mj_comVel(model, data)
        om, com = self._body_motion()
        twist = self._body_velocity[:, _SWAP]  # [v, w] to pair with the wrench [f, t]
        if self._dirty:  # work of the last tick's wrench, second half (trapezoid on velocity)
            work = np.vdot(self._wrench, twist)
            self.energy_dissipated -= 0.5 * self._last_dt * float(work)
        if not blocks:
            self._xfrc[self.body_ids] = 0.0
            self._wrench = np.zeros_like(self._wrench)
            self._dirty = False
            return
        self._resolve_overlaps(blocks)
        if self._direct:
            wrench, record = blocks[0][0].solve(blocks[0], self, om, com, dt)
            self._last.append(record)
        else:
            wrench = np.zeros_like(self._wrench)
            for block in blocks:
                group = block[0]
                geom_wrench, record = group.solve(block, self, om, com, dt)
                np.add.at(wrench, group.body, geom_wrench)
                self._last.append(record)
        self._wrench = wrench
        self._xfrc[self.body_ids] = wrench
        self.energy_dissipated -= 0.5 * dt * float(np.vdot(wrench, twist))
        self._last_dt = dt
        self._dirty = True

    def _claims_conflict(self, blocks: list[tuple]) -> bool:
        """Might a node be in contact with two geoms? (Cheap tests; False is certain.)"""
        for block in blocks:
            if block[0].count > 1:  # two node blocks of one group overlap
                width, first = block[2][0], block[10].tolist()
                for i, a in enumerate(first):
                    for b in first[i + 1 :]:
                        if abs(a[0] - b[0]) < width and abs(a[1] - b[1]) < width:
                            return True
        if len(blocks) == 1:
            return False
        if self._claim is None:
            self._claim = np.zeros(self.grid.level0.shape, dtype=np.int64)
        self._stamp += 1  # nodes in contact in two groups' blocks
        stamp, claim = self._stamp, self._claim
        for k, block in enumerate(blocks):
            nodes = block[4][block[9] > 0.0]
            if k and (claim[nodes] == stamp).any():
                return True
            claim[nodes] = stamp
        return False

    def _resolve_overlaps(self, blocks: list[tuple]) -> None:
        """Give a node claimed by several geoms to the geom whose surface is lowest there."""
        if not self._claims_conflict(blocks):
            return
        if self._zmin is None:
            self._zmin = np.full_like(self.grid.level0, np.inf)
            self._owner = np.full(self.grid.level0.shape, len(self.geom_ids), dtype=np.intp)
        zmin, owner = self._zmin, self._owner
        claims = []
        for block in blocks:
            index, contact = block[4], block[9]
            where = np.flatnonzero(contact)
            z = (block[1][:, 2, None] - block[5]).reshape(-1)[where]
            claims.append((where, index.reshape(-1)[where], z))
            np.minimum.at(zmin, claims[-1][1], z)
        uid = 0
        for block, (where, nodes, z) in zip(blocks, claims, strict=True):
            ids = uid + where // block[4].shape[1]
            uid += block[0].count
            win = z <= zmin[nodes]
            np.minimum.at(owner, nodes[win], ids[win])
        uid, losses = 0, []
        for block, (where, nodes, _) in zip(blocks, claims, strict=True):
            ids = uid + where // block[4].shape[1]
            uid += block[0].count
            losses.append(where[ids != owner[nodes]])
        for block, (_, nodes, _), lost in zip(blocks, claims, losses, strict=True):
            zmin[nodes] = np.inf
            owner[nodes] = len(self.geom_ids)
            block[9].reshape(-1)[lost] = 0.0  # out of contact for this geom
            block[4].reshape(-1)[lost] = 0  # its writes go to an inert padding node

    def _body_motion(self) -> tuple[np.ndarray, np.ndarray]:
        """Per soil body: Om (3 x 4) with v(p) = Om @ [1, p - com], and the com (3,)."""
        velocity = self._body_velocity
        for row, body in self._velocity_rows:
            self._object_velocity(self.model, self.data, self._obj_body, body, row, 0)
        om = velocity[:, _OM_SRC]
        om *= _OM_SIGN
        return om.reshape(-1, 3, 4), self._xipos[self.body_ids]

    # ---------------------------------------------------------------------------- state
    def reset(self) -> None:
        """Restore the initial soil (heights, plastic sinkage, shear) and zero the soil wrench."""
        self.grid.reset()
        for group in self._groups:
            group.last_index = None
        self._last = []
        self._wrench = np.zeros_like(self._wrench)
        self._xfrc[self.body_ids] = 0.0
        self._dirty = False
        self.energy_dissipated = 0.0

    def exclude_ground(self, ground: str | int = "floor") -> int:
        """``exclude_ground_contacts(model, ground, soil geoms)``; returns the bit used."""
        return exclude_ground_contacts(self.model, ground, self.geom_ids)

    def forces_on(self, body: str | int) -> np.ndarray:
        """Last soil wrench on ``body``: world force (3,) then torque about its CoM (3,)."""
        index = _object_id(self.model, "body", body, self.model.nbody)
        where = np.flatnonzero(self.body_ids == index)
        if where.size == 0:
            raise ValueError(f"body {body!r}: expected one of the soil's bodies")
        return self._wrench[where[0]].copy()

    def _scatter_last(self, pick: Any, flat: np.ndarray | None = None) -> np.ndarray:
        """Flat padded per-node array with ``pick(record)`` written at last tick's contacts."""
        flat = np.zeros_like(self.grid.level0) if flat is None else flat
        for record in self._last:
            index, contact = record[0], record[1] > 0.0
            flat[index[contact]] = pick(record)[contact]
        return flat

    @property
    def heights(self) -> np.ndarray:
        """Current surface height of every node (m), ``(nx, ny)``; under a body, its surface."""
        flat = self.grid.level0 - self.grid.plastic
        self._scatter_last(lambda r: r[2][:, 2, None] - r[3], flat)
        return self.grid.interior(flat).copy()

    @property
    def sinkage(self) -> np.ndarray:
        """Initial level minus current height (m), ``(nx, ny)``."""
        return self.grid.reset_level - self.heights

    @property
    def plastic_sinkage(self) -> np.ndarray:
        """Permanent (plastic) sinkage below ``level0`` of each node (m), ``(nx, ny)``."""
        return self.grid.interior(self.grid.plastic).copy()

    @property
    def pressure(self) -> np.ndarray:
        """Normal pressure at the last tick (Pa), ``(nx, ny)``; 0 out of contact."""
        flat = self._scatter_last(lambda r: r[4])
        return self.grid.interior(flat) / self.grid.node_area

    @property
    def shear_stress(self) -> np.ndarray:
        """Magnitude of the shear stress at the last tick (Pa), ``(nx, ny)``."""
        flat = self._scatter_last(lambda r: r[5])
        return self.grid.interior(flat) / -self.grid.node_area

    @property
    def shear_displacement(self) -> np.ndarray:
        """Shear displacement j of each node after the last tick (m), ``(nx, ny)``."""
        return self.grid.interior(self.grid.shear).copy()

    @property
    def elastic_energy(self) -> float:
        """Elastic energy stored in the soil under the bodies at the last tick (J)."""
        total = 0.0
        for record in self._last:
            static = np.maximum(record[6], 0.0) * record[1]
            total += float(np.vdot(static, static))
        return total * 0.5 * self.law.inv_elastic_area
