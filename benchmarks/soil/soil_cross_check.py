"""chronogym's SCM (under MuJoCo bodies) against Chrono's ``SCMTerrain``, same presets.

Both soils take one :class:`~chronogym.terrain.SoilParameters` (Chrono's own argument order),
so differences come from the implementations and the multibody engines around them. Problems:

* ``plate``: a square plate (side 0.21 m, 1 cm thick) settling on the soil under its weight;
  static sinkage against Bekker's closed form ``z = (W / (A (Kc / b + Kphi)))^(1/n)``,
  ``b = 2 A / perimeter`` (both engines estimate the patch width so). In both engines the
  plate rides a vertical slide with the same over-damping (zeta 1.5 at the soil's stiffness
  at the static sinkage, as ``tests/terrain/test_soil.py``): a free plate overshoots, and SCM
  keeps the deepest sinkage as plastic (a free Chrono plate, 300 kg on "firm": 61 mm against
  45 mm). The sinkage is the mean over the last ``--average-s`` seconds of ``--settle-s``.
* ``lander``: the default design's landing on ``--lander-soil`` ("mars", the soil study's),
  ``LanderSim`` on chronogym's SCM against ``ChronoLanderSim`` on Chrono's (pads on the soil,
  0.125 ms both): ``a_max``, ``E_abs``, the soil's work and the deepest rut (the deepest
  soil node at the end).
* ``go1``: the Go1 standing at its home pose with zero action for ``--stand-s`` seconds on
  each engine's soil (``terrain="soil"`` / ``terrain="scm"``): mean foot sinkage (foot sphere
  bottom below z = 0), base height, and the wall time of ``env.step`` per decision (run this
  on a quiet machine for that row).

Chrono's SCM finds the bodies by ray casts into the collision system, so its result depends on
that system. Chrono's default, Bullet in single precision, ends a ray-versus-shape cast once
the ray is within 1e-4 m² of squared distance (1 cm) of the shape, so it reports hits up to
about 1 cm off the surface: outside a box's edge once the box has moved (one that has not
moved gets exact answers), and below a sphere's rim. Both load soil that the shape does not
touch (``ray hits`` rows). Bullet also inflates shapes by their collision envelope and
``RayHit`` corrects only the depth, so the Go1 runs again at its rigid-ground 5 mm envelope
(its default on SCM is 0.1 mm) and the lander at 0.1 mm (its default is 5 mm). The plate and
the Go1 also run on Chrono's multicore collision system (``--no-multicore`` skips it), whose
ray tests are exact for boxes and spheres; not the lander, whose pads are cylinders, which
Chrono 10's multicore ray test treats as lying along y with the radius as half-length.

Prints a table, writes ``results/soil_cross_check.json``. Needs PyChrono with its vehicle
module for the Chrono columns (and Chrono built with Thrust for the multicore one).

    python -m benchmarks.soil.soil_cross_check
"""

from __future__ import annotations

import argparse
import math
import time
from pathlib import Path
from typing import Any

import gymnasium as gym
import numpy as np

import chronogym  # noqa: F401  (registers the envs)
from benchmarks.common import RESULTS, Column, header, settings, table, write_json
from chronogym.engines.chrono import body_pos, import_pychrono, set_collision_system
from chronogym.engines.chrono_scm import ChronoSCM
from chronogym.terrain import MujocoSoil, soil_preset

OUT = RESULTS / "soil_cross_check.json"
G = 9.81
RES = 0.01
HALF = 10.5 * RES  # plate half-width between grid nodes: 21 x 21 nodes under it
THICK = 0.01
PLATES = (("firm", 300.0), ("mars", 150.0), ("lete_sand", 1500.0))  # preset, kg
FOOT_RADIUS = 0.02


def bekker_sinkage(params: Any, weight: float, side: float = 2 * HALF) -> float:
    """Closed-form static sinkage of a square plate: b = 2 A / perimeter = side / 2."""
    area = side * side
    return (weight / (area * (params.Kc / (side / 2) + params.Kphi))) ** (1 / params.n)


def slide_damping(params: Any, mass: float) -> float:
    """Damping of the plate's vertical slide [N s/m]: zeta 1.5 at the soil's stiffness at
    the static sinkage (``n W / z``)."""
    depth = bekker_sinkage(params, mass * G)
    return 3.0 * math.sqrt(params.n * mass * G / depth * mass)


def mujoco_plate(params: Any, mass: float, settle_s: float, average_s: float) -> float:
    import mujoco

    dt = 0.002
    damping = slide_damping(params, mass)
    xml = f"""<mujoco><option timestep="{dt}"/><worldbody>
      <body name="plate" pos="0 0 {THICK + 1e-4}">
        <joint name="z" type="slide" axis="0 0 1" damping="{damping}"/>
        <geom type="box" size="{HALF} {HALF} {THICK}" mass="{mass}"/>
      </body></worldbody></mujoco>"""
    model = mujoco.MjModel.from_xml_string(xml)
    data = mujoco.MjData(model)
    soil = MujocoSoil(model, data, params, bodies=["plate"], extent=(0.5, 0.4), resolution=RES)
    steps, tail = round(settle_s / dt), round(average_s / dt)
    heights = []
    for i in range(steps):
        soil.Advance(dt)
        mujoco.mj_step(model, data)
        if i >= steps - tail:
            heights.append(float(data.xpos[model.body("plate").id, 2]))
    return THICK - float(np.mean(heights))


def chrono_plate(
    params: Any, mass: float, settle_s: float, average_s: float, collision: str = "bullet"
) -> tuple[float, int]:
    """Static sinkage [m] and the number of grid nodes Chrono's ray casts hit under the plate,
    on the named collision system."""
    chrono = import_pychrono()
    dt = 0.0005
    system = chrono.ChSystemSMC()
    system.SetGravitationalAcceleration(chrono.ChVector3d(0, 0, -G))
    set_collision_system(chrono, system, collision)
    material = chrono.ChContactMaterialSMC()
    side = 2 * HALF
    plate = chrono.ChBodyEasyBox(side, side, 2 * THICK, mass / (side * side * 2 * THICK), False)
    plate.SetPos(chrono.ChVector3d(0, 0, THICK + 1e-4))
    plate.AddCollisionShape(chrono.ChCollisionShapeBox(material, side, side, 2 * THICK))
    plate.EnableCollision(True)
    system.AddBody(plate)
    ground = chrono.ChBody()
    ground.SetFixed(True)
    system.AddBody(ground)
    slide = chrono.ChLinkLockPrismatic()  # along the frame's z
    slide.Initialize(plate, ground, chrono.ChFramed(chrono.ChVector3d(0, 0, 0)))
    damper = chrono.ChLinkTSDA()
    damper.Initialize(plate, ground, False, chrono.ChVector3d(0, 0, 0), chrono.ChVector3d(0, 0, 1))
    damper.SetSpringCoefficient(0.0)
    damper.SetDampingCoefficient(slide_damping(params, mass))
    system.AddLink(slide)
    system.AddLink(damper)
    soil = ChronoSCM(system, params, (0.5, 0.4), RES, [(plate, (0, 0, 0), (0.4, 0.4, 0.2))])
    steps, tail = round(settle_s / dt), round(average_s / dt)
    heights = []
    for i in range(steps):
        soil.Synchronize(system.GetChTime())
        soil.Advance(dt)
        system.DoStepDynamics(dt)
        if i >= steps - tail:
            heights.append(float(body_pos(plate)[2]))
    return THICK - float(np.mean(heights)), int(soil.terrain.GetNumRayHits())


def ray_error(collision: str, shape: str) -> float:
    """The largest distance [m] between a hit that Chrono's ``RayHit`` reports and the
    shape's true surface, for vertical rays every 0.25 mm from the centre to 2 cm outside the
    outline of a moving shape: the 0.21 m plate, or a 2 cm sphere (a Go1 foot). The shape
    moves down at 0.5 m/s for two 0.5 ms steps (rays see its pose at the last step's start)."""
    chrono = import_pychrono()
    system = chrono.ChSystemSMC()
    system.SetGravitationalAcceleration(chrono.ChVector3d(0, 0, 0))
    set_collision_system(chrono, system, collision)
    material = chrono.ChContactMaterialSMC()
    body = chrono.ChBody()
    half = np.array([HALF, HALF, THICK / 2])
    if shape == "plate":
        body.AddCollisionShape(chrono.ChCollisionShapeBox(material, *(2 * half)))
        edge = HALF
    else:
        body.AddCollisionShape(chrono.ChCollisionShapeSphere(material, FOOT_RADIUS))
        edge = FOOT_RADIUS
    body.EnableCollision(True)
    body.SetPos(chrono.ChVector3d(0, 0, 0.05))
    body.SetPosDt(chrono.ChVector3d(0, 0, -0.5))
    system.AddBody(body)
    for _ in range(2):
        system.DoStepDynamics(0.0005)
    centre = np.array([0.0, 0.0, 0.05 - 0.5 * 0.0005])
    result = chrono.ChRayhitResult()
    worst = 0.0
    for x in np.arange(0.0, edge + 0.02, 0.00025):
        start, end = chrono.ChVector3d(x, 0, -0.5), chrono.ChVector3d(x, 0, 0.5)
        if not (system.GetCollisionSystem().RayHit(start, end, result) and result.hit):
            continue
        p = np.array([x, 0.0, result.abs_hitPoint.z]) - centre
        if shape == "plate":
            q = np.abs(p) - half
            distance = np.linalg.norm(np.maximum(q, 0.0)) + min(q.max(), 0.0)
        else:
            distance = np.linalg.norm(p) - FOOT_RADIUS
        worst = max(worst, abs(float(distance)))
    return worst


def lander_landing(engine: str, preset: str) -> dict[str, float]:
    """The default design's landing metrics on the preset's soil: ``mujoco``, ``chrono``
    (Bullet, the lander's 5 mm envelope) or ``chrono_envelope`` (Bullet, 0.1 mm)."""
    from chronogym.tasks.lander import Terrain, simulate_landing

    terrain = Terrain(soil=preset)
    if engine == "mujoco":
        metrics = simulate_landing(terrain=terrain)
    else:
        from chronogym.tasks.lander.chrono.model import ChronoSettings
        from chronogym.tasks.lander.chrono.sim import simulate_chrono_landing

        small = {"envelope": 1e-4, "margin": 1e-4} if engine == "chrono_envelope" else {}
        metrics = simulate_chrono_landing(terrain=terrain, settings=ChronoSettings(**small))
    keys = ("a_max", "E_abs", "E_soil", "max_sinkage", "max_stroke", "J")
    return {key: float(metrics[key]) for key in keys}


#: The Chrono Go1's variants: ChronoGo1Settings fields. Bullet's collision envelope inflates
#: every shape its ray casts see; Chrono's ``hitPoint - normal * envelope`` puts the depth
#: back, not the footprint, which grows by the envelope. On SCM the Go1's default is 0.1 mm;
#: ``chrono_envelope`` runs it at its rigid-ground 5 mm.
GO1_CHRONO = {
    "chrono": {},
    "chrono_envelope": {"envelope": 0.005, "margin": 0.002},
    "chrono_multicore": {"collision": "multicore"},
}


def go1_standing(engine: str, preset: str, stand_s: float) -> dict[str, float]:
    """Mean foot sinkage and base height of the Go1 standing on ``engine``'s soil:
    ``mujoco``, or a :data:`GO1_CHRONO` variant, on the same 1 cm grid."""
    if engine == "mujoco":
        env = gym.make("chronogym/Go1Velocity-v0", terrain="soil", soil=preset, soil_resolution=RES)
    else:
        from chronogym.tasks.quadruped.chrono_model import ChronoGo1Settings

        env = gym.make(
            "chronogym/ChronoGo1Velocity-v0",
            terrain="scm",
            soil=preset,
            soil_resolution=RES,
            settings=ChronoGo1Settings(**GO1_CHRONO[engine]),
        )
    env.reset(seed=0, options={"command": (0.0, 0.0, 0.0)})
    task = env.unwrapped.task
    zero = np.zeros(12, dtype=np.float32)
    fell = False
    decisions = round(stand_s / task.control_dt)
    start = time.perf_counter()
    for _ in range(decisions):
        terminated = env.step(zero)[2]
        fell = fell or terminated
    step_s = (time.perf_counter() - start) / decisions
    feet_z = task.feet_positions()[:, 2]
    height = task._base_height()
    env.close()
    sinkage = float(np.mean(FOOT_RADIUS - feet_z))
    return {"foot_sinkage": sinkage, "base_height": height, "fell": fell, "step_s": step_s}


ROW_KEYS = (
    "problem",
    "quantity",
    "closed_form",
    "chronogym",
    "chrono",
    "difference",
    "chrono_nodes",
    "plate_nodes",
    "closed_form_on_chrono_nodes",
    "chrono_envelope_varied",
    "chrono_multicore",
    "multicore_nodes",
)


def row(**cells: Any) -> dict[str, Any]:
    """A table row: ``cells``, and ``None`` for every other column."""
    unknown = set(cells) - set(ROW_KEYS)
    if unknown:
        raise KeyError(f"unknown row keys {sorted(unknown)}")
    return {key: None for key in ROW_KEYS} | cells


def engine_rows(
    problem: str, results: dict[str, dict[str, float]], quantities: tuple
) -> list[dict[str, Any]]:
    """Table rows of one problem: per (key, label, scale) each engine's value (``None``
    where an engine did not run it)."""
    rows = []
    for key, label, scale in quantities:
        mj, ch = results["mujoco"][key], results["chrono"][key]
        others = {
            column: scale * results[engine][key]
            for column, engine in (
                ("chrono_envelope_varied", "chrono_envelope"),
                ("chrono_multicore", "chrono_multicore"),
            )
            if engine in results
        }
        rows.append(
            row(
                problem=problem,
                quantity=label,
                chronogym=scale * mj,
                chrono=scale * ch,
                difference=(mj - ch) / ch,
                **others,
            )
        )
    return rows


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--settle-s", type=float, default=2.0)
    parser.add_argument("--average-s", type=float, default=0.5)
    parser.add_argument("--stand-s", type=float, default=2.0)
    parser.add_argument("--go1-soil", default="firm")
    parser.add_argument("--lander-soil", default="mars")
    parser.add_argument(
        "--no-multicore",
        action="store_true",
        help="skip the Chrono runs on its multicore collision system (needs Thrust)",
    )
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args(argv)
    if not 0 < args.average_s <= args.settle_s or not args.stand_s > 0:
        parser.error("expected 0 < --average-s <= --settle-s and --stand-s > 0")
    multicore = not args.no_multicore
    rows = []
    for shape, label in (("plate", "a moving 0.21 m plate"), ("sphere", "a moving 2 cm sphere")):
        bullet = ray_error("bullet", shape)
        rows.append(
            row(
                problem=f"ray hits on {label}",
                quantity="worst error [mm]",
                closed_form=0.0,
                chrono=1e3 * bullet,
                chrono_multicore=1e3 * ray_error("multicore", shape) if multicore else None,
            )
        )
    for name, mass in PLATES:
        params = soil_preset(name)
        closed = bekker_sinkage(params, mass * G)
        mj = mujoco_plate(params, mass, args.settle_s, args.average_s)
        ch, hits = chrono_plate(params, mass, args.settle_s, args.average_s)
        mc, mc_hits = (
            chrono_plate(params, mass, args.settle_s, args.average_s, "multicore")
            if multicore
            else (None, None)
        )
        hit_side = math.sqrt(hits) * RES  # the square of nodes Chrono loads
        rows.append(
            row(
                problem=f"plate {name} {mass:g} kg",
                quantity="sinkage [mm]",
                closed_form=1e3 * closed,
                chronogym=1e3 * mj,
                chrono=1e3 * ch,
                difference=(mj - ch) / ch,
                chrono_nodes=hits,
                plate_nodes=round(2 * HALF / RES) ** 2,
                closed_form_on_chrono_nodes=1e3 * bekker_sinkage(params, mass * G, hit_side),
                chrono_multicore=None if mc is None else 1e3 * mc,
                multicore_nodes=mc_hits,
            )
        )
    landing = {
        e: lander_landing(e, args.lander_soil) for e in ("mujoco", "chrono", "chrono_envelope")
    }
    rows += engine_rows(
        f"lander default {args.lander_soil}",
        landing,
        (
            ("a_max", "a_max [m/s^2]", 1.0),
            ("E_abs", "E_abs [J]", 1.0),
            ("E_soil", "soil's work [J]", 1.0),
            ("max_sinkage", "deepest rut [mm]", 1e3),
            ("max_stroke", "max stroke [mm]", 1e3),
        ),
    )
    engines = ("mujoco", "chrono", "chrono_envelope") + (("chrono_multicore",) if multicore else ())
    stand = {e: go1_standing(e, args.go1_soil, args.stand_s) for e in engines}
    rows += engine_rows(
        f"go1 standing {args.go1_soil}",
        stand,
        (
            ("foot_sinkage", "foot sinkage [mm]", 1e3),
            ("base_height", "base height [mm]", 1e3),
            ("step_s", "ms per decision", 1e3),
        ),
    )
    columns = [
        Column("problem", 38, align="<", key="problem"),
        Column("quantity", 18, align="<", key="quantity"),
        Column("Bekker", 8, "{:.2f}", key="closed_form"),
        Column("chronogym SCM", 13, "{:.2f}", key="chronogym"),
        Column("Chrono SCM", 10, "{:.2f}", key="chrono"),
        Column("diff", 7, "{:+.1%}", key="difference"),
        Column("Chrono nodes", 12, "{}", key="chrono_nodes"),
        Column("Bekker on them", 14, "{:.2f}", key="closed_form_on_chrono_nodes"),
        Column("envelope varied", 15, "{:.2f}", key="chrono_envelope_varied"),
        Column("multicore", 9, "{:.2f}", key="chrono_multicore"),
        Column("its nodes", 9, "{}", key="multicore_nodes"),
    ]
    print(table(columns, rows, rule=True))
    record = {**header("soil_cross_check", "mujoco"), "settings": settings(args)}
    record["go1"] = stand
    record["lander"] = landing
    write_json(args.out, {**record, "rows": rows})


if __name__ == "__main__":
    main()
