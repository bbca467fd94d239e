"""Programmatic MuJoCo model of the six-legged lander (built with ``mujoco.MjSpec``).

Topology
--------
25 bodies besides the world body: the chassis, and per leg ``i = 0..5`` three strut
bodies and a foot pad::

    world
    |-- ground plane (+ optional rocks: static geoms, no bodies)
    `-- chassis                     free joint (6 DOF)
        |-- upper_i                 hinge (revolute), axis tangential to the chassis
        |   `-- lower_i             slide (prismatic) along the strut: the absorber stroke
        |       `-- pad_i           ball (spherical): the pad follows the ground
        `-- secondary_i             ball (spherical) at its root on the chassis bottom
    equality connect_i: point K of secondary_i  ==  knee point K of upper_i

* ``upper_i`` -- upper primary strut (outer cylinder, holds the honeycomb).  Hinged to
  the chassis at ``A_i`` (radius ``hinge_radius``, ``hinge_height`` above the chassis
  bottom) about the axis tangential to the chassis, so it can swing only in the leg's
  radial plane.  Its initial inclination from the vertical is ``alpha2``.
* ``secondary_i`` -- secondary strut / knee link from ``B_i`` on the chassis bottom
  (radius ``secondary_root_radius``) to the knee ``K_i`` on the upper strut,
  ``knee_distance`` from ``A_i``.  The leg is a closed loop chassis -> upper -> (knee)
  <- secondary <- chassis, which a kinematic tree cannot express: the secondary strut is
  a child of the chassis and the loop is closed with a ``connect`` equality (ball-type
  point constraint, 3 equations) at ``K_i``.  Mobility of the loop: hinge (1) + ball (3)
  - connect (3) = 1, and that one DOF is the spin of the secondary strut about its own
  axis (harmless, lightly damped).  So the triangle A-B-K is a rigid truss: the upper
  strut keeps its inclination under load, as in a cantilever landing gear.
* ``lower_i`` -- lower primary strut (piston), a slide joint along the strut axis.
  The joint coordinate is the absorber stroke ``s`` (0 at touchdown length, positive in
  compression, range ``[0, max_stroke + stop_margin]``: an extension stop and a hard
  bottoming stop).  The honeycomb force is applied on this DOF (see below).
* ``pad_i`` -- foot pad disc on a ball joint under the piston, initially level.

So the joint types are: 1 free, 6 hinge, 12 ball, 6 slide, closed by 6 connect
equalities.  The ball joints carry light damping and armature (the unconstrained spin
of the secondary struts, the light pads); the constraints' ``solref`` time constant is
``LanderParams.constraint_timeconst``.

Leg layout: three pairs of legs centred on the azimuths 0, 120, 240 deg, the two legs
of a pair ``+-beta/2`` about the pair's centre (``beta = 60 deg`` spaces all six
evenly).  The points and frames come from :func:`~chronogym.tasks.lander.geometry.leg_geometry`,
shared with the Chrono model.

Collisions: only the pads and the chassis collide, and only with the terrain (pads and
chassis have ``contype=1, conaffinity=0``, the terrain ``contype=0, conaffinity=1``;
struts have neither), so the lander never collides with itself.

Absorber forces are written to ``data.qfrc_applied`` at the six slide DOFs each tick
(generalized force ``-F``: it pushes the piston out of the cylinder and, by the
joint's action-reaction, the cylinder up).  This is cleaner than actuators: no control
ranges or gains to keep consistent with the crush law, and ``ctrl`` stays free for a
later controller.

The model enables ``mjENBL_ENERGY`` (``data.energy`` = potential and kinetic energy,
computed at the start of every step) for the energy ledger of ``LanderSim`` (:mod:`.sim`);
contacts use the elliptic friction cone, whose constraint rows split into one normal row
and two friction rows, which the ledger books apart.

Terrain (:class:`~chronogym.tasks.lander.terrain.Terrain`): an infinite rigid plane,
optionally inclined by ``slope`` (downhill towards world +x), with optional rocks (spheres
and boxes, partly buried, placed by a seeded generator over the ring where the pads land).
Rocks are static geoms of the world body, so the body count stays 25 whatever the terrain.
(No heightfield: slope and rocks cover the cases the study needs.)

Soil (``Terrain.soil``): a level patch of SCM soil (``chronogym.terrain.MujocoSoil``) at
the plane's height, under the pads and the chassis.  The model is the same (the plane
stays, as a picture); ``LanderSim`` builds the soil on the compiled model and stops the
plane's contacts with the pads and the chassis, so only the soil holds them (rocks still
do).  On soil the time step is ``LanderParams.soil_timestep`` (see
:func:`~chronogym.tasks.lander.terrain.terrain_params`).
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field

import mujoco
import numpy as np

from chronogym.tasks.lander.design import (
    DEFAULT_DESIGN,
    DESIGN_BOUNDS,
    LanderDesign,
    LanderParams,
)
from chronogym.tasks.lander.geometry import N_LEGS, leg_geometry, quat_from_axes
from chronogym.tasks.lander.terrain import Terrain, terrain_params

__all__ = ["LanderModelInfo", "build_lander_model", "build_lander_spec"]

_LANDER_CONTYPE = 1  # pads and chassis
_TERRAIN_CONAFFINITY = 1


@dataclass
class LanderModelInfo:
    """Indices and geometry of a compiled lander model."""

    model: mujoco.MjModel
    design: LanderDesign
    params: LanderParams
    terrain: Terrain
    seed: int
    chassis_body: int
    slide_qpos: np.ndarray  # qpos address of each slide joint
    slide_dof: np.ndarray  # dof address of each slide joint
    pad_geoms: np.ndarray
    chassis_geom: int
    azimuths: np.ndarray  # leg azimuths [rad]
    start_height: float  # initial chassis centre height [m]
    rocks: list[dict] = field(default_factory=list)


def _pad_bottom_offset(p: LanderParams) -> float:
    """Pad bottom below its ball joint [m]."""
    return p.pad_offset + 2.0 * p.pad_half_thickness


def _rock_ring(p: LanderParams) -> tuple[float, float]:
    """Inner and outer radius of the ring where rocks are scattered [m]."""
    lo, hi = DESIGN_BOUNDS["alpha2"]
    r_in = p.hinge_radius + p.primary_length * math.sin(lo) - 0.3
    r_out = p.hinge_radius + p.primary_length * math.sin(hi) + 0.3
    return r_in, r_out


def _place_rocks(terrain: Terrain, p: LanderParams, seed: int) -> list[dict]:
    """Rocks from the seed only (not the design)."""
    rng = np.random.default_rng(seed)
    r_in, r_out = _rock_ring(p)
    rocks = []
    lo, hi = terrain.rock_size
    for j in range(terrain.n_rocks):
        r = math.sqrt(rng.uniform(r_in**2, r_out**2))
        phi = rng.uniform(0.0, 2.0 * math.pi)
        size = rng.uniform(lo, hi)
        kind = "sphere" if rng.random() < 0.5 else "box"
        yaw = rng.uniform(0.0, math.pi)
        x, y = r * math.cos(phi), r * math.sin(phi)
        base = float(terrain.plane_height(x))
        # partly buried: centre 0.2 size above the plane, top 1.2 size above it
        rocks.append(
            {
                "name": f"rock_{j}",
                "kind": kind,
                "pos": np.array([x, y, base + 0.2 * size]),
                "size": size,
                "yaw": yaw,
                "top": base + 1.2 * size,
                # horizontal radius that bounds the rock (box: half-diagonal)
                "extent": size * (math.sqrt(2.0) if kind == "box" else 1.0),
            }
        )
    return rocks


def _ground_under(x: float, y: float, terrain: Terrain, rocks: list[dict], pad_r: float) -> float:
    """Highest terrain point that a level pad centred at (x, y) could touch [m]."""
    # a level disc meets the inclined plane first with its uphill edge
    h = float(terrain.plane_height(x)) + pad_r * math.tan(terrain.slope)
    for rock in rocks:
        dist = math.hypot(x - rock["pos"][0], y - rock["pos"][1])
        if dist < rock["extent"] + pad_r:
            h = max(h, rock["top"])
    return h


def build_lander_spec(
    design: LanderDesign = DEFAULT_DESIGN,
    params: LanderParams | None = None,
    terrain: Terrain | None = None,
    seed: int = 0,
) -> tuple[mujoco.MjSpec, dict]:
    """Build the ``MjSpec`` of the lander over its terrain.

    Returns the spec and a dict with ``azimuths``, ``start_height`` (initial chassis
    centre height: lowest pad ``start_clearance`` above the terrain under it) and
    ``rocks``.  The lander is built upright at that height, legs at zero stroke.
    """
    terrain = terrain if terrain is not None else Terrain()
    p = terrain_params(params if params is not None else LanderParams(), terrain)
    legs = leg_geometry(design, p)
    tc = p.constraint_timeconst
    solref = [tc, 1.0]

    spec = mujoco.MjSpec()
    spec.modelname = "chronogym_lander"
    spec.option.timestep = p.timestep
    spec.option.gravity = [0.0, 0.0, -p.gravity]
    spec.option.integrator = mujoco.mjtIntegrator.mjINT_IMPLICITFAST
    spec.option.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    # data.energy (potential, kinetic) at every step, for the energy ledger of LanderSim
    spec.option.enableflags |= mujoco.mjtEnableBit.mjENBL_ENERGY
    spec.compiler.degree = False

    # --- terrain ----------------------------------------------------------------------
    world = spec.worldbody
    half = 0.5 * terrain.slope
    world.add_geom(
        name="ground",
        type=mujoco.mjtGeom.mjGEOM_PLANE,
        size=[20.0, 20.0, 0.5],
        quat=[math.cos(half), 0.0, math.sin(half), 0.0],
        contype=0,
        conaffinity=_TERRAIN_CONAFFINITY,
        friction=[p.friction, 0.005, 0.0001],
        solref=solref,
        rgba=[0.55, 0.53, 0.5, 1.0],
    )
    rocks = _place_rocks(terrain, p, seed) if terrain.n_rocks else []
    for rock in rocks:
        kw = {}
        if rock["kind"] == "sphere":
            gtype, size = mujoco.mjtGeom.mjGEOM_SPHERE, [rock["size"], 0.0, 0.0]
        else:
            gtype, size = mujoco.mjtGeom.mjGEOM_BOX, [rock["size"]] * 3
            kw["quat"] = [math.cos(rock["yaw"] / 2), 0.0, 0.0, math.sin(rock["yaw"] / 2)]
        world.add_geom(
            name=rock["name"],
            type=gtype,
            size=size,
            pos=rock["pos"].tolist(),
            contype=0,
            conaffinity=_TERRAIN_CONAFFINITY,
            friction=[p.friction, 0.005, 0.0001],
            solref=solref,
            rgba=[0.45, 0.42, 0.4, 1.0],
            **kw,
        )

    # --- start height: lowest pad start_clearance above the terrain under it ------------
    pad_drop = _pad_bottom_offset(p)
    gaps = []
    for leg in legs:
        x, y, z = leg["P"]
        ground = _ground_under(x, y, terrain, rocks, p.pad_radius)
        gaps.append(z - pad_drop - ground)  # relative to a chassis centre at height 0
    start_height = p.start_clearance - min(gaps)

    # --- chassis ------------------------------------------------------------------------
    chassis = world.add_body(name="chassis", pos=[0.0, 0.0, start_height])
    chassis.add_freejoint(name="chassis_free")
    chassis.add_geom(
        name="chassis_geom",
        type=mujoco.mjtGeom.mjGEOM_CYLINDER,
        size=[p.chassis_radius, p.chassis_length / 2.0, 0.0],
        mass=p.chassis_mass,
        contype=_LANDER_CONTYPE,
        conaffinity=0,
        friction=[p.friction, 0.005, 0.0001],
        solref=solref,
        rgba=[0.75, 0.75, 0.78, 1.0],
    )

    no_collide = {"contype": 0, "conaffinity": 0}
    for i, leg in enumerate(legs):
        # upper primary strut, hinged to the chassis
        upper = chassis.add_body(
            name=f"upper_{i}", pos=leg["A"].tolist(), quat=leg["strut_quat"].tolist()
        )
        upper.add_joint(
            name=f"hinge_{i}",
            type=mujoco.mjtJoint.mjJNT_HINGE,
            axis=[1.0, 0.0, 0.0],
            damping=1.0,
        )
        upper.add_geom(
            name=f"upper_geom_{i}",
            type=mujoco.mjtGeom.mjGEOM_CAPSULE,
            fromto=[0.0, 0.0, 0.0, 0.0, 0.0, -p.upper_length],
            size=[p.strut_radius, 0.0, 0.0],
            mass=p.upper_mass,
            rgba=[0.85, 0.6, 0.2, 1.0],
            **no_collide,
        )
        upper.add_site(name=f"knee_{i}", pos=[0.0, 0.0, -p.knee_distance])

        # lower primary strut (piston) on the slide joint: the absorber stroke
        lower = upper.add_body(name=f"lower_{i}", pos=[0.0, 0.0, -p.primary_length])
        lower.add_joint(
            name=f"slide_{i}",
            type=mujoco.mjtJoint.mjJNT_SLIDE,
            axis=[0.0, 0.0, 1.0],
            range=[0.0, p.max_stroke + p.stop_margin],
            limited=mujoco.mjtLimited.mjLIMITED_TRUE,
            solref_limit=solref,
        )
        lower.add_geom(
            name=f"lower_geom_{i}",
            type=mujoco.mjtGeom.mjGEOM_CAPSULE,
            fromto=[0.0, 0.0, 0.0, 0.0, 0.0, p.lower_length],
            size=[0.75 * p.strut_radius, 0.0, 0.0],
            mass=p.lower_mass,
            rgba=[0.8, 0.8, 0.85, 1.0],
            **no_collide,
        )

        # foot pad, level at start, on a ball joint
        pad_quat = quat_from_axes(*leg["strut_rot"])  # rows of R: R^T, the inverse
        pad = lower.add_body(name=f"pad_{i}", pos=[0.0, 0.0, 0.0], quat=pad_quat.tolist())
        pad.add_joint(
            name=f"pad_ball_{i}",
            type=mujoco.mjtJoint.mjJNT_BALL,
            damping=2.0,
            armature=0.01,
        )
        pad.add_geom(
            name=f"pad_geom_{i}",
            type=mujoco.mjtGeom.mjGEOM_CYLINDER,
            size=[p.pad_radius, p.pad_half_thickness, 0.0],
            pos=[0.0, 0.0, -(p.pad_offset + p.pad_half_thickness)],
            mass=p.pad_mass,
            contype=_LANDER_CONTYPE,
            conaffinity=0,
            friction=[p.friction, 0.005, 0.0001],
            solref=solref,
            rgba=[0.3, 0.3, 0.32, 1.0],
        )

        # secondary strut from the chassis bottom to the knee; loop closed below
        sec = chassis.add_body(
            name=f"secondary_{i}", pos=leg["B"].tolist(), quat=leg["sec_quat"].tolist()
        )
        sec.add_joint(
            name=f"secondary_ball_{i}",
            type=mujoco.mjtJoint.mjJNT_BALL,
            damping=1.0,
            armature=0.01,
        )
        sec.add_geom(
            name=f"secondary_geom_{i}",
            type=mujoco.mjtGeom.mjGEOM_CAPSULE,
            fromto=[0.0, 0.0, 0.0, 0.0, 0.0, leg["sec_len"]],
            size=[0.75 * p.strut_radius, 0.0, 0.0],
            mass=p.secondary_mass,
            rgba=[0.85, 0.6, 0.2, 1.0],
            **no_collide,
        )
        data = np.zeros(mujoco.mjNEQDATA)
        data[:3] = [0.0, 0.0, leg["sec_len"]]
        data[10] = 1.0  # torque scale (unused by connect; MuJoCo's default)
        spec.add_equality(
            name=f"knee_connect_{i}",
            type=mujoco.mjtEq.mjEQ_CONNECT,
            objtype=mujoco.mjtObj.mjOBJ_BODY,
            name1=f"secondary_{i}",
            name2=f"upper_{i}",
            data=data.tolist(),
            solref=solref,
        )

    info = {"azimuths": np.array([leg["phi"] for leg in legs]), "start_height": start_height}
    info["rocks"] = rocks
    return spec, info


def build_lander_model(
    design: LanderDesign = DEFAULT_DESIGN,
    params: LanderParams | None = None,
    terrain: Terrain | None = None,
    seed: int = 0,
) -> LanderModelInfo:
    """Compile the lander and return the model with the indices the simulation needs."""
    terrain = terrain if terrain is not None else Terrain()
    p = terrain_params(params if params is not None else LanderParams(), terrain)
    spec, extra = build_lander_spec(design, p, terrain, seed)
    model = spec.compile()
    slide_ids = [model.joint(f"slide_{i}").id for i in range(N_LEGS)]
    return LanderModelInfo(
        model=model,
        design=design,
        params=p,
        terrain=terrain,
        seed=seed,
        chassis_body=model.body("chassis").id,
        slide_qpos=np.array([model.jnt_qposadr[j] for j in slide_ids]),
        slide_dof=np.array([model.jnt_dofadr[j] for j in slide_ids]),
        pad_geoms=np.array([model.geom(f"pad_geom_{i}").id for i in range(N_LEGS)]),
        chassis_geom=model.geom("chassis_geom").id,
        azimuths=extra["azimuths"],
        start_height=extra["start_height"],
        rocks=extra["rocks"],
    )
