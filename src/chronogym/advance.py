"""The generic advance operator: one physics tick over heterogeneous advanceables.

Advanceables do not share a method name, so each object is matched once, when
the plan is compiled, against these shapes (first match wins):

====  ==============================  =========================================
 1    ``Synced(obj, args_fn)``        ``obj.Synchronize(t, *args_fn(t))``; ``obj.Advance(dt)``
 2    ``(MjModel, MjData)`` pair      ``mujoco.mj_step(model, data)``
 3    has ``DoStepDynamics``          ``obj.DoStepDynamics(dt)`` (ChSystem; Chrono 10
                                      ``ChFsiSystem``)
 4    has ``DoStepDynamics_FSI``      ``obj.DoStepDynamics_FSI()`` (Chrono 8/9
                                      ``ChSystemFsi``; its step size must be ``dt``)
 5    has ``Synchronize``+``Advance`` ``obj.Synchronize(t)``; ``obj.Advance(dt)``
      (Chrono drivers, terrains)
 6    has ``Advance``                 ``obj.Advance(dt)``
 7    has ``Update``                  ``obj.Update()`` (Viper robot, sensor manager)
 8    callable                        ``fn(dt)``
====  ==============================  =========================================

A tick runs in two phases, as Chrono's own simulation loops do: first every
``Synchronize`` in list order (all modules agree on time ``t`` and exchange
inputs), then every step call (``mj_step``, ``DoStepDynamics``, ``Advance``,
``Update``, callables) in list order. Put objects in the order their step
calls must happen, e.g. ``[viper, system, sensor_manager]``.

Who steps a Chrono system is easy to get wrong: a vehicle built on an existing
system (``vehicle(system)``) does not step it, one that created its own does (in
``Advance``); an FSI system steps its multibody system itself; a Viper's
``Update`` steps nothing. So the first tick checks every Chrono system it can
reach -- listed ones (``GetChTime``) and those behind ``GetSystem()`` (vehicles,
robots) or ``GetMultibodySystem()`` (FSI) -- and raises if one did not advance by
exactly ``dt``: 0 means nothing steps it (list it), 2 ``dt`` means it is stepped
twice (drop it from the list).

Nothing here imports PyChrono: Chrono objects are matched by duck typing.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import dataclass
from typing import Any

from chronogym.validation import check_positive


@dataclass(frozen=True)
class Synced:
    """Wrap an object whose ``Synchronize`` needs more than the time.

    ``args_fn(t)`` returns the extra arguments, e.g. for a Chrono vehicle
    ``Synced(vehicle, lambda t: (driver.GetInputs(), terrain))``.
    """

    obj: Any
    args_fn: Callable[[float], tuple[Any, ...]]


def _is_mujoco_pair(obj: Any) -> bool:
    return (
        isinstance(obj, (tuple, list))
        and len(obj) == 2
        and type(obj[0]).__name__ == "MjModel"
        and type(obj[1]).__name__ == "MjData"
    )


class Advancer:
    """A compiled advance plan; call it once per physics tick with the tick's start time."""

    def __init__(self, advanceables: Sequence[Any], dt: float) -> None:
        if isinstance(advanceables, (str, bytes)) or not isinstance(advanceables, Sequence):
            raise TypeError(f"advanceables={advanceables!r}: expected a list of objects to step")
        self.dt = check_positive("dt", dt, "a finite float > 0")
        self._sync: list[Callable[[float], None]] = []
        self._step: list[Callable[[], None]] = []
        self.plan: list[str] = []
        self._mujoco_only: tuple[Any, Any] | None = None
        for index, obj in enumerate(advanceables):
            self._add(index, obj)
        self._clocks: list[tuple[str, Callable[[], float]]] | None = chrono_clocks(advanceables)
        if len(advanceables) == 1 and _is_mujoco_pair(advanceables[0]):
            self._mujoco_only = tuple(advanceables[0])

    def _add(self, index: int, obj: Any) -> None:
        dt = self.dt
        name = type(obj).__name__
        if isinstance(obj, Synced):
            sync, extra = obj.obj.Synchronize, obj.args_fn
            self._sync.append(lambda t: sync(t, *extra(t)))
            advance = obj.obj.Advance
            self._step.append(lambda: advance(dt))
            self.plan.append(f"{index}: {type(obj.obj).__name__}.Synchronize(t, *args) + Advance")
        elif _is_mujoco_pair(obj):
            import mujoco

            model, data = obj
            if abs(model.opt.timestep - dt) > 1e-12 * max(1.0, dt):
                raise ValueError(
                    f"advanceable {index}: MuJoCo model timestep {model.opt.timestep!r} "
                    f"differs from dt={dt!r}; expected equal values (set model.opt.timestep)"
                )
            step = mujoco.mj_step
            self._step.append(lambda: step(model, data))
            self.plan.append(f"{index}: mujoco.mj_step")
        elif hasattr(obj, "DoStepDynamics"):
            do_step = obj.DoStepDynamics
            if hasattr(obj, "Synchronize"):
                self._sync.append(obj.Synchronize)
            self._step.append(lambda: do_step(dt))
            self.plan.append(f"{index}: {name}.DoStepDynamics")
        elif hasattr(obj, "DoStepDynamics_FSI"):
            step_size = getattr(obj, "GetStepSize", None)
            if step_size is not None and abs(step_size() - dt) > 1e-12 * max(1.0, dt):
                raise ValueError(
                    f"advanceable {index}: {name} step size {step_size()!r} differs from "
                    f"dt={dt!r}; expected equal values (call its SetStepSize(dt))"
                )
            self._step.append(obj.DoStepDynamics_FSI)
            self.plan.append(f"{index}: {name}.DoStepDynamics_FSI")
        elif hasattr(obj, "Synchronize") and hasattr(obj, "Advance"):
            self._sync.append(obj.Synchronize)
            advance = obj.Advance
            self._step.append(lambda: advance(dt))
            self.plan.append(f"{index}: {name}.Synchronize(t) + Advance")
        elif hasattr(obj, "Advance"):
            advance = obj.Advance
            self._step.append(lambda: advance(dt))
            self.plan.append(f"{index}: {name}.Advance")
        elif hasattr(obj, "Update"):
            self._step.append(obj.Update)
            self.plan.append(f"{index}: {name}.Update")
        elif callable(obj):
            fn = obj
            self._step.append(lambda: fn(dt))
            self.plan.append(f"{index}: {getattr(obj, '__name__', name)}(dt)")
        else:
            raise TypeError(
                f"advanceable {index} of type {name} has no way to be stepped; expected a "
                "(MjModel, MjData) pair, an object with DoStepDynamics, Synchronize+Advance, "
                "Advance or Update, a chronogym.Synced wrapper, or a callable fn(dt)"
            )

    def __call__(self, time: float) -> None:
        if self._clocks:
            self._first_tick(time, self._clocks)
            return
        for sync in self._sync:
            sync(time)
        for step in self._step:
            step()

    def _first_tick(self, time: float, clocks: list[tuple[str, Callable[[], float]]]) -> None:
        """One tick, then raise unless every reachable Chrono system advanced by ``dt``."""
        self._clocks = None
        before = [clock() for _, clock in clocks]
        self(time)
        for (name, clock), start in zip(clocks, before, strict=True):
            advanced = clock() - start
            if abs(advanced - self.dt) <= 1e-9 * max(1.0, abs(start)):
                continue
            times = advanced / self.dt
            if abs(times) < 0.5:
                hint = (
                    "nothing steps it: a vehicle built on an existing system, or a robot's "
                    "Update, does not step that system; add the system to the advanceables"
                )
            else:
                hint = (
                    f"it was stepped {times:.3g} times: a vehicle that created its own "
                    "system, or an FSI system, steps it itself; remove the system from the "
                    "advanceables"
                )
            raise RuntimeError(
                f"advanceables: {name} advanced its time by {advanced!r} s in one tick of "
                f"dt={self.dt!r}; expected dt ({hint}). Plan: {self.plan}"
            )

    def run(self, time: float, ticks: int) -> None:
        """``ticks`` consecutive ticks from ``time``.

        A lone MuJoCo pair is stepped with one ``mj_step(..., nstep=ticks)`` call,
        which gives the same numbers as ``ticks`` separate calls, minus Python overhead.
        """
        if self._mujoco_only is not None:
            import mujoco

            mujoco.mj_step(*self._mujoco_only, nstep=ticks)
            return
        dt = self.dt
        for i in range(ticks):
            self(time + i * dt)


def chrono_clocks(advanceables: Sequence[Any]) -> list[tuple[str, Callable[[], float]]]:
    """(name, time getter) of each distinct Chrono system the advanceables reach.

    A system is anything with ``GetChTime``: a listed one, or one behind a listed
    object's ``GetSystem()`` (vehicles, robots) or ``GetMultibodySystem()`` (FSI).
    """
    clocks: dict[int, tuple[str, Callable[[], float]]] = {}
    for index, item in enumerate(advanceables):
        obj = item.obj if isinstance(item, Synced) else item
        found = [(f"advanceable {index} ({type(obj).__name__})", obj)]
        for getter in ("GetSystem", "GetMultibodySystem"):
            if callable(getattr(obj, getter, None)):
                try:
                    system = getattr(obj, getter)()
                except Exception:  # a getter that needs arguments is not ours
                    continue
                found.append((f"the system of advanceable {index} ({getter}())", system))
        for name, system in found:
            if callable(getattr(system, "GetChTime", None)):
                clocks.setdefault(_identity(system), (name, system.GetChTime))
    return list(clocks.values())


def _identity(obj: Any) -> int:
    """The C++ object behind a SWIG proxy (two proxies may wrap one system), else ``id``."""
    this = getattr(obj, "this", None)
    try:
        return int(this) if this is not None else id(obj)
    except (TypeError, ValueError):
        return id(obj)


def advance_all(advanceables: Sequence[Any], dt: float, time: float = 0.0) -> None:
    """Advance every object by one tick of ``dt`` starting at ``time``.

    Convenient for scripts; a loop should build one :class:`Advancer` and call it.
    """
    Advancer(advanceables, dt)(time)
