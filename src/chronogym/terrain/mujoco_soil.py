"""SCM soil under MuJoCo bodies: an advanceable that writes the soil wrench to ``xfrc_applied``.

Use it before ``mj_step`` in a task's advanceables::

    calves = ["FR_calf", "FL_calf", "RR_calf", "RL_calf"]   # calf capsule + foot sphere each
    soil = MujocoSoil(model, data, "soft", bodies=calves, extent=(8, 8), resolution=0.01)
    soil.exclude_ground("floor")      # the rigid floor does not touch the soil's geoms
    task.advanceables = [soil, (model, data)]

Order of one tick (``Advance(dt)``), for the state ``mj_step`` is about to integrate:

1. ``mj_kinematics``, ``mj_comPos``, ``mj_comVel``: poses and velocities of the current
   ``qpos``/``qvel`` (after ``mj_step`` MuJoCo's derived fields describe the previous state);
   steps 2-5 are one compiled call (``_kernels.soil_tick``, numba; see ``scm`` for why);
2. active region: per geom whose lowest point is below the highest soil node, a square block
   of nodes around the part of it that can touch the soil, and the height of the geom's lower
   surface over each node (closed form for sphere, capsule, ellipsoid, cylinder and box, any
   orientation; what a ray cast up from below the node would hit first);
3. contact where that surface is below the node's current surface (``level0 - plastic``,
   which holds the plastic flow of every earlier tick); a node under two geoms belongs to the
   one whose surface is lower there (on a tie, the first in (type, block width, id) order);
4. SCM law (``scm.ScmLaw``) at the contact nodes: pressure, shear, plastic sinkage and shear
   displacement; the grid is updated in place, at contact nodes only, each by its one geom
   (shear is reset where a node left contact; with ``bulldozing``, the displaced volume is
   put on the rim of each patch);
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
from chronogym.terrain.scm import ScmLaw, SoilGrid
from chronogym.validation import check_bool, check_positive, is_int

__all__ = ["MujocoSoil", "exclude_ground_contacts"]

# mjtGeom values (stable in MuJoCo's C API; ``_kernels`` has the same).
_SPHERE, _CAPSULE, _ELLIPSOID, _CYLINDER, _BOX = 2, 3, 4, 5, 6
_KIND_NAMES = {_SPHERE: "sphere", _CAPSULE: "capsule", _ELLIPSOID: "ellipsoid"}
_KIND_NAMES |= {_CYLINDER: "cylinder", _BOX: "box"}
_SHAPES = frozenset(_KIND_NAMES)
_TYPE_NAMES = {0: "plane", 1: "hfield", 7: "mesh", 8: "sdf"}


def _compiled() -> Any:
    """The numba kernels and their table layout (``_kernels``; imports numba on first use)."""
    from chronogym.terrain import _kernels

    return _kernels


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


# --------------------------------------------------------------------------------------------
# Model lookups.
# --------------------------------------------------------------------------------------------


def _object_id(model: Any, kind: str, key: str | int, count: int) -> int:
    import mujoco

    if is_int(key):
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
    Building one imports numba (and compiles the tick on first use, or loads it from the cache).
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
        follow: bool | str | int = False,
    ) -> None:
        if type(model).__name__ != "MjModel" or type(data).__name__ != "MjData":
            raise ValueError(
                f"model={type(model).__name__}, data={type(data).__name__}: expected a "
                "mujoco.MjModel and its mujoco.MjData"
            )
        res = check_positive("resolution", resolution, "a finite float > 0 (m)")
        self.model, self.data = model, data
        self.params = soil_preset(params) if isinstance(params, str) else params
        if not isinstance(self.params, SoilParameters):
            raise ValueError(f"params={params!r}: expected a SoilParameters or a preset name")
        geom_ids, skipped = _resolve_geoms(model, bodies, geoms)
        self.skipped_geoms = [model.geom(g).name or f"#{g}" for g in skipped]
        self.bulldozing = bulldozing = check_bool("bulldozing", bulldozing)
        rim = 1 if bulldozing else 0
        # Geoms in a fixed order (type, block width, id): the first wins a node on a tie.
        widths = {}
        for g in geom_ids:
            kind = int(model.geom_type[g])
            widths[g] = math.floor(2 * _horizontal_reach(kind, model.geom_size[g]) / res) + 1
        order = sorted(geom_ids, key=lambda g: (int(model.geom_type[g]), widths[g], g))
        self.geom_ids = sorted(geom_ids)
        geom_bodies = np.array([int(model.geom_bodyid[g]) for g in order])
        self.body_ids = np.unique(geom_bodies)
        self.grid = SoilGrid(extent, res, center, level, margin=max(widths.values()) + 2 * rim)
        self.law = ScmLaw(self.params, self.grid.node_area)
        self.follow_body = self._follow_body(follow, level)
        self._k = _compiled()  # numba: imported once a soil is built
        self._tick = self._k.soil_tick
        self._setup_tables(order, geom_bodies, widths, rim)
        # Views of MjData arrays (attribute access on MjData costs about a microsecond).
        self._xfrc = data.xfrc_applied
        self._args = (
            data.geom_xpos,
            data.geom_xmat,
            data.xipos,
            data.cvel,
            data.subtree_com,
            data.xfrc_applied,
            self.grid.state,
            self._gint,
            self._gflt,
            self._bint,
            self._bflt,
            self._const,
            self._nidx,
            self._nval,
            self._last_nodes,
        )
        self._mj: tuple | None = None

    def _follow_body(self, follow: bool | str | int, level: float | np.ndarray) -> int | None:
        """The body the window follows (``None``: a fixed field)."""
        if follow is False:
            return None
        if np.ndim(level) != 0:
            raise ValueError(
                "follow with an array level: expected a float level (a moving window has "
                "uniform soil ahead of it)"
            )
        if follow is True:
            roots = {int(self.model.body_rootid[b]) for b in self.body_ids}
            if len(roots) != 1:
                raise ValueError(
                    f"follow=True with soil bodies under {len(roots)} root bodies: expected one "
                    "root, or the name of the body to follow"
                )
            return roots.pop()
        return _object_id(self.model, "body", follow, self.model.nbody)

    def _recentre(self) -> None:
        """Move the window over the followed body when it is more than a quarter of the
        window from the centre (a shift of whole nodes; see ``SoilGrid.shift``)."""
        grid = self.grid
        x, y = self.data.xipos[self.follow_body, :2].tolist()
        cx, cy = grid.center
        res = grid.resolution
        if (
            abs(x - cx) * 4 <= (grid.shape[0] - 1) * res
            and abs(y - cy) * 4 <= (grid.shape[1] - 1) * res
        ):
            return
        delta = grid.shift(round((x - cx) / res), round((y - cy) / res))
        K = self._k
        self._const[K.C_ORIGIN_X], self._const[K.C_ORIGIN_Y] = grid.origin
        # Last tick's contact nodes (their shear resets when they lift), now moved by delta;
        # any the window left behind (bodies spread over more than half of it) are dropped.
        count = int(self._last_nodes[0])
        nodes = self._last_nodes[1 : 1 + count] - delta
        row, col = np.divmod(nodes, grid.stride)
        inside = (row >= grid.margin) & (row < grid.margin + grid.shape[0])
        inside &= (col >= grid.margin) & (col < grid.margin + grid.shape[1])
        kept = nodes[inside]
        self._last_nodes[0] = kept.size
        self._last_nodes[1 : 1 + kept.size] = kept
        self._nidx -= delta
        self._gint[:, K.GI_ACTIVE] = 0  # the accessors' view of the last tick is gone

    def _setup_tables(
        self, order: list[int], geom_bodies: np.ndarray, widths: dict[int, int], rim: int
    ) -> None:
        """The flat tables the compiled tick reads (layout in ``_kernels``)."""
        K, model, grid, law = self._k, self.model, self.grid, self.law
        count = len(order)
        slot = {int(b): i for i, b in enumerate(self.body_ids)}
        gint = np.zeros((count, K.GI_COLS), dtype=np.int64)
        gflt = np.zeros((count, K.GF_COLS))
        for i, g in enumerate(order):
            body = int(model.geom_bodyid[g])
            gint[i, [K.GI_GEOM, K.GI_KIND, K.GI_SLOT, K.GI_MAXW]] = (
                g,
                int(model.geom_type[g]),
                slot[body],
                widths[g],
            )
            size = np.array(model.geom_size[g], dtype=np.float64)
            gflt[i, K.GF_SIZE : K.GF_SIZE + 3] = size
            gflt[i, K.GF_REACH] = size[0] / grid.resolution + rim  # spheres' block, in cells
            # Body mass shared among the body's soil geoms (for the shear-stability limit).
            share = model.body_mass[body] / np.count_nonzero(geom_bodies == body)
            gflt[i, K.GF_MASS] = max(share, 1e-9)
        bint = np.array([(int(b), int(model.body_rootid[b])) for b in self.body_ids])
        const = np.zeros(K.C_COLS)
        columns = {
            K.C_RES: grid.resolution,
            K.C_INV_RES: 1.0 / grid.resolution,
            K.C_ORIGIN_X: grid.origin[0],
            K.C_ORIGIN_Y: grid.origin[1],
            K.C_CLIP_LO: -grid.margin,
            K.C_NX: grid.shape[0],
            K.C_NY: grid.shape[1],
            K.C_STRIDE: grid.stride,
            K.C_BASE: grid.margin * grid.stride + grid.margin,
            K.C_RIM: rim,
            K.C_N: law.n,
            K.C_KC: law.Kc_area,
            K.C_KPHI: law.Kphi_area,
            K.C_ELASTIC: law.elastic_area,
            K.C_INV_ELASTIC: law.inv_elastic_area,
            K.C_NEG_DAMPING: law.neg_damping_area,
            K.C_COHESION: law.cohesion_area,
            K.C_TAN_PHI: law.tan_phi,
            K.C_NEG_INV_JANOSI: law.neg_inv_janosi,
            K.C_NEEDS_WIDTH: law.needs_width,
        }
        for column, value in columns.items():
            const[column] = value
        nodes = int(max(widths[g] + 2 * rim for g in order) ** 2)
        self._order = np.array(order)
        self._gint, self._gflt, self._bint, self._const = gint, gflt, bint.astype(np.int64), const
        self._bflt = np.zeros((len(self.body_ids), K.BF_COLS))
        self._nidx = np.zeros((count, nodes), dtype=np.int64)
        self._nval = np.zeros((count, K.NV_ROWS, nodes))
        self._last_nodes = np.zeros(1 + count * nodes, dtype=np.int64)

    # ---------------------------------------------------------------------------- stepping
    def Advance(self, dt: float) -> None:
        """Compute the soil wrench on every soil body for the current state into xfrc_applied."""
        if self._mj is None:
            import mujoco

            self._mj = (mujoco.mj_kinematics, mujoco.mj_comPos, mujoco.mj_comVel)
        model, data = self.model, self.data
        kinematics, com_pos, com_vel = self._mj
        kinematics(model, data)
        com_pos(model, data)
        com_vel(model, data)
        if self.follow_body is not None:
            self._recentre()
        grid = self.grid
        grid.top = self._tick(*self._args, float(grid.top), float(dt))

    # ---------------------------------------------------------------------------- state
    @property
    def energy_dissipated(self) -> float:
        """Work taken by the soil since the last reset (J, trapezoidal rule over the ticks)."""
        return float(self._const[self._k.C_ENERGY])

    @energy_dissipated.setter
    def energy_dissipated(self, value: float) -> None:
        self._const[self._k.C_ENERGY] = value

    def reset(self) -> None:
        """Restore the initial soil (heights, plastic sinkage, shear) and zero the soil wrench."""
        self.grid.reset()
        self._const[self._k.C_ORIGIN_X], self._const[self._k.C_ORIGIN_Y] = self.grid.origin
        self._last_nodes[0] = 0
        self._gint[:, self._k.GI_ACTIVE] = 0
        self._bflt[:, self._k.BF_WRENCH : self._k.BF_WRENCH + 6] = 0.0
        self._xfrc[self.body_ids] = 0.0
        self._const[[self._k.C_ENERGY, self._k.C_LAST_DT, self._k.C_DIRTY]] = 0.0

    def exclude_ground(self, ground: str | int = "floor") -> int:
        """``exclude_ground_contacts(model, ground, soil geoms)``; returns the bit used."""
        return exclude_ground_contacts(self.model, ground, self.geom_ids)

    @property
    def body_forces(self) -> np.ndarray:
        """Read-only view of the last soil wrench on each soil body, ``(B, 6)``: world force
        then torque about its CoM, rows in ``body_ids`` order (updated in place each tick)."""
        view = self._bflt[:, self._k.BF_WRENCH : self._k.BF_WRENCH + 6]
        view.flags.writeable = False
        return view

    def forces_on(self, body: str | int) -> np.ndarray:
        """Last soil wrench on ``body``: world force (3,) then torque about its CoM (3,)."""
        index = _object_id(self.model, "body", body, self.model.nbody)
        where = np.flatnonzero(self.body_ids == index)
        if where.size == 0:
            raise ValueError(f"body {body!r}: expected one of the soil's bodies")
        return self._bflt[where[0], self._k.BF_WRENCH : self._k.BF_WRENCH + 6].copy()

    def _last_contacts(self):
        """Per geom in contact at the last tick: (nodes, its rows of the node scratch)."""
        for g in np.flatnonzero(self._gint[:, self._k.GI_ACTIVE]):
            n = int(self._gint[g, self._k.GI_WIDTH]) ** 2
            values = self._nval[g, :, :n]
            contact = values[self._k.NV_CONTACT] > 0.0
            yield (
                self._nidx[g, :n][contact],
                values[:, contact],
                self._gflt[g, self._k.GF_CENTRE + 2],
            )

    def _scatter_last(self, row: int, flat: np.ndarray | None = None) -> np.ndarray:
        """Flat padded per-node array with scratch row ``row`` written at last tick's contacts
        (``row`` = NV_BELOW writes the body surface's height there)."""
        flat = np.zeros_like(self.grid.level0) if flat is None else flat
        for nodes, values, centre_z in self._last_contacts():
            flat[nodes] = centre_z - values[row] if row == self._k.NV_BELOW else values[row]
        return flat

    @property
    def heights(self) -> np.ndarray:
        """Current surface height of every node (m), ``(nx, ny)``; under a body, its surface."""
        flat = self._scatter_last(self._k.NV_BELOW, self.grid.level0 - self.grid.plastic)
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
        return self.grid.interior(self._scatter_last(self._k.NV_NORMAL)) / self.grid.node_area

    @property
    def shear_stress(self) -> np.ndarray:
        """Magnitude of the shear stress at the last tick (Pa), ``(nx, ny)``."""
        return self.grid.interior(self._scatter_last(self._k.NV_TAU)) / -self.grid.node_area

    @property
    def shear_displacement(self) -> np.ndarray:
        """Shear displacement j of each node after the last tick (m), ``(nx, ny)``."""
        return self.grid.interior(self.grid.shear).copy()

    @property
    def elastic_energy(self) -> float:
        """Elastic energy stored in the soil under the bodies at the last tick (J)."""
        total = 0.0
        for _, values, _ in self._last_contacts():
            static = np.maximum(values[self._k.NV_STATIC], 0.0)
            total += float(np.vdot(static, static))
        return total * 0.5 * self.law.inv_elastic_area
