"""The struts of the Chrono lander: honeycomb force and slide stops on one ``ChLinkTSDA``.

Each leg has one ``ChLinkTSDA`` from the hinge ``A`` on the upper strut to the pad joint
``P`` on the piston: its length is ``primary_length - stroke``, and a positive force
pushes the two apart (opens the strut).  Its Python ``ForceFunctor`` returns
:meth:`StrutForces.evaluate`: the sum of

* the **honeycomb force**, committed once per physics tick by the simulation
  (:meth:`HoneycombAbsorber.update` at the tick's start state) and held over the tick --
  explicit, as in MuJoCo, where it goes to ``qfrc_applied``;
* the **slide stops** at 0 and ``max_stroke + stop_margin`` (MuJoCo's slide range).
  MuJoCo enforces the range with a soft limit constraint: the stroke beyond a stop relaxes
  like a critically damped oscillator of time constant ``constraint_timeconst`` (4 ms),
  whatever the masses.  Here a linear spring-damper does, ``k = m w^2``, ``c = 2 m w``
  with ``w = 1 / constraint_timeconst`` and ``m`` one leg's share of the lander mass,
  switched on at a tick's start when the stroke is beyond a stop and the spring-damper
  would push back (the bottom stop never pulls the strut shut, the extension stop never
  pushes it open).  As an explicit force it would be unstable on the 6 kg piston, so
  while a stop is engaged the link is declared stiff and Chrono adds its
  finite-difference Jacobian to the implicit step.  Chrono's linearized implicit Euler
  then keeps the force at the tick's start on the right-hand side as well, which counts
  a damper twice; measuring the damper from the tick's start velocity,
  ``-c (dL/dt - dL/dt_0)``, makes the step exactly backward Euler for the spring-damper
  (the applied force is ``k`` and ``c`` at the end state, :meth:`StrutForces.stop_force`).
  Chrono's own unilateral joint limits would need its complementarity (NSC) solvers,
  which would give up the exact joints of the direct solver.

Chrono calls the functors from ``Update``: once at the end of a step, once more at the
start of the next (the simulation's ``ForceUpdate``), and 24 more times per update for
the Jacobian of a stiff link; the functor is a pure function of the link state and the
tick's committed values, so the number of calls changes nothing.
"""

from __future__ import annotations

from typing import Any

import numpy as np

from chronogym.tasks.lander.design import LanderParams
from chronogym.tasks.lander.geometry import N_LEGS

__all__ = ["StrutForces", "stop_coefficients", "stop_engagement"]

FREE, BOTTOM, EXTENSION = 0, 1, -1


def stop_coefficients(
    params: LanderParams, time_constant: float | None = None
) -> tuple[float, float]:
    """(stiffness [N/m], damping [N s/m]) of a slide stop (see the module docstring)."""
    omega = 1.0 / (time_constant or params.constraint_timeconst)
    share = params.total_mass / N_LEGS
    return share * omega**2, 2.0 * share * omega


#: Depth beyond a stop below which it stays free [m]: the joints hold the unloaded struts
#: at zero stroke only to round-off (1e-12 m), and a stop engaged for a whole tick by that
#: noise would resist the first compression at touchdown.
ENGAGE_DEPTH = 1e-7


def stop_engagement(
    stroke: np.ndarray, rate: np.ndarray, upper: float, stiffness: float, damping: float
) -> np.ndarray:
    """Per leg: ``BOTTOM`` (1) beyond ``upper`` and pushing back, ``EXTENSION`` (-1) below 0
    and pulling back, else ``FREE`` (0) (see :data:`ENGAGE_DEPTH`)."""
    state = np.zeros(len(stroke), dtype=np.int8)
    bottom = stroke - upper
    state[(bottom > ENGAGE_DEPTH) & (stiffness * bottom + damping * rate > 0.0)] = BOTTOM
    state[(stroke < -ENGAGE_DEPTH) & (stiffness * stroke + damping * rate < 0.0)] = EXTENSION
    return state


_FUNCTOR_CLASS: dict[str, type] = {}


def _functor(chrono: Any, forces: StrutForces, leg: int) -> Any:
    """A ``ForceFunctor`` for leg ``leg``: ``forces.evaluate(leg, length, vel)``."""
    cls = _FUNCTOR_CLASS.get("strut")
    if cls is None:

        class StrutFunctor(chrono.ForceFunctor):
            """TSDA force of one leg: committed honeycomb force plus the engaged stop."""

            def __init__(self, forces: StrutForces, leg: int) -> None:
                super().__init__()
                self.forces, self.leg, self.calls = forces, leg, 0

            def evaluate(self, time, rest_length, length, vel, link) -> float:
                self.calls += 1
                return self.forces.evaluate(self.leg, length, vel)

        cls = _FUNCTOR_CLASS["strut"] = StrutFunctor
    return cls(forces, leg)


class StrutForces:
    """What the six struts' force functors return, set once per tick.

    Args:
        chrono: the ``pychrono`` module.
        links: one ``ChLinkTSDA`` per leg (``A`` on the upper strut, ``P`` on the piston).
        strut_length: link length at zero stroke [m].
        upper: bottom stop stroke ``max_stroke + stop_margin`` [m].
        stiffness, damping: of an engaged stop (:func:`stop_coefficients`).
    """

    def __init__(
        self,
        chrono: Any,
        links: list[Any],
        strut_length: float,
        upper: float,
        stiffness: float,
        damping: float,
    ) -> None:
        self.links = links
        self.strut_length, self.upper = float(strut_length), float(upper)
        self.stiffness, self.damping = float(stiffness), float(damping)
        n = len(links)
        self.honeycomb = np.zeros(n)  # committed honeycomb force of the tick [N]
        self.state = np.zeros(n, dtype=np.int8)  # stop engaged per leg (FREE, BOTTOM, ...)
        self._stiff = np.zeros(n, dtype=bool)  # links declared stiff
        self._stop_at = np.zeros(n)  # stroke of the engaged stop [m]
        self._length_rate0 = np.zeros(n)  # dL/dt at the tick's start [m/s]
        self.functors = [_functor(chrono, self, i) for i in range(n)]
        for link, functor in zip(links, self.functors, strict=True):
            link.SetSpringCoefficient(0.0)
            link.SetDampingCoefficient(0.0)
            link.RegisterForceFunctor(functor)

    def evaluate(self, leg: int, length: float, length_rate: float) -> float:
        """The link force of ``leg`` at this link state [N] (positive: opens the strut)."""
        force = float(self.honeycomb[leg])
        if self.state[leg]:
            stroke = self.strut_length - length
            rate = self._length_rate0[leg] - length_rate  # stroke rate past the tick start
            force += self.stiffness * (stroke - self._stop_at[leg]) + self.damping * rate
        return force

    def set_tick(self, honeycomb: np.ndarray, stroke: np.ndarray, rate: np.ndarray) -> None:
        """Commit the tick: the honeycomb force, and which stop is engaged (from the
        tick's start stroke and stroke rate); an engaged link is declared stiff."""
        self.honeycomb[:] = honeycomb
        state = stop_engagement(stroke, rate, self.upper, self.stiffness, self.damping)
        # Chrono keeps adding a link's last Jacobian once it has one, stiff or not: a link
        # stays stiff one tick after its stop lets go, so that its Jacobian is recomputed
        # (zero: the honeycomb force is constant) before it is frozen
        stiff = (state != FREE) | (self.state != FREE)
        for leg in np.flatnonzero(stiff != self._stiff).tolist():
            self.links[leg].IsStiff(bool(stiff[leg]))
        self._stiff = stiff
        self.state = state
        self._stop_at = np.where(state == BOTTOM, self.upper, 0.0)
        self._length_rate0 = -np.asarray(rate, dtype=np.float64)

    def stop_force(self, stroke: np.ndarray, rate: np.ndarray) -> np.ndarray:
        """The stops' force over the tick just taken [N], given its end stroke and rate:
        the implicit step applies the engaged spring-damper at the end state."""
        if not self.state.any():
            return np.zeros(len(self.links))
        force = self.stiffness * (stroke - self._stop_at) + self.damping * rate
        return np.where(self.state != FREE, force, 0.0)
