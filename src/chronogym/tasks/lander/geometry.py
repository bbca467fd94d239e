"""Engine-independent geometry of the lander's legs: the same points and frames for every
engine's builder (MuJoCo's :mod:`.mujoco.model`, Chrono's :mod:`.chrono.model`).

Leg layout: three pairs of legs centred on the azimuths 0, 120, 240 deg, the two legs of a
pair ``+-beta/2`` about the pair's centre (``beta = 60 deg`` spaces all six evenly).  See
:mod:`.mujoco.model` for the topology the points belong to.
"""

from __future__ import annotations

import math

import mujoco
import numpy as np

from chronogym.tasks.lander.design import LanderDesign, LanderParams

__all__ = ["N_LEGS", "leg_azimuths", "leg_geometry", "quat_from_axes"]

#: Number of legs.
N_LEGS = 6


def leg_azimuths(beta: float) -> np.ndarray:
    """Azimuths of the six legs [rad]: three pairs at 0/120/240 deg, +-beta/2 each."""
    centres = np.radians([0.0, 120.0, 240.0])
    return np.concatenate([[c - beta / 2, c + beta / 2] for c in centres])


def quat_from_axes(x: np.ndarray, y: np.ndarray, z: np.ndarray) -> np.ndarray:
    """Quaternion (w, x, y, z) of the rotation whose columns are the unit vectors x, y, z."""
    mat = np.column_stack([x, y, z]).reshape(-1)
    quat = np.zeros(4)
    mujoco.mju_mat2Quat(quat, mat)
    return quat


def _frame_with_z(z: np.ndarray) -> np.ndarray:
    """Quaternion of some frame whose z axis is ``z`` (unit)."""
    helper = np.array([0.0, 0.0, 1.0]) if abs(z[2]) < 0.9 else np.array([1.0, 0.0, 0.0])
    x = np.cross(helper, z)
    x /= np.linalg.norm(x)
    y = np.cross(z, x)
    return quat_from_axes(x, y, z)


def leg_geometry(design: LanderDesign, p: LanderParams) -> list[dict]:
    """Per-leg points and frames in the chassis frame (origin at the chassis centre, z up).

    One dict per leg (order of :func:`leg_azimuths`): ``phi`` (azimuth), the points ``A``
    (hinge), ``B`` (secondary-strut root), ``K`` (knee) and ``P`` (pad ball joint at zero
    stroke), ``strut_rot`` (columns: x tangential = hinge axis, y in the radial plane, z
    along the strut pointing up = slide axis, + is compression) and its quaternion
    ``strut_quat`` (w, x, y, z), the secondary strut's frame ``sec_quat`` (z from B to K)
    and length ``sec_len``.  Pure geometry: every engine's builder uses it.
    """
    bottom = -p.chassis_length / 2.0
    legs = []
    for phi in leg_azimuths(design.beta):
        e_r = np.array([math.cos(phi), math.sin(phi), 0.0])
        e_t = np.array([-math.sin(phi), math.cos(phi), 0.0])
        e_z = np.array([0.0, 0.0, 1.0])
        down = math.sin(design.alpha2) * e_r - math.cos(design.alpha2) * e_z
        up = -down
        a = p.hinge_radius * e_r + (bottom + p.hinge_height) * e_z
        b = p.secondary_root_radius * e_r + bottom * e_z
        k = a + p.knee_distance * down
        pad_joint = a + p.primary_length * down
        # strut frame: z along the strut pointing up (slide axis: + = compression),
        # x tangential (hinge axis), y = z cross x (in the radial plane).
        x_l, z_l = e_t, up
        y_l = np.cross(z_l, x_l)
        rot = np.column_stack([x_l, y_l, z_l])
        bk = k - b
        legs.append(
            {
                "phi": phi,
                "A": a,
                "B": b,
                "K": k,
                "P": pad_joint,
                "strut_quat": quat_from_axes(x_l, y_l, z_l),
                "strut_rot": rot,
                "sec_quat": _frame_with_z(bk / np.linalg.norm(bk)),
                "sec_len": float(np.linalg.norm(bk)),
            }
        )
    return legs
