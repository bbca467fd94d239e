"""RSL-RL on chronogym: the VecEnv adapter, the PPO config, training, resuming, policies."""

from __future__ import annotations

import csv
import math
import sys

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("rsl_rl")
import torch

import chronogym
from chronogym.rl import (
    FINETUNE_PPO,
    RslRlVecEnv,
    load_policy,
    ppo_train_config,
    train,
)
from chronogym.rl.progress import progress_columns
from chronogym.tasks.cartpole import CartPoleTask

CARTPOLE = "chronogym/CartPole-v0"
LOG_ENV = "chronogym-test/LogCartPole-v0"
SAME_STEP = gym.vector.AutoresetMode.SAME_STEP
HORIZON = 3
METRICS = {"x_mse": "/metrics/x_vel_mse", "y_mse": "/metrics/y_vel_mse"}  # pinned columns


class LogCartPole(CartPoleTask):
    """A cart-pole that never falls (no noise, zero force) and reports ``info["log"]``
    on the last step of each episode, as the quadruped task does."""

    def __init__(self, **kwargs) -> None:
        super().__init__(reset_noise=0.0, **kwargs)
        self.steps = 0

    def reset(self, rng, options) -> None:
        super().reset(rng, options)
        self.steps = 0

    def apply_action(self, action: np.ndarray) -> None:
        self.steps += 1
        super().apply_action(np.zeros_like(action))

    def info(self) -> dict:
        if self.steps < self.max_episode_steps:
            return {}
        return {"log": {"/metrics/x_vel_mse": 0.25, "/metrics/y_vel_mse": 0.5, "/r/alive": 3.0}}


chronogym.register_task(LOG_ENV, LogCartPole, max_episode_steps=HORIZON)


def tiny_cfg(**algorithm):
    small = {"hidden_dims": [16, 16]}
    return ppo_train_config(
        num_steps_per_env=8,
        save_interval=50,
        actor=small,
        critic=small,
        algorithm={"num_learning_epochs": 1, "num_mini_batches": 2, **algorithm},
    )


def serial(env_id: str = CARTPOLE, num_envs: int = 2, **kwargs):
    return chronogym.make_vec(
        env_id, num_envs, backend="serial", autoreset_mode=SAME_STEP, **kwargs
    )


def read_rows(path) -> list[dict[str, str]]:
    with open(path, newline="") as handle:
        return list(csv.DictReader(handle))


# -- adapter ---------------------------------------------------------------------------
def test_import_is_lazy():
    import subprocess

    code = "import sys, chronogym.rl; print('torch' in sys.modules, 'rsl_rl' in sys.modules)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.split() == ["False", "False"]


def test_adapter_shapes_dtypes_and_fresh_tensors():
    env = RslRlVecEnv(serial(env_kwargs={"max_episode_steps": 5}), seed=1)
    try:
        assert (env.num_envs, env.num_actions, env.max_episode_length) == (2, 1, 5)
        assert env.cfg["id"] == CARTPOLE and env.cfg["backend"] == "SerialVectorEnv"
        obs = env.get_observations()
        assert obs.batch_size == torch.Size([2])
        assert obs["policy"].shape == (2, 4) and obs["policy"].dtype == torch.float32
        torch.testing.assert_close(obs["critic"], obs["policy"])
        before = obs["policy"].clone()
        obs["policy"].add_(100.0)
        torch.testing.assert_close(env.get_observations()["policy"], before)

        actions = torch.full((2, 1), 5.0)  # clipped to the [-1, 1] bounds, not rejected
        step = 0
        while step < 5:
            step += 1
            obs, rewards, dones, extras = env.step(actions)
            assert rewards.dtype == torch.float32 and rewards.shape == (2,)
            assert dones.dtype == torch.long and dones.shape == (2,)
            assert "log" not in extras
            obs["policy"].zero_()
            assert env.get_observations()["policy"].abs().sum() > 0
            if dones.any():
                break
        # the random start falls under full force or is cut off at the 5-step horizon
        timed_out = extras["time_outs"]
        assert timed_out.dtype == torch.bool
        if step == 5:
            assert timed_out.all() and dones.all()
        assert (env.episode_length_buf[dones.bool()] == 0).all()
        assert env.episodes_done == int(dones.sum())
    finally:
        env.close()


def test_time_outs_and_episode_log():
    env = RslRlVecEnv(serial(LOG_ENV, num_envs=2), seed=0)
    try:
        assert env.max_episode_length == HORIZON
        for step in range(1, 2 * HORIZON + 1):
            _, _, dones, extras = env.step(torch.zeros(2, 1))
            if step % HORIZON:
                assert not dones.any() and "log" not in extras
                assert not extras["time_outs"].any()
                assert env.episode_length_buf.tolist() == [step % HORIZON] * 2
            else:
                assert dones.tolist() == [1, 1] and extras["time_outs"].all()
                assert env.episode_length_buf.tolist() == [0, 0]
                log = extras["log"]
                assert set(log) == {"/metrics/x_vel_mse", "/metrics/y_vel_mse", "/r/alive"}
                torch.testing.assert_close(log["/metrics/x_vel_mse"], torch.full((2,), 0.25))
        assert env.episodes_done == 4
    finally:
        env.close()


def test_needs_same_step_autoreset():
    vec = chronogym.make_vec(CARTPOLE, 2, backend="serial")
    with pytest.raises(ValueError, match=r"SAME_STEP.*NextStep"):
        RslRlVecEnv(vec)
    vec.close()


def test_gymnasium_sync_vector_env_is_accepted():
    vec = gym.make_vec(
        CARTPOLE,
        2,
        vectorization_mode="sync",
        vector_kwargs={"autoreset_mode": SAME_STEP},
        max_episode_steps=7,
    )
    env = RslRlVecEnv(vec, seed=0)
    assert env.max_episode_length == 7
    env.close()


# -- config ----------------------------------------------------------------------------
def test_ppo_train_config_defaults_and_deep_merge():
    cfg = ppo_train_config()
    assert cfg["actor"]["hidden_dims"] == [512, 256, 128]
    assert cfg["actor"]["distribution_cfg"]["init_std"] == 1.0
    assert cfg["obs_groups"] == {"actor": ["policy"], "critic": ["critic"]}
    assert cfg["algorithm"]["learning_rate"] == 1e-3 and cfg["num_steps_per_env"] == 24
    cfg["actor"]["hidden_dims"].append(1)
    assert ppo_train_config()["actor"]["hidden_dims"] == [512, 256, 128]  # fresh copies

    tuned = ppo_train_config(algorithm=FINETUNE_PPO, actor={"hidden_dims": [8]})
    assert tuned["algorithm"]["learning_rate"] == 1e-5 and tuned["algorithm"]["clip_param"] == 0.02
    assert tuned["algorithm"]["gamma"] == 0.99  # untouched keys survive the merge
    assert tuned["actor"]["hidden_dims"] == [8] and tuned["actor"]["activation"] == "elu"


def test_ppo_train_config_unknown_key():
    with pytest.raises(ValueError, match="'num_step_per_env'"):
        ppo_train_config(num_step_per_env=8)


# -- training --------------------------------------------------------------------------
def test_train_checks_budget(tmp_path):
    for budget in ({}, {"iterations": 0}, {"minutes": -1.0}):
        with pytest.raises(ValueError):
            train(None, tmp_path, **budget)


def test_train_on_ray(ray_cluster, tmp_path):
    vec = chronogym.make_vec(CARTPOLE, 2, backend="ray", autoreset_mode=SAME_STEP)
    try:
        result = train(vec, tmp_path, iterations=2, train_cfg=tiny_cfg(), progress=False)
    finally:
        vec.close()
    rows = read_rows(result.csv_path)
    assert [int(r["iteration"]) for r in rows] == [0, 1]
    assert [int(r["env_steps"]) for r in rows] == [16, 32]
    assert result.iterations_done == 2 and result.env_steps == 32
    assert result.checkpoint == tmp_path / "model_1.pt" and result.checkpoint.exists()
    assert (tmp_path / "latest.pt").exists()
    assert any(p.name.startswith("events.out.tfevents") for p in tmp_path.iterdir())


def test_train_serial_resume_and_policy(tmp_path, capsys):
    env = RslRlVecEnv(serial(LOG_ENV), seed=0)
    try:
        first = train(
            env, tmp_path, iterations=2, train_cfg=tiny_cfg(), progress=False,
            progress_metrics=METRICS,
        )  # fmt: skip
        assert capsys.readouterr().out == ""  # RSL-RL's console output is suppressed
        rows = read_rows(first.csv_path)
        assert tuple(rows[0]) == progress_columns(METRICS)
        assert len(rows) == 2 and float(rows[1]["x_mse"]) == pytest.approx(0.25)
        assert float(rows[1]["mean_reward"]) == pytest.approx(HORIZON)

        finetune = tiny_cfg(**FINETUNE_PPO)
        second = train(
            env, tmp_path, iterations=1, resume=first.checkpoint, train_cfg=finetune,
            progress=False, progress_metrics=METRICS,
        )  # fmt: skip
    finally:
        env.close()
    rows = read_rows(second.csv_path)
    assert len(rows) == 3
    assert int(rows[2]["iteration"]) == 2 and int(rows[2]["env_steps"]) == 48
    assert second.iterations_done == 3 and second.checkpoint.name == "model_2.pt"
    saved = torch.load(second.checkpoint, weights_only=False)
    assert saved["infos"]["iterations_done"] == 3 and saved["infos"]["env_steps"] == 48
    assert saved["optimizer_state_dict"]["param_groups"][0]["lr"] < 1e-4  # fine-tuning rate

    policy = load_policy(tmp_path / "latest.pt", 4, 1)
    single = policy(np.zeros(4))
    batch = policy(np.full((3, 4), 50.0))
    assert single.shape == (1,) and batch.shape == (3, 1) and batch.dtype == np.float32
    assert np.all(np.abs(batch) <= 1.0)
    with pytest.raises(ValueError, match="obs_dim=5"):
        load_policy(second.checkpoint, 5, 1)


class _OpensAFile:
    """Unpickling this opens (creates) a file: what a hostile checkpoint could do."""

    def __init__(self, path) -> None:
        self.path = str(path)

    def __reduce__(self):
        return (open, (self.path, "w"))


def test_resume_and_load_policy_never_unpickle(tmp_path):
    marker = tmp_path / "unpickled"
    hostile = tmp_path / "hostile.pt"
    torch.save({"actor_state_dict": {}, "iter": 0, "infos": _OpensAFile(marker)}, hostile)
    env = RslRlVecEnv(serial(), seed=0)
    try:
        with pytest.raises(ValueError, match="hostile.pt'.*expected a chronogym/RSL-RL checkpoint"):
            train(env, tmp_path / "run", iterations=1, resume=hostile, train_cfg=tiny_cfg(),
                  progress=False)  # fmt: skip
    finally:
        env.close()
    with pytest.raises(ValueError, match="checkpoint=.*hostile.pt'.*expected"):
        load_policy(hostile, 4, 1)
    assert not marker.exists()


def test_train_stops_on_minutes(tmp_path):
    env = RslRlVecEnv(serial(), seed=0)
    try:
        result = train(env, tmp_path, minutes=1e-6, train_cfg=tiny_cfg(), progress=False)
    finally:
        env.close()
    assert result.iterations_done == 1 and not math.isnan(result.wall_time)
    assert len(read_rows(result.csv_path)) == 1
