"""chronogym: high-fidelity multibody simulations as Gymnasium environments, in parallel on Ray.

Public names are imported lazily so that ``import chronogym`` stays light
(no Ray, MuJoCo or PyChrono import); importing it registers the
``chronogym/...`` Gymnasium ids.

Where to read on: the life of a vector step, hop by hop, is in :mod:`chronogym.vector`'s
docstring; the stages of a training iteration in :mod:`chronogym.rl`'s; everything about the
Go1 (task, training, evaluation, play) in :mod:`chronogym.tasks.quadruped`'s.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from chronogym._lazy import lazy_exports

__version__ = "0.1.0"

_EXPORTS = {
    "Task": "chronogym.task",
    "FunctionTask": "chronogym.task",
    "SimEnv": "chronogym.env",
    "Advancer": "chronogym.advance",
    "Synced": "chronogym.advance",
    "advance_all": "chronogym.advance",
    "MujocoTask": "chronogym.engines.mujoco",
    "RayVectorEnv": "chronogym.vector.ray_vector_env",
    "SerialVectorEnv": "chronogym.vector.serial",
    "make_vec": "chronogym.vector.factory",
    "register_task": "chronogym.registration",
    "make_sim_env": "chronogym.registration",
    "BoolArgumentError": "chronogym.errors",
    "ChronogymError": "chronogym.errors",
    "TaskDefinitionError": "chronogym.errors",
    "WorkerCrashLoopError": "chronogym.errors",
    "WorkerCallError": "chronogym.errors",
    "WorkerEnvError": "chronogym.errors",
    "RemoteTraceback": "chronogym.errors",
    "RenderModeError": "chronogym.errors",
    "VectorEnvClosedError": "chronogym.errors",
    "EnvsInFlightError": "chronogym.errors",
    "RecvTimeoutError": "chronogym.errors",
    "DisabledAutoresetError": "chronogym.errors",
}

__all__ = [*sorted(_EXPORTS), "__version__"]

if TYPE_CHECKING:
    from chronogym.advance import Advancer, Synced, advance_all
    from chronogym.engines.mujoco import MujocoTask
    from chronogym.env import SimEnv
    from chronogym.errors import (
        BoolArgumentError,
        ChronogymError,
        DisabledAutoresetError,
        EnvsInFlightError,
        RecvTimeoutError,
        RemoteTraceback,
        RenderModeError,
        TaskDefinitionError,
        VectorEnvClosedError,
        WorkerCallError,
        WorkerCrashLoopError,
        WorkerEnvError,
    )
    from chronogym.registration import make_sim_env, register_task
    from chronogym.task import FunctionTask, Task
    from chronogym.vector.factory import make_vec
    from chronogym.vector.ray_vector_env import RayVectorEnv
    from chronogym.vector.serial import SerialVectorEnv


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())


def _can_load(library: str) -> bool:
    import ctypes

    try:
        ctypes.CDLL(library)
    except OSError:
        return False
    return True


def _setup() -> None:
    import os
    import sys

    # MuJoCo picks its GL backend when it is first imported; without a display,
    # GLFW cannot render, so default to headless EGL (the user's choice wins). Without
    # libEGL, MUJOCO_GL=egl would make ``import mujoco`` itself fail: turn rendering off.
    if (
        "MUJOCO_GL" not in os.environ
        and not os.environ.get("DISPLAY")
        and sys.platform.startswith("linux")
    ):
        os.environ["MUJOCO_GL"] = "egl" if _can_load("libEGL.so.1") else "disable"
    from chronogym.registration import register_envs

    register_envs()


_setup()
