"""advance_all: dispatch on each advanceable shape, in the documented order."""

from __future__ import annotations

import mujoco
import pytest

from chronogym import Advancer, Synced, advance_all
from chronogym.tasks.cartpole import XML_PATH


class System:
    """Shaped like a Chrono ChSystem: DoStepDynamics(dt)."""

    def __init__(self, log):
        self.log = log

    def DoStepDynamics(self, dt):
        self.log.append(("system.DoStepDynamics", dt))


class Terrain:
    """Shaped like a Chrono terrain or driver: Synchronize(t) + Advance(dt)."""

    def __init__(self, log, name="terrain"):
        self.log, self.name = log, name

    def Synchronize(self, t):
        self.log.append((f"{self.name}.Synchronize", t))

    def Advance(self, dt):
        self.log.append((f"{self.name}.Advance", dt))


class Vehicle:
    """Shaped like a Chrono vehicle: Synchronize(t, inputs, terrain) + Advance(dt)."""

    def __init__(self, log):
        self.log = log

    def Synchronize(self, t, inputs, terrain):
        self.log.append(("vehicle.Synchronize", t, inputs, terrain))

    def Advance(self, dt):
        self.log.append(("vehicle.Advance", dt))


class Sensors:
    """Shaped like a Chrono sensor manager or Viper robot: Update()."""

    def __init__(self, log):
        self.log = log

    def Update(self):
        self.log.append(("sensors.Update",))


def test_dispatch_order_over_every_shape():
    log: list = []
    model = mujoco.MjModel.from_xml_path(str(XML_PATH))
    data = mujoco.MjData(model)
    dt = model.opt.timestep
    objects = [
        Sensors(log),
        Terrain(log, "driver"),
        Synced(Vehicle(log), lambda t: ("throttle", "terrain")),
        (model, data),
        System(log),
        lambda step: log.append(("callable", step)),
        Terrain(log),
    ]
    advancer = Advancer(objects, dt)
    advancer(1.5)
    # Phase 1: every Synchronize in list order; phase 2: every step call in list order.
    assert log == [
        ("driver.Synchronize", 1.5),
        ("vehicle.Synchronize", 1.5, "throttle", "terrain"),
        ("terrain.Synchronize", 1.5),
        ("sensors.Update",),
        ("driver.Advance", dt),
        ("vehicle.Advance", dt),
        ("system.DoStepDynamics", dt),
        ("callable", dt),
        ("terrain.Advance", dt),
    ]
    assert data.time == pytest.approx(dt)
    assert [line.split(": ")[1] for line in advancer.plan] == [
        "Sensors.Update",
        "Terrain.Synchronize(t) + Advance",
        "Vehicle.Synchronize(t, *args) + Advance",
        "mujoco.mj_step",
        "System.DoStepDynamics",
        "<lambda>(dt)",
        "Terrain.Synchronize(t) + Advance",
    ]


def test_advance_all_steps_mujoco_pair():
    model = mujoco.MjModel.from_xml_path(str(XML_PATH))
    data = mujoco.MjData(model)
    for _ in range(3):
        advance_all([(model, data)], model.opt.timestep)
    assert data.time == pytest.approx(3 * model.opt.timestep)


def test_mujoco_timestep_mismatch_is_rejected():
    model = mujoco.MjModel.from_xml_path(str(XML_PATH))
    with pytest.raises(ValueError, match="timestep 0.002 differs from dt=0.01"):
        Advancer([(model, mujoco.MjData(model))], 0.01)


def test_unsteppable_object_is_rejected():
    with pytest.raises(TypeError, match="advanceable 0 of type object has no way to be stepped"):
        Advancer([object()], 0.01)


@pytest.mark.parametrize("dt", [0, -1.0, float("inf")])
def test_bad_dt_is_rejected(dt):
    with pytest.raises(ValueError, match="dt="):
        advance_all([], dt)


def test_run_many_ticks_matches_single_ticks():
    model = mujoco.MjModel.from_xml_path(str(XML_PATH))
    one, many = mujoco.MjData(model), mujoco.MjData(model)
    for data in (one, many):
        data.qvel[:] = 0.4
        data.ctrl[0] = 0.7
    single = Advancer([(model, one)], model.opt.timestep)
    for i in range(25):
        single(i * model.opt.timestep)
    Advancer([(model, many)], model.opt.timestep).run(0.0, 25)
    assert (one.qpos == many.qpos).all() and (one.qvel == many.qvel).all()
    assert one.time == many.time


def test_run_loops_over_generic_objects():
    log: list = []
    Advancer([Terrain(log), System(log)], 0.5).run(1.0, 2)
    assert [entry for entry in log if entry[0].endswith("Synchronize")] == [
        ("terrain.Synchronize", 1.0),
        ("terrain.Synchronize", 1.5),
    ]
    assert sum(entry[0] == "system.DoStepDynamics" for entry in log) == 2


# -- who steps a Chrono system: the first tick checks every reachable system's clock ----------
class ClockedSystem:
    """Shaped like a ChSystem with its clock: DoStepDynamics(dt) advances GetChTime()."""

    def __init__(self):
        self.time = 0.0

    def DoStepDynamics(self, dt):
        self.time += dt

    def GetChTime(self):
        return self.time


class OwningVehicle:
    """A Chrono vehicle: Advance steps its system only if it created it (owns it)."""

    def __init__(self, system, owns):
        self.system, self.owns = system, owns

    def Synchronize(self, t):
        pass

    def Advance(self, dt):
        if self.owns:
            self.system.DoStepDynamics(dt)

    def GetSystem(self):
        return self.system


class FsiSystem:
    """Chrono 10's ChFsiSystem: DoStepDynamics(dt) steps its multibody system itself."""

    def __init__(self, mbs):
        self.mbs = mbs

    def DoStepDynamics(self, dt):
        self.mbs.DoStepDynamics(dt)

    def GetMultibodySystem(self):
        return self.mbs


class LegacyFsi:
    """Chrono 8/9's ChSystemFsi: DoStepDynamics_FSI() with its own step size."""

    def __init__(self, step):
        self.step, self.calls = step, 0

    def DoStepDynamics_FSI(self):
        self.calls += 1

    def GetStepSize(self):
        return self.step


def plan_of(owns: bool, list_system: bool) -> tuple[ClockedSystem, list]:
    system = ClockedSystem()
    vehicle = OwningVehicle(system, owns)
    return system, [vehicle, system] if list_system else [vehicle]


@pytest.mark.parametrize(("owns", "list_system"), [(True, False), (False, True)])
def test_each_system_stepped_once_passes(owns, list_system):
    system, plan = plan_of(owns, list_system)
    advancer = Advancer(plan, 0.01)
    advancer.run(0.0, 3)
    assert system.time == pytest.approx(0.03)


@pytest.mark.parametrize(
    ("owns", "list_system", "match"),
    [
        (False, False, r"advanced its time by 0\.0 s .*nothing steps it"),
        (True, True, r"advanced its time by 0\.02 s .*stepped 2 times.*remove the system"),
    ],
)
def test_system_stepped_never_or_twice_is_named(owns, list_system, match):
    _, plan = plan_of(owns, list_system)
    with pytest.raises(RuntimeError, match=match):
        Advancer(plan, 0.01)(0.0)


def test_fsi_system_and_its_multibody_system_listed_twice():
    mbs = ClockedSystem()
    Advancer([FsiSystem(mbs)], 0.01)(0.0)  # the FSI system steps its MBS itself
    assert mbs.time == pytest.approx(0.01)
    with pytest.raises(RuntimeError, match=r"GetMultibodySystem\(\).*stepped 2 times"):
        Advancer([FsiSystem(mbs), mbs], 0.01)(0.0)


def test_legacy_fsi_shape_and_its_step_size():
    fsi = LegacyFsi(0.001)
    advancer = Advancer([fsi], 0.001)
    advancer.run(0.0, 4)
    assert fsi.calls == 4 and advancer.plan == ["0: LegacyFsi.DoStepDynamics_FSI"]
    with pytest.raises(ValueError, match=r"LegacyFsi step size 0\.001 differs from dt=0\.002"):
        Advancer([fsi], 0.002)
