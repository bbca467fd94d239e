"""Pictures of a landing, in either engine, drawn with the MuJoCo model of the same design.

MuJoCo's renderer draws what ``MjData`` holds (body and geom poses), so a Chrono landing is
drawn by writing each Chrono body's pose into a MuJoCo ``MjData`` of the same design: both
engines' bodies match one to one (:mod:`.chrono.model` builds the Chrono bodies from the
MuJoCo model). Chrono's own visual systems need a display or a GPU; this needs only
offscreen OpenGL (EGL or OSMesa), as every chronogym picture does.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import mujoco
import numpy as np

from chronogym.engines.mujoco import check_headless_gl

__all__ = ["LanderRenderer", "pose_bodies"]


def pose_bodies(
    model: mujoco.MjModel,
    data: mujoco.MjData,
    body_ids: Sequence[int],
    com_pos: np.ndarray,
    com_quat: np.ndarray,
) -> None:
    """Write body and geom poses into ``data`` from each body's centre of mass ``com_pos``
    (n, 3) and principal axes ``com_quat`` (n, 4: w, x, y, z), world frame (Chrono's body
    frames)."""
    for b, pos, quat in zip(body_ids, com_pos, com_quat, strict=True):
        rot = np.zeros(9)
        mujoco.mju_quat2Mat(rot, quat)
        rot = rot.reshape(3, 3)
        inertial = np.zeros(9)
        mujoco.mju_quat2Mat(inertial, model.body_iquat[b])
        frame = rot @ inertial.reshape(3, 3).T
        origin = pos - frame @ model.body_ipos[b]
        data.xpos[b], data.xmat[b] = origin, frame.reshape(9)
        data.xipos[b], data.ximat[b] = pos, rot.reshape(9)
        start, count = model.body_geomadr[b], model.body_geomnum[b]
        for g in range(start, start + count) if start >= 0 else ():
            local = np.zeros(9)
            mujoco.mju_quat2Mat(local, model.geom_quat[g])
            data.geom_xpos[g] = origin + frame @ model.geom_pos[g]
            data.geom_xmat[g] = (frame @ local.reshape(3, 3)).reshape(9)


class LanderRenderer:
    """Offscreen frames of a lander model: ``frame(data)`` -> (height, width, 3) uint8."""

    def __init__(self, model: mujoco.MjModel, width: int = 480, height: int = 360) -> None:
        check_headless_gl()
        self.model = model
        self.size = (width, height)
        self._renderer: Any = mujoco.Renderer(model, height, width)
        self.camera = mujoco.MjvCamera()
        mujoco.mjv_defaultFreeCamera(model, self.camera)
        self.camera.elevation = -15.0
        self.camera.distance *= 0.9

    def frame(self, data: mujoco.MjData) -> np.ndarray:
        self._renderer.update_scene(data, camera=self.camera)
        return self._renderer.render()

    def close(self) -> None:
        self._renderer.close()
