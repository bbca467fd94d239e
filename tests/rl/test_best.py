"""best.pt: every saved checkpoint is scored, the best by the walking criterion is kept."""

from __future__ import annotations

import csv
import json
import math
from dataclasses import dataclass

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("rsl_rl")

import chronogym  # noqa: F401
from chronogym.rl.best import BestCheckpoint
from chronogym.rl.progress import TIMING_COLUMNS
from chronogym.tasks.quadruped.engines import ENV_ID
from chronogym.tasks.quadruped.evaluation import run_episode, run_episodes_together
from chronogym.tasks.quadruped.training import (
    quadruped_train_config,
    train_quadruped,
    walking_evaluator,
)
from chronogym.tasks.quadruped.walking import CommandCheck, WalkingVerdict

SHORT = {"max_episode_steps": 40}  # short episodes keep the evaluations cheap


@dataclass
class ScriptedScore:
    """A score chosen by the test for each checkpoint name."""

    passed: int
    worst: float

    def verdict(self) -> WalkingVerdict:
        def check(i):
            failures = () if i < self.passed else ("steady state: made up",)
            values = dict(rise_s=None, x_mse=0.0, y_mse=0.0, yaw_mse=None, episode_x_mse=0.0,
                          episode_y_mse=0.0, ratio=self.worst)  # fmt: skip
            return CommandCheck(f"c{i}", (0.0, 0.0, 0.0), 1, 1, failures=failures, **values)

        return WalkingVerdict(tuple(check(i) for i in range(self.passed + 1)), 7)

    def key(self) -> tuple[float, ...]:
        return self.verdict().key()

    def describe(self) -> str:
        return self.verdict().describe()

    def columns(self) -> dict[str, float]:
        return {"passed": self.passed}


class ScriptedEvaluator:
    columns = ("passed",)

    def __init__(self, scores: dict[str, ScriptedScore]) -> None:
        self.scores = scores

    def __call__(self, checkpoint):
        return self.scores[checkpoint.name]


def write_checkpoints(folder, names):
    for name in names:
        (folder / name).write_bytes(name.encode())


def test_the_best_is_more_groups_passed_then_a_smaller_worst_ratio(tmp_path):
    scores = {
        "model_0.pt": ScriptedScore(0, 0.2),
        "model_1.pt": ScriptedScore(3, 0.05),
        "model_2.pt": ScriptedScore(2, 0.001),  # fewer commands pass: not better
        "model_3.pt": ScriptedScore(3, 0.02),  # same commands, smaller MSE: better
        "model_4.pt": ScriptedScore(3, 0.02),  # a tie keeps the earlier one
    }
    write_checkpoints(tmp_path, scores)
    best = BestCheckpoint(tmp_path, ScriptedEvaluator(scores))
    for it, name in enumerate(scores):
        values = best.consider(it, 100 * (it + 1), tmp_path / name)
        assert values["passed"] == scores[name].passed and values["eval_s"] >= 0
    assert (tmp_path / "best.pt").read_bytes() == b"model_3.pt"
    record = json.loads((tmp_path / "best.json").read_text())
    assert record["iteration"] == 3 and record["env_steps"] == 400
    assert record["source"] == "model_3.pt"
    assert "3/7 pass (v2); first failure: c3: steady state: made up" in best.summary()


def test_a_resumed_run_keeps_the_best_of_the_earlier_part(tmp_path):
    scores = {"model_0.pt": ScriptedScore(4, 0.01), "model_1.pt": ScriptedScore(2, 0.01)}
    write_checkpoints(tmp_path, scores)
    BestCheckpoint(tmp_path, ScriptedEvaluator(scores)).consider(0, 10, tmp_path / "model_0.pt")
    resumed = BestCheckpoint(tmp_path, ScriptedEvaluator(scores), resumed=True)
    resumed.consider(1, 20, tmp_path / "model_1.pt")
    assert (tmp_path / "best.pt").read_bytes() == b"model_0.pt"
    assert json.loads((tmp_path / "best.json").read_text())["iteration"] == 0


def test_episodes_in_step_give_the_results_of_one_at_a_time():
    policy = ZeroPolicy()
    jobs = [((0.5, 0.0, 0.0), 0), ((0.0, 0.2, 0.0), 1), ((0.0, 0.0, 0.0), 2)]
    envs = [gym.make(ENV_ID, **SHORT) for _ in jobs]
    single = gym.make(ENV_ID, **SHORT)
    try:
        together = run_episodes_together(envs, policy, jobs)
        alone = [run_episode(single, policy, command, seed) for command, seed in jobs]
    finally:
        for env in [*envs, single]:
            env.close()
    assert together == alone
    for a, b in zip(together, alone, strict=True):
        np.testing.assert_array_equal(a.trace.vx, b.trace.vx)
        np.testing.assert_array_equal(a.trace.wz, b.trace.wz)
        np.testing.assert_array_equal(a.trace.commands, b.trace.commands)


class ZeroPolicy:
    """The home pose: the Go1 stands."""

    def __call__(self, obs):
        obs = np.asarray(obs)
        return np.zeros((*obs.shape[:-1], 12), dtype=np.float32)


def train_tiny(out, seed=0):
    cfg = quadruped_train_config(num_steps_per_env=8, save_interval=2)
    return train_quadruped(
        out, num_envs=4, backend="serial", iterations=6, seed=seed, train_cfg=cfg,
        task_kwargs=SHORT, eval_episodes=1, progress=False, update_threads=1,
    )  # fmt: skip


def read_rows(path):
    with path.open(newline="") as handle:
        return list(csv.DictReader(handle))


def test_training_keeps_the_checkpoint_the_criterion_ranks_first(tmp_path):
    result = train_tiny(tmp_path / "run")
    run = tmp_path / "run"
    rows = read_rows(run / "progress.csv")
    evaluated = [r for r in rows if r["eval_commands_passed"] != "nan"]
    assert [int(r["iteration"]) for r in evaluated] == [1, 3, 5]  # the save points
    assert all(float(r["eval_s"]) > 0 for r in evaluated)
    assert all(math.isnan(float(r["eval_worst_ratio"])) for r in rows if r not in evaluated)
    assert len({r["eval_worst_ratio"] for r in evaluated}) > 1  # the ranking has a choice

    def key(r):
        return (int(r["eval_commands_passed"]), -float(r["eval_worst_ratio"]))

    winner = max(evaluated, key=key)  # max keeps the first of equals, as best.pt does
    record = json.loads((run / "best.json").read_text())
    assert record["iteration"] == int(winner["iteration"])
    assert record["env_steps"] == int(winner["env_steps"])
    source = run / f"model_{winner['iteration']}.pt"
    assert (run / "best.pt").read_bytes() == source.read_bytes()
    assert result.best.startswith(f"best checkpoint {run / 'best.pt'} = {source.name}")

    # the evaluator sees what `chronogym play` sees: rejudging best.pt gives its row again
    evaluator = walking_evaluator("mujoco", "rigid", SHORT, 1)
    try:
        again = evaluator(run / "best.pt")
    finally:
        evaluator.close()
    assert evaluator.criterion.version == "v2" and evaluator.criterion.switch.at_s == 0.4
    assert again.commands_passed == int(winner["eval_commands_passed"])
    assert again.worst_ratio == pytest.approx(float(winner["eval_worst_ratio"]), rel=1e-9)


def test_the_same_seed_gives_the_same_rows_evaluations_included(tmp_path):
    train_tiny(tmp_path / "a", seed=3)
    train_tiny(tmp_path / "b", seed=3)
    timing = {"wall_time", "eval_s", *TIMING_COLUMNS}

    def untimed(run):
        return [{k: v for k, v in r.items() if k not in timing} for r in read_rows(run)]

    a, b = untimed(tmp_path / "a" / "progress.csv"), untimed(tmp_path / "b" / "progress.csv")
    assert a == b and "eval_worst_ratio" in a[0]


def test_eval_episodes_zero_keeps_no_best_and_the_plain_header(tmp_path):
    cfg = quadruped_train_config(num_steps_per_env=4, save_interval=1)
    result = train_quadruped(
        tmp_path, num_envs=2, backend="serial", iterations=1, train_cfg=cfg,
        task_kwargs=SHORT, eval_episodes=0, progress=False, update_threads=1,
    )  # fmt: skip
    assert result.best == "" and not (tmp_path / "best.pt").exists()
    assert "eval_s" not in read_rows(tmp_path / "progress.csv")[0]


@pytest.mark.parametrize("bad", [-1, 1.5, True, "2"])
def test_eval_episodes_must_be_a_count(tmp_path, bad):
    with pytest.raises(ValueError, match="eval_episodes"):
        train_quadruped(tmp_path, iterations=1, eval_episodes=bad)


@pytest.mark.parametrize("trained_with", [True, False])
def test_a_checkpoint_resumes_with_the_critic_it_was_trained_with(
    tmp_path, monkeypatch, trained_with
):
    from chronogym.tasks.quadruped import training as quadruped

    cfg = quadruped_train_config(num_steps_per_env=4, save_interval=1)
    common = dict(num_envs=2, backend="serial", train_cfg=cfg, eval_episodes=0, progress=False)
    first = train_quadruped(
        tmp_path, iterations=1, task_kwargs={**SHORT, "privileged_critic": trained_with}, **common
    )
    assert quadruped.critic_input_size(first.checkpoint) == (49 if trained_with else 48)
    # whatever the training default says now, the resumed run reads what the critic was built for
    monkeypatch.setattr(quadruped, "QUADRUPED_TASK", {"privileged_critic": not trained_with})
    second = train_quadruped(
        tmp_path, iterations=1, resume=first.checkpoint, task_kwargs=SHORT, **common
    )
    assert quadruped.critic_input_size(second.checkpoint) == (49 if trained_with else 48)
