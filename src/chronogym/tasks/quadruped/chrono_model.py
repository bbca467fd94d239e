"""Project Chrono model of the Go1, built from the numbers of ``go1.xml`` (needs ``pychrono``).

Everything physical is read from the compiled MuJoCo model, so the two engines simulate the
same robot and a change to the MJCF reaches both:

* **Bodies.**  13 ``ChBody`` (trunk, then hip, thigh, calf of FR, FL, RR, RL), each at its
  centre of mass along its principal axes, with MuJoCo's mass and principal inertia.  The
  reflected rotor inertia of each joint (MuJoCo's ``armature``: 0.00448 kg m^2 hip and thigh,
  0.01008 knee) is added to the child body's inertia about the joint axis (MuJoCo adds it to
  the joint's diagonal of the mass matrix only; here it also couples with the parent's
  rotation, a term of the armature's size).
* **Joints.**  One ``ChLinkMotorRotationTorque`` per hinge (a revolute guide plus a torque
  about the joint axis, child = body 1), at MuJoCo's anchor and axis; built with every joint
  at 0, so the motor angle *is* MuJoCo's joint angle.  :class:`Go1Servos` closes the loop in
  Python every tick: MuJoCo's position servo (``kp (target - q) - kd qdot``, clipped at the
  motor's torque limit; the target clipped to the joint range as MuJoCo clamps ``ctrl``) and
  the joint limits (MuJoCo's default soft limit, ``solref`` 0.02 s critically damped:
  ``M_jj (r / tc^2 + 2 v / tc)`` pushing back, ``M_jj`` the joint's inertia at home).
  Unlike MuJoCo's implicitfast, the damping is explicit (held over a tick).
* **Contact**: the MJCF's collision primitives (trunk box, hip cylinders, thigh capsules,
  foot spheres; the calf capsules are left out so that a calf's contact force is its foot's)
  against a fixed ground box with its top at z = 0, Bullet collision, friction 1 (the
  MJCF's).  The robot never collides with itself (MJCF: contype 0).  ``contact="nsc"``:
  complementarity contacts (hard, no penetration), the Barzilai-Borwein solver;
  ``"smc"``: penalty contacts (Hooke, :class:`ChronoGo1Settings`), joints solved exactly by
  sparse LU.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np

from chronogym.engines.chrono import check_collision_system, set_collision_system
from chronogym.tasks.quadruped.model import (
    BASE_BODY_NAME,
    FOOT_GEOM_NAMES,
    JOINT_NAMES,
    LEG_NAMES,
    TORQUE_LIMITS,
    go1_xml_path,
)
from chronogym.validation import check_int, check_positive

__all__ = [
    "CONTACT_METHODS",
    "ChronoGo1Model",
    "ChronoGo1Settings",
    "Go1Layout",
    "Go1Servos",
    "build_chrono_go1",
    "go1_layout",
    "limit_torque",
    "quat_from_matrix",
    "servo_torque",
]

#: Contact formulations of the Chrono Go1.
CONTACT_METHODS: tuple[str, ...] = ("nsc", "smc")
#: Bullet's (envelope, margin) [m] on rigid ground and on SCM soil (ChronoGo1Settings).
RIGID_MARGINS: tuple[float, float] = (0.005, 0.002)
SOIL_MARGINS: tuple[float, float] = (1e-4, 1e-4)
#: Collision geoms of the Chrono model, by MJCF geom name (see the module docstring).
_COLLISION_GEOMS: tuple[str, ...] = (
    "trunk",
    *(f"{leg}_{part}" for leg in LEG_NAMES for part in ("hip", "thigh")),
    *FOOT_GEOM_NAMES,
)


@dataclass(frozen=True)
class ChronoGo1Settings:
    """Numerical settings of the Chrono Go1.

    Attributes:
        contact: ``"nsc"`` (complementarity) or ``"smc"`` (penalty).
        friction: Coulomb friction of feet and ground (``None``: the MJCF's, 1.0).
        solver_iterations: iterations of the NSC solver (Barzilai-Borwein); 40 gave the same
            gaits as 100 (to 0.01 m/s) at 0.58x the cost (``docs/performance/chrono.md``).
        contact_stiffness: SMC normal stiffness per contact [N/m]: a standing foot
            (31 N) sinks 31 / k.
        contact_damping: SMC normal damping coefficient ``g_n`` [1/s] (Chrono scales it by
            the reduced mass of the pair).
        friction_damping: SMC tangential damping ``g_t`` [1/s]: Coulomb's limit is reached
            above ``mu F_n / (g_t m)`` of slip.
        collision: Chrono's collision system, ``"bullet"`` (Chrono's default) or
            ``"multicore"`` (needs Chrono built with Thrust). It matters on SCM soil, whose
            ray casts find the feet: Bullet's (single precision) hit up to ~1 cm outside a
            moving foot sphere, so its soil carries a wider footprint and the feet sink
            less; multicore's are exact (``benchmarks/soil/soil_cross_check.py``).
        envelope: Bullet's collision envelope [m] (``None``: 5 mm on rigid ground, where
            contacts are found this far out; 0.1 mm without it, on SCM soil, whose ray casts
            see every shape inflated by the envelope: a 5 mm envelope widens a foot's
            footprint from 2 to 2.5 cm and the feet sink 29 instead of 35 mm).
        margin: Bullet's collision margin [m] (``None``: 2 mm on rigid ground, 0.1 mm on
            SCM soil).
        limit_time_constant: time constant of the joint limits [s] (MuJoCo's default
            ``solref``).
    """

    contact: str = "nsc"
    friction: float | None = None
    solver_iterations: int = 40
    contact_stiffness: float = 2.0e5
    contact_damping: float = 4.0e3
    friction_damping: float = 2.0e3
    collision: str = "bullet"
    envelope: float | None = None
    margin: float | None = None
    limit_time_constant: float = 0.02

    def __post_init__(self) -> None:
        if self.contact not in CONTACT_METHODS:
            raise ValueError(
                f"contact={self.contact!r}: expected one of {', '.join(CONTACT_METHODS)}"
            )
        check_collision_system(self.collision)
        for name in (
            "contact_stiffness",
            "contact_damping",
            "friction_damping",
            "limit_time_constant",
        ):
            check_positive(name, getattr(self, name), expected="a finite float > 0")
        for name in ("envelope", "margin"):
            value = getattr(self, name)
            if value is not None:
                check_positive(name, value, expected="None or a finite float > 0")
        if self.friction is not None:
            check_positive("friction", self.friction, expected="None or a float > 0")
        check_int("solver_iterations", self.solver_iterations, low=1)

    def collision_margins(self, rigid_ground: bool) -> tuple[float, float]:
        """(envelope, margin) [m] for a Go1 on rigid ground or (``False``) on SCM soil."""
        envelope, margin = RIGID_MARGINS if rigid_ground else SOIL_MARGINS
        return (
            envelope if self.envelope is None else float(self.envelope),
            margin if self.margin is None else float(self.margin),
        )


def quat_from_matrix(rot: np.ndarray) -> np.ndarray:
    """Unit quaternion (w, x, y, z) of a 3x3 rotation matrix."""
    q = np.zeros(4)
    mujoco.mju_mat2Quat(q, np.ascontiguousarray(rot, dtype=np.float64).reshape(9))
    return q


def quat_to_matrix(q: np.ndarray) -> np.ndarray:
    """3x3 rotation matrix of a unit quaternion (w, x, y, z)."""
    rot = np.zeros(9)
    mujoco.mju_quat2Mat(rot, np.asarray(q, dtype=np.float64))
    return rot.reshape(3, 3)


def _z_to(axis: np.ndarray) -> np.ndarray:
    """A quaternion that turns the z axis onto the unit vector ``axis``."""
    q = np.zeros(4)
    mujoco.mju_quatZ2Vec(q, np.asarray(axis, dtype=np.float64))
    return q


def servo_torque(
    q: np.ndarray, qd: np.ndarray, targets: np.ndarray, kp: float, kd: float
) -> np.ndarray:
    """MuJoCo's position servo: ``kp (target - q) - kd qdot``, clipped at the torque limits."""
    return np.clip(kp * (targets - q) - kd * qd, -TORQUE_LIMITS, TORQUE_LIMITS)


def limit_torque(
    q: np.ndarray,
    qd: np.ndarray,
    low: np.ndarray,
    high: np.ndarray,
    stiffness: np.ndarray,
    damping: np.ndarray,
) -> np.ndarray:
    """Torque of the joint limits: a spring-damper that only pushes back into the range."""
    over, under = q - high, low - q
    torque = np.zeros_like(q)
    if (over > 0).any() or (under > 0).any():
        torque -= np.where(over > 0, np.maximum(0.0, stiffness * over + damping * qd), 0.0)
        torque += np.where(under > 0, np.maximum(0.0, stiffness * under - damping * qd), 0.0)
    return torque


class Go1Servos:
    """The 12 position servos and joint limits, evaluated in Python before every tick.

    An advanceable (``fn(dt)``, listed before the system): it reads the motors' angles and
    rates, computes ``clip(kp (target - q) - kd qdot, +-limit)`` plus the joint-limit torque,
    and writes it into each motor's constant torque function.
    """

    def __init__(
        self,
        motors: list[Any],
        functions: list[Any],
        *,
        kp: float,
        kd: float,
        ranges: np.ndarray,
        joint_inertia: np.ndarray,
        limit_time_constant: float,
    ) -> None:
        self.motors = motors
        self.functions = functions
        self._angle = [m.GetMotorAngle for m in motors]
        self._rate = [m.GetMotorAngleDt for m in motors]
        self._set = [f.SetConstant for f in functions]
        self.kp, self.kd = float(kp), float(kd)
        self.low, self.high = ranges[:, 0].copy(), ranges[:, 1].copy()
        self.targets = np.zeros(len(motors))
        self.torque = np.zeros(len(motors))  # the servos' torque of the last tick
        tc = float(limit_time_constant)
        self._limit_k = joint_inertia / (tc * tc)
        self._limit_b = joint_inertia * (2.0 / tc)

    def set_targets(self, targets: np.ndarray) -> None:
        """Joint targets, clipped to the joint ranges (as MuJoCo clamps ``ctrl``)."""
        np.clip(targets, self.low, self.high, out=self.targets)

    def angles(self) -> np.ndarray:
        return np.array([f() for f in self._angle])

    def rates(self) -> np.ndarray:
        return np.array([f() for f in self._rate])

    def __call__(self, dt: float) -> None:
        q, qd = self.angles(), self.rates()
        self.torque[:] = servo_torque(q, qd, self.targets, self.kp, self.kd)
        total = self.torque + limit_torque(q, qd, self.low, self.high, self._limit_k, self._limit_b)
        for setter, value in zip(self._set, total.tolist(), strict=True):
            setter(value)

    def zero(self) -> None:
        """No torque until the next tick computes one (after a reset)."""
        self.torque[:] = 0.0
        for setter in self._set:
            setter(0.0)


@dataclass(frozen=True)
class BodyLayout:
    """One rigid body: at its centre of mass, along its principal axes (MuJoCo's ``xipos``,
    ``ximat`` with every joint at 0), inertia tensor in that frame, armature included."""

    name: str
    mujoco_id: int
    mass: float
    inertia: np.ndarray  # 3x3
    pos: np.ndarray
    quat: np.ndarray


@dataclass(frozen=True)
class JointLayout:
    """One hinge: child and parent (indices into the bodies), anchor, frame with z = axis."""

    name: str
    child: int
    parent: int
    anchor: np.ndarray
    quat: np.ndarray
    axis: np.ndarray


@dataclass(frozen=True)
class ShapeLayout:
    """One collision primitive on a body, pose in the body's (principal) frame."""

    name: str
    body: int
    kind: str  # "sphere", "box", "cylinder", "capsule"
    size: tuple[float, ...]  # Chrono's arguments: radius / full lengths / radius, length
    pos: np.ndarray
    quat: np.ndarray
    foot: bool


@dataclass(frozen=True)
class Go1Layout:
    """Everything the Chrono Go1 is built from, read off the compiled MJCF (no PyChrono)."""

    bodies: list[BodyLayout]
    joints: list[JointLayout]
    shapes: list[ShapeLayout]
    friction: float
    trunk_ipos: np.ndarray  # the trunk's centre of mass in the MuJoCo trunk frame
    trunk_irot: np.ndarray  # 3x3: principal axes in the MuJoCo trunk frame
    foot_offsets: np.ndarray  # (4, 3) foot centres in the calves' principal frames
    joint_ranges: np.ndarray  # (12, 2)
    joint_inertia: np.ndarray  # (12,) mass-matrix diagonal at home [kg m^2]

    def body_index(self, name: str) -> int:
        return next(i for i, b in enumerate(self.bodies) if b.name == name)


def mujoco_go1() -> tuple[mujoco.MjModel, mujoco.MjData]:
    """The MJCF model with every joint at 0 (legs straight), kinematics computed."""
    model = mujoco.MjModel.from_xml_path(str(go1_xml_path()))
    data = mujoco.MjData(model)
    mujoco.mj_kinematics(model, data)
    return model, data


def home_joint_inertia(model: mujoco.MjModel) -> np.ndarray:
    """Diagonal of MuJoCo's joint-space mass matrix at the home keyframe, armature included."""
    data = mujoco.MjData(model)
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    mujoco.mj_forward(model, data)
    full = np.zeros((model.nv, model.nv))
    mujoco.mj_fullM(model, data, full)
    return np.diag(full)[6:].copy()


def go1_layout() -> Go1Layout:
    """Bodies, joints and collision shapes of the Chrono Go1, from ``go1.xml``."""
    m, d = mujoco_go1()
    names = [BASE_BODY_NAME] + [
        f"{leg}_{part}" for leg in LEG_NAMES for part in ("hip", "thigh", "calf")
    ]
    ids = [m.body(n).id for n in names]
    index = {b: i for i, b in enumerate(ids)}
    joint_of_body = {int(m.jnt_bodyid[j]): j for j in range(m.njnt)}
    bodies = []
    for name, b in zip(names, ids, strict=True):
        rot_i = d.ximat[b].reshape(3, 3)
        inertia = np.diag(m.body_inertia[b]).astype(np.float64)
        j = joint_of_body[b]
        if m.jnt_type[j] == mujoco.mjtJoint.mjJNT_HINGE:
            axis = rot_i.T @ d.xaxis[j]  # the joint axis in the principal frame
            inertia += float(m.dof_armature[m.jnt_dofadr[j]]) * np.outer(axis, axis)
        bodies.append(
            BodyLayout(
                name, b, float(m.body_mass[b]), inertia, d.xipos[b].copy(), quat_from_matrix(rot_i)
            )
        )
    joints = []
    for name in JOINT_NAMES:
        j = m.joint(name).id
        child = int(m.jnt_bodyid[j])
        axis = d.xaxis[j].copy()
        joints.append(
            JointLayout(
                name,
                index[child],
                index[int(m.body_parentid[child])],
                d.xanchor[j].copy(),
                _z_to(axis),
                axis,
            )
        )
    shapes = [_shape_layout(m, d, name, index) for name in _COLLISION_GEOMS]
    trunk = ids[0]
    foot_offsets = np.array(
        [
            d.ximat[m.geom_bodyid[g]].reshape(3, 3).T @ (d.geom_xpos[g] - d.xipos[m.geom_bodyid[g]])
            for g in (m.geom(n).id for n in FOOT_GEOM_NAMES)
        ]
    )
    return Go1Layout(
        bodies=bodies,
        joints=joints,
        shapes=shapes,
        friction=float(m.geom(FOOT_GEOM_NAMES[0]).friction[0]),
        trunk_ipos=m.body_ipos[trunk].copy(),
        trunk_irot=quat_to_matrix(m.body_iquat[trunk]),
        foot_offsets=foot_offsets,
        joint_ranges=np.array([m.joint(n).range for n in JOINT_NAMES], dtype=np.float64),
        joint_inertia=home_joint_inertia(m),
    )


def _shape_layout(
    m: mujoco.MjModel, d: mujoco.MjData, name: str, index: dict[int, int]
) -> ShapeLayout:
    g = m.geom(name).id
    b = int(m.geom_bodyid[g])
    rot_i = d.ximat[b].reshape(3, 3)
    size = [float(x) for x in m.geom_size[g]]
    kinds = {
        mujoco.mjtGeom.mjGEOM_SPHERE: ("sphere", (size[0],)),
        mujoco.mjtGeom.mjGEOM_BOX: ("box", tuple(2.0 * x for x in size)),
        mujoco.mjtGeom.mjGEOM_CYLINDER: ("cylinder", (size[0], 2.0 * size[1])),
        mujoco.mjtGeom.mjGEOM_CAPSULE: ("capsule", (size[0], 2.0 * size[1])),
    }
    kind, args = kinds[mujoco.mjtGeom(m.geom_type[g])]
    return ShapeLayout(
        name=name,
        body=index[b],
        kind=kind,
        size=args,
        pos=rot_i.T @ (d.geom_xpos[g] - d.xipos[b]),
        quat=quat_from_matrix(rot_i.T @ d.geom_xmat[g].reshape(3, 3)),
        foot=name in FOOT_GEOM_NAMES,
    )


@dataclass
class ChronoGo1Model:
    """A built Chrono Go1: the system and what the task reads and writes."""

    system: Any
    ground: Any
    bodies: list[Any]  # 13, in the layout's order (trunk, then per leg hip, thigh, calf)
    motors: list[Any]  # 12, joint order
    torque_functions: list[Any]
    calves: list[Any]  # FR, FL, RR, RL
    fatal: list[Any]  # trunk and hips: their contact ends an episode
    materials: list[Any]  # the foot and ground contact materials (friction changes)
    layout: Go1Layout
    settings: ChronoGo1Settings
    keep_alive: list[Any] = field(default_factory=list)

    @property
    def trunk(self) -> Any:
        return self.bodies[0]


def _material(chrono: Any, friction: float, settings: ChronoGo1Settings) -> Any:
    if settings.contact == "nsc":
        material = chrono.ChContactMaterialNSC()
    else:
        material = chrono.ChContactMaterialSMC()
        material.SetKn(float(settings.contact_stiffness))
        material.SetGn(float(settings.contact_damping))
        material.SetKt(0.0)
        material.SetGt(float(settings.friction_damping))
    material.SetFriction(friction)
    material.SetRestitution(0.0)
    return material


def _new_system(chrono: Any, settings: ChronoGo1Settings, rigid_ground: bool) -> Any:
    if settings.contact == "nsc":
        system = chrono.ChSystemNSC()
    else:
        system = chrono.ChSystemSMC()
        system.UseMaterialProperties(False)
        system.SetContactForceModel(chrono.ChSystemSMC.Hooke)
        system.SetTangentialDisplacementModel(chrono.ChSystemSMC.OneStep)
    system.SetGravitationalAcceleration(chrono.ChVector3d(0.0, 0.0, -9.81))
    set_collision_system(chrono, system, settings.collision)
    if settings.contact == "nsc":
        system.SetSolverType(chrono.ChSolver.Type_BARZILAIBORWEIN)
        system.GetSolver().AsIterative().SetMaxIterations(int(settings.solver_iterations))
    else:
        solver = chrono.ChSolverSparseLU()
        solver.LockSparsityPattern(True)  # penalty contacts add no rows
        system.SetSolver(solver)
    system.SetTimestepperType(chrono.ChTimestepper.Type_EULER_IMPLICIT_LINEARIZED)
    envelope, margin = settings.collision_margins(rigid_ground)
    chrono.ChCollisionModel.SetDefaultSuggestedEnvelope(envelope)
    chrono.ChCollisionModel.SetDefaultSuggestedMargin(margin)
    return system


def build_chrono_go1(
    settings: ChronoGo1Settings | None = None,
    layout: Go1Layout | None = None,
    rigid_ground: bool = True,
) -> ChronoGo1Model:
    """Build the Chrono system of the Go1 with every joint at 0 (the task resets the pose).

    ``rigid_ground=False`` leaves the ground out (for a deformable terrain, which finds the
    robot's collision shapes by itself); ``ground`` is then a fixed body without shapes.
    """
    from chronogym.engines.chrono import (
        chrono_frame,
        chrono_quaternion,
        chrono_vector,
        import_pychrono,
    )

    chrono = import_pychrono()
    settings = settings if settings is not None else ChronoGo1Settings()
    layout = layout if layout is not None else go1_layout()
    friction = layout.friction if settings.friction is None else float(settings.friction)

    system = _new_system(chrono, settings, rigid_ground)
    foot_material = _material(chrono, friction, settings)
    body_material = _material(chrono, friction, settings)
    ground_material = _material(chrono, friction, settings)
    ground = chrono.ChBody()
    ground.SetFixed(True)
    ground.SetMass(1e6)
    ground.SetPos(chrono.ChVector3d(0.0, 0.0, -0.5))
    if rigid_ground:
        ground.AddCollisionShape(chrono.ChCollisionShapeBox(ground_material, 200.0, 200.0, 1.0))
        ground.EnableCollision(True)
    system.AddBody(ground)

    bodies = []
    for spec in layout.bodies:
        body = chrono.ChBody()
        body.SetName(spec.name)
        body.SetMass(spec.mass)
        i = spec.inertia
        body.SetInertiaXX(chrono_vector(np.diag(i)))
        body.SetInertiaXY(chrono_vector((i[0, 1], i[0, 2], i[1, 2])))
        body.SetPos(chrono_vector(spec.pos))
        body.SetRot(chrono_quaternion(spec.quat))
        system.AddBody(body)
        bodies.append(body)
    makers = {
        "sphere": chrono.ChCollisionShapeSphere,
        "box": chrono.ChCollisionShapeBox,
        "cylinder": chrono.ChCollisionShapeCylinder,  # both engines: axis = the shape's z
        "capsule": chrono.ChCollisionShapeCapsule,
    }
    for shape in layout.shapes:
        material = foot_material if shape.foot else body_material
        body = bodies[shape.body]
        body.AddCollisionShape(
            makers[shape.kind](material, *shape.size), chrono_frame(shape.pos, shape.quat)
        )
        body.EnableCollision(True)
    for body in bodies:
        model = body.GetCollisionModel()
        model.SetFamily(1)
        model.DisallowCollisionsWith(1)  # the robot never collides with itself

    motors, functions = [], []
    for joint in layout.joints:
        motor = chrono.ChLinkMotorRotationTorque()
        motor.Initialize(
            bodies[joint.child], bodies[joint.parent], chrono_frame(joint.anchor, joint.quat)
        )
        function = chrono.ChFunctionConst(0.0)
        motor.SetTorqueFunction(function)
        system.AddLink(motor)
        motors.append(motor)
        functions.append(function)

    return ChronoGo1Model(
        system=system,
        ground=ground,
        bodies=bodies,
        motors=motors,
        torque_functions=functions,
        calves=[bodies[layout.body_index(f"{leg}_calf")] for leg in LEG_NAMES],
        fatal=[bodies[0], *(bodies[layout.body_index(f"{leg}_hip")] for leg in LEG_NAMES)],
        materials=[foot_material, ground_material],
        layout=layout,
        settings=settings,
        keep_alive=[body_material],
    )
