"""Touchdown simulation of the lander in Project Chrono (needs ``pychrono``).

:class:`ChronoLanderSim` is :class:`~..mujoco.sim.LanderSim` on the Chrono model of
:mod:`.model`: same constructor, ``reset``, ``step``, ``run`` and metrics (the
engine-independent ones computed by the same code, :class:`~..landing.Landing`).
Flat rigid ground only.

One tick (:meth:`ChronoLanderSim.step`), as in MuJoCo: read the six strokes and stroke
rates (the struts' ``ChLinkTSDA`` lengths, updated by Chrono at the end of the previous
step), advance the honeycomb law once (:meth:`HoneycombAbsorber.update`), commit its
forces and the slide stops' engagement for the struts' force functors
(:mod:`.struts`), then ``DoStepDynamics``.  Chrono evaluates link forces in
``Update``, which it runs at the end of a step -- with the *previous* tick's forces -- so
the step is preceded by ``ForceUpdate()``: Chrono then updates again at the start of the
step, after the new forces are committed (each functor is called twice per tick, the law
runs once).  Without it every strut force would lag a tick.

A landing costs about 10x MuJoCo's: 4000-5000 steps of 0.25 ms at about 1 ms each (Chrono's
sparse LU of the 264 x 264 system about 0.7 ms, the Python side of the tick 0.3 ms).

Energy balance (``metrics()["energy"]``, :meth:`ChronoLanderSim.energy_ledger`)::

    E_in = KE_0 + PE_released = absorbers + joint_limits + KE + rest,
    rest = contact + residual

* ``absorbers``: the honeycomb force (held over the tick) times the mid-tick stroke rate
  ``(v_n + v_n+1) / 2``, as in MuJoCo's ledger (:mod:`~..mujoco.sim`: with it the work and the
  kinetic energy agree over a velocity jump), split as there into ``absorbers_dissipated``
  (``E_abs``, the law's own account), ``absorbers_elastic`` and ``absorbers_coupling``;
* ``joint_limits``: the same for the slide stops;
* ``KE`` and ``PE`` from the 25 bodies' masses, principal inertias and states;
* ``rest``: what the contacts and the joints took, ``>= 0`` -- booked as ``contact``
  (Chrono's per-body contact wrench on the pads and the chassis, held over the tick,
  times their mid-tick velocities: friction, normal damping and the little elastic
  energy of the penalty contacts), and the ``residual`` (``residual_rel`` over
  ``E_init``): the half-tick offset of the potential energy (the positions advance with
  ``v_n+1``, about -2 J for a landing, as in MuJoCo), the integrator's numerical damping
  and the work of the constraint stabilization.  Joint reactions do no work otherwise:
  Chrono's joints are exact.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from chronogym.engines.chrono import (
    GETTERS,
    bodies_diverged,
    body_ang_vel,
    body_lin_vel,
    body_pos,
    body_rot,
    probe,
    set_body_state,
    vec3,
)
from chronogym.tasks.lander.chrono.model import (
    BODY_NAMES,
    ChronoLanderModel,
    ChronoSettings,
    build_chrono_lander,
    check_chrono_terrain,
    chrono_params,
)
from chronogym.tasks.lander.design import DEFAULT_DESIGN, LanderDesign, LanderParams
from chronogym.tasks.lander.landing import Landing
from chronogym.tasks.lander.terrain import Terrain

__all__ = ["CHRONO_LEDGER_TERMS", "ChronoLanderSim", "simulate_chrono_landing"]

#: Work booked per tick by :class:`ChronoLanderSim` [J] (see the module docstring).
CHRONO_LEDGER_TERMS: tuple[str, ...] = ("absorbers", "joint_limits", "contact", "soil")


class ChronoLanderSim(Landing):
    """Chrono system and absorbers of one lander; one :meth:`step` per physics tick.

    Args:
        design: the design vector.
        params: fixed parameters (default :class:`LanderParams`); the time step is
            ``settings.timestep``, on soil at most ``params.soil_timestep`` (``self.params``
            holds the one used).
        terrain: flat ground (``None``, ``Terrain()`` or ``Terrain(soil=...)``: Chrono's SCM
            soil under the pads, needs PyChrono's vehicle module); slopes and rocks are a
            ``ValueError`` naming what is supported.
        seed: accepted for the same signature as ``LanderSim`` (rocks); no effect here.
        settings: contact, stop and collision settings (:class:`ChronoSettings`).

    Raises:
        ModuleNotFoundError: without PyChrono (the message gives the conda command).
        RuntimeError: from :meth:`step`, on soil, when the chassis reaches the soil.
    """

    def __init__(
        self,
        design: LanderDesign = DEFAULT_DESIGN,
        params: LanderParams | None = None,
        terrain: Terrain | None = None,
        seed: int = 0,
        settings: ChronoSettings | None = None,
    ) -> None:
        self.terrain = check_chrono_terrain(terrain)
        self.settings = settings if settings is not None else ChronoSettings()
        self.params = chrono_params(
            params if params is not None else LanderParams(), self.settings, self.terrain
        )
        self.seed = int(seed)
        self.design = design
        self._init_absorber()
        self._init_history(self.params.timestep)
        self.model: ChronoLanderModel
        self.reset()

    # --- lifecycle -----------------------------------------------------------------------
    def reset(self, design: LanderDesign | None = None, *, seed: int | None = None) -> None:
        """Back to the touchdown state; optionally with another design.

        Rebuilds the Chrono system every time (about 10 ms): a snapshot of the bodies
        would miss what Chrono keeps between steps (collision manifolds, solver state).
        """
        if design is not None:
            self.design = design
        if seed is not None:
            self.seed = int(seed)
        p = self.params
        self._reset_absorber()
        self.model = build_chrono_lander(self.design, p, self.terrain, self.settings)
        self._twist_getters = [
            (probe(body, GETTERS["lin_vel"]), probe(body, GETTERS["ang_vel_world"]))
            for body in self.model.contact_bodies
        ]
        velocity = np.array([p.horizontal_speed, 0.0, -p.touchdown_speed])
        for body in self.model.bodies:
            set_body_state(body, lin_vel=velocity)
        self.model.system.Update()  # links cache lengths and speeds: the struts' strokes
        self._stroke, self._rate = self._read_strokes()
        self._contact_twist = self._read_contact_twist()
        self._soil_touched = False
        self._work = np.zeros(len(CHRONO_LEDGER_TERMS))
        self._energy0 = self.mechanical_energy()
        self._start_history(body_lin_vel(self.model.chassis), self._cos_tilt())

    # --- stepping ------------------------------------------------------------------------
    @property
    def time(self) -> float:
        return float(self.model.system.GetChTime())

    @property
    def stroke(self) -> np.ndarray:
        """Current stroke of the six absorbers [m] (compression positive)."""
        return self._stroke.copy()

    def _read_strokes(self) -> tuple[np.ndarray, np.ndarray]:
        """(strokes, stroke rates) from the struts' lengths as Chrono last updated them."""
        length = self.model.strut_length
        struts = self.model.struts
        stroke = np.array([length - s.GetLength() for s in struts])
        rate = np.array([-s.GetVelocity() for s in struts])
        return stroke, rate

    def step(self) -> None:
        """One physics tick: commit the absorber force and the stops, the Chrono step, then
        the ledger's work over the tick."""
        m = self.model
        stroke, rate = self._stroke, self._rate
        force = self.absorber.update(stroke, rate)
        m.strut_forces.set_tick(force, stroke, rate)
        if m.soil is not None:
            m.soil.Synchronize(self.time)
            m.soil.Advance(m.timestep)
        m.system.ForceUpdate()  # re-evaluate the struts at the step start (see the docstring)
        m.system.DoStepDynamics(m.timestep)
        self._stroke, self._rate = self._read_strokes()
        # work over the tick at the mid-tick velocity (see the module docstring)
        half_dt = 0.5 * m.timestep
        rate_sum = rate + self._rate
        work = self._work
        work[0] += half_dt * float(force @ rate_sum)
        stops = m.strut_forces.stop_force(self._stroke, self._rate)  # applied at the end state
        work[1] += half_dt * float(stops @ rate_sum)
        twist, self._contact_twist = self._contact_twist, self._read_contact_twist()
        touching = m.system.GetNumContacts() > 0
        if touching or m.soil is not None:
            twist += self._contact_twist
        if touching:
            work[2] -= half_dt * self._contact_power(twist)
        if m.soil is not None:
            soil_power = self._soil_power(twist)
            work[3] -= half_dt * soil_power
            touching = self._soil_touched = self._soil_touched or soil_power != 0.0
            self._check_chassis_above_soil()
        self._record(body_lin_vel(m.chassis), self._cos_tilt())
        if self._t_touchdown is None and touching:
            self._t_touchdown = self.time

    def _read_contact_twist(self) -> np.ndarray:
        """Linear and angular velocity (world) of the bodies that can touch, (7, 6)."""
        twist = np.empty((len(self._twist_getters), 6))
        for row, (lin_vel, ang_vel) in zip(twist, self._twist_getters, strict=True):
            row[:3] = vec3(lin_vel())
            row[3:] = vec3(ang_vel())
        return twist

    def _contact_power(self, twist: np.ndarray) -> float:
        """Power of the contact wrenches of the tick just taken for the given twists
        (one row per contact body): Chrono's per-body resultant force and torque, held
        over the tick."""
        total = 0.0
        for body, row in zip(self.model.contact_bodies, twist, strict=True):
            force = vec3(body.GetContactForce())
            if force.any():
                total += float(force @ row[:3] + vec3(body.GetContactTorque()) @ row[3:])
        return total

    def _soil_power(self, twist: np.ndarray) -> float:
        """Power of the SCM soil's wrenches on the pads for the given twists (rows of the
        contact bodies; the chassis, row 0, is not on the soil), held over the tick."""
        soil = self.model.soil
        total = 0.0
        for body, row in zip(self.model.contact_bodies[1:], twist[1:], strict=True):
            force, torque = soil.force_on(body)
            total += float(force @ row[:3] + torque @ row[3:])
        return total

    def _check_chassis_above_soil(self) -> None:
        """Raise when the chassis cylinder's lowest point reaches the soil surface (z = 0):
        the chassis is not on the Chrono soil (see :mod:`.model`)."""
        centre_local, radius, half = self.model.chassis_shape
        chassis = self.model.chassis
        w, x, y, z = body_rot(chassis).tolist()
        rot_z = np.array([2 * (x * z - w * y), 2 * (y * z + w * x), 1 - 2 * (x * x + y * y)])
        centre_z = body_pos(chassis)[2] + float(rot_z @ centre_local)
        axis_z = abs(float(rot_z @ self.model.chassis_axis))
        lowest = centre_z - half * axis_z - radius * math.sqrt(max(0.0, 1.0 - axis_z * axis_z))
        if lowest <= 0.0:
            raise RuntimeError(
                f"the chassis reached the soil (lowest point z={lowest:.3f} m at "
                f"t={self.time:.3f} s): the Chrono lander has only its pads on SCM soil; "
                "use the MuJoCo lander (LanderSim) for this landing"
            )

    def _cos_tilt(self) -> float:
        """Cosine of the chassis axis' angle from the vertical (flat ground): the world z
        component of the axis, from the last row of the rotation matrix."""
        w, x, y, z = body_rot(self.model.chassis).tolist()
        ax, ay, az = self.model.chassis_axis.tolist()
        return (
            2.0 * (x * z - w * y) * ax
            + 2.0 * (y * z + w * x) * ay
            + (1.0 - 2.0 * (x * x + y * y)) * az
        )

    def _chassis_velocity(self) -> tuple[np.ndarray, np.ndarray]:
        chassis = self.model.chassis
        return body_lin_vel(chassis), body_ang_vel(chassis)

    def render(self, width: int = 480, height: int = 360) -> np.ndarray:
        """An offscreen picture of the lander now, (height, width, 3) uint8: the Chrono bodies'
        poses drawn with the MuJoCo model of the same design (:mod:`..render`)."""
        import mujoco

        from chronogym.tasks.lander.render import LanderRenderer, pose_bodies

        m = self.model
        model = m.mujoco_model
        cache = getattr(self, "_picture", None)
        if cache is None or cache[0] is not model or cache[3].size != (width, height):
            data = mujoco.MjData(model)
            mujoco.mj_kinematics(model, data)  # world geoms, lights and cameras
            ids = [model.body(name).id for name in BODY_NAMES]
            cache = self._picture = (model, data, ids, LanderRenderer(model, width, height))
        _, data, ids, renderer = cache
        pos = np.array([body_pos(b) for b in m.bodies])
        quat = np.array([body_rot(b) for b in m.bodies])
        pose_bodies(model, data, ids, pos, quat)
        return renderer.frame(data)

    def diverged(self, limit: float = 1e6) -> bool:
        """NaN/Inf or a huge value in a body state (``bodies_diverged``)."""
        return bodies_diverged(self.model.bodies, limit)

    # --- energy and metrics ---------------------------------------------------------------
    def mechanical_energy(self) -> tuple[float, float]:
        """(potential, kinetic) energy of the 25 bodies [J]: ``m g z`` of each centre of
        mass (``z = 0`` at the ground), ``m v^2 / 2`` plus the rotational energy about
        the principal axes."""
        m = self.model
        g = self.params.gravity
        potential = kinetic = 0.0
        for body, mass, inertia in zip(m.bodies, m.masses, m.inertias, strict=True):
            v = body_lin_vel(body)
            w = body_ang_vel(body, local=True)
            potential += mass * g * body_pos(body)[2]
            kinetic += 0.5 * (mass * float(v @ v) + float(w @ (inertia * w)))
        return float(potential), float(kinetic)

    def energy_ledger(self) -> dict[str, float]:
        """The energy balance of the landing so far [J] (see the module docstring)."""
        pot0, kin0 = self._energy0
        pot, kin = self.mechanical_energy()
        work = dict(zip(CHRONO_LEDGER_TERMS, (float(w) for w in self._work), strict=True))
        ab = self.absorber
        e_abs = float(np.sum(ab.absorbed_energy))
        elastic = float(np.sum(ab.elastic_energy))
        e_in = kin0 + pot0 - pot
        rest = e_in - kin - work["absorbers"] - work["joint_limits"]
        residual = rest - work["contact"] - work["soil"]
        e_init = self.params.e_init
        return {
            "E_init": e_init,
            "KE_0": kin0,
            "PE_released": pot0 - pot,
            "E_in": e_in,
            **work,
            "absorbers_dissipated": e_abs,
            "absorbers_elastic": elastic,
            "absorbers_coupling": work["absorbers"] - e_abs - elastic,
            "KE": kin,
            "rest": rest,
            "residual": residual,
            "residual_rel": residual / e_init,
        }

    def metrics(self) -> dict[str, Any]:
        """Touchdown metrics so far: those of ``LanderSim`` with the Chrono energy ledger.
        ``E_soil`` is the soil's work on the pads, ``max_sinkage`` the depth of the deepest
        soil node (both 0 on rigid ground)."""
        energy = self.energy_ledger()
        metrics = self._landing_metrics()
        metrics.update(
            E_soil=energy["soil"],
            max_sinkage=self.pad_sinkage(),
            E_available=energy["E_in"],
            energy=energy,
        )
        return metrics

    def pad_sinkage(self) -> float:
        """Depth of the deepest soil node now [m] (0 on rigid ground): the deepest rut, as
        ``LanderSim``'s ``max_sinkage`` (its soil grid's deepest plastic sinkage)."""
        return 0.0 if self.model.soil is None else self.model.soil.deepest()


def simulate_chrono_landing(
    design: LanderDesign = DEFAULT_DESIGN,
    params: LanderParams | None = None,
    terrain: Terrain | None = None,
    settings: ChronoSettings | None = None,
) -> dict[str, Any]:
    """Run one full touchdown in Chrono and return its metrics (deterministic)."""
    return ChronoLanderSim(design, params, terrain, settings=settings).run()
