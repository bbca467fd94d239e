"""Crushable-honeycomb shock absorber, vectorized over the lander's legs.

Each primary strut holds an aluminium-honeycomb cartridge that the piston (lower
primary strut) crushes on touchdown.  Honeycomb is a one-shot absorber: it deforms
plastically at a nearly constant force and does not spring back.  The law used here,
per leg, in terms of the strut stroke ``s`` (compression positive, 0 at touchdown
length) and a permanent crushed length ``s_c`` (0 before the first impact):

* crush envelope (the force needed to crush further)::

      F_env(s) = f_y                                          s <= s_d
      F_env(s) = f_y * (1 + (r - 1) * ((s - s_d) / (s_max - s_d))**2)   s > s_d

  a plateau at the yield force ``f_y`` followed by a steep densification rise that
  reaches ``r * f_y`` at the maximum stroke ``s_max`` (``s_d = onset * s_max``) and
  keeps rising past it;
* elastic line above the crushed length, reaching the envelope after a fixed elastic
  stroke ``d_e`` (``elastic_stroke``)::

      F_el = F_env(s_c + d_e) * (s - s_c) / d_e      for s_c < s <= s_c + d_e
      F_el = 0                                       for s <= s_c (the piston has backed
                                                     off the crushed block; honeycomb
                                                     cannot pull)

  so the elastic stiffness is ``k = F_env(s_c + d_e) / d_e``: ``f_y / d_e`` on the
  plateau and proportionally stiffer as the honeycomb densifies (compacted honeycomb
  tends to solid metal), which keeps the recoverable energy at most ``F d_e / 2``;
* return mapping: if ``s - s_c > d_e`` the honeycomb crushes: ``s_c`` grows to
  ``s - d_e`` and the force is ``F_env(s)``.

Hence a first load rises elastically (``f_y / d_e``) to ``f_y``, crushes along the
plateau, stiffens in densification; unloading drops along the steep elastic line to
zero at ``s_c`` (only the small elastic energy ``F d_e / 2`` comes back, the crushed
length is permanent); reloading is elastic again until the force meets the envelope at
the new crushed length, i.e. where the previous load stopped.

A viscous term ``c * ds/dt`` is added while the honeycomb is loaded but *not* crushing
(on the elastic line): it damps the ringing of the landed vehicle on the stiff elastic
line.  The total force is capped by the yield force ``F_env(s_c + d_e)``, so the crush
plateau stays at exactly ``f_y`` whatever the stroke rate.

``absorbed_energy`` is the work dissipated by the absorber, per leg: the plastic
dissipation plus the work of the viscous term.  The plastic dissipation is the work put
in minus the growth of the stored elastic energy ``E_el = k(s_c) (s - s_c)^2 / 2``.
Because the elastic stiffness ``k(s_c) = F_env(s_c + d_e) / d_e`` rises with the crush,
the stored energy on the crush branch (``F_env d_e / 2``) grows in densification, and
that growth is not dissipated::

    dE_diss = (F_env(s_c + d_e) - F_env'(s_c + d_e) d_e / 2) ds_c

integrated exactly per crush increment as the trapezoid of ``F_env`` times ``ds_c``
minus ``d_e / 2`` times the rise of ``F_env``.  A plateau crush gives exactly ``f_y *
crushed length`` at any step size; in densification the correction is at most
``(F_env(s) - f_y) d_e / 2`` per leg (12 J for a 1 kN cartridge crushed onto its stop),
and without it the account would exceed the work put in by that much -- energy that
comes back out on unloading.

The class holds per-leg NumPy state and works on arrays of strokes, so one call
serves all six legs.  In the simulation loop call :meth:`update` once per physics tick
with the current strokes and stroke rates; it commits the state and returns the
forces to apply during the tick.  :meth:`force` is the same law without side effects.
"""

from __future__ import annotations

import numpy as np

__all__ = ["HoneycombAbsorber"]


class HoneycombAbsorber:
    """Elastic-plastic honeycomb crush law with densification and no spring-back.

    Args:
        n: number of absorbers (legs).
        f_y: plateau (yield) crush force [N], scalar or one per leg.
        max_stroke: stroke at full densification ``s_max`` [m].
        elastic_stroke: stroke ``d_e`` of the elastic rise from 0 to the yield force [m];
            the elastic stiffness is ``f_y / d_e`` on the plateau, ``F_env(s_c + d_e) /
            d_e`` in general.
        densification_onset: ``s_d / s_max``, in (0, 1).
        densification_ratio: ``F_env(s_max) / f_y`` (> 1).
        damping: viscous coefficient of the elastic line [N s/m], scalar or per leg.
    """

    def __init__(
        self,
        n: int,
        f_y: float | np.ndarray,
        max_stroke: float,
        elastic_stroke: float = 0.003,
        densification_onset: float = 0.8,
        densification_ratio: float = 5.0,
        damping: float | np.ndarray = 0.0,
    ) -> None:
        if n < 1:
            raise ValueError(f"n={n!r} must be >= 1")
        if max_stroke <= 0 or elastic_stroke <= 0:
            raise ValueError(
                f"max_stroke={max_stroke!r} and elastic_stroke={elastic_stroke!r} must be > 0"
            )
        if not 0.0 < densification_onset < 1.0:
            raise ValueError(f"densification_onset={densification_onset!r} must be in (0, 1)")
        if densification_ratio <= 1.0:
            raise ValueError(f"densification_ratio={densification_ratio!r} must be > 1")
        self.n = int(n)
        self.max_stroke = float(max_stroke)
        self.elastic_stroke = float(elastic_stroke)
        self.densification_onset = float(densification_onset)
        self.densification_ratio = float(densification_ratio)
        self._s_d = self.densification_onset * self.max_stroke
        self._span = self.max_stroke - self._s_d
        self.f_y = np.zeros(self.n)
        self.k_e = np.zeros(self.n)
        self.damping = np.zeros(self.n)
        self.set_properties(f_y, damping)
        self.reset()

    # --- configuration ------------------------------------------------------------
    def set_properties(
        self, f_y: float | np.ndarray, damping: float | np.ndarray | None = None
    ) -> None:
        """Change the yield force (and the elastic-line damping) of every leg."""
        f_y_arr = np.broadcast_to(np.asarray(f_y, dtype=np.float64), (self.n,)).copy()
        if not np.all(np.isfinite(f_y_arr)) or np.any(f_y_arr <= 0):
            raise ValueError(f"f_y={f_y!r} must be finite and > 0")
        self.f_y = f_y_arr
        self.k_e = f_y_arr / self.elastic_stroke  # elastic stiffness on the plateau
        if damping is not None:
            d = np.broadcast_to(np.asarray(damping, dtype=np.float64), (self.n,)).copy()
            if not np.all(np.isfinite(d)) or np.any(d < 0):
                raise ValueError(f"damping={damping!r} must be finite and >= 0")
            self.damping = d

    def reset(self) -> None:
        """Fresh, uncrushed honeycomb in every leg."""
        n = self.n
        #: permanent crushed length ``s_c`` per leg [m]
        self.crush_stroke = np.zeros(n)
        #: energy dissipated per leg [J]
        self.absorbed_energy = np.zeros(n)
        #: plastic part of ``absorbed_energy`` [J]
        self.plastic_energy = np.zeros(n)
        #: largest stroke seen per leg [m]
        self.max_stroke_reached = np.zeros(n)
        #: force returned by the last :meth:`update` [N]
        self.last_force = np.zeros(n)
        #: elastic (spring) part of ``last_force``, without the viscous term [N]
        self.last_elastic_force = np.zeros(n)
        self._last_stroke = np.zeros(n)  # the strut starts at zero stroke
        self._last_damping_force = np.zeros(n)

    # --- the law --------------------------------------------------------------------
    def envelope(self, stroke: np.ndarray | float) -> np.ndarray:
        """Crush force ``F_env(s)`` (plateau then densification) per leg [N]."""
        x = np.maximum(np.asarray(stroke, dtype=np.float64) - self._s_d, 0.0)
        x *= 1.0 / self._span
        return self.f_y * (1.0 + (self.densification_ratio - 1.0) * x * x)

    def _evaluate(
        self, stroke: np.ndarray, stroke_rate: np.ndarray
    ) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """(force, new crush stroke, yield force, elastic part) without touching state.

        The yield force ``F_env(s_c + d_e)`` is the force at which the honeycomb crushes
        further from its (new) state; on the crush branch it is ``F_env(s)``.
        """
        d_e = self.elastic_stroke
        crush = np.maximum(self.crush_stroke, stroke - d_e)
        stretch = stroke - crush  # > 0: piston bears on the honeycomb
        yield_force = self.envelope(crush + d_e)
        elastic = yield_force * (np.maximum(stretch, 0.0) / d_e)
        # viscous term only on the elastic line: in contact and not crushing
        on_line = (stretch > 0.0) & (crush <= self.crush_stroke)
        force = elastic + on_line * (self.damping * stroke_rate)
        np.maximum(force, 0.0, out=force)
        np.minimum(force, yield_force, out=force)
        return force, crush, yield_force, elastic

    def _as_legs(self, value: np.ndarray | float) -> np.ndarray:
        arr = np.asarray(value, dtype=np.float64)
        if arr.shape != (self.n,):
            arr = np.broadcast_to(arr, (self.n,))
        return arr

    def force(
        self, stroke: np.ndarray | float, stroke_rate: np.ndarray | float = 0.0
    ) -> np.ndarray:
        """Absorber force per leg [N] (>= 0, resisting compression) for the given
        strokes [m] and stroke rates [m/s], given the current crush state.  Pure: the
        state is not changed (see :meth:`update`)."""
        return self._evaluate(self._as_legs(stroke), self._as_legs(stroke_rate))[0]

    def update(
        self, stroke: np.ndarray | float, stroke_rate: np.ndarray | float = 0.0
    ) -> np.ndarray:
        """Advance the state to the given strokes and return the forces to apply.

        Books the dissipation since the previous call (viscous work of the force applied
        over the last tick; plastic work of the crush increment), moves the permanent
        crushed length forward where the honeycomb yields, and returns the new forces.
        """
        s = np.array(self._as_legs(stroke))  # own copy: callers may pass live views
        force, crush, env, elastic = self._evaluate(s, self._as_legs(stroke_rate))

        d_crush = crush - self.crush_stroke
        last = self._last_stroke
        dissipated = self._last_damping_force * (s - last)
        if d_crush.any():
            # trapezoid along the envelope over the crush increment, less the growth of
            # the elastic energy stored at full stretch d_e (see the module docstring);
            # on the plateau both ends are f_y: exactly f_y * d_crush at any step size
            env_prev = self.envelope(self.crush_stroke + self.elastic_stroke)
            plastic = 0.5 * (env + env_prev) * d_crush - 0.5 * self.elastic_stroke * (
                env - env_prev
            )
            self.plastic_energy += plastic
            dissipated += plastic
        self.absorbed_energy += dissipated

        self.crush_stroke = crush
        np.maximum(self.max_stroke_reached, s, out=self.max_stroke_reached)
        self._last_stroke = s
        self._last_damping_force = force - elastic
        self.last_force = force
        self.last_elastic_force = elastic
        return force

    # --- derived ----------------------------------------------------------------------
    @property
    def elastic_energy(self) -> np.ndarray:
        """Recoverable energy stored on the elastic line at the last update [J]:
        ``F_el^2 / (2 k)`` of the spring part only (the viscous part of ``last_force``
        stores nothing; at touchdown it can saturate the force at the yield force while
        the spring is still nearly relaxed)."""
        stiffness = self.envelope(self.crush_stroke + self.elastic_stroke) / self.elastic_stroke
        return 0.5 * self.last_elastic_force**2 / stiffness

    @property
    def bottomed_out(self) -> np.ndarray:
        """Per leg: did the stroke reach the maximum (full densification)?"""
        return self.max_stroke_reached >= self.max_stroke
