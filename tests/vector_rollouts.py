"""Rollout helpers shared by the vector-env tests."""

from __future__ import annotations

import os
import signal
import time

import numpy as np

ENV_ID = "chronogym/CartPole-v0"


def vector_rollout(vec, steps: int, seed: int = 11, kill=None) -> list:
    """Reset with ``seed``, then ``steps`` random steps; ``kill(t, vec)`` runs before step t."""
    out = [vec.reset(seed=seed)]
    rng = np.random.default_rng(1)
    for t in range(steps):
        if kill is not None:
            kill(t, vec)
        actions = rng.uniform(-1, 1, (vec.num_envs, 1)).astype(np.float32)
        out.append(vec.step(actions))
    return out


def single_env_rollouts(make_env, num_envs: int, steps: int, seed: int = 11) -> list:
    """What a plain loop over SimEnvs gives: per env, (obs, reward, term, trunc) per step.

    Follows NEXT_STEP autoreset by hand: after an episode ends, the next step resets.
    """
    rng = np.random.default_rng(1)
    actions = [rng.uniform(-1, 1, (num_envs, 1)).astype(np.float32) for _ in range(steps)]
    per_env = []
    for i in range(num_envs):
        env = make_env()
        obs, _ = env.reset(seed=seed + i)
        rows = [(obs, 0.0, False, False)]
        done = False
        for t in range(steps):
            if done:
                obs, _ = env.reset()
                rows.append((obs, 0.0, False, False))
                done = False
            else:
                obs, reward, term, trunc, _ = env.step(actions[t][i])
                rows.append((obs, reward, term, trunc))
                done = term or trunc
        per_env.append(rows)
    return per_env


def assert_same_rollouts(got: list, want: list) -> None:
    """Observations, rewards and flags identical, step by step."""
    assert len(got) == len(want)
    for a, b in zip(got, want, strict=True):
        np.testing.assert_array_equal(a[0], b[0])
        if len(a) == 5:
            for k in (1, 2, 3):
                np.testing.assert_array_equal(a[k], b[k])


def kill_at(pid: int, step: int):
    """A ``kill`` for :func:`vector_rollout`: SIGKILL ``pid`` just before step ``step``."""

    def kill(t, vec) -> None:
        if t == step:
            os.kill(pid, signal.SIGKILL)
            time.sleep(0.3)

    return kill
