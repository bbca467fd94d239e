"""Rollout helpers shared by the vector-env tests."""

from __future__ import annotations

import os
import signal
import time
from functools import partial

import gymnasium as gym
import numpy as np

ENV_ID = "chronogym/CartPole-v0"
SEED = 7
STEPS = 60  # per env; the policy below drops the pole in ~10-30 steps, so episodes end
COSTS = (5, 40, 400)  # physics ticks per env step of workers 0, 1, 2 (two envs each)


def uneven_fns(costs: tuple[int, ...] = COSTS, per_worker: int = 2) -> list:
    """Env factories whose step cost differs by worker: ``k`` ticks of ``dt = 20 ms / k``.

    Every env has the same 20 ms control period (so similar episode lengths); only
    the physics cost of a step differs.
    """
    return [partial(gym.make, ENV_ID, k=k, dt=0.02 / k) for k in costs for _ in range(per_worker)]


def policy(obs: np.ndarray) -> np.ndarray:
    """A deterministic action from one env's own observation (chaotic, so episodes end)."""
    return np.array([np.sin(1e3 * float(np.sum(obs)))], dtype=np.float32)


def rows_of(out: tuple, env_ids: np.ndarray) -> dict[int, tuple]:
    """Per env id: (obs, reward, terminated, truncated, final_obs or None) of one result."""
    obs, rewards, terms, truncs, info = out[:5]
    finals = info.get("final_obs", [None] * len(env_ids))
    has_final = info.get("_final_obs", np.zeros(len(env_ids), dtype=bool))
    return {
        int(i): (obs[j], rewards[j], terms[j], truncs[j], finals[j] if has_final[j] else None)
        for j, i in enumerate(env_ids)
    }


def async_rollout(
    vec, steps: int, min_envs: int, max_envs: int | None = None
) -> tuple[dict, dict, list]:
    """async_reset, then send/recv with ``min_envs`` (and ``max_envs``) until every env took
    ``steps`` steps.

    Returns per-env trajectories, per-env actions and the env ids of every recv.
    """
    n = vec.num_envs
    traj: dict[int, list] = {i: [] for i in range(n)}
    acts: dict[int, list] = {i: [] for i in range(n)}
    batches, skew = [], 0
    vec.async_reset(seed=SEED)
    while vec.envs_in_flight.size:
        k = min(min_envs, vec.envs_in_flight.size)
        out = vec.recv(min_envs=k, max_envs=max_envs)
        ids = out[5]
        assert len(ids) >= k and len(ids) == len(out[0]) == len(out[1])
        assert max_envs is None or len(ids) <= max_envs
        batches.append(ids.tolist())
        for i, row in rows_of(out, ids).items():
            traj[i].append(row)
        todo = [int(i) for i in ids if len(acts[int(i)]) < steps]
        if todo:
            actions = np.stack([policy(traj[i][-1][0]) for i in todo])
            for i, a in zip(todo, actions, strict=True):
                acts[i].append(a)
            vec.send(actions, todo)
        skew = max(skew, max(map(len, acts.values())) - min(map(len, acts.values())))
    return traj, acts, [batches, skew]


def sync_replay(fns: list, acts: dict, steps: int, mode: str) -> dict[int, list]:
    """The same per-env action sequences through Gymnasium's SyncVectorEnv."""
    vec = gym.vector.SyncVectorEnv(fns, autoreset_mode=gym.vector.AutoresetMode(mode))
    ids = np.arange(len(fns))
    obs, _ = vec.reset(seed=SEED)
    zeros = np.zeros(len(fns))
    traj = {i: [row] for i, row in rows_of((obs, zeros, zeros > 0, zeros > 0, {}), ids).items()}
    for t in range(steps):
        out = vec.step(np.stack([acts[i][t] for i in ids]))
        for i, row in rows_of(out, ids).items():
            traj[i].append(row)
    vec.close()
    return traj


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


def synthetic_rollout(vec, steps: int) -> list:
    """A ``chronogym/Synthetic-v0`` vector env: seeded random actions (2 floats); the reset's
    and every step's results."""
    rng = np.random.default_rng(5)
    out = [vec.reset(seed=3)]
    for _ in range(steps):
        out.append(vec.step(rng.uniform(-1, 1, (vec.num_envs, 2)).astype(np.float32)))
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


def kill_and_step(vec, pid: int, actions: np.ndarray, sig: int = signal.SIGKILL) -> tuple:
    """Send ``sig`` to worker process ``pid``, let it die, then one ``step``: its
    (truncations, infos)."""
    os.kill(pid, sig)
    time.sleep(0.3)
    _, _, _, truncated, info = vec.step(actions)
    return truncated, info
