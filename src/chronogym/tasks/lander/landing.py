"""The engine-independent half of a touchdown simulation: history, settling, metrics.

:class:`Landing` is the base class of the MuJoCo lander (:class:`~.mujoco.sim.LanderSim`)
and the Chrono lander (:class:`~.chrono.sim.ChronoLanderSim`): each engine's class steps its
own physics and hands the chassis state to :meth:`Landing._record` once per tick; this
class keeps the history, decides when the lander has settled (:meth:`Landing.run`) and
computes the metrics both engines share -- ``a_max`` (the 20 ms box filter, see
:mod:`~.mujoco.sim`), ``J``, the absorbers' energy and strokes, tilt -- with the same code,
so a cross-engine comparison compares physics, not bookkeeping.  Pure NumPy.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from chronogym.tasks.lander.absorber import HoneycombAbsorber
from chronogym.tasks.lander.design import LanderDesign, LanderParams
from chronogym.tasks.lander.geometry import N_LEGS

__all__ = ["Landing", "filtered_acceleration", "objective"]


def objective(a_max: float, e_abs: float, params: LanderParams) -> float:
    """``J = a_max / a_ref + (alpha (E_abs / E_init - 1))^2`` (see :mod:`~.mujoco.sim`)."""
    return a_max / params.a_ref + (params.energy_weight * (e_abs / params.e_init - 1.0)) ** 2


def filtered_acceleration(vel: np.ndarray, window: int, dt: float) -> np.ndarray:
    """Box-filtered acceleration ``(v(t + T) - v(t)) / T`` of a velocity history sampled
    every ``dt``, ``T = window dt``; shape ``(len(vel) - window, 3)`` (empty if shorter)."""
    if len(vel) <= window:
        return np.zeros((0, 3))
    return (vel[window:] - vel[:-window]) / (window * dt)


class Landing:
    """History, settling and shared metrics of one touchdown (base class).

    Subclasses set ``params`` and ``design``, call :meth:`_init_absorber` and
    :meth:`_init_history` once (with their time step), :meth:`_reset_absorber` and
    :meth:`_start_history` in ``reset`` and :meth:`_record` after each tick, set
    ``_t_touchdown`` at the first contact, and implement :meth:`step`, :attr:`time`,
    :meth:`_chassis_velocity` and :meth:`metrics` (starting from :meth:`_landing_metrics`).
    """

    params: LanderParams
    design: LanderDesign
    absorber: HoneycombAbsorber

    # --- to implement -------------------------------------------------------------------
    @property
    def time(self) -> float:
        """Simulated time [s]."""
        raise NotImplementedError

    def step(self) -> None:
        """One physics tick."""
        raise NotImplementedError

    def _chassis_velocity(self) -> tuple[np.ndarray, np.ndarray]:
        """(linear velocity of the chassis CoM [m/s], angular velocity [rad/s]), any frame."""
        raise NotImplementedError

    def metrics(self) -> dict[str, Any]:
        """Touchdown metrics so far."""
        raise NotImplementedError

    # --- absorbers ------------------------------------------------------------------------
    def _init_absorber(self) -> None:
        """The six honeycomb cartridges of ``design`` (the law's shape from ``params``)."""
        p, f_y = self.params, self.design.f_y
        self.absorber = HoneycombAbsorber(
            N_LEGS,
            f_y=f_y,
            max_stroke=p.max_stroke,
            elastic_stroke=p.elastic_stroke,
            densification_onset=p.densification_onset,
            densification_ratio=p.densification_ratio,
            damping=p.absorber_damping(f_y),
        )

    def _reset_absorber(self) -> None:
        """Fresh honeycomb with the current design's yield force."""
        f_y = self.design.f_y
        self.absorber.set_properties(f_y, self.params.absorber_damping(f_y))
        self.absorber.reset()

    # --- history --------------------------------------------------------------------------
    def _init_history(self, timestep: float) -> None:
        """Size the history for ``params.max_time`` at ``timestep``."""
        p = self.params
        self._dt = timestep
        self._window = max(1, round(p.accel_window / timestep))
        self._capacity = math.ceil(p.max_time / timestep) + self._window + 2

    def _start_history(self, velocity: np.ndarray, cos_tilt: float) -> None:
        """Empty the history; the touchdown state has chassis velocity ``velocity``."""
        self._n = 0
        self._vel = np.zeros((self._capacity, 3))
        self._tilt_cos = np.ones(self._capacity)
        self._vel[0] = velocity
        self._tilt_cos[0] = cos_tilt
        self._ke0 = 0.5 * self.params.total_mass * float(velocity[0] ** 2 + velocity[2] ** 2)
        self._t_touchdown: float | None = None
        self._calm_since: float | None = None
        self.settled = False

    def _record(self, velocity: np.ndarray, cos_tilt: float) -> None:
        """Add the chassis CoM velocity and the cosine of its tilt after a tick."""
        n = self._n + 1
        if n < self._capacity:
            self._vel[n] = velocity
            self._tilt_cos[n] = cos_tilt
            self._n = n

    def _calm(self) -> bool:
        p = self.params
        v, w = self._chassis_velocity()
        return (
            float(v[0] ** 2 + v[1] ** 2 + v[2] ** 2) < p.settle_speed**2
            and float(w[0] ** 2 + w[1] ** 2 + w[2] ** 2) < p.settle_angular_speed**2
        )

    def run(self) -> dict[str, Any]:
        """Step until settled (calm for ``settle_time`` after touchdown) or ``max_time``;
        return :meth:`metrics`."""
        p = self.params
        check_every = max(1, round(0.005 / self._dt))
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

    # --- metrics --------------------------------------------------------------------------
    def chassis_acceleration(self) -> np.ndarray:
        """Filtered chassis CoM acceleration history (kinematic), shape (n, 3)."""
        return filtered_acceleration(self._vel[: self._n + 1], self._window, self._dt)

    def _landing_metrics(self) -> dict[str, Any]:
        """The metrics every engine computes the same way (see :mod:`~.mujoco.sim`)."""
        p = self.params
        ab = self.absorber
        acc = self.chassis_acceleration()
        g_vec = np.array([0.0, 0.0, -p.gravity])
        a_max = float(np.max(np.linalg.norm(acc, axis=1))) if len(acc) else 0.0
        a_max_proper = float(np.max(np.linalg.norm(acc - g_vec, axis=1))) if len(acc) else 0.0
        tilt = np.arccos(np.clip(self._tilt_cos[: self._n + 1], -1.0, 1.0))
        e_abs = float(np.sum(ab.absorbed_energy))
        return {
            "J": float(objective(a_max, e_abs, p)),
            "a_max": a_max,
            "a_max_proper": a_max_proper,
            "a_ref": p.a_ref,
            "E_abs": e_abs,
            "E_abs_legs": ab.absorbed_energy.copy(),
            "E_init": p.e_init,
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
            "t_end": float(self.time),
            "n_steps": int(self._n),
            "touchdown_speed": p.touchdown_speed,
        }
