"""Project Chrono helpers: body state to NumPy, motor inputs, divergence, a Task base class.

PyChrono is optional: nothing here imports it at module import, and Chrono objects
are reached by duck typing. Where a method was renamed between Chrono 8, 9 and 10
the helpers probe the candidate names (newest first) instead of checking versions;
the names were checked against PyChrono 10.0.0 (core module).
"""

from __future__ import annotations

import math
from collections.abc import Iterable, Sequence
from types import ModuleType
from typing import Any

import numpy as np

from chronogym.task import Task

INSTALL_HINT = "install it with conda: conda install projectchrono::pychrono -c conda-forge"

# Candidate method names, newest first (Chrono 10/9, then Chrono 8).
GETTERS: dict[str, tuple[str, ...]] = {
    "pos": ("GetPos",),
    "rot": ("GetRot",),
    "lin_vel": ("GetPosDt", "GetLinVel", "GetPos_dt"),
    "ang_vel_world": ("GetAngVelParent", "GetWvel_par"),
    "ang_vel_local": ("GetAngVelLocal", "GetWvel_loc"),
}
SETTERS: dict[str, tuple[str, ...]] = {
    "pos": ("SetPos",),
    "rot": ("SetRot",),
    "lin_vel": ("SetPosDt", "SetLinVel", "SetPos_dt"),
    "ang_vel_world": ("SetAngVelParent", "SetWvel_par"),
    "lin_acc": ("SetPosDt2", "SetLinAcc", "SetPos_dtdt"),
    "ang_acc_world": ("SetAngAccParent", "SetWacc_par"),
}
BODY_LISTS = ("GetBodies", "Get_bodylist")
CONSTANT_FUNCTIONS = ("ChFunctionConst", "ChFunction_Const")
CONSTANT_SETTERS = ("SetConstant", "Set_yconst")
MOTOR_FUNCTION_SETTERS = (
    "SetMotorFunction",
    "SetForceFunction",
    "SetTorqueFunction",
    "SetSpeedFunction",
    "SetAngleFunction",
    "SetMotionFunction",
)
#: Chrono's collision systems by chronogym name: ``bullet`` (Chrono's default) and
#: ``multicore`` (Chrono's own, needs Chrono built with Thrust). On SCM soil they differ in
#: the ray casts that find the bodies: single-precision Bullet reports hits up to ~1 cm
#: outside a moving shape, multicore's are exact for spheres and boxes (but its cylinder
#: and capsule ray tests use the wrong axis in Chrono 10).
#: See ``benchmarks/soil/soil_cross_check.py``.
COLLISION_SYSTEMS: dict[str, str] = {"bullet": "Type_BULLET", "multicore": "Type_MULTICORE"}
VECTOR_TYPES = ("ChVector3d", "ChVectorD")
QUATERNION_TYPES = ("ChQuaterniond", "ChQuaternionD")

_resolved: dict[tuple[type, tuple[str, ...]], str] = {}


def import_pychrono() -> Any:
    """Return the ``pychrono`` module, or raise ModuleNotFoundError with the conda command."""
    try:
        import pychrono
    except ImportError as exc:
        raise ModuleNotFoundError(
            f"this task needs Project Chrono's Python API, but `import pychrono` failed ({exc}); "
            f"PyChrono is not on PyPI, {INSTALL_HINT}",
            name="pychrono",
        ) from exc
    return pychrono


def probe(obj: Any, names: Sequence[str]) -> Any:
    """Return ``obj``'s attribute under the first of ``names`` it has (cached per type)."""
    if isinstance(obj, ModuleType):  # modules share one type: no cache
        return getattr(obj, _first_present(obj, names))
    key = (type(obj), tuple(names))
    name = _resolved.get(key)
    if name is None:
        name = _resolved[key] = _first_present(obj, names)
    return getattr(obj, name)


def _first_present(obj: Any, names: Sequence[str]) -> str:
    name = next((n for n in names if hasattr(obj, n)), None)
    if name is None:
        what = obj.__name__ if isinstance(obj, ModuleType) else type(obj).__name__
        raise AttributeError(
            f"{what} has none of {', '.join(names)}; "
            "expected a PyChrono object of Chrono 8, 9 or 10"
        )
    return name


# --- reading state ---------------------------------------------------------------------------


def vec3(v: Any) -> np.ndarray:
    """A Chrono vector as a float64 array of shape (3,)."""
    if hasattr(v, "to_numpy"):
        return np.asarray(v.to_numpy(), dtype=np.float64).reshape(3)
    return np.array([v.x, v.y, v.z], dtype=np.float64)


def quat(q: Any) -> np.ndarray:
    """A Chrono quaternion as a float64 array (w, x, y, z)."""
    if hasattr(q, "to_numpy"):
        return np.asarray(q.to_numpy(), dtype=np.float64).reshape(4)
    return np.array([q.e0, q.e1, q.e2, q.e3], dtype=np.float64)


def rotate_inverse(q: np.ndarray, v: np.ndarray) -> np.ndarray:
    """Express the world vector ``v`` in the frame of the unit quaternion ``q`` (w, x, y, z)."""
    w, u = q[0], -q[1:]
    return v + 2.0 * np.cross(u, np.cross(u, v) + w * v)


def body_pos(body: Any) -> np.ndarray:
    """Position of the body's reference frame in the world, (3,)."""
    return vec3(probe(body, GETTERS["pos"])())


def body_rot(body: Any) -> np.ndarray:
    """Orientation of the body as a unit quaternion (w, x, y, z)."""
    return quat(probe(body, GETTERS["rot"])())


def body_lin_vel(body: Any, local: bool = False) -> np.ndarray:
    """Linear velocity, in world coordinates or (``local=True``) in the body frame."""
    v = vec3(probe(body, GETTERS["lin_vel"])())
    return rotate_inverse(body_rot(body), v) if local else v


def body_ang_vel(body: Any, local: bool = False) -> np.ndarray:
    """Angular velocity, in world coordinates or (``local=True``) in the body frame."""
    return vec3(probe(body, GETTERS["ang_vel_local" if local else "ang_vel_world"])())


def body_state(body: Any) -> np.ndarray:
    """(13,): position, quaternion (w, x, y, z), linear and angular velocity, all in world."""
    return np.concatenate([body_pos(body), body_rot(body), body_lin_vel(body), body_ang_vel(body)])


def system_bodies(system: Any) -> list[Any]:
    """The bodies of a ChSystem (fixed ones included)."""
    return list(probe(system, BODY_LISTS)())


def renew_collision_system(system: Any) -> None:
    """Give ``system`` a new Bullet collision system, every collision model bound again.

    Bullet keeps state from step to step that no body setter reaches: its persistent contact
    manifolds, its broadphase tree (rebalanced a little every step from a cursor that moves
    on) and the order of its pair cache. After a long episode they change the order in which
    the next contacts are found, which changes the iterative solver's result by ~1e-8, and
    contacts amplify that: an episode started by ``reset`` would differ from the same episode
    in a fresh env. A new collision system starts as a fresh env's did. Call it after the
    bodies are in place: the new broadphase is built around their current positions.

    Only Bullet (Chrono's default) is renewed: Chrono's multicore collision system cannot
    remove a model (Chrono 10 raises "not yet implemented"); it rebuilds its broadphase every
    step, but whether anything else of it persists is not checked. A PyChrono before 9.0 (no
    ``UnbindItem``) keeps its collision system too.
    """
    chrono = import_pychrono()
    old = system.GetCollisionSystem()
    bullet = getattr(chrono.ChCollisionSystem, "Type_BULLET", None)
    if old is None or not hasattr(old, "UnbindItem") or bullet is None:
        return
    if int(old.GetType()) != int(bullet):
        return
    items = system_bodies(system)
    if hasattr(system, "GetOtherPhysicsItems"):  # e.g. particle clouds
        items += list(system.GetOtherPhysicsItems())
    for item in items:  # detach every model first: none may point into the old system
        old.UnbindItem(item)
    new = chrono.ChCollisionSystemBullet()
    system.SetCollisionSystem(new)
    new.Initialize()  # binds every collision model of the system


def finish_reset(system: Any) -> None:
    """After a reset has written every body's state: time 0, ``Update()`` (the links' cached
    residuals and Jacobians are those of the old positions; without it the next step differs)
    and a new collision system built around the new positions (:func:`renew_collision_system`),
    so that the episode is the one a fresh env would run."""
    system.SetChTime(0.0)
    system.Update()
    renew_collision_system(system)


# --- writing state ---------------------------------------------------------------------------


def check_collision_system(name: str) -> str:
    """``name`` if it is one of :data:`COLLISION_SYSTEMS`, else ValueError."""
    if name not in COLLISION_SYSTEMS:
        raise ValueError(f"collision={name!r}: expected one of {', '.join(COLLISION_SYSTEMS)}")
    return name


def set_collision_system(chrono: ModuleType, system: Any, name: str) -> None:
    """Give ``system`` the named collision system (before any body is added).

    Chrono built without Thrust quietly falls back to Bullet when asked for multicore; this
    raises instead, so that a setting never silently means something else.
    """
    kind = getattr(chrono.ChCollisionSystem, COLLISION_SYSTEMS[check_collision_system(name)])
    system.SetCollisionSystemType(kind)
    if int(system.GetCollisionSystem().GetType()) != int(kind):
        raise RuntimeError(
            f"collision={name!r}: this PyChrono has no {name} collision system (Chrono "
            "builds it only with Thrust); use collision='bullet'"
        )


def chrono_vector(values: Iterable[float]) -> Any:
    """A Chrono vector (``ChVector3d``) of three floats."""
    x, y, z = (float(c) for c in values)
    return probe(import_pychrono(), VECTOR_TYPES)(x, y, z)


def chrono_quaternion(values: Iterable[float]) -> Any:
    """A Chrono quaternion (``ChQuaterniond``) of (w, x, y, z)."""
    w, x, y, z = (float(c) for c in values)
    return probe(import_pychrono(), QUATERNION_TYPES)(w, x, y, z)


def chrono_frame(pos: Iterable[float], rot: Iterable[float]) -> Any:
    """A Chrono frame (``ChFramed``) at ``pos`` with orientation ``rot`` (w, x, y, z)."""
    return import_pychrono().ChFramed(chrono_vector(pos), chrono_quaternion(rot))


def set_body_state(
    body: Any,
    pos: Sequence[float] | None = None,
    rot: Sequence[float] | None = None,
    lin_vel: Sequence[float] | None = None,
    ang_vel: Sequence[float] | None = None,
) -> None:
    """Set what is given (world frame; ``rot`` as w, x, y, z); zero the accelerations.

    Call ``system.Update()`` once after the last change, before the next step: links
    cache their residuals and Jacobians from the previous positions.
    """
    if pos is not None:
        probe(body, SETTERS["pos"])(chrono_vector(pos))
    if rot is not None:
        probe(body, SETTERS["rot"])(chrono_quaternion(rot))
    if lin_vel is not None:
        probe(body, SETTERS["lin_vel"])(chrono_vector(lin_vel))
    if ang_vel is not None:
        probe(body, SETTERS["ang_vel_world"])(chrono_vector(ang_vel))
    probe(body, SETTERS["lin_acc"])(chrono_vector((0.0, 0.0, 0.0)))
    probe(body, SETTERS["ang_acc_world"])(chrono_vector((0.0, 0.0, 0.0)))


class SystemSnapshot:
    """Every body's position, orientation and velocities, to put a system back at reset."""

    def __init__(self, system: Any) -> None:
        self.system = system
        self.states = [(body, body_state(body)) for body in system_bodies(system)]

    def restore(self) -> None:
        """Write the saved body states back, then :func:`finish_reset`."""
        for body, s in self.states:
            set_body_state(body, pos=s[:3], rot=s[3:7], lin_vel=s[7:10], ang_vel=s[10:13])
        finish_reset(self.system)


# --- actions ---------------------------------------------------------------------------------


def constant_function(value: float = 0.0) -> Any:
    """A new Chrono constant function (``ChFunctionConst``) with ``value``."""
    fn = probe(import_pychrono(), CONSTANT_FUNCTIONS)()
    set_constant(fn, value)
    return fn


def set_constant(fn: Any, value: float) -> None:
    """Set the value of a Chrono constant function."""
    value = float(value)
    if not math.isfinite(value):
        raise ValueError(f"value={value!r}: expected a finite float")
    probe(fn, CONSTANT_SETTERS)(value)


class MotorInput:
    """Drive a Chrono motor with a constant function whose value is set each step.

    Works for any ``ChLinkMotor*``: the value is a force (``ChLinkMotorLinearForce``),
    a torque, a speed or a position target, whatever the motor's function means.
    """

    def __init__(self, motor: Any, value: float = 0.0) -> None:
        self.motor = motor
        self.function = constant_function(value)
        probe(motor, MOTOR_FUNCTION_SETTERS)(self.function)
        self.value = float(value)

    def set(self, value: float) -> None:
        """Set the motor's input from now on."""
        set_constant(self.function, value)
        self.value = float(value)


# --- divergence ------------------------------------------------------------------------------


_STATE_GETTERS = ("pos", "rot", "lin_vel", "ang_vel_world")  # the 13 floats of body_state
_state_names: dict[type, tuple[str, ...]] = {}


def bodies_diverged(bodies: Iterable[Any], limit: float = 1e6) -> bool:
    """True when a body's state holds NaN/Inf or a component beyond ``limit`` in magnitude.

    Checks the same 13 floats as :func:`body_state`, read as plain floats: a task checks
    every body after every step, and NumPy arrays per body cost 3x more.
    """
    for body in bodies:
        names = _state_names.get(type(body))
        if names is None:
            names = tuple(_first_present(body, GETTERS[key]) for key in _STATE_GETTERS)
            _state_names[type(body)] = names
        p, q, v, w = (getattr(body, name)() for name in names)
        for c in (p.x, p.y, p.z, q.e0, q.e1, q.e2, q.e3, v.x, v.y, v.z, w.x, w.y, w.z):
            if not abs(c) <= limit:  # NaN fails every comparison
                return True
    return False


# --- Task base class -------------------------------------------------------------------------


class ChronoTask(Task):
    """A Task over one PyChrono ``ChSystem``, built once and reset by mutation.

    Subclasses set ``dt`` and ``k``, implement ``build_system()`` (and usually
    ``setup()`` for spaces and motor inputs), then ``reset`` (start with
    ``self.reset_system()``), ``apply_action``, ``observe``, ``reward`` and
    ``terminated``. The system is the only advanceable (``DoStepDynamics(dt)``);
    divergence detection over every body comes for free.
    """

    divergence_limit: float = 1e6
    system: Any

    def build_system(self) -> Any:
        """Return the ``ChSystem`` (bodies, links, motors) this task simulates."""
        raise NotImplementedError(f"{type(self).__name__} must implement build_system()")

    def setup(self) -> None:
        """Hook run once after the system exists: spaces, motor inputs, buffers."""

    def init(self) -> None:
        import_pychrono()
        self.system = self.build_system()
        if not hasattr(self.system, "DoStepDynamics"):
            raise TypeError(
                f"{type(self).__name__}.build_system() returned {type(self.system).__name__}; "
                "expected a PyChrono ChSystem (ChSystemNSC or ChSystemSMC)"
            )
        self.advanceables = [self.system]
        self.setup()
        self.initial_state = SystemSnapshot(self.system)

    def reset_system(self) -> None:
        """Put every body back where ``init`` left it, at time 0."""
        self.initial_state.restore()

    def diverged(self) -> bool:
        return bodies_diverged(system_bodies(self.system), self.divergence_limit)
