"""The compiled (numba) tick of ``MujocoSoil``: geometry, SCM law and body wrench in one pass.

Imported by ``MujocoSoil`` when a soil is built, never by ``import chronogym.terrain``. One
kernel, :func:`soil_tick`, does a whole tick for every soil geom; its helpers (the lower
surface of each geom type, the block span, overlaps, Bekker width, bulldozing) are compiled into
it. All arguments are float64/int64 C arrays plus two floats: one type signature, compiled once
per machine and cached on disk (``cache=True``, in ``__pycache__`` or numba's cache dir). The table
layout below lives in this file on purpose: numba freezes globals into the cached code and
only re-checks this file, so constants imported from elsewhere could go stale in the cache.

Why numba
    A tick touches tens (feet) to a few thousand (plates, wheels) nodes. Written as NumPy
    array operations it was ~70 calls of 0.4-1 us fixed overhead each, whatever the block
    size: 60-80 us per tick for the Go1's feet, 4x a rigid ``mj_step``, and 12-16x with the
    calf capsules. Here each node is visited once, in compiled loops without temporaries: a
    tick costs ~1.3 us of call overhead (17 arguments) plus ~20 ns per block node and ~50 ns
    per node in contact, 4-6 us for the Go1 (measured on a 2-core x86 VM).

The formulas, their order and the rounding follow ``scm.ScmLaw.update`` (kept as the NumPy
reference of the law) and the docstring of ``mujoco_soil``.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# mjtGeom values (stable in MuJoCo's C API).
SPHERE, CAPSULE, ELLIPSOID, CYLINDER, BOX = 2, 3, 4, 5, 6
EPS = 1e-12
SLIP_EPS = 1e-4  # m/s; below this slip speed the shear force fades out linearly
MISS = -1e6  # "below" of a vertical line that misses a geom: finite, never in contact

# Columns of the per-geom int table (G, GI_COLS); the last four are rewritten every tick.
GI_GEOM, GI_KIND, GI_SLOT, GI_MAXW, GI_ACTIVE, GI_WIDTH, GI_FIRSTX, GI_FIRSTY = range(8)
GI_COLS = 8
# Columns of the per-geom float table (G, GF_COLS); centre and offsets are rewritten every tick.
GF_SIZE, GF_REACH, GF_MASS, GF_CENTRE, GF_REL = 0, 3, 4, 5, 8
GF_COLS = 10
# Rows of the per-node scratch (G, NV_ROWS, nodes): geometry, start-of-tick state, law outputs.
NV_BELOW, NV_SINK, NV_PLASTIC, NV_SHEAR, NV_CONTACT, NV_NORMAL, NV_TAU, NV_STATIC = range(8)
NV_ROWS = 8
# Per-body float table (B, 12): soil wrench [force, torque] then velocity [w, v] at the CoM.
BF_WRENCH, BF_VEL = 0, 6
BF_COLS = 12
# Constants and state vector (float64): grid, law, then energy bookkeeping.
(
    C_RES,
    C_INV_RES,
    C_ORIGIN_X,
    C_ORIGIN_Y,
    C_CLIP_LO,
    C_NX,
    C_NY,
    C_STRIDE,
    C_BASE,
    C_RIM,
    C_N,
    C_KC,
    C_KPHI,
    C_ELASTIC,
    C_INV_ELASTIC,
    C_NEG_DAMPING,
    C_COHESION,
    C_TAN_PHI,
    C_NEG_INV_JANOSI,
    C_NEEDS_WIDTH,
    C_ENERGY,
    C_LAST_DT,
    C_DIRTY,
) = range(23)
C_COLS = 23

# --------------------------------------------------------------------------------------------
# Lower surface of a geom over the vertical line at (dx, dy) from its centre: the centre height
# minus the height of the geom's lowest point on the line, or MISS where the line misses it.
# ``m``: row-major rotation (9-tuple), ``s``: MuJoCo geom_size (3-tuple). Tuples, not array views:
# they are plain values in registers (an array view passed per node costs reference counting).
# --------------------------------------------------------------------------------------------


@njit(cache=True)
def _side_below(dx: float, dy: float, m: tuple, r: float, hl: float) -> tuple[float, float]:
    """Lower crossing of the infinite cylinder of radius r around the axis, within |t| <= hl."""
    ax, ay, az = m[2], m[5], m[8]
    e = dx * ax + dy * ay
    a = 1.0 - az * az
    c = dx * dx + dy * dy - e * e - r * r
    disc = e * e * az * az - a * c
    if a > EPS and disc > 0.0:
        dz = (e * az - math.sqrt(disc)) / a
        if abs(e + dz * az) <= hl:
            return -dz, e
    return -math.inf, e


@njit(cache=True)
def _below(kind: int, dx: float, dy: float, m: tuple, s: tuple) -> float:
    """Centre height minus the lower surface's height on the line (dx, dy), or MISS."""
    if kind == SPHERE:
        rem = s[0] * s[0] - dx * dx - dy * dy
        return math.sqrt(rem) if rem > 0.0 else MISS
    if kind == CAPSULE:
        r, hl = s[0], s[1]
        below, _ = _side_below(dx, dy, m, r, hl)
        for sign in (1.0, -1.0):
            ex, ey = dx - sign * hl * m[2], dy - sign * hl * m[5]
            rem = r * r - ex * ex - ey * ey
            if rem > 0.0:
                below = max(below, math.sqrt(rem) - sign * hl * m[8])
        return below if below > -math.inf else MISS
    if kind == CYLINDER:
        r, hl, az = s[0], s[1], m[8]
        below, e = _side_below(dx, dy, m, r, hl)
        if abs(az) > EPS:
            for t in (hl, -hl):
                dz = (t - e) / az
                if dx * dx + dy * dy + dz * dz - t * t <= r * r:
                    below = max(below, -dz)
        return below if below > -math.inf else MISS
    if kind == ELLIPSOID:
        a = b = c = 0.0
        for k in range(3):
            inv2 = 1.0 / s[k] ** 2
            u0 = dx * m[k] + dy * m[3 + k]  # local coordinates at the centre height
            up = m[6 + k]  # and of the line's direction
            a += up * up * inv2
            b += u0 * up * inv2
            c += u0 * u0 * inv2
        disc = b * b - a * (c - 1.0)
        return (b + math.sqrt(disc)) / a if disc > 0.0 else MISS
    # BOX: slab intersection of the vertical line with the three face pairs.
    entry, leave = -math.inf, math.inf
    for k in range(3):
        cz, h = m[6 + k], s[k]
        e = dx * m[k] + dy * m[3 + k]
        if abs(cz) <= EPS:  # face normal horizontal: the slab does not depend on z
            if abs(e) > h:
                return MISS
        else:
            t1, t2 = (-h - e) / cz, (h - e) / cz
            entry = max(entry, min(t1, t2))
            leave = min(leave, max(t1, t2))
    return -entry if entry <= leave and -math.inf < entry < math.inf else MISS


@njit(cache=True)
def _span(
    kind: int, cx: float, cy: float, cz: float, m: tuple, s: tuple, top: float
) -> tuple[float, float, float, float, float]:
    """(lowest point's height, lo x, lo y, hi x, hi y): the horizontal box that holds the part
    of a non-sphere geom below the height ``top`` (the highest soil node)."""
    if kind in (BOX, ELLIPSOID):
        ex = ey = ez = 0.0  # half-extent along world x, y, z
        for k in range(3):
            if kind == BOX:
                ex += abs(m[k]) * s[k]
                ey += abs(m[3 + k]) * s[k]
                ez += abs(m[6 + k]) * s[k]
            else:
                ex += (m[k] * s[k]) ** 2
                ey += (m[3 + k] * s[k]) ** 2
                ez += (m[6 + k] * s[k]) ** 2
        if kind == ELLIPSOID:
            ex, ey, ez = math.sqrt(ex), math.sqrt(ey), math.sqrt(ez)
        return cz - ez, cx - ex, cy - ey, cx + ex, cy + ey
    # Capsule, cylinder: around the part of the axis segment whose cross-section (reaching
    # ``down`` below the axis and ``pad`` sideways) dips below ``top``.
    r, hl = s[0], s[1]
    ax, ay, az = m[2], m[5], m[8]
    if kind == CAPSULE:
        down, pad_x, pad_y = r, r, r
    else:  # a disk of radius r across the axis a reaches r * sqrt(1 - a_i^2) along world i
        down = r * math.sqrt(max(1.0 - az * az, 0.0))
        pad_x = r * math.sqrt(max(1.0 - ax * ax, 0.0))
        pad_y = r * math.sqrt(max(1.0 - ay * ay, 0.0))
    up, dips = az > EPS, az < -EPS
    limit = (top + down - cz) / (az if up or dips else 1.0)
    t0 = max(-hl, limit) if dips else -hl
    t1 = min(hl, limit) if up else hl
    x0, y0, x1, y1 = cx + t0 * ax, cy + t0 * ay, cx + t1 * ax, cy + t1 * ay
    lowest = cz - abs(az) * hl - down
    lo_x, lo_y = min(x0, x1) - pad_x, min(y0, y1) - pad_y
    return lowest, lo_x, lo_y, max(x0, x1) + pad_x, max(y0, y1) + pad_y


# --------------------------------------------------------------------------------------------
# The tick.
# --------------------------------------------------------------------------------------------


@njit(cache=True)
def _locate(
    geom_xpos: np.ndarray,
    geom_xmat: np.ndarray,
    grid: np.ndarray,
    gint: np.ndarray,
    gflt: np.ndarray,
    const: np.ndarray,
    nidx: np.ndarray,
    nval: np.ndarray,
    top: float,
) -> bool:
    """Blocks, lower surface, sinkage and contact of every geom below ``top``; any active?"""
    res, inv_res = const[C_RES], const[C_INV_RES]
    ox, oy, rim = const[C_ORIGIN_X], const[C_ORIGIN_Y], int(const[C_RIM])
    clip_lo, nx, ny = const[C_CLIP_LO], const[C_NX], const[C_NY]
    stride, base = int(const[C_STRIDE]), int(const[C_BASE])
    level0, plastic, shear = grid[0], grid[1], grid[2]
    any_active = False
    for g in range(gint.shape[0]):
        gint[g, GI_ACTIVE] = 0
        geom, kind = gint[g, GI_GEOM], gint[g, GI_KIND]
        cx, cy, cz = geom_xpos[geom, 0], geom_xpos[geom, 1], geom_xpos[geom, 2]
        r = geom_xmat[geom]
        m = (r[0], r[1], r[2], r[3], r[4], r[5], r[6], r[7], r[8])
        s = (gflt[g, GF_SIZE], gflt[g, GF_SIZE + 1], gflt[g, GF_SIZE + 2])
        cell_x, cell_y = (cx - ox) * inv_res, (cy - oy) * inv_res
        if kind == SPHERE:
            if not cz - s[0] < top:
                continue
            first_x = np.ceil(cell_x - gflt[g, GF_REACH])
            first_y = np.ceil(cell_y - gflt[g, GF_REACH])
            width = gint[g, GI_MAXW] + 2 * rim
        else:
            lowest, lo_x, lo_y, hi_x, hi_y = _span(kind, cx, cy, cz, m, s, top)
            if not lowest < top:
                continue
            first_x, first_y = np.ceil((lo_x - ox) * inv_res), np.ceil((lo_y - oy) * inv_res)
            last_x, last_y = np.floor((hi_x - ox) * inv_res), np.floor((hi_y - oy) * inv_res)
            span = max(last_x - first_x, last_y - first_y)
            if not math.isfinite(span):
                continue
            width = min(max(int(span) + 1, 1), gint[g, GI_MAXW]) + 2 * rim
            first_x -= rim
            first_y -= rim
        if not (math.isfinite(first_x) and math.isfinite(first_y) and math.isfinite(cz)):
            continue
        first_x = min(max(first_x, clip_lo), nx)
        first_y = min(max(first_y, clip_lo), ny)
        rel_x, rel_y = (first_x - cell_x) * res, (first_y - cell_y) * res
        fx, fy = int(first_x), int(first_y)
        gint[g, GI_ACTIVE], gint[g, GI_WIDTH] = 1, width
        gint[g, GI_FIRSTX], gint[g, GI_FIRSTY] = fx, fy
        gflt[g, GF_CENTRE], gflt[g, GF_CENTRE + 1], gflt[g, GF_CENTRE + 2] = cx, cy, cz
        gflt[g, GF_REL], gflt[g, GF_REL + 1] = rel_x, rel_y
        any_active = True
        row = base + fx * stride + fy
        for i in range(width):
            dx = rel_x + i * res
            for j in range(width):
                k, node = i * width + j, row + i * stride + j
                below = _below(kind, dx, rel_y + j * res, m, s)
                sink = level0[node] - cz + below  # the surface's depth below level0
                nidx[g, k] = node
                nval[g, NV_BELOW, k] = below
                nval[g, NV_SINK, k] = sink
                nval[g, NV_PLASTIC, k] = plastic[node]
                nval[g, NV_SHEAR, k] = shear[node]
                nval[g, NV_CONTACT, k] = 1.0 if sink - plastic[node] > 0.0 else 0.0
    return any_active


@njit(cache=True)
def _resolve_overlaps(gint: np.ndarray, gflt: np.ndarray, nval: np.ndarray) -> None:
    """A node in contact with several geoms goes to the one whose surface is lowest there
    (ties: the first geom); the others lose it (contact 0)."""
    count = gint.shape[0]
    for g in range(count):
        if not gint[g, GI_ACTIVE]:
            continue
        wg, gx, gy = gint[g, GI_WIDTH], gint[g, GI_FIRSTX], gint[g, GI_FIRSTY]
        for h in range(g + 1, count):
            if not gint[h, GI_ACTIVE]:
                continue
            wh, hx, hy = gint[h, GI_WIDTH], gint[h, GI_FIRSTX], gint[h, GI_FIRSTY]
            x0, x1 = max(gx, hx), min(gx + wg, hx + wh)
            y0, y1 = max(gy, hy), min(gy + wg, hy + wh)
            for x in range(x0, x1):
                for y in range(y0, y1):
                    kg, kh = (x - gx) * wg + (y - gy), (x - hx) * wh + (y - hy)
                    # 2.0 marks a lost claim; it still counts as a claim for the other pairs.
                    if nval[g, NV_CONTACT, kg] == 0.0 or nval[h, NV_CONTACT, kh] == 0.0:
                        continue
                    zg = gflt[g, GF_CENTRE + 2] - nval[g, NV_BELOW, kg]
                    zh = gflt[h, GF_CENTRE + 2] - nval[h, NV_BELOW, kh]
                    if zg <= zh:
                        nval[h, NV_CONTACT, kh] = 2.0
                    else:
                        nval[g, NV_CONTACT, kg] = 2.0
    for g in range(count):
        if gint[g, GI_ACTIVE]:
            width = gint[g, GI_WIDTH]
            for k in range(width * width):
                if nval[g, NV_CONTACT, k] == 2.0:
                    nval[g, NV_CONTACT, k] = 0.0


@njit(cache=True)
def _inverse_width(contact: np.ndarray, width: int, res: float) -> float:
    """Bekker's 1/b of a block's patch: boundary nodes x res / (2 x nodes x res^2)."""
    nodes = boundary = 0
    for i in range(width):
        for j in range(width):
            if contact[i * width + j] == 0.0:
                continue
            nodes += 1
            inner = (
                i > 0
                and j > 0
                and i < width - 1
                and j < width - 1
                and contact[(i - 1) * width + j] != 0.0
                and contact[(i + 1) * width + j] != 0.0
                and contact[i * width + j - 1] != 0.0
                and contact[i * width + j + 1] != 0.0
            )
            if not inner:
                boundary += 1
    return boundary / (2.0 * res * max(nodes, 1))


@njit(cache=True)
def _bulldoze(
    level0: np.ndarray, nidx: np.ndarray, contact: np.ndarray, width: int, removed: float
) -> float:
    """Spread ``removed`` evenly over the block nodes next to (not in) the patch; new max."""
    ring = 0
    for pass_ in range(2):
        highest = -math.inf
        rise = removed / max(ring, 1)
        for i in range(width):
            for j in range(width):
                k = i * width + j
                if contact[k] != 0.0:
                    continue
                if (
                    (i > 0 and contact[k - width] != 0.0)
                    or (i < width - 1 and contact[k + width] != 0.0)
                    or (j > 0 and contact[k - 1] != 0.0)
                    or (j < width - 1 and contact[k + 1] != 0.0)
                ):
                    if pass_ == 0:
                        ring += 1
                    else:
                        level0[nidx[k]] += rise
                        highest = max(highest, level0[nidx[k]])
    return highest


@njit(cache=True)
def soil_tick(
    geom_xpos: np.ndarray,
    geom_xmat: np.ndarray,
    xipos: np.ndarray,
    cvel: np.ndarray,
    subtree_com: np.ndarray,
    xfrc_applied: np.ndarray,
    grid: np.ndarray,
    gint: np.ndarray,
    gflt: np.ndarray,
    bint: np.ndarray,
    bflt: np.ndarray,
    const: np.ndarray,
    nidx: np.ndarray,
    nval: np.ndarray,
    last: np.ndarray,
    top: float,
    dt: float,
) -> float:
    """One tick of the soil for the current MuJoCo state (after kinematics, comPos, comVel).

    ``grid`` (3, N): level0, plastic, shear (updated in place); ``gint``/``gflt``: per-geom
    tables, ``bint`` (B, 2): body id and root id, ``bflt``: per-body wrench and velocity,
    ``const``: grid and law constants and the energy state, ``nidx``/``nval``: per-geom node
    scratch (read back by the accessors), ``last``: count then nodes in contact last tick.
    Writes the soil wrench into ``xfrc_applied``; returns the new highest soil level.
    """
    level0, plastic, shear = grid[0], grid[1], grid[2]
    nbody = bint.shape[0]
    # Velocity [w, v] of each soil body at its CoM (as mj_objectVelocity, world frame).
    for b in range(nbody):
        body, root = bint[b, 0], bint[b, 1]
        w0, w1, w2 = cvel[body, 0], cvel[body, 1], cvel[body, 2]
        d0 = xipos[body, 0] - subtree_com[root, 0]
        d1 = xipos[body, 1] - subtree_com[root, 1]
        d2 = xipos[body, 2] - subtree_com[root, 2]
        vel = bflt[b, BF_VEL : BF_VEL + 6]
        vel[0], vel[1], vel[2] = w0, w1, w2
        vel[3] = cvel[body, 3] - (d1 * w2 - d2 * w1)
        vel[4] = cvel[body, 4] - (d2 * w0 - d0 * w2)
        vel[5] = cvel[body, 5] - (d0 * w1 - d1 * w0)
    any_active = _locate(geom_xpos, geom_xmat, grid, gint, gflt, const, nidx, nval, top)
    for k in range(last[0]):  # j resets out of contact (the old values are in nval)
        shear[last[1 + k]] = 0.0
    last[0] = 0
    dirty = const[C_DIRTY] != 0.0
    if not any_active and not dirty:
        return top
    if dirty:  # work of the last tick's wrench, second half (trapezoid on velocity)
        const[C_ENERGY] -= 0.5 * const[C_LAST_DT] * _power(bflt)
    for b in range(nbody):
        bflt[b, BF_WRENCH : BF_WRENCH + 6] = 0.0
    if not any_active:
        for b in range(nbody):
            xfrc_applied[bint[b, 0], :] = 0.0
        const[C_DIRTY] = 0.0
        return top
    _resolve_overlaps(gint, gflt, nval)
    res, rim = const[C_RES], int(const[C_RIM])
    n_exp, kc, kphi = const[C_N], const[C_KC], const[C_KPHI]
    elastic, inv_elastic = const[C_ELASTIC], const[C_INV_ELASTIC]
    neg_damping, cohesion = const[C_NEG_DAMPING], const[C_COHESION]
    tan_phi, neg_inv_janosi = const[C_TAN_PHI], const[C_NEG_INV_JANOSI]
    count = 0
    for g in range(gint.shape[0]):
        if not gint[g, GI_ACTIVE]:
            continue
        width, slot = gint[g, GI_WIDTH], gint[g, GI_SLOT]
        body = bint[slot, 0]
        vel = bflt[slot, BF_VEL : BF_VEL + 6]
        w0, w1, w2, v0, v1, v2 = vel[0], vel[1], vel[2], vel[3], vel[4], vel[5]
        arm_x = gflt[g, GF_CENTRE] - xipos[body, 0]  # geom centre relative to the body CoM
        arm_y = gflt[g, GF_CENTRE + 1] - xipos[body, 1]
        arm_z = gflt[g, GF_CENTRE + 2] - xipos[body, 2]
        rel_x, rel_y = gflt[g, GF_REL], gflt[g, GF_REL + 1]
        contact = nval[g, NV_CONTACT]
        modulus = kphi
        if const[C_NEEDS_WIDTH] != 0.0:
            modulus = kc * _inverse_width(contact, width, res) + kphi
        # Normal force and its moment; shear force (before the stability scaling) and moment.
        fz = tnx = tny = 0.0
        viscosity = sx = sy = tsx = tsy = tsz = 0.0
        removed = 0.0
        for i in range(width):
            rx = rel_x + i * res + arm_x
            for j in range(width):
                k = i * width + j
                if contact[k] == 0.0:
                    continue
                node = nidx[g, k]
                ry = rel_y + j * res + arm_y
                rz = arm_z - nval[g, NV_BELOW, k]
                vx = v0 + (w1 * rz - w2 * ry)
                vy = v1 + (w2 * rx - w0 * rz)
                vz = v2 + (w0 * ry - w1 * rx)
                slip = math.hypot(vx, vy)
                sink, zp, j_old = nval[g, NV_SINK, k], nval[g, NV_PLASTIC, k], nval[g, NV_SHEAR, k]
                # SCM law (as scm.ScmLaw.update, at one node in contact).
                bekker = max(sink, 0.0)
                if n_exp != 1.0:
                    bekker = bekker**n_exp
                bekker *= modulus
                static = min((sink - zp) * elastic, bekker)
                zp_new = max(sink - bekker * inv_elastic, zp)
                normal = max(vz * neg_damping + static, 0.0)
                tau = math.expm1(j_old * neg_inv_janosi) * (normal * tan_phi + cohesion)
                plastic[node] = zp_new
                shear[node] = slip * dt + j_old
                last[1 + count] = node
                count += 1
                removed += zp_new - zp
                nval[g, NV_NORMAL, k] = normal
                nval[g, NV_TAU, k] = tau
                nval[g, NV_STATIC, k] = static
                fz += normal
                tnx += ry * normal
                tny -= rx * normal
                # Shear force coef * v_t (coef <= 0: against the slip).
                coef = tau / max(slip, SLIP_EPS)
                ux, uy = vx * coef, vy * coef
                viscosity += coef
                sx += ux
                sy += uy
                tsx -= rz * uy
                tsy += rz * ux
                tsz += rx * uy - ry * ux
        # At low slip speed the shear is a viscous force sum(-coef) * v_t; where that viscosity
        # would reverse the slip within one tick (> mass / dt, the explicit limit), it is scaled
        # down to stop the slip instead.
        mass = gflt[g, GF_MASS]
        scale = mass / max(-dt * viscosity, mass)
        wrench = bflt[slot, BF_WRENCH : BF_WRENCH + 6]
        wrench[0] += scale * sx
        wrench[1] += scale * sy
        wrench[2] += fz
        wrench[3] += tnx + scale * tsx
        wrench[4] += tny + scale * tsy
        wrench[5] += scale * tsz
        if rim:
            highest = _bulldoze(level0, nidx[g], contact, width, removed)
            top = max(top, highest)
    last[0] = count
    for b in range(nbody):
        xfrc_applied[bint[b, 0], :] = bflt[b, BF_WRENCH : BF_WRENCH + 6]
    const[C_ENERGY] -= 0.5 * dt * _power(bflt)
    const[C_LAST_DT] = dt
    const[C_DIRTY] = 1.0
    return top


@njit(cache=True)
def _power(bflt: np.ndarray) -> float:
    """Sum over the soil bodies of wrench . twist: force . v + torque . w."""
    total = 0.0
    for b in range(bflt.shape[0]):
        for c in range(3):
            total += bflt[b, BF_WRENCH + c] * bflt[b, BF_VEL + 3 + c]
            total += bflt[b, BF_WRENCH + 3 + c] * bflt[b, BF_VEL + c]
    return total
