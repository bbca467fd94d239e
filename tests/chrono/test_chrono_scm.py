"""Chrono's own SCM terrain (``pychrono.vehicle.SCMTerrain``) under chronogym: a plate sinks to
Bekker's closed form, the advance operator steps the real terrain, the Go1 stands on it and a
reset puts the soil back. Skipped without PyChrono's vehicle module."""

from __future__ import annotations

import subprocess
import sys

import gymnasium as gym
import numpy as np
import pytest

from chronogym.advance import Advancer
from chronogym.terrain import soil_preset

G = 9.81
SIDE = 0.21
THICK = 0.02


def plate_on_soil(
    chrono, preset: str, mass: float, damping: float = 0.0, collision: str = "bullet"
):
    """A square plate on Chrono SCM soil; with ``damping`` [N s/m] on a vertical slide (as the
    MuJoCo plate of tests/terrain/test_soil.py: a free plate overshoots, and its ruts keep
    the deepest sinkage). Skips the test if this PyChrono lacks the ``collision`` system."""
    from chronogym.engines.chrono import set_collision_system
    from chronogym.engines.chrono_scm import ChronoSCM

    system = chrono.ChSystemSMC()
    system.SetGravitationalAcceleration(chrono.ChVector3d(0, 0, -G))
    try:
        set_collision_system(chrono, system, collision)
    except RuntimeError as exc:
        pytest.skip(str(exc))
    material = chrono.ChContactMaterialSMC()
    plate = chrono.ChBodyEasyBox(SIDE, SIDE, THICK, mass / (SIDE * SIDE * THICK), False)
    plate.AddCollisionShape(chrono.ChCollisionShapeBox(material, SIDE, SIDE, THICK))
    plate.EnableCollision(True)
    plate.SetPos(chrono.ChVector3d(0, 0, THICK / 2 + 1e-4))
    system.AddBody(plate)
    if damping > 0:
        ground = chrono.ChBody()
        ground.SetFixed(True)
        system.AddBody(ground)
        slide = chrono.ChLinkLockPrismatic()  # along the frame's z
        slide.Initialize(plate, ground, chrono.ChFramed(chrono.ChVector3d(0, 0, 0)))
        damper = chrono.ChLinkTSDA()
        damper.Initialize(
            plate, ground, False, chrono.ChVector3d(0, 0, 0), chrono.ChVector3d(0, 0, 1)
        )
        damper.SetSpringCoefficient(0.0)
        damper.SetDampingCoefficient(damping)
        system.AddLink(slide)
        system.AddLink(damper)
        plate.keep = (ground, slide, damper)
    domain = [(plate, (0, 0, 0), (0.4, 0.4, 0.2))]
    soil = ChronoSCM(system, soil_preset(preset), (0.6, 0.6), 0.01, domain)
    return system, plate, soil


@pytest.mark.parametrize(
    ("collision", "tolerance"),
    # Bullet's ray casts also load a ring of nodes just outside the moving plate (about 1 cm
    # off its edge: benchmarks/soil/soil_cross_check.py), so the plate sinks ~9 % less.
    [("bullet", 0.10), ("multicore", 0.01)],
)
def test_plate_sinks_to_bekker_closed_form(chrono, vehicle, collision, tolerance):
    params = soil_preset("firm")
    mass = 300.0
    bekker = (mass * G / (SIDE * SIDE * params.Kphi)) ** (1 / params.n)  # Kc = 0: b drops out
    stiffness = params.n * mass * G / bekker  # of the soil at the static sinkage
    damping = 3.0 * (stiffness * mass) ** 0.5  # zeta 1.5
    system, plate, soil = plate_on_soil(chrono, "firm", mass, damping, collision)
    advance = Advancer([soil, system], 0.0005)
    assert advance.plan == [
        "0: ChronoSCM.Synchronize(t) + Advance",
        "1: ChSystemSMC.DoStepDynamics",
    ]
    for i in range(3000):  # 1.5 s
        advance(i * 0.0005)
    sinkage = THICK / 2 - plate.GetPos().z
    assert sinkage == pytest.approx(bekker, rel=tolerance)
    if collision == "multicore":
        assert soil.terrain.GetNumRayHits() == 21 * 21  # exactly the nodes under the plate
    force, _ = soil.force_on(plate)
    assert force[2] == pytest.approx(mass * G, rel=0.05)
    assert soil.height(0.0, 0.0) < -0.5 * bekker  # the rut is in the soil
    soil.reset()
    assert soil.height(0.0, 0.0) == 0.0


def test_advancer_steps_the_real_terrain_once_per_tick(chrono, vehicle):
    system, _, soil = plate_on_soil(chrono, "soft", 50.0)
    advance = Advancer([soil.terrain, system], 0.001)
    assert advance.plan == [
        "0: SCMTerrain.Synchronize(t) + Advance",
        "1: ChSystemSMC.DoStepDynamics",
    ]
    for i in range(3):
        advance(i * 0.001)
    assert system.GetChTime() == pytest.approx(0.003)  # once per tick: the terrain steps nothing
    with pytest.raises(RuntimeError, match=r"stepped 2 times"):
        Advancer([soil.terrain, system, system], 0.001)(0.003)


@pytest.mark.parametrize("collision", ["bullet", "multicore"])
def test_go1_stands_on_chrono_scm_and_reset_restores_the_soil(chrono, vehicle, collision):
    from chronogym.tasks.quadruped.chrono_model import ChronoGo1Settings

    settings = ChronoGo1Settings(collision=collision)
    try:
        env = gym.make(
            "chronogym/ChronoGo1Velocity-v0", terrain="scm", soil="firm", settings=settings
        )
    except RuntimeError as exc:  # a PyChrono without the multicore collision system
        pytest.skip(str(exc))

    def stand(seed: int) -> np.ndarray:
        rows = [env.reset(seed=seed)[0]]
        for _ in range(25):
            obs, _, terminated, _, _ = env.step(np.zeros(12, dtype=np.float32))
            assert not terminated
            rows.append(obs)
        return np.array(rows)

    first = stand(0)
    task = env.unwrapped.task
    assert task.feet_contact_now.all()
    assert 0.15 < task._base_height() < 0.3
    stand(1)
    np.testing.assert_array_equal(stand(0), first)
    env.close()


NO_VEHICLE = """
import sys
sys.modules["pychrono.vehicle"] = None  # PyChrono built without its vehicle module
import gymnasium as gym
import chronogym
try:
    gym.make("chronogym/ChronoGo1Velocity-v0", terrain="scm")
except ModuleNotFoundError as exc:
    print("ERROR:", exc)
else:
    raise SystemExit("built without pychrono.vehicle")
"""


def test_without_the_vehicle_module_scm_names_it(chrono):
    result = subprocess.run(
        [sys.executable, "-c", NO_VEHICLE], capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, result.stderr
    assert "pychrono.vehicle" in result.stdout and "CH_ENABLE_MODULE_VEHICLE" in result.stdout


def test_lander_lands_on_chrono_scm_with_the_mujoco_soil_preset(chrono, vehicle):
    """The default design on "mars" soil in both engines (a 4 cm grid keeps it to seconds):
    the soil takes a large part of the energy in both, and Chrono's ledger closes."""
    from chronogym.tasks.lander import Terrain, simulate_landing
    from chronogym.tasks.lander.chrono.sim import ChronoLanderSim

    terrain = Terrain(soil="mars", soil_resolution=0.04)
    sim = ChronoLanderSim(terrain=terrain)
    assert sim.params.timestep == sim.params.soil_timestep  # the soil's step, as in MuJoCo
    chrono_metrics = sim.run()
    mujoco_metrics = simulate_landing(terrain=terrain)
    energy = chrono_metrics["energy"]
    assert chrono_metrics["settled"] and not chrono_metrics["tipped_over"]
    assert abs(energy["residual_rel"]) < 0.01
    for metrics in (chrono_metrics, mujoco_metrics):
        assert 0.3 < metrics["E_soil"] / metrics["E_init"] < 0.9
        assert 0.05 < metrics["max_sinkage"] < 0.3
    assert chrono_metrics["a_max"] == pytest.approx(mujoco_metrics["a_max"], rel=0.15)


def test_lander_raises_when_its_chassis_reaches_the_chrono_soil(chrono, vehicle):
    """Only the pads are on Chrono's soil: a chassis at the surface is an error, not a pass."""
    from chronogym.engines.chrono import body_pos, set_body_state
    from chronogym.tasks.lander import Terrain
    from chronogym.tasks.lander.chrono.sim import ChronoLanderSim

    sim = ChronoLanderSim(terrain=Terrain(soil="mars", soil_resolution=0.04))
    sim.step()
    sim._check_chassis_above_soil()  # 1.2 m up: fine
    chassis = sim.model.chassis
    x, y, _ = body_pos(chassis)
    set_body_state(chassis, pos=(x, y, 0.3))  # the cylinder's bottom 0.5 m below the surface
    with pytest.raises(RuntimeError, match=r"the chassis reached the soil .*use the MuJoCo"):
        sim._check_chassis_above_soil()
