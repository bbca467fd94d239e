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
    ``a_ref``, itself a kinematic deceleration.  It is filtered by a moving average over
    ``accel_window`` = 5 ms, computed exactly as the velocity difference across the
    window, ``(v(t) - v(t - 5 ms)) / 5 ms``; this removes the single-tick spikes of
    contact and constraint impulses.  Longer events stay: bottoming on the joint stop,
    and the touchdown transient -- the strut's slide joint is rigid sideways, so when a
    pad lands its piston and pad are kicked inward at ``v tan(alpha2)`` and the chassis
    takes that (friction-amplified) impulse over a few ms.  At the default design this
    transient sets ``a_max`` (22 m/s^2 against a crush plateau of 17.3 m/s^2); its
    filtered height depends on the constraint compliance (see
    ``LanderParams.constraint_timeconst``).  ``a_max_proper`` is the same for the
    accelerometer reading ``dv/dt - g``.
``E_abs`` [J]
    Energy dissipated by the six absorbers (plastic crush work + elastic-line damping),
    summed over legs; ``E_abs_legs`` per leg.
``E_init`` [J]
    ``M g h`` as above.
``E_available`` [J]
    The mechanical energy the landing released: initial kinetic energy plus the
    potential energy lost by the lander's CoM between the start and the end,
    ``KE_0 + M g (z_0 - z_end)``.  Energy balance: ``E_abs + (friction, contact and
    constraint losses) + KE_end + (elastic energy left in the honeycomb) = E_available``,
    so ``E_abs <= E_available`` always.  ``E_abs`` can exceed ``E_init`` because the
    lander also sinks by roughly the vertical component of the stroke.
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
    acceleration term at ``a_max = a_ref`` (the default design scores 2.05 + 0.25), so
    the energy term steers without swamping the acceleration term; with ``alpha = 1``
    it would hardly matter (0.06), with ``alpha = 3`` it would rival it.

Plus ``settled``, ``t_end``, ``t_touchdown``, ``max_tilt``/``final_tilt`` [rad],
``n_steps``, ``a_ref``, ``touchdown_speed``, ``KE_0``.
"""

from __future__ import annotations

import math
from typing import Any

import mujoco
import numpy as np

from chronogym.tasks.lander.absorber import HoneycombAbsorber
from chronogym.tasks.lander.design import DEFAULT_DESIGN, LanderDesign, LanderParams
from chronogym.tasks.lander.model import N_LEGS, LanderModelInfo, Terrain, build_lander_model

__all__ = ["LanderSim", "simulate_landing"]


class LanderSim:
    """Model, data and absorbers of one lander; one :meth:`step` per physics tick.

    Args:
        design: the design vector.
        params: fixed parameters (default :class:`LanderParams`).
        terrain: ground (default flat).
        seed: places the rocks of ``terrain``; the simulation itself is deterministic.
    """

    def __init__(
        self,
        design: LanderDesign = DEFAULT_DESIGN,
        params: LanderParams | None = None,
        terrain: Terrain | None = None,
        seed: int = 0,
    ) -> None:
        self.params = params if params is not None else LanderParams()
        self.terrain = terrain if terrain is not None else Terrain()
        self.seed = int(seed)
        self.design = design
        self.info: LanderModelInfo = build_lander_model(design, self.params, self.terrain, seed)
        self.model = self.info.model
        self.data = mujoco.MjData(self.model)
        p = self.params
        self.absorber = HoneycombAbsorber(
            N_LEGS,
            f_y=design.f_y,
            max_stroke=p.max_stroke,
            elastic_stroke=p.elastic_stroke,
            densification_onset=p.densification_onset,
            densification_ratio=p.densification_ratio,
            damping=p.absorber_damping(design.f_y),
        )
        self._window = max(1, round(p.accel_window / p.timestep))
        self._capacity = math.ceil(p.max_time / p.timestep) + self._window + 2
        self.reset()

    # --- lifecycle -----------------------------------------------------------------------
    def reset(self, design: LanderDesign | None = None, *, seed: int | None = None) -> None:
        """Back to the touchdown state; optionally with another design or rock seed.

        A design that changes only ``f_y`` keeps the compiled model; a new ``beta`` or
        ``alpha2`` (or seed with rocks) rebuilds it.
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
        self.info.design = self.design
        self.absorber.set_properties(self.design.f_y, p.absorber_damping(self.design.f_y))
        self.absorber.reset()

        m, d = self.model, self.data
        mujoco.mj_resetData(m, d)
        d.qvel[0] = p.horizontal_speed
        d.qvel[2] = -p.touchdown_speed
        mujoco.mj_forward(m, d)

        self._chassis = self.info.chassis_body
        self._sq = self.info.slide_qpos
        self._sd = self.info.slide_dof
        self._n = 0
        self._vel = np.zeros((self._capacity, 3))
        self._tilt_cos = np.ones(self._capacity)
        self._vel[0] = d.qvel[0:3]
        slope = self.terrain.slope
        self._normal = np.array([math.sin(slope), 0.0, math.cos(slope)])
        self._tilt_cos[0] = self._cos_tilt()
        self._com0 = d.subtree_com[self._chassis].copy()
        self._ke0 = 0.5 * p.total_mass * float(d.qvel[0] ** 2 + d.qvel[2] ** 2)
        self._t_touchdown: float | None = None
        self._calm_since: float | None = None
        self.settled = False

    # --- stepping ----------------------------------------------------------------------------
    @property
    def time(self) -> float:
        return float(self.data.time)

    @property
    def stroke(self) -> np.ndarray:
        """Current stroke of the six absorbers [m] (compression positive)."""
        return self.data.qpos[self._sq].copy()

    def step(self) -> None:
        """One physics tick: absorber forces at the slide DOFs, then ``mj_step``."""
        d = self.data
        force = self.absorber.update(d.qpos[self._sq], d.qvel[self._sd])
        d.qfrc_applied[self._sd] = -force
        mujoco.mj_step(self.model, d)
        n = self._n + 1
        if n < self._capacity:
            self._vel[n] = d.qvel[0:3]
            self._tilt_cos[n] = self._cos_tilt()
            self._n = n
        if self._t_touchdown is None and d.ncon > 0:
            self._t_touchdown = float(d.time)

    def _cos_tilt(self) -> float:
        """Cosine of the angle between the chassis axis and the ground-plane normal."""
        r = self.data.xmat[self._chassis]
        nx, _, nz = self._normal
        return float(r[2] * nx + r[8] * nz)

    def _calm(self) -> bool:
        p = self.params
        q = self.data.qvel
        return (
            float(q[0] ** 2 + q[1] ** 2 + q[2] ** 2) < p.settle_speed**2
            and float(q[3] ** 2 + q[4] ** 2 + q[5] ** 2) < p.settle_angular_speed**2
        )

    def run(self) -> dict[str, Any]:
        """Step until settled (calm for ``settle_time`` after touchdown) or ``max_time``;
        return :meth:`metrics`."""
        p = self.params
        check_every = max(1, round(0.005 / p.timestep))
        n_max = self._capacity - self._window - 2
        while self._n < n_max:
            for _ in range(check_every):
                self.step()
            if self._t_touchdown is None:
                continue
            if self._calm():
                if self._calm_since is None:
                    self._calm_since = self.time
                elif self.time - self._calm_since >= p.settle_time:
                    self.settled = True
                    break
            else:
                self._calm_since = None
        return self.metrics()

    # --- metrics ------------------------------------------------------------------------------
    def chassis_acceleration(self) -> np.ndarray:
        """Filtered chassis CoM acceleration history (kinematic), shape (n, 3)."""
        w = self._window
        vel = self._vel[: self._n + 1]
        if len(vel) <= w:
            return np.zeros((0, 3))
        return (vel[w:] - vel[:-w]) / (w * self.params.timestep)

    def metrics(self) -> dict[str, Any]:
        """Touchdown metrics so far (see the module docstring)."""
        p = self.params
        d = self.data
        ab = self.absorber
        acc = self.chassis_acceleration()
        g_vec = np.array([0.0, 0.0, -p.gravity])
        a_max = float(np.max(np.linalg.norm(acc, axis=1))) if len(acc) else 0.0
        a_max_proper = float(np.max(np.linalg.norm(acc - g_vec, axis=1))) if len(acc) else 0.0
        tilt = np.arccos(np.clip(self._tilt_cos[: self._n + 1], -1.0, 1.0))
        e_abs = float(np.sum(ab.absorbed_energy))
        e_init = p.e_init
        a_ref = p.a_ref
        com_end = d.subtree_com[self._chassis]
        e_available = self._ke0 + p.total_mass * p.gravity * float(self._com0[2] - com_end[2])
        j = a_max / a_ref + (p.energy_weight * (e_abs / e_init - 1.0)) ** 2
        return {
            "J": float(j),
            "a_max": a_max,
            "a_max_proper": a_max_proper,
            "a_ref": a_ref,
            "E_abs": e_abs,
            "E_abs_legs": ab.absorbed_energy.copy(),
            "E_init": e_init,
            "E_available": float(e_available),
            "KE_0": self._ke0,
            "max_stroke": float(np.max(ab.max_stroke_reached)),
            "max_stroke_legs": ab.max_stroke_reached.copy(),
            "crush_stroke_legs": ab.crush_stroke.copy(),
            "bottomed_out": bool(np.any(ab.bottomed_out)),
            "max_tilt": float(np.max(tilt)),
            "final_tilt": float(tilt[-1]),
            "tipped_over": bool(np.max(tilt) > p.tip_angle),
            "settled": bool(self.settled),
            "t_touchdown": self._t_touchdown,
            "t_end": float(d.time),
            "n_steps": int(self._n),
            "touchdown_speed": p.touchdown_speed,
        }


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
