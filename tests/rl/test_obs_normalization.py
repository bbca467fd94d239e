"""Observation normalisation travels with the checkpoint: ``play`` acts as training did."""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("rsl_rl")

import torch
from tensordict import TensorDict

from chronogym.rl.checkpoint import load_policy, read_checkpoint
from chronogym.rl.progress import ProgressBar
from chronogym.rl.trainer import Budget, Runner
from chronogym.rl.vecenv import RslRlVecEnv
from chronogym.tasks.quadruped.training import make_quadruped_vec_env, quadruped_train_config


def test_play_gives_the_actions_of_the_training_process(tmp_path):
    cfg = quadruped_train_config(num_steps_per_env=8, save_interval=10)
    assert cfg["actor"]["obs_normalization"] is True
    env = RslRlVecEnv(make_quadruped_vec_env(4, "serial"), seed=0)
    try:
        runner = Runner(env, tmp_path, cfg, seed=0, policy_lag=0, torch_threads=1, update_threads=1)
        result = runner.learn(Budget.of(3, None), ProgressBar(False, 3, float("inf"), print))
        obs = env.get_observations()["policy"].clone()
    finally:
        env.close()
    actor = runner.alg.get_policy()
    actor.eval()
    with torch.inference_mode():
        trained = actor(TensorDict({"policy": obs}, batch_size=[obs.shape[0]])).numpy()

    state = read_checkpoint(result.checkpoint, "checkpoint")["actor_state_dict"]
    normalizer = {k: v for k, v in state.items() if "obs_normalizer" in k}
    assert normalizer, sorted(state)  # the running statistics are in the checkpoint...
    means = [v for k, v in normalizer.items() if k.endswith("mean") or k.endswith("_mean")]
    assert means and any(float(m.abs().max()) > 0 for m in means)  # ...and were updated

    played = load_policy(result.checkpoint)(obs.numpy())
    low, high = env.cfg["action_low"], env.cfg["action_high"]
    np.testing.assert_array_equal(played, np.clip(trained, low, high).astype(np.float32))

    # without the statistics (a fresh normaliser) the same weights act differently
    stripped = {**state}
    for key in normalizer:
        fresh = torch.zeros_like(state[key]) if "mean" in key else torch.ones_like(state[key])
        stripped[key] = fresh if state[key].is_floating_point() else state[key]
    actor.load_state_dict(stripped)
    with torch.inference_mode():
        unnormalized = actor(TensorDict({"policy": obs}, batch_size=[obs.shape[0]])).numpy()
    assert not np.allclose(unnormalized, trained)
