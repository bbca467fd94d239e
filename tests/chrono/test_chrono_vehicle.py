"""Chrono vehicles under the advance operator, on the real module (``tests/test_advance.py``
checks the same shapes on stand-ins): a small four-wheel cart, read by Chrono from JSON written
here, on a system it shares or on its own, on Chrono's rigid terrain and on its SCM soil.
Skipped without PyChrono's vehicle module."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from chronogym.advance import Advancer, Synced
from chronogym.terrain import soil_preset

DT = 0.002
WHEEL_RADIUS = 0.15

# A rigid-suspension cart: chassis, two axles, four rigid tires, a four-wheel simple driveline.
CART = {
    "cart.json": {
        "Name": "cart",
        "Type": "Vehicle",
        "Template": "WheeledVehicle",
        "Chassis": {"Input File": "chassis.json"},
        "Axles": [
            {
                "Suspension Input File": "axle.json",
                "Suspension Location": [x, 0.0, 0.0],
                "Left Wheel Input File": "wheel.json",
                "Right Wheel Input File": "wheel.json",
            }
            for x in (0.4, -0.4)
        ],
        "Driveline": {"Input File": "driveline.json", "Suspension Indexes": [0, 1]},
        "Wheelbase": 0.8,
    },
    "chassis.json": {
        "Name": "cart chassis",
        "Type": "Chassis",
        "Template": "RigidChassis",
        "Components": [
            {
                "Centroidal Frame": {"Location": [0, 0, 0.05], "Orientation": [1, 0, 0, 0]},
                "Mass": 60.0,
                "Moments of Inertia": [2.0, 4.0, 5.0],
                "Products of Inertia": [0, 0, 0],
                "Void": False,
            }
        ],
        "Driver Position": {"Location": [0, 0, 0.3], "Orientation": [1, 0, 0, 0]},
    },
    "axle.json": {
        "Name": "cart axle",
        "Type": "Suspension",
        "Template": "RigidSuspension",
        "Spindle": {
            "Mass": 2.0,
            "COM": [0, 0.35, 0],
            "Inertia": [0.02, 0.04, 0.02],
            "Radius": 0.03,
            "Width": 0.03,
        },
        "Axle": {"Inertia": 0.01},
    },
    "wheel.json": {
        "Name": "cart wheel",
        "Type": "Wheel",
        "Template": "Wheel",
        "Mass": 2.0,
        "Inertia": [0.02, 0.04, 0.02],
    },
    "tire.json": {
        "Name": "cart tire",
        "Type": "Tire",
        "Template": "RigidTire",
        "Radius": WHEEL_RADIUS,
        "Width": 0.08,
        "Mass": 2.0,
        "Inertia": [0.02, 0.04, 0.02],
        "Contact Material": {
            "Coefficient of Friction": 0.9,
            "Coefficient of Restitution": 0.1,
            "Properties": {"Young Modulus": 2e7, "Poisson Ratio": 0.3},
        },
    },
    "driveline.json": {
        "Name": "cart driveline",
        "Type": "Driveline",
        "Template": "SimpleDriveline",
        "Front Torque Fraction": 0.5,
        "Front Differential Max Bias": 2.0,
        "Rear Differential Max Bias": 2.0,
        "Front Conical Gear Ratio": -0.2,
        "Rear Conical Gear Ratio": -0.2,
    },
}


@pytest.fixture
def cart_file(vehicle, tmp_path: Path):
    """The cart's JSON files in a fresh folder, made Chrono's vehicle data path for the test:
    (vehicle file, tire file)."""
    for name, spec in CART.items():
        (tmp_path / name).write_text(json.dumps(spec))
    before = vehicle.GetVehicleDataFile("")
    vehicle.SetVehicleDataPath(f"{tmp_path}/")
    yield str(tmp_path / "cart.json"), str(tmp_path / "tire.json")
    vehicle.SetVehicleDataPath(before)


def start(chrono, vehicle, cart, tire_file: str, speed: float = 1.0):
    """Initialise the cart just above the ground, rolling forward at ``speed``, with rigid
    tires (no visual assets: Chrono's tire textures live in its data folder); its driver."""
    cart.Initialize(chrono.ChCoordsysd(chrono.ChVector3d(0, 0, WHEEL_RADIUS + 0.02)), speed)
    no_visuals = getattr(vehicle, "VisualizationType_NONE", None)  # Chrono 9's place
    if no_visuals is None:
        no_visuals = chrono.VisualizationType_NONE  # Chrono 10's
    for axle in cart.GetAxles():
        for wheel in axle.GetWheels():
            tire = vehicle.RigidTire(tire_file)
            cart.InitializeTire(tire, wheel, no_visuals)
    driver = vehicle.ChDriver(cart)
    driver.Initialize()
    return driver


def rigid_ground(chrono, vehicle, system):
    terrain = vehicle.RigidTerrain(system)
    material = chrono.ChContactMaterialNSC()
    material.SetFriction(0.9)
    terrain.AddPatch(material, chrono.CSYSNORM, 20.0, 20.0)
    terrain.Initialize()
    return terrain


def new_system(chrono, contact: str):
    """A ``ChSystemNSC`` or ``ChSystemSMC`` with gravity and Bullet collision."""
    system = chrono.ChSystemNSC() if contact == "nsc" else chrono.ChSystemSMC()
    system.SetGravitationalAcceleration(chrono.ChVector3d(0, 0, -9.81))
    system.SetCollisionSystemType(chrono.ChCollisionSystem.Type_BULLET)
    return system


def wheel_position(cart) -> tuple[float, float, float]:
    """The front left wheel's centre."""
    pos = cart.GetAxles()[0].GetWheels()[0].GetPos()
    return pos.x, pos.y, pos.z


def test_cart_on_a_shared_system_rolls_once_the_system_is_listed(chrono, vehicle, cart_file):
    system = new_system(chrono, "nsc")
    cart = vehicle.WheeledVehicle(system, cart_file[0])
    driver = start(chrono, vehicle, cart, cart_file[1])
    terrain = rigid_ground(chrono, vehicle, system)
    synced = Synced(cart, lambda t: (driver.GetInputs(), terrain))

    # A vehicle built on an existing system does not step it: without it, the first tick says so.
    with pytest.raises(RuntimeError, match=r"advanced its time by 0.0 s.*nothing steps it"):
        Advancer([synced, driver, terrain], DT)(0.0)

    advance = Advancer([synced, driver, terrain, system], DT)
    assert advance.plan == [
        "0: WheeledVehicle.Synchronize(t, *args) + Advance",
        "1: ChDriver.Synchronize(t) + Advance",
        "2: RigidTerrain.Synchronize(t) + Advance",
        "3: ChSystemNSC.DoStepDynamics",
    ]
    advance.run(0.0, 250)
    x, y, z = wheel_position(cart)
    assert system.GetChTime() == pytest.approx(250 * DT)
    assert 0.6 < x < 1.0  # rolled forward from 0.4 m, started at 1 m/s, for 0.5 s
    assert abs(y - 0.35) < 0.01
    assert z == pytest.approx(WHEEL_RADIUS, abs=0.002)  # on its tires, on the ground


def test_cart_owning_its_system_must_not_be_listed_with_it(chrono, vehicle, cart_file):
    cart = vehicle.WheeledVehicle(cart_file[0], chrono.ChContactMethod_NSC)
    system = cart.GetSystem()
    system.SetCollisionSystemType(chrono.ChCollisionSystem.Type_BULLET)  # before Initialize
    driver = start(chrono, vehicle, cart, cart_file[1])
    terrain = rigid_ground(chrono, vehicle, system)
    synced = Synced(cart, lambda t: (driver.GetInputs(), terrain))

    with pytest.raises(RuntimeError, match=r"stepped 2 times.*remove the system"):
        Advancer([synced, driver, terrain, system], DT)(0.0)

    start_time = system.GetChTime()
    Advancer([synced, driver, terrain], DT).run(start_time, 100)
    assert system.GetChTime() == pytest.approx(start_time + 100 * DT)  # its Advance steps it
    x, _, z = wheel_position(cart)
    assert x > 0.45
    assert z == pytest.approx(WHEEL_RADIUS, abs=0.002)


def test_cart_rolls_on_chrono_scm_and_leaves_ruts(chrono, vehicle, cart_file):
    from chronogym.engines.chrono_scm import ChronoSCM

    system = new_system(chrono, "smc")
    cart = vehicle.WheeledVehicle(system, cart_file[0])
    driver = start(chrono, vehicle, cart, cart_file[1])
    # No active domains: the soil casts rays under the bounding box of all collision shapes.
    soil = ChronoSCM(system, soil_preset("firm"), (4.0, 2.0), 0.02, [])
    synced = Synced(cart, lambda t: (driver.GetInputs(), soil.terrain))
    advance = Advancer([synced, soil, system], DT)
    assert advance.plan[1] == "1: ChronoSCM.Synchronize(t) + Advance"
    advance.run(0.0, 250)
    x, y, z = wheel_position(cart)
    assert system.GetChTime() == pytest.approx(250 * DT)
    assert 0.005 < WHEEL_RADIUS - z < 0.1  # the tires sank into the soil
    assert soil.deepest() > 0.005
    assert soil.height(x - 0.1, y) < -0.005  # the rut the front left tire left behind it
    assert soil.height(x + 0.2, y) == 0.0  # none ahead of it
    assert 0.45 < x < 0.9
