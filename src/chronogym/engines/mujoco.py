"""MuJoCo helpers: a Task base class over one model/data pair."""

from __future__ import annotations

import os
import sys
import warnings
from typing import Any

import numpy as np

from chronogym.task import Task


def check_headless_gl() -> None:
    """Raise a clear error when MuJoCo chose GLFW (needs a display) and there is none.

    MuJoCo picks its GL backend once, at ``import mujoco``: ``import chronogym``
    first (it defaults ``MUJOCO_GL`` to ``egl`` when there is no display), or set
    ``MUJOCO_GL=egl`` / ``osmesa`` yourself.
    """
    backend = getattr(_gl_context(), "_MUJOCO_GL", "")
    if (
        sys.platform.startswith("linux")
        and backend in ("", "glfw", "enable", "enabled", "on", "true", "1")
        and not os.environ.get("DISPLAY")
    ):
        raise RuntimeError(
            f"MuJoCo uses the GLFW backend (MUJOCO_GL={backend!r}) but there is no display; "
            "expected MUJOCO_GL=egl or osmesa set before mujoco is first imported "
            "(importing chronogym before mujoco does this)"
        )


GL_HINT = (
    "install EGL (apt-get install libegl1 libgl1-mesa-dri) or OSMesa (apt-get install "
    "libosmesa6, then MUJOCO_GL=osmesa); see docs/guides/rendering.md"
)


def _gl_context() -> Any:
    """MuJoCo's ``gl_context`` module, where it records the backend chosen at import."""
    import mujoco  # noqa: F401  (importing it picks the backend)

    try:
        from mujoco.rendering.classic import gl_context
    except ImportError:  # older MuJoCo kept it at the top level
        from mujoco import gl_context
    return gl_context


def gl_unavailable() -> str | None:
    """Why MuJoCo cannot render offscreen in this process, or None when it has a GL backend.

    Cheap: it reads the backend MuJoCo chose at import and whether its library loaded,
    without creating a GL context (a backend that loads but finds no device fails at the
    first ``render()`` instead).
    """
    gl_context = _gl_context()
    backend = getattr(gl_context, "_MUJOCO_GL", "")
    if backend in ("disable", "disabled", "off", "false", "0"):
        return (
            f"MUJOCO_GL={backend!r} turns MuJoCo's rendering off (chronogym sets it when "
            f"there is no display and libEGL cannot be loaded); {GL_HINT}"
        )
    context = getattr(gl_context, "GLContext", None)
    if context is None or context.__name__ == "_MissingGLContext":
        error = getattr(gl_context, "_import_error", None)
        return f"MuJoCo could not load its GL backend (MUJOCO_GL={backend!r}: {error}); {GL_HINT}"
    try:
        check_headless_gl()
    except RuntimeError as error:
        return str(error)
    return None


# mjtWarning indices of mjWARN_BADQPOS, mjWARN_BADQVEL and mjWARN_BADQACC (stable in the C API).
_BADQPOS, _BADQVEL, _BADQACC = 3, 4, 5


def mujoco_diverged(data: Any) -> bool:
    """True when MuJoCo flagged an unstable state or qpos/qvel hold NaN/Inf.

    MuJoCo resets a diverged simulation to qpos0 by itself and only counts a
    warning, so the warning counters are the reliable signal.
    """
    counts = data.warning.number
    if counts[_BADQPOS] or counts[_BADQVEL] or counts[_BADQACC]:
        return True
    return not (np.isfinite(data.qpos).all() and np.isfinite(data.qvel).all())


class SceneRenderer:
    """Offscreen frames of a MuJoCo model from one camera; the GL context is made (and
    checked) on the first frame, so a task that never renders never needs one."""

    def __init__(self, model: Any, width: int, height: int, camera: str | int = -1) -> None:
        self.model = model
        self.size = (width, height)
        self.camera = camera
        self._renderer: Any = None

    def frame(self, data: Any) -> np.ndarray:
        """(height, width, 3) uint8 image of ``data``'s current scene."""
        if self._renderer is None:
            import mujoco

            check_headless_gl()
            width, height = self.size
            self._renderer = mujoco.Renderer(self.model, height, width)
        self._renderer.update_scene(data, camera=self.camera)
        return self._renderer.render()

    def close(self) -> None:
        if self._renderer is not None:
            self._renderer.close()
            self._renderer = None


_WARNED_DT: set[type] = set()


def _warn_class_dt(task: MujocoTask, timestep: float) -> None:
    """Warn once per class when a ``dt`` set on the class (not by the constructor) differs
    from the timestep of the model that ``load_model()`` returned."""
    cls = type(task)
    dt = task.dt
    if (
        "dt" in vars(task)  # the instance's own dt: a constructor argument, chosen on purpose
        or cls in _WARNED_DT
        or dt is None
        or abs(timestep - dt) <= 1e-12 * max(1.0, dt)
    ):
        return
    _WARNED_DT.add(cls)
    warnings.warn(
        f"{cls.__name__}.dt = {dt!r} differs from its MuJoCo model's timestep {timestep!r} "
        f"(<option timestep> in the MJCF, 0.002 when it sets none); dt wins: the model steps "
        f"at {dt!r} s. Make the two equal to silence this warning (given once per class)",
        UserWarning,
        stacklevel=3,
    )


class MujocoTask(Task):
    """A Task over one MuJoCo model/data pair.

    Subclasses implement ``load_model()`` (and usually ``setup()`` to define
    spaces and look up ids), ``reset``, ``apply_action``, ``observe``,
    ``reward`` and ``terminated``. ``dt`` wins over the MJCF timestep: ``init()`` sets
    ``model.opt.timestep = dt`` (and takes ``dt`` from the model only when it is None). A
    ``dt`` set on the class that differs from the model's timestep warns once per class; a
    ``dt`` the constructor sets (``CartPoleTask(dt=0.001)``) is an explicit choice and does
    not (docs/guides/advance.md, "MuJoCo's timestep and dt").
    Divergence detection and offscreen ``rgb_array`` rendering come for free
    (rendering needs an OpenGL backend: ``MUJOCO_GL=egl`` or ``osmesa``; without
    one, ``SimEnv`` lists no render mode). Set ``render_modes = ()`` to opt out.
    """

    dt: float | None = None  # type: ignore[assignment]
    dt_from_init = True  # dt None: init() takes the model's timestep
    render_modes: tuple[str, ...] = ("rgb_array",)
    render_width: int = 480
    render_height: int = 360
    render_camera: str | int = -1

    model: Any
    data: Any

    def load_model(self) -> Any:
        """Return the ``mujoco.MjModel`` this task simulates."""
        raise NotImplementedError(f"{type(self).__name__} must implement load_model()")

    def setup(self) -> None:
        """Hook run once after the model and data exist: spaces, ids, buffers."""

    def init(self) -> None:
        import mujoco

        self.model = self.load_model()
        if self.dt is None:
            self.dt = float(self.model.opt.timestep)
        else:
            _warn_class_dt(self, float(self.model.opt.timestep))
            self.model.opt.timestep = self.dt
        self.data = mujoco.MjData(self.model)
        self.advanceables = [(self.model, self.data)]
        self._scene: SceneRenderer | None = None
        self.setup()

    def reset_data(self, keyframe: int | str | None = None) -> None:
        """Reset ``data`` to the model defaults or to a keyframe (index or name)."""
        import mujoco

        if keyframe is None:
            mujoco.mj_resetData(self.model, self.data)
        else:
            key = keyframe if isinstance(keyframe, int) else self.model.key(keyframe).id
            mujoco.mj_resetDataKeyframe(self.model, self.data, key)

    def forward(self) -> None:
        """Recompute derived quantities (positions, sensors) after editing qpos/qvel."""
        import mujoco

        mujoco.mj_forward(self.model, self.data)

    def diverged(self) -> bool:
        return mujoco_diverged(self.data)

    def render_unavailable(self) -> str | None:
        return gl_unavailable()

    def render(self) -> np.ndarray:
        if self._scene is None:
            self._scene = SceneRenderer(
                self.model, self.render_width, self.render_height, self.render_camera
            )
        return self._scene.frame(self.data)

    def close(self) -> None:
        scene = getattr(self, "_scene", None)
        if scene is not None:
            scene.close()
