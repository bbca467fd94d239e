"""Touchdown simulation of the lander and its metrics.

:class:`LanderSim` owns the compiled model, its ``MjData`` and the six honeycomb
absorbers.  One :meth:`LanderSim.step` is one physics tick: read the six strokes and
stroke rates, advance the absorbers (:meth:`HoneycombAbsorber.update`), write ``-F`` to
``data.qfrc_applied`` at the slide DOFs, ``mj_step``.  :func:`simulate_landing` runs a
whole touchdown until the lander settles (or ``params.max_time``) and returns the
metrics.

Initial state
-------------
The drop itself is not simulated.  The lander starts upright, legs at zero stroke, its
lowest pad ``start_clearance`` (1 cm) above the terrain under it, every body moving
down at the touchdown speed ``v = sqrt(2 g h)`` of a drop from ``h = drop_height``
(Chrono demo: 2 m -> 2.55 m/s at lunar gravity), plus ``horizontal_speed`` along +x.
``E_init = M g h`` is "the initial gravitational potential energy of the lander prior to
impact" -- the potential energy at the drop height relative to touchdown -- and equals
the kinetic energy ``M v^2 / 2`` the simulation starts with (vertical part).

Metrics (returned by :meth:`LanderSim.metrics` / :func:`simulate_landing`)
--------------------------------------------------------------------------
``a_max`` [m/s^2]
    Peak magnitude of the *chassis* centre-of-mass acceleration.  The chassis carries
    the payload and the absorbers stand between it and the pads, so its acceleration
    is the design-relevant load; the whole-lander CoM acceleration would instead be
    dominated by the 2 kg pads' contact impulses.  The acceleration is the kinematic
    one (``dv/dt``: free fall reads 1.62, rest reads 0) so that it is comparable to
    ``a_ref``, itself a kinematic deceleration.  ``a_max_proper`` is the same for the
    accelerometer reading ``dv/dt - g``.

    *Filter.*  The chassis velocity is recorded every tick and the acceleration is its
    moving average over ``accel_window`` = 20 ms, computed exactly as the velocity
    difference across the window, ``a(t) = (v(t + T) - v(t)) / T`` (a box filter: first
    zero at 50 Hz); ``a_max`` is the largest magnitude over the landing.

    *Why 20 ms (the conditioning issue).*  When a pad lands, the slide joint is rigid
    sideways, so the piston and pad (and part of the upper strut) are stopped vertically
    and kicked inward at ``v tan(alpha2)`` within the first milliseconds; the chassis
    takes that (friction-amplified) impulse.  The impulse is physical -- the momentum of
    the unsprung masses -- but its *duration* is set by the compliance of the soft
    constraints (knee loops, joint stops, contacts: ``LanderParams.constraint_timeconst``
    = 4 ms, critically damped, settled within about 5 time constants).  With the earlier
    5 ms window the filtered spike rode on that numerical stiffness rather than on the
    design.  The first version noted ``a_max`` 22 -> 27 -> 29 m/s^2 at the default design
    (crush plateau 17.3 m/s^2) for time constants 4 -> 2 -> 1 ms; those figures come back
    when only the knee loops are stiffened (22.1, 26.9, 28.6), while stiffening all
    constraints gives 22.1, 23.2, 22.9 there and 54 -> 71 -> 85 m/s^2 at ``alpha2`` =
    50 deg.  A window of at least 5 time constants holds the whole
    kick, so the filtered peak measures its impulse, not its shape; 20 ms is still short
    against the crush pulse (about 55 ms for the stiffest honeycomb in bounds on upright
    legs, 15 kN at ``alpha2`` = 10 deg, whose 46.6 m/s^2 plateau it keeps to 0.2 %), so
    the plateau, the densification rise and bottoming stay in.  With 20 ms the same
    knee-only sweep gives 18.7 -> 18.8 -> 19.2 m/s^2, and the spread of ``a_max`` over
    all-constraint time constants 4 / 2 / 1 ms drops (5 ms -> 20 ms window) from 5 to
    3 % (default; 22.1 -> 18.7 m/s^2 at 4 ms), 6 to 1 % (8 kN), 6 to 2 % (15 kN), 57 to
    5 % (``alpha2`` = 50 deg), 15 to 3 % (``beta`` = 20, ``alpha2`` = 40 deg).  Still
    ill-conditioned: designs that bottom out hit the slide joint's hard stop, whose
    stiffness is again the constraint time constant (2 kN: 17 -> 10 %; 1 kN: 175 ->
    22 %, ``a_max`` 119-145 m/s^2); they score badly whatever value they get.
``E_abs`` [J]
    Energy dissipated by the six absorbers (plastic crush work + elastic-line damping),
    summed over legs; ``E_abs_legs`` per leg.
``E_soil`` [J]
    Work taken by the SCM soil (``Terrain.soil``; 0 on rigid ground): its own account,
    ``MujocoSoil.energy_dissipated`` (pressing the ruts plastically, shear, damping).
``max_sinkage`` [m]
    Deepest permanent (plastic) sinkage of the soil, i.e. the deepest pad rut (0 on rigid
    ground).
``E_init`` [J]
    ``M g h`` as above.
``E_available`` [J]
    The mechanical energy the landing released: initial kinetic energy plus the
    potential energy lost by the lander's CoM between the start and the end,
    ``KE_0 + M g (z_0 - z_end)``, from MuJoCo's energies (= ``energy["E_in"]``).
    ``E_abs <= E_available`` always.  ``E_abs`` can exceed ``E_init`` because the lander
    also sinks by roughly the vertical component of the stroke.
``energy``
    The energy ledger (dict of floats [J], see below and :data:`LEDGER_TERMS`).
``max_stroke`` [m]
    Largest stroke over legs and time (``max_stroke_legs`` per leg; ``crush_stroke_legs``:
    the permanent crushed lengths at the end).
``bottomed_out``
    Some stroke reached ``max_stroke`` (full densification).
``tipped_over``
    The chassis tilt exceeded ``tip_angle`` (30 deg) at some time.  Tilt is the angle
    between the chassis axis and the ground plane's normal (on flat ground: from the
    vertical; on a slope the upright lander starts at ``slope``).
``J``
    The objective ``J = a_max / a_ref + (alpha (E_abs / E_init - 1))^2`` with
    ``a_ref = v^2 / (2 s_max)``: the constant deceleration that stops the touchdown
    speed ``v`` within the maximum stroke ``s_max`` (from ``v^2 = 2 a s``; design
    independent, 10.8 m/s^2 by default), and ``alpha = energy_weight = 2``: absorbers
    that take 25 % too little or too much of ``E_init`` cost 0.25, a quarter of the
    acceleration term at ``a_max = a_ref`` (the default design scores 1.73 + 0.25), so
    the energy term steers without swamping the acceleration term; with ``alpha = 1``
    it would hardly matter (0.06), with ``alpha = 3`` it would rival it.  Along ``f_y``
    at the default geometry J falls from 12.0 (1 kN, bottoms out) to a minimum near
    3.5 kN (1.74) and rises again to 6.8 (15 kN).

Plus ``settled``, ``t_end``, ``t_touchdown``, ``max_tilt``/``final_tilt`` [rad],
``n_steps``, ``a_ref``, ``touchdown_speed``, ``KE_0``.

Energy ledger
-------------
Every tick :meth:`LanderSim.step` books the work of each non-conservative force, and
``metrics()["energy"]`` (:meth:`LanderSim.energy_ledger`) closes the balance

    E_in = KE_0 + PE_released
         = joint_loops + joint_limits + friction + contact_normal + joint_friction
           + absorbers + joint_damping + KE + residual

with the potential and kinetic energies from MuJoCo (``mjENBL_ENERGY``:
``mj_energyPos`` -- gravity -- and ``mj_energyVel`` -- ``v^T M v / 2``, armature
included), ``PE_released = PE_0 - PE(t)`` (the lander sinks while stroking), and each
term the work the force took out of the mechanism (positive: dissipated, or stored
where the potential energy does not see it: the honeycomb's elastic line, the
penetration of a soft constraint):

* constraint rows, from ``data.efc_force`` and the constraint Jacobian: equality rows
  (the six knee ``connect`` loops), joint limits (slide stops), contact friction rows and
  contact normal rows (the first row of each elliptic-cone contact), frictionloss rows;
* ``absorbers``: the honeycomb force times the stroke rate at the six slide joints; it
  splits into ``absorbers_dissipated`` (= ``E_abs``, the crush law's own account),
  ``absorbers_elastic`` (still stored on the elastic line) and ``absorbers_coupling``
  (the rest: the law is applied explicitly, once per tick, so the work the mechanism
  delivers and the law's own account of it differ slightly -- -5 J at the default
  design, at most 13 J, 0.2 % of ``E_init``, over the designs in the tests);
* ``joint_damping``: the passive joint damping;
* ``soil``: on SCM soil, the soil wrench (``data.xfrc_applied`` of the pads and the
  chassis, mapped to joint space with ``mj_applyFT``) times the mid-tick velocity.  Like
  the absorbers it splits into ``soil_dissipated`` (the soil's own trapezoidal account
  ``MujocoSoil.energy_dissipated`` less what is still stored), ``soil_elastic``
  (``MujocoSoil.elastic_energy``, under the resting pads) and ``soil_coupling`` (the rest:
  the two accounts use different velocities); all 0 on rigid ground.

``residual = E_total(0) - (E_total(t) + sum of the terms)``; ``residual_rel`` is it over
``E_init``, ``residual_max`` its largest magnitude over every tick of the landing.

*Which velocity.*  A force ``f`` held over the tick (all of them are evaluated at the
tick's start state ``n``) is booked as ``f . (v_n + v_n+1) / 2 * dt``: MuJoCo updates
``v_n+1 = v_n + dt M^-1 f`` and then ``q`` with ``v_n+1``, so the kinetic energy changes
by exactly ``(v_n + v_n+1) / 2 . M (v_n+1 - v_n)`` -- the mid-tick velocity makes the
work and the kinetic energy agree to round-off, whatever the size of the velocity jump.
(Joint damping is integrated implicitly by ``implicitfast``: its force is ``-D v_n+1``,
booked as such.)  What is left is the half-tick offset of the potential energy (the
positions advance with ``v_n+1``, not the mid-tick velocity), which telescopes to
``M g dt (v_z(t) - v_z(0)) / 2`` = -2.2 J for a landing from 2.55 m/s to rest, and the
change of ``M`` over each tick (< 0.1 J): the residual is -2.1 J, 0.03 % of ``E_init``,
at every design tried.  The obvious alternative, ``-efc_force . efc_vel * dt``, uses
``v_n`` instead; the soft contacts and loops stop the pads and pistons within a few
ticks, and each such velocity jump then books ``|v_n+1 - v_n|_M^2 / 2`` of phantom
work (``v_n+1`` books the same amount with the other sign): the residual becomes
-3.2 % (+3.1 %) of ``E_init`` at a constraint time constant of 4 ms, -8 % at 2 ms and
-30 % at 1 ms.  With the mid-tick velocity it stays at 0.03 % for all three.

The ledger costs about 14 us per tick (~14 % of a landing).
"""

from __future__ import annotations

import math
from typing import Any

import mujoco
import numpy as np

from chronogym.engines.mujoco import mujoco_diverged
from chronogym.tasks.lander.design import DEFAULT_DESIGN, LanderDesign, LanderParams
from chronogym.tasks.lander.geometry import N_LEGS
from chronogym.tasks.lander.landing import Landing
from chronogym.tasks.lander.mujoco.model import LanderModelInfo, build_lander_model
from chronogym.tasks.lander.render import LanderRenderer
from chronogym.tasks.lander.terrain import Terrain, terrain_params
from chronogym.terrain import MujocoSoil

__all__ = ["LEDGER_TERMS", "LanderSim", "simulate_landing"]

#: Non-conservative channels of the energy ledger, in the order of ``LanderSim._work``:
#: the work each one took out of the mechanism [J] (positive: dissipated or stored
#: outside the potential and kinetic energy).  See "Energy ledger" in the module docstring.
LEDGER_TERMS: tuple[str, ...] = (
    "joint_loops",  # equality rows: the six knee connect constraints
    "joint_limits",  # slide-joint stops (extension and bottoming)
    "friction",  # contact friction rows (both tangential rows of the elliptic cone)
    "contact_normal",  # contact normal rows
    "joint_friction",  # dof/tendon frictionloss rows (none in this model)
    "absorbers",  # honeycomb force x stroke rate, at the six slide joints
    "joint_damping",  # passive joint damping (hinges, ball joints)
    "soil",  # SCM soil wrench on the pads and the chassis (0 on rigid ground)
)
_N_EFC_TERMS = 5  # the first five terms are booked from constraint rows
_ABSORBERS = LEDGER_TERMS.index("absorbers")
_DAMPING = LEDGER_TERMS.index("joint_damping")
_SOIL = LEDGER_TERMS.index("soil")
_NORMAL = LEDGER_TERMS.index("contact_normal")
_C = mujoco.mjtConstraint
#: ledger term of each constraint row type (index: ``mjtConstraint`` value).  Pyramidal
#: cone rows mix normal and friction directions and all go to "friction" (this model
#: uses the elliptic cone, whose first row per contact is the normal one).
_EFC_TERM = np.zeros(max(int(c) for c in _C.__members__.values()) + 1, dtype=np.intp)
for _type, _term in (
    (_C.mjCNSTR_EQUALITY, "joint_loops"),
    (_C.mjCNSTR_FRICTION_DOF, "joint_friction"),
    (_C.mjCNSTR_FRICTION_TENDON, "joint_friction"),
    (_C.mjCNSTR_LIMIT_JOINT, "joint_limits"),
    (_C.mjCNSTR_LIMIT_TENDON, "joint_limits"),
    (_C.mjCNSTR_CONTACT_FRICTIONLESS, "contact_normal"),
    (_C.mjCNSTR_CONTACT_PYRAMIDAL, "friction"),
    (_C.mjCNSTR_CONTACT_ELLIPTIC, "friction"),
):
    _EFC_TERM[int(_type)] = LEDGER_TERMS.index(_term)


class LanderSim(Landing):
    """Model, data and absorbers of one lander; one :meth:`step` per physics tick.

    History, settling (:meth:`run`) and the engine-independent metrics come from
    :class:`~chronogym.tasks.lander.landing.Landing`.

    Args:
        design: the design vector.
        params: fixed parameters (default :class:`LanderParams`).
        terrain: ground (default flat, rigid).  With ``terrain.soil`` the pads and the
            chassis stand on SCM soil (``soil``), stepped before each ``mj_step``, and the
            time step is ``params.soil_timestep`` (``self.params`` holds the one used).
        seed: places the rocks of ``terrain``; the simulation itself is deterministic.
    """

    def __init__(
        self,
        design: LanderDesign = DEFAULT_DESIGN,
        params: LanderParams | None = None,
        terrain: Terrain | None = None,
        seed: int = 0,
    ) -> None:
        self.terrain = terrain if terrain is not None else Terrain()
        self.params = terrain_params(params if params is not None else LanderParams(), self.terrain)
        self.seed = int(seed)
        self.design = design
        self.info: LanderModelInfo = build_lander_model(design, self.params, self.terrain, seed)
        self.model = self.info.model
        self.data = mujoco.MjData(self.model)
        self.soil = self._make_soil()
        self._init_absorber()
        self._init_history(self.params.timestep)
        self._scratch: mujoco.MjData | None = None
        self.reset()

    # --- lifecycle -----------------------------------------------------------------------
    def reset(self, design: LanderDesign | None = None, *, seed: int | None = None) -> None:
        """Back to the touchdown state; optionally with another design or rock seed.

        A design that changes only ``f_y`` keeps the compiled model (and the soil, restored
        in place); a new ``beta`` or ``alpha2`` (or seed with rocks) rebuilds both.
        """
        p = self.params
        rebuild = False
        if design is not None and design != self.design:
            rebuild = design.geometry_key() != self.design.geometry_key()
            self.design = design
        if seed is not None and int(seed) != self.seed:
            self.seed = int(seed)
            rebuild = rebuild or self.terrain.n_rocks > 0
        if rebuild:
            self.info = build_lander_model(self.design, p, self.terrain, self.seed)
            self.model = self.info.model
            self.data = mujoco.MjData(self.model)
            self.soil = self._make_soil()
            self._scratch = None
        self.info.design = self.design
        self._reset_absorber()

        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        if self.soil is not None:
            self.soil.reset()
        d.qvel[0] = p.horizontal_speed
        d.qvel[2] = -p.touchdown_speed
        mujoco.mj_forward(m, d)

        self._chassis = self.info.chassis_body
        self._sq = self.info.slide_qpos
        self._sd = self.info.slide_dof
        slope = self.terrain.slope
        self._normal = np.array([math.sin(slope), 0.0, math.cos(slope)])
        self._start_history(d.qvel[0:3], self._cos_tilt())
        # energy ledger (see the module docstring)
        self._damping = m.dof_damping.copy()
        self._split_normal = m.opt.cone == mujoco.mjtCone.mjCONE_ELLIPTIC
        self._qvel0 = np.zeros(m.nv)
        self._vmid = np.zeros(m.nv)
        self._work = np.zeros(len(LEDGER_TERMS))
        self._qfrc_soil = np.zeros(m.nv)
        self._energy0 = (float(d.energy[0]), float(d.energy[1]))  # (potential, kinetic)
        self._residual_max = 0.0

    def _make_soil(self) -> MujocoSoil | None:
        """The terrain's SCM soil on this model (``None`` on rigid ground), holding the pads
        and the chassis; the ground plane does not touch them."""
        terrain = self.terrain
        if terrain.soil is None:
            return None
        self._check_pads_on_soil()
        bodies = ["chassis", *(f"pad_{i}" for i in range(N_LEGS))]
        side = float(terrain.soil_extent)
        soil = MujocoSoil(
            self.model,
            self.data,
            terrain.soil,
            bodies=bodies,
            extent=(side, side),
            resolution=float(terrain.soil_resolution),
        )
        soil.exclude_ground("ground")
        return soil

    def _check_pads_on_soil(self) -> None:
        """Raise if a pad's rim starts less than 0.2 m inside the soil patch."""
        start = mujoco.MjData(self.model)  # at qpos0: the touchdown pose
        mujoco.mj_kinematics(self.model, start)
        pads = start.geom_xpos[self.info.pad_geoms, :2]
        reach = float(np.max(np.abs(pads))) + self.params.pad_radius
        half = 0.5 * self.terrain.soil_extent
        if reach > half - 0.2:
            raise ValueError(
                f"soil_extent={self.terrain.soil_extent!r}: a pad reaches {reach:.3f} m from "
                f"the centre; expected a patch wider than {2 * (reach + 0.2):.3f} m"
            )

    # --- stepping ----------------------------------------------------------------------------
    @property
    def time(self) -> float:
        return float(self.data.time)

    @property
    def stroke(self) -> np.ndarray:
        """Current stroke of the six absorbers [m] (compression positive)."""
        return self.data.qpos[self._sq].copy()

    def step(self) -> None:
        """One physics tick: the soil wrench (on soil), absorber forces at the slide DOFs,
        ``mj_step``, then the energy ledger's work over the tick."""
        d = self.data
        soil = self.soil
        if soil is not None:
            soil.Advance(self.model.opt.timestep)
        self._qvel0[:] = d.qvel
        force = self.absorber.update(d.qpos[self._sq], d.qvel[self._sd])
        d.qfrc_applied[self._sd] = -force
        mujoco.mj_step(self.model, d)
        self._book_work(force)
        self._record(d.qvel[0:3], self._cos_tilt())
        if self._t_touchdown is None and (d.ncon > 0 or self._on_soil()):
            self._t_touchdown = float(d.time)

    def _on_soil(self) -> bool:
        """Did the soil push on a body during the tick just taken?"""
        soil = self.soil
        return soil is not None and bool(self.data.xfrc_applied[soil.body_ids].any())

    def _book_work(self, force: np.ndarray) -> None:
        """Add the work of every non-conservative force over the tick just taken.

        After ``mj_step`` the data still hold the forces of the tick (constraint forces,
        Jacobian, passive forces, all evaluated at its start state ``n``) and the new
        velocity ``v_n+1``.  Each force ``f`` did the work ``f . (v_n + v_n+1) / 2 * dt``
        (see the module docstring for why the mid-tick velocity).
        """
        m, d = self.model, self.data
        dt = m.opt.timestep
        work = self._work
        # ledger residual at state n: data.energy was computed at the start of the tick,
        # the work so far covers the ticks before it
        pot0, kin0 = self._energy0
        residual = pot0 + kin0 - float(d.energy[0] + d.energy[1]) - float(work.sum())
        self._residual_max = max(self._residual_max, abs(residual))

        vmid = self._vmid
        np.add(self._qvel0, d.qvel, out=vmid)
        vmid *= 0.5
        work[_ABSORBERS] += dt * float(force @ vmid[self._sd])
        # implicit(fast) integration applies joint damping at the new velocity:
        # qfrc_passive (-D v_n) - D (v_n+1 - v_n) = -D v_n+1
        passive = d.qfrc_passive - self._damping * (d.qvel - self._qvel0)
        work[_DAMPING] -= dt * float(passive @ vmid)
        nefc = d.nefc
        if nefc:
            power = np.empty(nefc)
            mujoco.mj_mulJacVec(m, d, power, vmid)  # constraint velocity J v_mid
            power *= d.efc_force[:nefc]
            term = _EFC_TERM[d.efc_type[:nefc]]
            if self._split_normal and d.ncon:
                first = d.contact.efc_address[: d.ncon]
                term[first[first >= 0]] = _NORMAL
            work[:_N_EFC_TERMS] -= dt * np.bincount(term, power, _N_EFC_TERMS)
        if self.soil is not None:
            work[_SOIL] -= dt * float(self._soil_force() @ vmid)

    def _soil_force(self) -> np.ndarray:
        """Joint-space force of the soil wrench applied over the tick just taken.

        After ``mj_step`` the kinematics (``xipos``, Jacobians) still describe the tick's
        start state, where the soil computed its wrench about each body's CoM.
        """
        m, d = self.model, self.data
        qfrc = self._qfrc_soil
        qfrc[:] = 0.0
        xfrc, bodies = d.xfrc_applied, self.soil.body_ids
        for body in bodies[xfrc[bodies].any(axis=1)].tolist():
            wrench = xfrc[body]
            mujoco.mj_applyFT(m, d, wrench[:3], wrench[3:], d.xipos[body], body, qfrc)
        return qfrc

    def _cos_tilt(self) -> float:
        """Cosine of the angle between the chassis axis and the ground-plane normal."""
        r = self.data.xmat[self._chassis]
        nx, _, nz = self._normal
        return float(r[2] * nx + r[8] * nz)

    def _chassis_velocity(self) -> tuple[np.ndarray, np.ndarray]:
        q = self.data.qvel
        return q[0:3], q[3:6]

    def render(self, width: int = 480, height: int = 360) -> np.ndarray:
        """An offscreen picture of the lander now, (height, width, 3) uint8 (needs EGL or
        OSMesa; :class:`~..render.LanderRenderer`)."""
        renderer = getattr(self, "_renderer", None)
        if renderer is None or renderer.model is not self.model or renderer.size != (width, height):
            renderer = self._renderer = LanderRenderer(self.model, width, height)
        return renderer.frame(self.data)

    def diverged(self) -> bool:
        """MuJoCo flagged an unstable state, or NaN/Inf in the state (``mujoco_diverged``)."""
        return mujoco_diverged(self.data)

    def mechanical_energy(self) -> tuple[float, float]:
        """(potential, kinetic) energy of the current state [J], from MuJoCo's
        ``mj_energyPos`` / ``mj_energyVel`` (gravitational potential relative to
        ``z = 0``; kinetic energy including the joints' armature).

        Evaluated on a scratch ``MjData``, so calling it never touches the simulation.
        """
        m, d = self.model, self.data
        if self._scratch is None:
            self._scratch = mujoco.MjData(m)
        scratch = self._scratch
        scratch.qpos[:] = d.qpos
        scratch.qvel[:] = d.qvel
        mujoco.mj_forward(m, scratch)  # fills scratch.energy (mjENBL_ENERGY)
        return float(scratch.energy[0]), float(scratch.energy[1])

    def energy_ledger(self) -> dict[str, float]:
        """The energy balance of the landing so far [J] (see "Energy ledger" in the
        module docstring): ``E_in = KE_0 + PE_released`` equals the sum of the
        ``LEDGER_TERMS``, the kinetic energy ``KE`` and ``residual``."""
        pot0, kin0 = self._energy0
        pot, kin = self.mechanical_energy()
        work = dict(zip(LEDGER_TERMS, (float(w) for w in self._work), strict=True))
        residual = pot0 + kin0 - pot - kin - float(self._work.sum())
        ab = self.absorber
        e_abs = float(np.sum(ab.absorbed_energy))
        elastic = float(np.sum(ab.elastic_energy))
        e_init = self.params.e_init
        soil_taken, soil_elastic = self._soil_energies()
        return {
            "E_init": e_init,
            "KE_0": kin0,
            "PE_released": pot0 - pot,
            "E_in": kin0 + pot0 - pot,
            **work,
            "absorbers_dissipated": e_abs,
            "absorbers_elastic": elastic,
            "absorbers_coupling": work["absorbers"] - e_abs - elastic,
            "soil_dissipated": soil_taken - soil_elastic,
            "soil_elastic": soil_elastic,
            "soil_coupling": work["soil"] - soil_taken,
            "KE": kin,
            "residual": residual,
            "residual_rel": residual / e_init,
            "residual_max": max(self._residual_max, abs(residual)),
        }

    def _soil_energies(self) -> tuple[float, float]:
        """(work taken by the soil by its own account, elastic energy stored in it) [J]."""
        if self.soil is None:
            return 0.0, 0.0
        return self.soil.energy_dissipated, self.soil.elastic_energy

    def _max_sinkage(self) -> float:
        """Deepest plastic sinkage of the soil [m] (0 on rigid ground)."""
        if self.soil is None:
            return 0.0
        return float(np.max(self.soil.plastic_sinkage))

    def metrics(self) -> dict[str, Any]:
        """Touchdown metrics so far (see the module docstring)."""
        energy = self.energy_ledger()
        metrics = self._landing_metrics()
        metrics.update(
            E_soil=energy["soil_dissipated"] + energy["soil_elastic"],
            max_sinkage=self._max_sinkage(),
            E_available=energy["E_in"],
            energy=energy,
        )
        return metrics


def simulate_landing(
    design: LanderDesign = DEFAULT_DESIGN,
    params: LanderParams | None = None,
    terrain: Terrain | None = None,
    seed: int = 0,
) -> dict[str, Any]:
    """Run one full touchdown and return its metrics (see the module docstring).

    Deterministic: the same arguments give identical metrics.
    """
    return LanderSim(design, params, terrain, seed).run()
