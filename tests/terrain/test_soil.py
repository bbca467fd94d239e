"""SCM soil under MuJoCo bodies against closed forms: Bekker sinkage, elastic unloading and ruts,
Janosi-Hanamoto shear, passivity and energy balance, reset, determinism, bulldozed volume, one
owner per node (also on unloading), geometry (vs mj_ray), the compiled tick against a NumPy
reference, the Go1 through the Advancer, parameter errors, import weight."""

from __future__ import annotations

import math

import mujoco
import numpy as np
import pytest

from chronogym.advance import Advancer
from chronogym.tasks.quadruped import FOOT_GEOM_NAMES, load_go1
from chronogym.terrain import (
    SOIL_PRESETS,
    MujocoSoil,
    SoilParameters,
    exclude_ground_contacts,
    patch_inverse_width,
    soil_preset,
)

G = 9.81
RES = 0.01
HALF = 10.5 * RES  # plate half-width between nodes: 21 x 21 nodes, contact area exactly (2 HALF)^2
THICK = 0.01


def _plate(mass: float, damping: float, dt: float, drag: bool = False):
    x_joint = '<joint name="x" type="slide" axis="1 0 0"/>' if drag else ""
    xml = f"""<mujoco><option timestep="{dt}"/><worldbody>
      <body name="plate" pos="0 0 {THICK + 1e-4}">{x_joint}
        <joint name="z" type="slide" axis="0 0 1" damping="{damping}"/>
        <geom type="box" size="{HALF} {HALF} {THICK}" mass="{mass}"/>
      </body></worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    return model, mujoco.MjData(model)


def _bekker_sinkage(p: SoilParameters, weight: float) -> float:
    """Closed form for a square plate of side L: b = 2 area / perimeter = L / 2."""
    side = 2 * HALF
    area = side * side
    return (weight / (area * (p.Kc / (side / 2) + p.Kphi))) ** (1 / p.n)


def _settle_plate(name: str, mass: float, dt: float = 0.002, drag: bool = False):
    """Plate on the soil with an over-damped vertical joint (zeta 1.5 at the Bekker stiffness)."""
    p = soil_preset(name)
    depth = _bekker_sinkage(p, mass * G)
    stiffness = p.n * mass * G / depth
    model, data = _plate(mass, 3.0 * math.sqrt(stiffness * mass), dt, drag)
    soil = MujocoSoil(model, data, p, bodies=["plate"], extent=(0.5, 0.4), resolution=RES)
    for _ in range(800):
        soil.Advance(dt)
        mujoco.mj_step(model, data)
    return p, depth, model, data, soil


PLATE_LOADS = [("firm", 300.0), ("mars", 150.0), ("lete_sand", 1500.0)]  # kg


@pytest.mark.parametrize(("name", "mass"), PLATE_LOADS)
def test_plate_sinks_to_bekker_closed_form(name, mass):
    _, depth, model, data, soil = _settle_plate(name, mass)
    sinkage = -(data.xpos[model.body("plate").id, 2] - THICK)
    assert depth > 0.02  # several cm
    assert sinkage == pytest.approx(depth, rel=0.02)
    assert abs(data.qvel[0]) < 5e-3 * depth  # settled: the creep left is under 0.1 % of it
    assert soil.forces_on("plate")[2] == pytest.approx(mass * G, rel=1e-3)
    # The rut under the plate is level and as deep as the plate (minus the elastic part).
    under = np.abs(soil.grid.x)[:, None] < HALF
    under = under & (np.abs(soil.grid.y)[None, :] < HALF)
    assert soil.sinkage[under] == pytest.approx(sinkage, rel=1e-9)
    assert np.all(soil.sinkage[~under] == 0.0)


def test_sphere_loading_unloading_and_rut():
    r, dt, down, up = 0.1, 0.002, 0.05, 0.005
    xml = f"""<mujoco><option timestep="{dt}"/><worldbody><body name="ball" pos="0 0 {r}">
      <joint type="slide" axis="0 0 1"/><geom type="sphere" size="{r}" mass="10"/>
      </body></worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    p = soil_preset("firm")
    soil = MujocoSoil(model, data, p, bodies=["ball"], extent=(0.4, 0.4), resolution=RES)

    def press(sink: float, speed: float) -> float:
        data.qpos[0], data.qvel[0] = -sink, -speed
        soil.Advance(dt)
        return soil.forces_on("ball")[2]

    steps = 400
    sinks = down * dt * np.arange(steps + 1)
    loading = np.array([press(s, down) for s in sinks])
    s_max = sinks[-1]
    assert s_max == pytest.approx(0.04)
    assert np.all(np.diff(loading) >= 0.0) and loading[0] == 0.0 and loading[-1] > 100.0
    # Jerked up fast at the deepest point: damping cuts the pressure, but never below 0.
    assert 0.0 < press(s_max, -1.0) < loading[-1]
    assert soil.pressure.min() == 0.0 and np.count_nonzero(soil.pressure) > 10
    rises = up * dt * np.arange(1, 101)  # 1 mm in 0.01 mm steps
    unloading = np.array([press(s_max - rise, -up) for rise in rises])
    # Elastic unloading: far stiffer than the virgin loading curve, gone after a fraction of a mm.
    sigma_y = p.Kphi * s_max**p.n
    elastic_rebound = sigma_y / p.elastic_stiffness
    unload_slope = (unloading[4] - unloading[14]) / (rises[14] - rises[4])
    assert unload_slope > 50 * loading[-1] / s_max
    assert np.all(np.diff(unloading) <= 1e-9)
    assert np.all(unloading[rises > 1.5 * elastic_rebound] == 0.0)
    # Lift off: the rut stays, as deep as the yield sinkage minus the elastic rebound.
    press(-0.01, -up)
    assert soil.forces_on("ball")[2] == 0.0
    centre = np.argmin(np.abs(soil.grid.x)), np.argmin(np.abs(soil.grid.y))
    assert soil.heights[centre] == pytest.approx(-(s_max - elastic_rebound), rel=1e-9, abs=1e-12)
    assert soil.plastic_sinkage[centre] == pytest.approx(s_max - elastic_rebound, rel=1e-9)
    footprint = np.hypot(*np.meshgrid(soil.grid.x, soil.grid.y, indexing="ij"))
    inside = footprint < 0.9 * math.sqrt(2 * r * s_max - s_max**2)
    assert np.all(soil.heights[inside] < -0.001)
    assert np.all(soil.heights[footprint > math.sqrt(2 * r * s_max) + RES] == 0.0)


def test_bulldozing_conserves_soil_volume():
    xml = """<mujoco><worldbody><body name="ball" pos="0.002 0.001 0.05">
      <joint type="slide" axis="0 0 1"/><geom type="sphere" size="0.05" mass="2"/>
      </body></worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    soil = MujocoSoil(model, data, "soft", bodies=["ball"], extent=(0.3, 0.3), resolution=RES,
                      bulldozing=True)  # fmt: skip
    for sink in [*np.linspace(0.0, 0.03, 31), -0.01]:  # press 3 cm, then lift off
        data.qpos[0], data.qvel[0] = -sink, -0.01
        soil.Advance(0.001)
    grid = soil.grid
    pile = grid.interior(grid.level0) - grid.reset_level
    assert soil.plastic_sinkage.sum() > 0.1  # m, summed over nodes
    assert pile.sum() == pytest.approx(soil.plastic_sinkage.sum(), rel=1e-12)
    assert soil.heights.max() > 0.002 and soil.heights.min() < -0.02  # a rim around the rut


def test_bulldozing_conserves_volume_under_overlapping_geoms():
    """Go1 calves (capsule + foot sphere, whose blocks overlap) walking on soft soil."""
    model, data = load_go1()
    calves = [f"{leg}_calf" for leg in ("FR", "FL", "RR", "RL")]
    soil = MujocoSoil(model, data, "soft", bodies=calves, extent=(2, 2), resolution=RES,
                      bulldozing=True)  # fmt: skip
    soil.exclude_ground("floor")
    rng = np.random.default_rng(0)
    home, offset = data.ctrl.copy(), np.zeros(model.nu)
    for tick in range(300):
        if tick % 4 == 0:
            offset = 0.8 * offset + 0.2 * rng.normal(0.0, 0.3, size=model.nu)
            data.ctrl[:] = home + offset
        soil.Advance(model.opt.timestep)
        mujoco.mj_step(model, data)
    grid = soil.grid
    pile = grid.interior(grid.level0) - grid.reset_level
    assert soil.plastic_sinkage.sum() > 10.0
    assert pile.sum() == pytest.approx(soil.plastic_sinkage.sum(), rel=1e-12)


def test_dragged_plate_follows_janosi_hanamoto():
    mass, dt, speed = 150.0, 0.002, 0.05
    p, _, model, data, soil = _settle_plate("mars", mass, dt, drag=True)
    area = (2 * HALF) ** 2
    tau_max = p.cohesion + mass * G / area * p.tan_phi
    x, y = np.meshgrid(soil.grid.x, soil.grid.y, indexing="ij")
    interior = (x > -HALF + 0.06) & (x < HALF - RES) & (np.abs(y) < HALF - RES)
    checked = []
    for tick in range(3 * 178 + 1):
        displacement = speed * dt * tick
        data.qpos[0], data.qvel[0] = displacement, speed  # driven at constant speed
        soil.Advance(dt)
        if tick in (89, 178, 3 * 178):  # j = K/2, K, 3K
            expected = tau_max * (1 - math.exp(-displacement / p.janosi_shear))
            tau = soil.shear_stress
            assert tau[interior] == pytest.approx(expected, rel=0.02)
            # Whole plate: nodes that entered at the leading edge have slipped less.
            j = displacement - np.maximum(x - HALF, 0.0)
            under = (np.abs(x - displacement) <= HALF) & (np.abs(y) <= HALF)
            grip = 1 - np.exp(-np.maximum(j[under], 0.0) / p.janosi_shear)
            force = soil.forces_on("plate")
            assert force[0] == pytest.approx(-(RES**2) * tau_max * grip.sum(), rel=0.02)
            assert abs(force[1]) < 1e-9 * abs(force[0])
            assert np.all(soil.shear_displacement[~under] == 0.0)  # j resets out of contact
            checked.append(displacement)
        mujoco.mj_step(model, data)
    assert checked == pytest.approx([0.0089, 0.0178, 0.0534])


def _drop(free: bool, dt: float = 0.001, ticks: int = 600):
    r, mass = 0.05, 5.0
    joint = "<freejoint/>" if free else '<joint type="slide" axis="0 0 1"/>'
    xml = f"""<mujoco><option timestep="{dt}"/><worldbody>
      <body name="ball" pos="0.003 -0.002 {r + 0.05}">{joint}
      <geom type="sphere" size="{r}" mass="{mass}"/></body></worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    model.opt.enableflags |= mujoco.mjtEnableBit.mjENBL_ENERGY
    data = mujoco.MjData(model)
    if free:
        data.qvel[:] = [0.3, 0.0, 0.0, 0.0, 2.0, 0.5]
    soil = MujocoSoil(model, data, "soft", bodies=["ball"], extent=(0.6, 0.6), resolution=RES)
    return model, data, soil, ticks, dt


def _run_drop(model, data, soil, ticks, dt):
    """Per tick: body energy + soil elastic energy, work taken by the soil, qpos."""
    energy, taken, qpos = [], [], []
    for _ in range(ticks):
        soil.Advance(dt)
        mujoco.mj_forward(model, data)
        energy.append(data.energy.sum() + soil.elastic_energy)
        taken.append(soil.energy_dissipated)
        qpos.append(data.qpos.copy())
        mujoco.mj_step(model, data)
    return np.array(energy), np.array(taken), np.array(qpos)


@pytest.mark.parametrize("free", [False, True])
def test_soil_only_dissipates(free):
    # dt = 1 ms < 2 R / E for "soft": the explicit elastic branch is passive tick by tick.
    model, data, soil, ticks, dt = _drop(free)
    mujoco.mj_forward(model, data)
    start = data.energy.sum()
    energy, taken, _ = _run_drop(model, data, soil, ticks, dt)
    assert np.all(np.diff(energy) <= 1e-9 * start)
    assert energy[-1] < start - 0.5 * abs(start)  # it did take most of the drop energy
    assert soil.sinkage.max() > 0.02
    # Energy balance: what the body lost is what the soil took (trapezoidal work of the wrench).
    assert energy[-1] - soil.elastic_energy + taken[-1] == pytest.approx(start, rel=1e-5)


def test_reset_restores_soil_exactly_and_replays():
    model, data, soil, ticks, dt = _drop(True, ticks=300)
    initial = soil.heights
    arrays = (soil.grid.level0, soil.grid.plastic, soil.grid.shear)
    _, _, first = _run_drop(model, data, soil, ticks, dt)
    assert soil.sinkage.max() > 0.01 and np.any(soil.shear_displacement > 0)
    soil.reset()
    assert np.array_equal(soil.heights, initial)
    assert not soil.plastic_sinkage.any() and not soil.shear_displacement.any()
    now = (soil.grid.level0, soil.grid.plastic, soil.grid.shear)
    assert all(a is b for a, b in zip(arrays, now, strict=True))  # reset in place
    assert not data.xfrc_applied.any() and soil.energy_dissipated == 0.0
    mujoco.mj_resetData(model, data)
    data.qvel[:] = [0.3, 0.0, 0.0, 0.0, 2.0, 0.5]
    _, _, second = _run_drop(model, data, soil, ticks, dt)
    assert np.array_equal(first, second)


def _go1_on_soil(ticks: int):
    """Go1 lower legs on firm soil (floor excluded), smooth random joint targets, via Advancer."""
    model, data = load_go1()
    calves = [f"{leg}_calf" for leg in ("FR", "FL", "RR", "RL")]  # calf capsule + foot sphere
    soil = MujocoSoil(model, data, "firm", bodies=calves, extent=(2, 2), resolution=RES)
    soil.exclude_ground("floor")
    advance = Advancer([soil, (model, data)], model.opt.timestep)
    rng = np.random.default_rng(0)
    home, offset = data.ctrl.copy(), np.zeros(model.nu)
    trajectory, support = [], []
    for tick in range(ticks):
        if tick % 4 == 0:
            offset = 0.8 * offset + 0.2 * rng.normal(0.0, 0.3, size=model.nu)
            data.ctrl[:] = home + offset
        advance(tick * model.opt.timestep)
        trajectory.append(data.qpos.copy())
        support.append(sum(soil.forces_on(calf)[2] for calf in calves))
    return model, data, soil, advance, np.array(trajectory), np.array(support)


def test_go1_stands_on_soil_through_the_advancer():
    model, data, soil, advance, trajectory, support = _go1_on_soil(300)
    assert advance.plan == ["0: MujocoSoil.Advance", "1: mujoco.mj_step"]
    assert np.isfinite(trajectory).all() and trajectory[:, 2].min() > 0.15
    legs = set(soil.geom_ids)
    assert {model.geom(name).id for name in FOOT_GEOM_NAMES} < legs
    floor = model.geom("floor").id
    pairs = [{c.geom1, c.geom2} for c in data.contact[: data.ncon]]
    assert not any(floor in pair and pair & legs for pair in pairs)
    assert 0.005 < soil.sinkage.max() < 0.1
    weight = mujoco.mj_getTotalmass(model) * G
    assert support[-100:].mean() == pytest.approx(weight, rel=0.25)  # the soil carries it


def test_same_inputs_give_bitwise_identical_runs():
    _, _, soil_a, _, first, _ = _go1_on_soil(120)
    _, _, soil_b, _, second, _ = _go1_on_soil(120)
    assert np.array_equal(first, second)
    assert np.array_equal(soil_a.heights, soil_b.heights)
    assert soil_a.energy_dissipated == soil_b.energy_dissipated


def test_ground_exclusion_keeps_every_other_pair():
    model, _ = load_go1()
    before_type, before_aff = model.geom_contype.copy(), model.geom_conaffinity.copy()

    def collides(a, b, contype, conaffinity):
        return bool(contype[a] & conaffinity[b] or contype[b] & conaffinity[a])

    feet = [model.geom(name).id for name in FOOT_GEOM_NAMES]
    exclude_ground_contacts(model, "floor", FOOT_GEOM_NAMES)
    for a in range(model.ngeom):
        for b in range(a + 1, model.ngeom):
            was = collides(a, b, before_type, before_aff)
            now = collides(a, b, model.geom_contype, model.geom_conaffinity)
            floor_foot = model.geom("floor").id in (a, b) and ({a, b} & set(feet))
            assert now == (was and not floor_foot), (a, b)


def test_go1_at_task_step_does_not_chatter():
    """dt = 5 ms, light calves deep in soft soil: the shear force must not flip every tick."""
    model, data = load_go1()
    calves = [f"{leg}_calf" for leg in ("FR", "FL", "RR", "RL")]
    soil = MujocoSoil(model, data, "soft", bodies=calves, extent=(1, 1), resolution=RES)
    soil.exclude_ground("floor")
    force = []
    for _ in range(400):
        soil.Advance(model.opt.timestep)
        mujoco.mj_step(model, data)
        force.append(soil.forces_on("FR_calf")[:3])
    last = np.array(force[-40:])
    assert soil.sinkage.max() > 0.05 and last[:, 2].mean() > 10.0
    assert np.sqrt(np.mean(np.diff(last, axis=0) ** 2)) < 1.0  # N, tick to tick


@pytest.mark.parametrize("extra", ["sphere at the capsule end", "same sphere twice"])
def test_node_under_two_geoms_counts_once(extra):
    """A geom inside another changes nothing: each node belongs to the lowest surface."""
    base = '<geom type="capsule" size="0.03 0.06" euler="0 1.0 0"/>'
    if extra == "same sphere twice":
        base = '<geom type="sphere" size="0.05" pos="0 0 -0.03"/>'
        added = base
    else:  # the capsule's lower cap: centre at -hl along its tilted axis
        end = f"{-0.06 * math.sin(1.0)} 0 {-0.06 * math.cos(1.0)}"
        added = f'<geom type="sphere" size="0.03" pos="{end}"/>'

    def pressed(geoms: str) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
        xml = f"""<mujoco><compiler angle="radian"/><worldbody><body name="b" pos="0.004 0 0.1">
          <joint type="slide" axis="0 0 1"/>{geoms}</body></worldbody></mujoco>"""
        model = mujoco.MjModel.from_xml_string(xml)
        data = mujoco.MjData(model)
        soil = MujocoSoil(model, data, "firm", bodies=["b"], extent=(0.4, 0.4), resolution=RES)
        forces = []
        for tick in range(60):
            data.qpos[0], data.qvel[0] = -0.002 * tick, -1.0
            soil.Advance(0.002)
            wrench = soil.forces_on("b")  # torque about the CoM: move it to the body origin
            arm = data.xipos[1] - data.xpos[1]
            forces.append(np.concatenate([wrench[:3], wrench[3:] + np.cross(arm, wrench[:3])]))
        return np.array(forces), soil.heights, soil.pressure

    alone, heights_alone, pressure_alone = pressed(base)
    both, heights_both, pressure_both = pressed(base + added)
    assert alone[-1, 2] > 50.0
    assert np.allclose(both, alone, rtol=1e-9, atol=1e-9)
    assert np.allclose(heights_both, heights_alone, rtol=0.0, atol=1e-12)
    assert np.allclose(pressure_both, pressure_alone, rtol=1e-9, atol=1e-6)


def test_hidden_geom_does_not_undo_the_rut():
    """A thin capsule inside a sphere (as a calf above its foot) changes nothing, also on
    unloading: only the owner of a contact node writes its plastic sinkage and shear."""

    def pressed(geoms: str) -> tuple[np.ndarray, np.ndarray]:
        xml = f"""<mujoco><worldbody><body name="b" pos="0.004 0.002 0.03">
          <joint type="slide" axis="0 0 1"/>{geoms}</body></worldbody></mujoco>"""
        model = mujoco.MjModel.from_xml_string(xml)
        data = mujoco.MjData(model)
        soil = MujocoSoil(model, data, "firm", bodies=["b"], extent=(0.3, 0.3), resolution=0.005)
        forces = []
        for tick in range(60):  # 2 cm down, then 4 mm back up
            data.qpos[0] = -0.0005 * min(tick, 40) + 0.0002 * max(tick - 40, 0)
            data.qvel[0] = -0.25 if tick < 40 else 0.1
            soil.Advance(0.002)
            forces.append(soil.forces_on("b")[2])
        return np.array(forces), soil.plastic_sinkage

    sphere = '<geom type="sphere" size="0.03"/>'
    capsule = '<geom type="capsule" size="0.015" fromto="0 0 0  0 0 0.1"/>'
    alone, rut_alone = pressed(sphere)
    both, rut_both = pressed(sphere + capsule)
    assert alone.max() > 50.0 and alone[-1] == 0.0 and rut_alone.max() > 0.015
    assert np.allclose(both, alone, rtol=1e-12, atol=1e-9)
    assert np.allclose(rut_both, rut_alone, rtol=0.0, atol=1e-12)


@pytest.mark.parametrize("surface", [1.0, 0.025])
@pytest.mark.parametrize("kind", ["sphere", "capsule", "ellipsoid", "cylinder", "box"])
def test_lower_surface_matches_mj_ray(kind, surface):
    """Soil level far above the geom (all of it touches) or through its middle (part of it)."""
    size = {"sphere": "0.05", "capsule": "0.03 0.05", "ellipsoid": "0.06 0.03 0.04"}
    size |= {"cylinder": "0.04 0.03", "box": "0.05 0.03 0.02"}
    xml = f"""<mujoco><compiler angle="radian"/><worldbody>
      <body name="b" pos="0.013 -0.007 0.02" euler="0.5 -0.9 0.3">
      <freejoint/><geom name="g" type="{kind}" size="{size[kind]}"/></body></worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    soil = MujocoSoil(model, data, "firm", geoms=["g"], extent=(0.4, 0.4), resolution=0.005)
    soil.grid.level0[soil.grid.level0 > -1.0] = surface
    soil.grid.top = surface
    soil.Advance(0.001)
    expected = np.full(soil.grid.shape, surface)
    geomid = np.zeros(1, dtype=np.int32)
    for i, x in enumerate(soil.grid.x):
        for j, y in enumerate(soil.grid.y):
            dist = mujoco.mj_ray(model, data, np.array([x, y, -1.0]), np.array([0, 0, 1.0]),
                                 None, 1, -1, geomid)  # fmt: skip
            if dist >= 0:
                expected[i, j] = min(surface, -1.0 + dist)
    assert np.count_nonzero(expected < surface) > 20
    assert np.allclose(soil.heights, expected, atol=1e-9, rtol=0.0)


def _reference_tick(model, data, soil, dt: float):
    """One tick in NumPy from the state before it: lower surface by mj_ray, Bekker width by
    ``patch_inverse_width``, velocity by ``mj_objectVelocity``, law by ``ScmLaw.update``."""
    grid, law = soil.grid, soil.law
    mujoco.mj_kinematics(model, data)
    mujoco.mj_comPos(model, data)
    mujoco.mj_comVel(model, data)
    level0, plastic, shear = (grid.interior(a).copy() for a in grid.state)
    x, y = np.meshgrid(grid.x, grid.y, indexing="ij")
    surface = np.full(grid.shape, 1.0)  # above the soil where the vertical line misses the geom
    geomid = np.zeros(1, dtype=np.int32)
    for i, j in np.ndindex(grid.shape):
        dist = mujoco.mj_ray(model, data, np.array([x[i, j], y[i, j], -1.0]),
                             np.array([0, 0, 1.0]), None, 1, -1, geomid)  # fmt: skip
        if dist >= 0:
            surface[i, j] = -1.0 + dist
    sinkage = level0 - surface
    elastic = sinkage - plastic
    contact = (elastic > 0.0).astype(float)
    modulus = law.modulus_area(patch_inverse_width(contact[None] > 0.0, grid.resolution)[0])
    body = model.body("b").id
    velocity = np.zeros(6)
    mujoco.mj_objectVelocity(model, data, mujoco.mjtObj.mjOBJ_BODY, body, velocity, 0)
    arm = np.stack([x, y, surface], axis=-1) - data.xipos[body]
    v = velocity[3:] + np.cross(velocity[:3], arm)
    slip = np.hypot(v[..., 0], v[..., 1])
    normal, tau, plastic_new, shear_new, _ = law.update(
        sinkage, elastic, plastic, shear, contact, v[..., 2], slip, modulus, dt
    )
    coef = tau / np.maximum(slip, 1e-4)
    mass = model.body_mass[body]
    coef *= mass / max(-dt * coef.sum(), mass)
    force = np.stack([v[..., 0] * coef, v[..., 1] * coef, normal], axis=-1)
    wrench = np.concatenate([force.sum(axis=(0, 1)), np.cross(arm, force).sum(axis=(0, 1))])
    return wrench, plastic_new, shear_new, normal / grid.node_area, contact


@pytest.mark.parametrize("kind", ["capsule", "box"])
def test_compiled_tick_matches_numpy_reference(kind):
    """lete_sand (Kc, cohesion, n != 1): a tilted geom pushed down and sideways while spinning,
    so that ruts, shear displacement, damping and the shear scaling all take part."""
    size = {"capsule": "0.03 0.05", "box": "0.05 0.03 0.02"}[kind]
    xml = f"""<mujoco><compiler angle="radian"/><worldbody>
      <body name="b" pos="0.013 -0.007 0.045" euler="0.5 -0.9 0.3"><freejoint/>
      <geom type="{kind}" size="{size}" mass="3"/></body></worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    soil = MujocoSoil(model, data, "lete_sand", bodies=["b"], extent=(0.3, 0.3), resolution=0.005)
    dt, start = 0.002, data.qpos[:3].copy()
    checked = 0
    for tick in range(25):
        data.qpos[:3] = start + tick * dt * np.array([0.4, -0.2, -1.0])
        data.qvel[:] = [0.4, -0.2, -1.0 if tick < 20 else 0.3, 1.5, -1.0, 2.0]
        wrench, plastic, shear, pressure, contact = _reference_tick(model, data, soil, dt)
        soil.Advance(dt)
        scale = np.abs(wrench).max() + 1.0
        assert np.allclose(soil.forces_on("b"), wrench, rtol=1e-7, atol=1e-9 * scale)
        # mj_ray's surface agrees to ~1e-12 m, and the plastic sinkage inherits that.
        assert np.allclose(soil.plastic_sinkage, plastic, rtol=0.0, atol=1e-10)
        assert np.allclose(soil.shear_displacement, shear, rtol=0.0, atol=1e-12)
        assert np.allclose(soil.pressure, pressure, rtol=1e-7, atol=1e-6 * pressure.max() + 1e-9)
        checked += contact.sum() > 20
    assert checked >= 15 and soil.plastic_sinkage.max() > 0.01
    assert soil.shear_displacement.max() > 0.01


def test_terrain_import_stays_light():
    import subprocess
    import sys

    code = (
        "import sys, chronogym.terrain; "
        "print(sorted(m for m in ('numba', 'mujoco', 'ray', 'torch') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"


@pytest.mark.parametrize(
    ("field", "value"),
    [
        ("Kphi", -1.0),
        ("Kc", float("nan")),
        ("n", 0.0),
        ("cohesion", -5.0),
        ("friction_angle", 95.0),
        ("janosi_shear", 0.0),
        ("elastic_stiffness", float("inf")),
        ("damping", -1.0),
        ("Kphi", "2e6"),
    ],
)
def test_bad_parameters_name_field_and_value(field, value):
    with pytest.raises(ValueError, match=rf"{field}={value!r}".replace("(", r"\(")):
        soil_preset("firm", **{field: value})


def test_bad_names_and_shapes_are_rejected():
    with pytest.raises(ValueError, match=r"'clay'.*'firm', 'soft', 'mars', 'lete_sand'"):
        soil_preset("clay")
    with pytest.raises(ValueError, match="soil parameter 'phi'.*friction_angle"):
        soil_preset("firm", phi=30.0)
    assert set(SOIL_PRESETS) == {"firm", "soft", "mars", "lete_sand"}
    assert soil_preset("mars").Kc == 1.4e3 and soil_preset("lete_sand").n == 0.793
    model, data = load_go1()
    with pytest.raises(ValueError, match="'floor' has type plane"):
        MujocoSoil(model, data, "firm", geoms=["floor"])
    with pytest.raises(ValueError, match="geom 'nope'"):
        MujocoSoil(model, data, "firm", geoms=["nope"])
    with pytest.raises(ValueError, match="resolution=0"):
        MujocoSoil(model, data, "firm", geoms=FOOT_GEOM_NAMES, resolution=0)
    with pytest.raises(ValueError, match="extent="):
        MujocoSoil(model, data, "firm", geoms=FOOT_GEOM_NAMES, extent=(1.0, -2.0))
    with pytest.raises(ValueError, match="preset 'sand'"):
        MujocoSoil(model, data, "sand", geoms=FOOT_GEOM_NAMES)
