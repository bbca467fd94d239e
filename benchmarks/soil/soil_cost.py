"""Cost of SCM soil (``chronogym.terrain.MujocoSoil``) against rigid ground for the Go1.

The same seeded smooth random joint targets as ``quadruped_physics.py`` (walking-like contact
changes) drive the Go1 at the task's contact settings (elliptic cone, impratio 100) with 5 ms
physics steps, 4 per 20 ms policy step, for the same number of physics steps on:

* ``rigid``: the floor plane, ``mj_step(model, data, 4)`` per policy step;
* ``<preset>/feet``: soil under the four foot spheres; the floor keeps touching the rest;
* ``<preset>/legs``: soil under the four calf bodies (calf capsule + foot sphere).

Soil rows step ``soil.Advance(dt)`` + ``mj_step`` once per physics step (the advanceables
``[soil, (model, data)]``), with the floor excluded from the soil's geoms. Columns: one-core
µs per physics step (best of ``--repeats``), ratio to rigid, mean base height, deepest sinkage,
falls (base below 0.12 m: the robot and the soil are reset, and the reset is timed; the sinkage
statistic read before it is not) and MuJoCo contacts (mean over the policy steps; on soil the
floor only touches geoms the soil does not hold). The first soil tick in the process compiles
the numba kernel (or loads it from the cache); it is timed apart (``first_advance_s``) and not
counted in the rows.

A second table times the Go1 task itself (``SimEnv.step``: observation, reward, the soil window
following the trunk) at each terrain's default physics step (``PHYSICS_STEP``: rigid 10 ms x 2,
soil 2 ms x 10, the smaller step that the soil's explicit force law needs): the cost of a soil
episode against a rigid one, as training pays it.

    python -m benchmarks.soil.soil_cost [--out benchmarks/results/soil_cost.json]
"""

from __future__ import annotations

import argparse
import math
import time
from dataclasses import asdict, dataclass
from pathlib import Path

import mujoco
import numpy as np

import chronogym  # noqa: F401  (sets the GL backend before mujoco rendering is touched)
from benchmarks.common import RESULTS, Column, header, table, versions, write_json
from benchmarks.rl.quadruped_physics import action_sequence  # same seeded targets
from chronogym.env import SimEnv
from chronogym.tasks.quadruped import FOOT_GEOM_NAMES, LEG_NAMES, load_go1
from chronogym.terrain import MujocoSoil

DEFAULT_OUT = RESULTS / "soil_cost.json"
DT, SUBSTEPS = 0.005, 4
EXTENT, RESOLUTION = (8.0, 8.0), 0.01
SETTINGS = [  # (name, preset or None for rigid, soil geoms)
    ("rigid", None, None),
    ("firm/feet", "firm", "feet"),
    ("soft/feet", "soft", "feet"),
    ("firm/legs", "firm", "legs"),
    ("soft/legs", "soft", "legs"),
]


ROW_COLUMNS = (
    Column("setting", 10, key="setting"),
    Column("us/step", 8, "{:.1f}", key="us_per_step"),
    Column("ratio", 6, "{:.2f}", key="ratio"),
    Column("base_h", 7, "{:.3f}", key="base_height"),
    Column("sink_mm", 8, "{:.1f}", key="max_sinkage_mm"),
    Column("falls", 5, "{:d}", key="falls"),
    Column("ncon", 5, "{:.2f}", key="contacts_per_step"),
)
EPISODE_COLUMNS = (
    Column("terrain", 8, key="terrain"),
    Column("dt_ms", 6, "{:.1f}", key="dt_ms"),
    Column("k", 3, "{:d}", key="k"),
    Column("us/policy step", 15, "{:.1f}", key="us_per_policy_step"),
    Column("ratio", 6, "{:.2f}", key="ratio"),
)


@dataclass
class Row:
    setting: str
    us_per_step: float
    ratio: float
    base_height: float
    max_sinkage_mm: float
    falls: int
    contacts_per_step: float


def build(preset: str | None, holds: str | None):
    model, data = load_go1()
    model.opt.cone = mujoco.mjtCone.mjCONE_ELLIPTIC
    model.opt.impratio = 100.0
    model.opt.timestep = DT
    if preset is None:
        return model, data, None
    where = (
        {"geoms": FOOT_GEOM_NAMES}
        if holds == "feet"
        else {"bodies": [f"{leg}_calf" for leg in LEG_NAMES]}
    )
    soil = MujocoSoil(model, data, preset, extent=EXTENT, resolution=RESOLUTION, **where)
    soil.exclude_ground("floor")
    return model, data, soil


def home(model, data, soil) -> None:
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    if soil is not None:
        soil.reset()
    mujoco.mj_forward(model, data)


def run(model, data, soil, targets: np.ndarray) -> tuple[float, dict]:
    """Seconds for the whole sequence, and what the robot did."""
    home(model, data, soil)
    heights, falls, contacts, sinkage = [], 0, 0, 0.0
    step = mujoco.mj_step
    bookkeeping = 0.0  # seconds spent on this script's statistics, not counted
    start = time.perf_counter()
    for target in targets:
        data.ctrl[:] = target
        if soil is None:
            step(model, data, SUBSTEPS)
        else:
            for _ in range(SUBSTEPS):
                soil.Advance(DT)
                step(model, data)
        contacts += data.ncon
        heights.append(data.qpos[2])
        if data.qpos[2] < 0.12:  # fell: stand up again so the load stays walking-like
            falls += 1
            if soil is not None:
                tick = time.perf_counter()  # a full-field scan (ms on 8 x 8 m): not soil cost
                sinkage = max(sinkage, float(soil.sinkage.max()))
                bookkeeping += time.perf_counter() - tick
            home(model, data, soil)
    elapsed = time.perf_counter() - start - bookkeeping
    if soil is not None:
        sinkage = max(sinkage, float(soil.sinkage.max()))
    stats = {
        "base_height": float(np.mean(heights)),
        "max_sinkage_mm": 1000 * sinkage,
        "falls": falls,
        "contacts_per_step": contacts / len(targets),
    }
    return elapsed, stats


def task_episodes(targets: np.ndarray, repeats: int) -> list[dict]:
    """The Go1 task as training runs it (``SimEnv.step``, the task's physics step per terrain,
    ``PHYSICS_STEP``; on soil the window follows the trunk), the same targets."""
    from chronogym.tasks.quadruped import DEFAULT_JOINT_POS, Go1VelocityTask

    actions = ((targets - DEFAULT_JOINT_POS) / 0.25).astype(np.float32)
    rows, rigid_us = [], math.nan
    for terrain in ("rigid", "soil"):
        env = SimEnv(Go1VelocityTask(terrain=terrain, max_episode_steps=None))
        best = math.inf
        for _ in range(repeats):
            env.reset(seed=0, options={"command": (0.5, 0.0, 0.0)})
            start = time.perf_counter()
            for action in actions:
                _, _, terminated, _, _ = env.step(action)
                if terminated:
                    env.reset(seed=0, options={"command": (0.5, 0.0, 0.0)})
            best = min(best, time.perf_counter() - start)
        us = best / len(actions) * 1e6
        rigid_us = us if terrain == "rigid" else rigid_us
        task = env.task
        row = {"terrain": terrain, "dt": task.dt, "k": task.k, "us_per_policy_step": us}
        row["ratio"] = us / rigid_us
        if task.soil is not None:
            grid = task.soil.grid
            row["window_mb"] = grid.state.nbytes / 1e6
            row["archive_mb"] = grid.archive.nbytes / 1e6 if grid.archive is not None else 0.0
        rows.append(row)
        env.close()
    return rows


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    parser.add_argument("--repeats", type=int, default=10, help="best of (shared machines)")
    parser.add_argument("--steps", type=int, default=500, help="policy steps (x4 physics steps)")
    args = parser.parse_args()
    targets = action_sequence(args.steps)
    physics_steps = args.steps * SUBSTEPS
    rows: list[Row] = []
    rigid_us, first_advance_s = math.nan, math.nan
    for name, preset, holds in SETTINGS:
        model, data, soil = build(preset, holds)
        if soil is not None and math.isnan(first_advance_s):
            start = time.perf_counter()  # compiles the soil's kernel, or loads it from the cache
            soil.Advance(DT)
            first_advance_s = time.perf_counter() - start
        best, stats = math.inf, {}
        for _ in range(args.repeats):
            elapsed, stats = run(model, data, soil, targets)
            best = min(best, elapsed)
        us = best / physics_steps * 1e6
        if preset is None:
            rigid_us = us
        rows.append(Row(name, us, us / rigid_us, **stats))
    print(table(ROW_COLUMNS, rows, sep=" "))
    episodes = task_episodes(targets, max(1, args.repeats // 2))
    print("\nGo1 task, SimEnv.step at each terrain's default physics step (policy at 50 Hz):")
    print(table(EPISODE_COLUMNS, [{**r, "dt_ms": r["dt"] * 1e3} for r in episodes], sep=" "))
    result = {
        **header("soil_cost", "numba"),
        **versions("mujoco", "numpy", "numba"),  # also top-level keys, as in the committed JSON
        "first_advance_s": first_advance_s,
        "dt": DT,
        "substeps": SUBSTEPS,
        "physics_steps": physics_steps,
        "repeats": args.repeats,
        "resolution": RESOLUTION,
        "extent": EXTENT,
        "rows": [asdict(row) for row in rows],
        "task_episodes": episodes,
    }
    print(f"first soil tick (kernel compile or cache load): {first_advance_s:.2f} s")
    write_json(args.out, result)


if __name__ == "__main__":
    main()
