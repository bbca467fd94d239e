"""PPO with the update overlapped with the next rollout (policy_lag=1) against synchronous PPO.

Real RSL-RL, real MuJoCo cart-pole, real Ray. Lag 0 must reproduce RSL-RL's own training
loop (``OnPolicyRunner.learn``) weight for weight; lag 1 must be deterministic for a seed,
record a lag of exactly 1 after the first update, and still learn.
"""

from __future__ import annotations

import copy
import csv

import pytest

pytest.importorskip("rsl_rl")

import torch
from gymnasium.vector import AutoresetMode

import chronogym
from chronogym.rl import RslRlVecEnv, ppo_train_config, train
from chronogym.rl.progress import progress_columns

CARTPOLE = "chronogym/CartPole-v0"
TIMING = ("wall_time", "collect_s", "learn_s", "eval_s")
SEED = 3


def cfg(**overrides):
    small = {"hidden_dims": [16, 16]}
    return ppo_train_config(
        num_steps_per_env=8,
        actor=small,
        critic=small,
        algorithm={"num_learning_epochs": 2, "num_mini_batches": 2},
        **overrides,
    )


def vec(backend: str = "serial", num_envs: int = 4):
    kwargs = {"envs_per_worker": 2} if backend == "ray" else {}
    return chronogym.make_vec(
        CARTPOLE, num_envs, backend=backend, autoreset_mode=AutoresetMode.SAME_STEP, **kwargs
    )


def rows(path) -> list[dict[str, str]]:
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


def untimed(table: list[dict[str, str]]) -> list[dict[str, str]]:
    return [{k: v for k, v in row.items() if k not in TIMING} for row in table]


def trained(tmp_path, backend: str, policy_lag: int, iterations: int = 4):
    env = vec(backend)
    try:
        result = train(
            env, tmp_path, iterations=iterations, train_cfg=cfg(), seed=SEED,
            policy_lag=policy_lag, progress=False,
        )  # fmt: skip
    finally:
        env.close()
    weights = torch.load(result.checkpoint, weights_only=True)["actor_state_dict"]
    return rows(result.csv_path), weights


def test_lag_zero_reproduces_rsl_rl_own_loop(tmp_path):
    from rsl_rl.runners import OnPolicyRunner

    table, ours = trained(tmp_path / "ours", "serial", policy_lag=0, iterations=3)
    torch.set_num_threads(1)
    torch.manual_seed(SEED)
    env = RslRlVecEnv(vec(), seed=SEED)
    try:
        runner = OnPolicyRunner(env, copy.deepcopy(cfg()), log_dir=None, device="cpu")
        runner.learn(3)
    finally:
        env.close()
    theirs = runner.alg.actor.state_dict()
    assert ours.keys() == theirs.keys()
    for key in ours:
        assert torch.equal(ours[key], theirs[key]), key
    assert [int(r["policy_lag"]) for r in table] == [0, 0, 0]


def test_lag_one_is_deterministic_bounded_and_differs_from_lag_zero(ray_cluster, tmp_path):
    first, weights = trained(tmp_path / "a", "ray", policy_lag=1)
    second, again = trained(tmp_path / "b", "serial", policy_lag=1)
    assert tuple(first[0]) == progress_columns(())  # a cart-pole reports no metric
    assert untimed(first) == untimed(second)  # Ray == serial, whatever the thread timing
    for key in weights:
        assert torch.equal(weights[key], again[key]), key
    assert [int(r["policy_lag"]) for r in first] == [0, 1, 1, 1]  # versions tracked, bounded
    _, synchronous = trained(tmp_path / "c", "serial", policy_lag=0)
    assert any(not torch.equal(weights[k], synchronous[k]) for k in weights)


def test_lag_one_learns_cartpole(tmp_path):
    env = vec(num_envs=8)
    try:
        result = train(
            env, tmp_path, iterations=60, seed=0, policy_lag=1, progress=False,
            train_cfg=ppo_train_config(num_steps_per_env=16, actor={"hidden_dims": [32, 32]},
                                       critic={"hidden_dims": [32, 32]}),
        )  # fmt: skip
    finally:
        env.close()
    rewards = [float(r["mean_reward"]) for r in rows(result.csv_path)]
    early = [r for r in rewards[:10] if r == r]
    assert max(rewards[-10:]) > 2 * max(early), (early, rewards[-10:])


@pytest.mark.parametrize("bad", [-1, 2, 0.5, True, "1"])
def test_bad_policy_lag_names_the_value(tmp_path, bad):
    with pytest.raises(ValueError, match=rf"policy_lag={bad!r}"):
        train(None, tmp_path, iterations=1, policy_lag=bad)


def test_default_training_twice_gives_the_same_rows(ray_cluster, tmp_path):
    from chronogym.tasks.quadruped.training import quadruped_train_config, train_quadruped

    small = {"hidden_dims": [16, 16]}
    tiny = quadruped_train_config(num_steps_per_env=6, actor=small, critic=small)
    tables = []
    for run in ("a", "b"):
        result = train_quadruped(
            tmp_path / run, num_envs=4, envs_per_worker=2, iterations=3, seed=5,
            train_cfg=tiny, progress=False,
        )  # fmt: skip
        tables.append(rows(result.csv_path))
    assert untimed(tables[0]) == untimed(tables[1])
    # the default: synchronous PPO, its update on every core (2 threads on a 2-CPU machine)
    assert [int(r["policy_lag"]) for r in tables[0]] == [0, 0, 0]


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"update_threads": 0}, "update_threads=0: expected an integer >= 1"),
        ({"torch_threads": True}, "torch_threads=True: expected an integer >= 1"),
        ({"update_threads": 2, "policy_lag": 1}, "update_threads=2 with policy_lag=1"),
    ],
)
def test_bad_thread_counts_name_the_value(tmp_path, kwargs, message):
    with pytest.raises(ValueError, match=message):
        train(None, tmp_path, iterations=1, **kwargs)
