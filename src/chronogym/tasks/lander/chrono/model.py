"""Project Chrono model of the six-legged lander (PyChrono 10 API; needs ``pychrono``).

The same 25 bodies, joints and geometry as the MuJoCo model (:mod:`..mujoco.model`), built
as a ``ChSystemSMC``:

* **Bodies.**  Mass, inertia and the touchdown pose of every body are read from the
  compiled MuJoCo model of the same design (``build_lander_model`` at ``qpos0``): each
  Chrono body sits at the MuJoCo body's centre of mass with its principal inertia axes,
  so both engines integrate the same rigid bodies (MuJoCo derives the capsule and
  cylinder inertias from the geoms); the armature of MuJoCo's ball joints (0.01 kg m^2)
  is added to the pads' and secondary struts' inertia.  MuJoCo's joint damping (1-2
  N m s/rad on the hinges and balls, 2 J of a landing) is left out.  Joint anchors and
  axes come from :func:`..geometry.leg_geometry`.
* **Joints** (``ChLinkLock*``, bilateral): per leg a revolute hinge chassis-upper at
  ``A`` (axis tangential), a prismatic slide upper-lower along the strut (the stroke), a
  spherical pad joint at ``P``, and the secondary strut on two spherical joints, at its
  root ``B`` on the chassis and at the knee ``K`` on the upper strut: that second ball
  closes the loop that MuJoCo closes with a ``connect`` equality.  Chrono solves all of
  them exactly (direct sparse LU); MuJoCo's knee loops are soft (``solref``).
* **Struts.**  One ``ChLinkTSDA`` per leg from ``A`` on the upper strut to ``P`` on the
  piston (length ``primary_length - stroke``; positive force opens the strut), whose
  Python ``ForceFunctor`` applies the honeycomb force of :class:`HoneycombAbsorber`
  (committed once per tick by ``ChronoLanderSim``) and the slide stops at 0 and
  ``max_stroke + stop_margin``: see :mod:`.struts`.
* **Contact**: the pads and the chassis against a fixed ground box (Bullet collision),
  smooth contact (SMC, Hooke law with explicit coefficients); see :class:`ChronoSettings`
  for why and for the values.  Friction ``params.friction``.
* **Integration**: Chrono's linearized implicit Euler (its default), direct sparse LU.

Ground (:func:`check_chrono_terrain`): flat and rigid (a box), or Chrono's own SCM soil
(``Terrain(soil=...)``: ``pychrono.vehicle.SCMTerrain`` with the same chronogym preset as the
MuJoCo lander's soil, :class:`~chronogym.engines.chrono_scm.ChronoSCM`).  On soil each pad
touches it with its cylinder (SCM finds the pads' collision shapes by ray casting, in a box
around each pad), and there is no rigid ground.  The chassis is not on the soil: its cylinder
would need an SCM domain of about 2 x 2 m (10^4 rays per tick at 2 cm); it starts 1.2 m up, and
:class:`~.sim.ChronoLanderSim` raises if its lowest point reaches the soil surface.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass, field
from typing import Any

import mujoco
import numpy as np

from chronogym.engines.chrono import chrono_frame, chrono_quaternion, chrono_vector, import_pychrono
from chronogym.engines.chrono_scm import ChronoSCM
from chronogym.tasks.lander.chrono.struts import StrutForces, stop_coefficients
from chronogym.tasks.lander.design import LanderDesign, LanderParams
from chronogym.tasks.lander.geometry import N_LEGS, leg_geometry, quat_from_axes
from chronogym.tasks.lander.mujoco.model import build_lander_model
from chronogym.tasks.lander.terrain import Terrain
from chronogym.terrain.params import soil_preset

__all__ = [
    "CHRONO_TERRAIN",
    "ChronoLanderModel",
    "ChronoSettings",
    "build_chrono_lander",
    "check_chrono_terrain",
    "chrono_params",
]

#: The terrain the Chrono lander supports, in words (for error messages).
CHRONO_TERRAIN = (
    "flat ground, rigid or SCM soil: Terrain() or Terrain(soil=...) (slope 0, no rocks)"
)

#: Body names, in the order of :attr:`ChronoLanderModel.bodies`.
BODY_NAMES: tuple[str, ...] = (
    "chassis",
    *(f"{part}_{i}" for i in range(N_LEGS) for part in ("upper", "lower", "pad", "secondary")),
)


@dataclass(frozen=True)
class ChronoSettings:
    """Numerical settings of the Chrono lander: contact, stops, collision, time step.

    **Why SMC.**  MuJoCo's contacts are soft (a critically damped spring-damper in
    constraint space with the ``constraint_timeconst`` time constant), so penalty contacts
    (Chrono SMC) are the closer model; and SMC lets a direct sparse solver enforce the 114
    joint equations exactly, where NSC's iterative complementarity solvers would leave
    them soft at a 1000:1 mass ratio (2000 kg chassis, 2 kg pads).  Hooke's law per contact
    point, ``F_n = k_n delta - g_n m v_n`` (``m`` = the pad's 2 kg: Chrono scales the
    damping by the two bodies' reduced mass, and the ground is made heavy), and Coulomb
    friction regularized as ``min(mu F_n, g_t m |v_t|)`` (``k_t = 0``).  All three are
    explicit forces: the values below stay well inside their stability limits at 0.25 ms.

    **Pad contact.**  Bullet finds a cylinder lying flat on a box one point per step and
    builds up its contact manifold over several steps, so a pad landing flat tipped over
    on its rim; each pad therefore touches with a ring of ``pad_points`` small spheres on
    its bottom face (the pad's cylinder in MuJoCo: 3 contacts per pad).  The ring's radius
    is ``R / sqrt(2)``, the polar radius of gyration of the pad's face: the points resist
    the pad's spin (through friction) as the whole face would.  On the rim they resisted
    it twice as much, and that explicit viscous torque on the pad's small spin inertia
    chattered (the pad spinning back and forth at 2-3 rad/s, which used up the points'
    Coulomb limits and cut the pads' sliding friction to a quarter at slow slip).  The
    stiffness and damping below are per pad, shared by its points.

    Attributes:
        contact_stiffness: ``k_n`` per pad [N/m].  MuJoCo's pads sink 3 mm at the
            touchdown peak (about 12 kN per pad), and so do these; 0.15 mm under the
            landed weight.  Default design, 1e6 / 2e6 / 4e6 N/m (damping critical as
            below): ``a_max`` 18.47 / 18.47 / 18.39 m/s^2, ``E_abs`` 5009 / 5073 / 5108 J;
            the stiffest honeycomb (15 kN), in series with it, 66.2 (2e6) / 68.9 (4e6)
            m/s^2 against MuJoCo's 68.9.
        contact_damping: ``g_n`` per pad [1/s]: ``2 sqrt(k_n m_u) / m_pad``, critically
            damped for the unsprung mass that the contact stops at touchdown (piston and
            pad, ``m_u`` = 6 kg), as MuJoCo's contacts are critically damped; the pads do
            not bounce.  (Explicit force: ``c dt / m_pad`` = 1.2 at 0.25 ms, below 2.)
        friction_damping: ``g_t`` per pad [1/s]: the pads slide at the Coulomb force
            ``mu F_n`` above ``mu F_n / (g_t m_pad)`` of slip (0.13 m/s during the crush);
            as high as the explicit force stays stable with the piston (6 kg) on the slide
            at ``alpha2`` = 50 deg and 0.5 ms.
        stop_time_constant: time constant of the slide stops [s] (``None``:
            ``params.constraint_timeconst``, as MuJoCo's soft joint limit; see
            :mod:`.struts`).
        pad_points, pad_point_radius: contact spheres per pad and their radius [m].
        pad_ring: radius of their ring over the pad radius.
        envelope: Bullet's collision envelope [m] (contacts are found this far out; SMC
            applies force only on overlap).
        margin: Bullet's collision margin [m].
        timestep: physics step [s] (``None``: ``params.timestep``).  Default design,
            0.5 / 0.25 / 0.125 ms: see ``benchmarks/chrono/cross_engine.py --convergence``;
            0.25 ms is within about 1 % of 0.125 ms, 0.5 ms is not (explicit contact and
            friction forces; MuJoCo's implicit soft contacts are converged at 0.5 ms).
    """

    contact_stiffness: float = 4.0e6
    contact_damping: float = 4.9e3
    friction_damping: float = 1.0e4
    stop_time_constant: float | None = None
    pad_points: int = 8
    pad_point_radius: float = 0.005
    pad_ring: float = 0.7071
    envelope: float = 0.005
    margin: float = 0.001
    timestep: float | None = 0.00025


def chrono_params(
    params: LanderParams, settings: ChronoSettings, terrain: Terrain | None = None
) -> LanderParams:
    """``params`` with the Chrono time step (``settings.timestep``; ``None`` keeps
    ``params.timestep``); on soil at most ``params.soil_timestep``, as in MuJoCo."""
    timestep = params.timestep if settings.timestep is None else float(settings.timestep)
    if terrain is not None and terrain.soil is not None:
        timestep = min(timestep, params.soil_timestep)
    if timestep == params.timestep:
        return params
    return dataclasses.replace(params, timestep=timestep)


def check_chrono_terrain(terrain: Terrain | None) -> Terrain:
    """``terrain`` (default flat rigid) if the Chrono lander supports it, else ValueError."""
    terrain = terrain if terrain is not None else Terrain()
    unsupported = []
    if terrain.slope != 0.0:
        unsupported.append(f"slope={terrain.slope!r}")
    if terrain.n_rocks:
        unsupported.append(f"n_rocks={terrain.n_rocks!r}")
    if unsupported:
        raise ValueError(
            f"the Chrono lander supports {CHRONO_TERRAIN}; got {', '.join(unsupported)} "
            "(use the MuJoCo lander, LanderSim, for slopes and rocks)"
        )
    return terrain


@dataclass
class ChronoLanderModel:
    """A built Chrono lander: the system and what the simulation needs from it."""

    system: Any
    ground: Any
    bodies: list[Any]  # the 25 lander bodies, in the order of BODY_NAMES
    struts: list[Any]  # the six ChLinkTSDA, leg order
    strut_forces: StrutForces  # what their force functors return (honeycomb, stops)
    strut_length: float  # TSDA length at zero stroke [m]
    chassis_axis: np.ndarray  # the chassis cylinder axis in the Chrono chassis frame
    masses: np.ndarray  # per body [kg]
    inertias: np.ndarray  # per body, principal moments [kg m^2] (Chrono body axes)
    timestep: float
    keep_alive: list[Any] = field(default_factory=list)  # links and material
    soil: Any = None  # ChronoSCM on soil, else None
    mujoco_model: Any = None  # the MuJoCo model of the same design (pictures)
    chassis_shape: tuple[np.ndarray, float, float] = (np.zeros(3), 0.0, 0.0)
    # (cylinder centre in the chassis frame, radius, half length)

    @property
    def chassis(self) -> Any:
        return self.bodies[0]

    @property
    def contact_bodies(self) -> list[Any]:
        """The bodies with contact shapes: the chassis and the six pads."""
        return [self.bodies[0], *self.bodies[3::4]]


def _material(chrono: Any, friction: float, settings: ChronoSettings) -> Any:
    """The one SMC material of every shape: a pad's ``pad_points`` contact points together
    have the settings' stiffness and damping (Chrono averages the coefficients of the two
    materials in contact, so ground and lander must share them)."""
    points = settings.pad_points
    material = chrono.ChContactMaterialSMC()
    material.SetFriction(friction)
    material.SetKn(settings.contact_stiffness / points)
    material.SetGn(settings.contact_damping / points)
    material.SetKt(0.0)
    material.SetGt(settings.friction_damping / points)
    material.SetRestitution(0.0)
    return material


def build_chrono_lander(
    design: LanderDesign,
    params: LanderParams,
    terrain: Terrain | None = None,
    settings: ChronoSettings | None = None,
) -> ChronoLanderModel:
    """Build the Chrono system of the lander at its touchdown pose, at rest.

    The caller sets the touchdown velocity (``ChronoLanderSim.reset``).
    """
    chrono = import_pychrono()
    terrain = check_chrono_terrain(terrain)
    settings = settings if settings is not None else ChronoSettings()

    # the MuJoCo model of the same design: mass properties and the touchdown pose
    info = build_lander_model(design, params, terrain)
    m = info.model
    d = mujoco.MjData(m)
    mujoco.mj_kinematics(m, d)

    system = _new_system(chrono, params, settings)
    material = _material(chrono, params.friction, settings)
    ground = chrono.ChBody()
    ground.SetFixed(True)
    ground.SetMass(1e9)  # SMC uses m1 m2 / (m1 + m2): the pads' own mass against the ground
    ground.SetPos(chrono.ChVector3d(0.0, 0.0, -0.5))
    on_soil = terrain.soil is not None
    if not on_soil:
        ground.AddCollisionShape(chrono.ChCollisionShapeBox(material, 40.0, 40.0, 1.0))
        ground.EnableCollision(True)
    system.AddBody(ground)

    bodies, masses, inertias = [], np.zeros(len(BODY_NAMES)), np.zeros((len(BODY_NAMES), 3))
    for j, name in enumerate(BODY_NAMES):
        b = m.body(name).id
        masses[j], inertias[j] = m.body_mass[b], m.body_inertia[b] + _ball_armature(m, b)
        body = chrono.ChBody()  # at the centre of mass, along the principal axes
        body.SetName(name)
        body.SetMass(float(masses[j]))
        body.SetInertiaXX(chrono_vector(inertias[j]))
        body.SetPos(chrono_vector(d.xipos[b]))
        body.SetRot(chrono_quaternion(quat_from_axes(*d.ximat[b].reshape(3, 3).T)))
        system.AddBody(body)
        bodies.append(body)
    pad_boxes = _add_contact_shapes(chrono, bodies, info, d, material, settings, on_soil)
    soil = _add_soil(system, terrain, bodies, pad_boxes) if on_soil else None

    keep: list[Any] = [material]
    struts = []
    legs = leg_geometry(design, params)
    origin = d.xpos[info.chassis_body].copy()  # the chassis frame is the world frame, shifted
    index = dict(zip(BODY_NAMES, bodies, strict=True))
    for i, leg in enumerate(legs):
        links = _leg_links(chrono, index, i, leg, origin)
        for link in links:
            system.AddLink(link)
        keep.extend(links)
        struts.append(links[-1])

    upper = params.max_stroke + params.stop_margin
    stiffness, damping = stop_coefficients(params, settings.stop_time_constant)
    chassis_rot = d.ximat[info.chassis_body].reshape(3, 3)
    g = info.chassis_geom
    chassis_centre = chassis_rot.T @ (d.geom_xpos[g] - d.xipos[info.chassis_body])
    return ChronoLanderModel(
        system=system,
        ground=ground,
        bodies=bodies,
        struts=struts,
        strut_forces=StrutForces(chrono, struts, params.primary_length, upper, stiffness, damping),
        strut_length=float(params.primary_length),
        chassis_axis=chassis_rot.T @ d.xmat[info.chassis_body].reshape(3, 3)[:, 2],
        masses=masses,
        inertias=inertias,
        timestep=params.timestep,
        keep_alive=keep,
        soil=soil,
        mujoco_model=m,
        chassis_shape=(chassis_centre, float(m.geom_size[g][0]), float(m.geom_size[g][1])),
    )


def _ball_armature(m: mujoco.MjModel, body: int) -> float:
    """Armature of the body's ball joint in the MuJoCo model [kg m^2] (0 without one).

    MuJoCo adds it to the joint's rotational inertia, the same about every axis, so here
    it is added to each principal moment of the body (the pads and the secondary struts:
    0.01 kg m^2, half the pad's own spin inertia)."""
    start = m.body_jntadr[body]
    joints = range(start, start + m.body_jntnum[body]) if start >= 0 else range(0)
    ball = mujoco.mjtJoint.mjJNT_BALL
    return float(sum(m.dof_armature[m.jnt_dofadr[j]] for j in joints if m.jnt_type[j] == ball))


def _new_system(chrono: Any, params: LanderParams, settings: ChronoSettings) -> Any:
    """An empty SMC system: gravity, Bullet collision, Hooke contacts, direct sparse LU."""
    system = chrono.ChSystemSMC()  # starts with zero gravity in PyChrono 10
    system.SetGravitationalAcceleration(chrono.ChVector3d(0.0, 0.0, -params.gravity))
    system.SetCollisionSystemType(chrono.ChCollisionSystem.Type_BULLET)
    system.UseMaterialProperties(False)
    system.SetContactForceModel(chrono.ChSystemSMC.Hooke)
    system.SetTangentialDisplacementModel(chrono.ChSystemSMC.OneStep)
    solver = chrono.ChSolverSparseLU()
    solver.LockSparsityPattern(True)  # SMC contacts add no rows: the pattern never changes
    system.SetSolver(solver)
    system.SetTimestepperType(chrono.ChTimestepper.Type_EULER_IMPLICIT_LINEARIZED)
    chrono.ChCollisionModel.SetDefaultSuggestedEnvelope(settings.envelope)
    chrono.ChCollisionModel.SetDefaultSuggestedMargin(settings.margin)
    return system


def _add_contact_shapes(
    chrono: Any,
    bodies: list[Any],
    info: Any,
    data: mujoco.MjData,
    material: Any,
    settings: ChronoSettings,
    on_soil: bool = False,
) -> list[tuple[Any, np.ndarray, np.ndarray]]:
    """The chassis cylinder, and on each pad a ring of small spheres along the rim of its
    bottom face, where MuJoCo has the pad cylinders (see :class:`ChronoSettings`); on soil
    the pad cylinder itself (the soil ray-casts it).  Returns each pad's SCM active domain:
    ``(pad body, box centre, box size)`` in the pad's frame, the cylinder's bounding box
    grown by 3 cm sideways and 15 cm up and down."""
    m = info.model
    geoms = {"chassis": info.chassis_geom}
    geoms.update({f"pad_{i}": int(g) for i, g in enumerate(info.pad_geoms)})
    identity = np.array([1.0, 0.0, 0.0, 0.0])
    pad_boxes = []
    for body, name in zip(bodies, BODY_NAMES, strict=True):
        g = geoms.get(name)
        if g is None:
            continue
        rot_b = data.ximat[m.body(name).id].reshape(3, 3)
        pos = rot_b.T @ (data.geom_xpos[g] - data.xipos[m.body(name).id])  # in the body frame
        rot = rot_b.T @ data.geom_xmat[g].reshape(3, 3)
        radius, half = (float(x) for x in m.geom_size[g][:2])
        if name == "chassis" or on_soil:
            shape = chrono.ChCollisionShapeCylinder(material, radius, 2.0 * half)
            body.AddCollisionShape(shape, chrono_frame(pos, quat_from_axes(*rot.T)))
            if name != "chassis":
                extent = np.array([radius + 0.03, radius + 0.03, half + 0.15])  # cylinder frame
                pad_boxes.append((body, pos, 2.0 * np.abs(rot) @ extent))
        else:
            r, n = settings.pad_point_radius, settings.pad_points
            for phi in 2.0 * math.pi * np.arange(n) / n:
                rim = settings.pad_ring * radius
                local = np.array([rim * math.cos(phi), rim * math.sin(phi), r - half])
                point = chrono.ChCollisionShapeSphere(material, r)
                body.AddCollisionShape(point, chrono_frame(pos + rot @ local, identity))
        body.EnableCollision(True)
        model = body.GetCollisionModel()
        model.SetFamily(1)
        model.DisallowCollisionsWith(1)  # the lander never collides with itself
    return pad_boxes


def _add_soil(
    system: Any,
    terrain: Terrain,
    bodies: list[Any],
    pad_boxes: list[tuple[Any, np.ndarray, np.ndarray]],
) -> Any:
    """Chrono's SCM soil with the terrain's preset, active around each pad."""
    params = soil_preset(terrain.soil) if isinstance(terrain.soil, str) else terrain.soil
    side = float(terrain.soil_extent)
    return ChronoSCM(system, params, (side, side), float(terrain.soil_resolution), pad_boxes)


def _leg_links(
    chrono: Any, index: dict[str, Any], i: int, leg: dict, origin: np.ndarray
) -> list[Any]:
    """Leg ``i``'s joints, then its strut (the ``ChLinkTSDA`` from ``A`` to ``P``)."""
    chassis = index["chassis"]
    upper, lower = index[f"upper_{i}"], index[f"lower_{i}"]
    pad, secondary = index[f"pad_{i}"], index[f"secondary_{i}"]
    a, b, k, p = (origin + leg[key] for key in ("A", "B", "K", "P"))
    x_l, y_l, z_l = leg["strut_rot"].T
    hinge = chrono.ChLinkLockRevolute()  # about the frame's z: the tangential axis
    hinge.Initialize(upper, chassis, chrono_frame(a, quat_from_axes(y_l, z_l, x_l)))
    slide = chrono.ChLinkLockPrismatic()  # along the frame's z: the strut axis
    slide.Initialize(lower, upper, chrono_frame(p, leg["strut_quat"]))
    links = [hinge, slide]
    identity = np.array([1.0, 0.0, 0.0, 0.0])
    for body_1, body_2, point in ((pad, lower, p), (secondary, chassis, b), (secondary, upper, k)):
        ball = chrono.ChLinkLockSpherical()
        ball.Initialize(body_1, body_2, chrono_frame(point, identity))
        links.append(ball)
    strut = chrono.ChLinkTSDA()  # force: struts.StrutForces
    strut.Initialize(upper, lower, False, chrono_vector(a), chrono_vector(p))
    return [*links, strut]
