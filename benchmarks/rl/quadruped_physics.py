"""Physics settings of the Go1 task: cost and contact quality of cone type and time step.

For each setting (friction cone, physics step ``dt``, ``k`` substeps per 20 ms policy step):
* ``raw_us``: one-core cost of the raw ``mj_step`` loop per policy step, under a walking-like
  load (the same seeded random joint targets for every setting);
* ``stand_h``: base height after 2 s standing at the home pose (penetration / sag);
* ``slip_mm``: how far the feet slide in 2 s on a 25 deg slope (friction 1.0 holds up to 45 deg,
  so an exact cone gives ~0);
* ``task_us`` and ``task/raw`` (the task's default setting only): the full ``SimEnv.step`` of
  ``Go1VelocityTask`` against the raw loop over the same states: the task's overhead.

With ``--policy CKPT`` it also plays a trained policy at each physics step of the elliptic,
impratio-100 settings (the walking criterion's commands and episodes, ``WalkingCriterion``):
a policy trained at one step that walks as well at the smaller ones has not learned to exploit
the step's error.

    python -m benchmarks.rl.quadruped_physics [--out benchmarks/results/quadruped_physics.json]
    python -m benchmarks.rl.quadruped_physics --policy runs/quadruped/latest.pt

Prints a table and writes JSON. Timings are one core, best of ``--repeats``.
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
from chronogym.env import SimEnv
from chronogym.tasks.quadruped import DEFAULT_JOINT_POS, FOOT_GEOM_NAMES, Go1VelocityTask
from chronogym.tasks.quadruped.model import go1_xml_path

DEFAULT_OUT = RESULTS / "quadruped_physics.json"
CONTROL_DT = 0.02
STEPS = 1500  # policy steps per timing
SETTINGS = [  # (cone, dt, impratio)
    ("pyramidal", 0.005, 1.0),
    ("elliptic", 0.005, 1.0),
    ("elliptic", 0.005, 100.0),
    ("pyramidal", 0.002, 1.0),
    ("elliptic", 0.002, 100.0),
    ("pyramidal", 0.01, 1.0),
    ("elliptic", 0.01, 100.0),
]


COLUMNS = (
    Column("cone", 9, key="cone"),
    Column("dt", 6, "{:.3f}", key="dt"),
    Column("impratio", 8, "{:.0f}", key="impratio"),
    Column("k", 3, "{:d}", key="k"),
    Column("raw_us", 8, "{:.1f}", key="raw_us"),
    Column("stand_h", 8, "{:.4f}", key="stand_h"),
    Column("slip_mm", 8, "{:.2f}", key="slip_mm"),
    Column("task_us", 8, "{:.1f}", key="task_us"),
    Column("task/raw", 8, "{:.2f}", key="task_over_raw"),
)


@dataclass
class Row:
    cone: str
    dt: float
    impratio: float
    k: int
    raw_us: float
    stand_h: float
    slip_mm: float
    task_us: float | None = None
    task_over_raw: float | None = None


def build(cone: str, dt: float, impratio: float) -> tuple[mujoco.MjModel, mujoco.MjData]:
    model = mujoco.MjModel.from_xml_path(str(go1_xml_path()))
    model.opt.cone = (
        mujoco.mjtCone.mjCONE_PYRAMIDAL if cone == "pyramidal" else (mujoco.mjtCone.mjCONE_ELLIPTIC)
    )
    model.opt.timestep = dt
    model.opt.impratio = impratio
    data = mujoco.MjData(model)
    return model, data


def home(model: mujoco.MjModel, data: mujoco.MjData) -> None:
    mujoco.mj_resetDataKeyframe(model, data, model.key("home").id)
    mujoco.mj_forward(model, data)


def action_sequence(steps: int, seed: int = 0) -> np.ndarray:
    """Smooth random joint targets around the home pose (walking-like contact changes)."""
    rng = np.random.default_rng(seed)
    noise = rng.normal(0.0, 0.5, size=(steps, 12))
    smooth = np.zeros_like(noise)
    for i in range(1, steps):
        smooth[i] = 0.8 * smooth[i - 1] + 0.2 * noise[i] * 3
    return DEFAULT_JOINT_POS + 0.25 * smooth


def raw_cost(model, data, k: int, targets: np.ndarray, repeats: int) -> float:
    best = math.inf
    for _ in range(repeats):
        home(model, data)
        start = time.perf_counter()
        for target in targets:
            data.ctrl[:] = target
            mujoco.mj_step(model, data, k)
            if data.qpos[2] < 0.12:  # fell: stand up again so the load stays walking-like
                home(model, data)
        best = min(best, time.perf_counter() - start)
    return best / len(targets) * 1e6


def stand_height(model, data) -> float:
    home(model, data)
    mujoco.mj_step(model, data, round(2.0 / model.opt.timestep))
    return float(data.qpos[2])


def slope_slip(model, data, degrees: float = 25.0) -> float:
    """Foot travel (mm) in 2 s standing on a slope, emulated by tilting gravity."""
    gravity = model.opt.gravity.copy()
    angle = math.radians(degrees)
    model.opt.gravity[:] = (9.81 * math.sin(angle), 0.0, -9.81 * math.cos(angle))
    home(model, data)
    mujoco.mj_step(model, data, round(0.5 / model.opt.timestep))  # settle
    sites = [model.site(name).id for name in FOOT_GEOM_NAMES]
    start = data.site_xpos[sites].copy()
    mujoco.mj_step(model, data, round(2.0 / model.opt.timestep))
    mujoco.mj_forward(model, data)
    model.opt.gravity[:] = gravity
    return float(np.linalg.norm(data.site_xpos[sites] - start, axis=1).max() * 1000)


def task_cost(env: SimEnv, targets: np.ndarray, repeats: int) -> tuple[float, float]:
    """(SimEnv.step, raw loop) cost per policy step over the same actions, same process."""
    task = env.task
    actions = ((targets - DEFAULT_JOINT_POS) / task.action_scale).astype(np.float32)
    best_task = best_raw = math.inf
    for _ in range(repeats):
        env.reset(seed=0)
        start = time.perf_counter()
        for action in actions:
            _, _, terminated, _, _ = env.step(action)
            if terminated:
                env.reset()
        best_task = min(best_task, time.perf_counter() - start)
        best_raw = min(best_raw, raw_cost(task.model, task.data, task.k, targets, 1))
    return best_task / len(targets) * 1e6, best_raw


def policy_across_steps(checkpoint: Path, rows: list[Row]) -> list[dict]:
    """The walking criterion's summary of ``checkpoint`` at each elliptic, impratio-100 step."""
    from chronogym.rl.trainer import load_policy
    from chronogym.tasks.quadruped.evaluation import WalkingCriterion, evaluate, summarize
    from chronogym.tasks.quadruped.training import checkpoint_task_kwargs

    criterion = WalkingCriterion()
    policy = load_policy(checkpoint)
    observations = checkpoint_task_kwargs(checkpoint)  # what the policy was trained to read
    results = []
    for row in rows:
        if (row.cone, row.impratio) != ("elliptic", 100.0):
            continue
        env = SimEnv(Go1VelocityTask(dt=row.dt, k=row.k, **observations))
        episodes = evaluate(
            env,
            policy,
            commands=criterion.commands,
            episodes=criterion.episodes,
            seed=criterion.seed,
            progress=False,
            switch=criterion.switch,
        )
        summary = summarize(episodes, criterion)
        env.close()
        results.append({
            "dt": row.dt, "k": row.k,
            "walks": all(r["v2"] for r in summary),
            "walks_v1": all(r["v1"] for r in summary if r["v1"] is not None),
            "commands_passed": sum(r["v2"] for r in summary),
            "min_survival": min(r["survival"] for r in summary),
            "worst_x_mse": max(r["x_vel_mse"] for r in summary),
            "worst_y_mse": max(r["y_vel_mse"] for r in summary),
            "per_command": summary,
        })  # fmt: skip
    return results


POLICY_COLUMNS = (
    Column("dt", 6, "{:.3f}", key="dt"),
    Column("k", 3, "{:d}", key="k"),
    Column("walks", 6, key="walks"),
    Column("passed", 6, "{:d}", key="commands_passed"),
    Column("survival", 8, "{:.2f}", key="min_survival"),
    Column("worst x_mse", 11, "{:.4f}", key="worst_x_mse"),
    Column("worst y_mse", 11, "{:.4f}", key="worst_y_mse"),
)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    parser.add_argument("--repeats", type=int, default=3)
    parser.add_argument("--policy", type=Path, default=None, help="a checkpoint to play")
    args = parser.parse_args()
    if args.policy is not None and not args.policy.is_file():
        parser.error(f"--policy={args.policy}: no such checkpoint file")
    targets = action_sequence(STEPS)
    rows: list[Row] = []
    for cone, dt, impratio in SETTINGS:
        model, data = build(cone, dt, impratio)
        k = round(CONTROL_DT / dt)
        rows.append(
            Row(
                cone=cone,
                dt=dt,
                impratio=impratio,
                k=k,
                raw_us=raw_cost(model, data, k, targets, args.repeats),
                stand_h=stand_height(model, data),
                slip_mm=slope_slip(model, data),
            )
        )
    env = SimEnv(Go1VelocityTask(max_episode_steps=None))
    task = env.task
    setting = (task.cone, task.dt, task.impratio)
    chosen = next(row for row in rows if (row.cone, row.dt, row.impratio) == setting)
    task_us, raw_us = task_cost(env, targets, args.repeats)
    chosen.task_us = task_us
    chosen.task_over_raw = task_us / raw_us
    print(table(COLUMNS, rows, sep=" ", missing=""))
    played = policy_across_steps(args.policy, rows) if args.policy is not None else None
    if played is not None:
        print(f"\npolicy {args.policy} (trained at the task's default step) at each step:")
        print(table(POLICY_COLUMNS, played, sep=" "))
    result = {
        **header("quadruped_physics"),
        **versions("mujoco"),  # also a top-level key, as in the committed JSON
        "control_dt": CONTROL_DT,
        "policy_steps": STEPS,
        "rows": [asdict(row) for row in rows],
    }
    if played is not None:
        result["policy"] = {"checkpoint": str(args.policy), "default_dt": task.dt,
                            "steps": played}  # fmt: skip
    write_json(args.out, result)


if __name__ == "__main__":
    main()
