"""Infos travel as columns or per-env dicts; either way the vector info is Gymnasium's."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence
from info_envs import STYLES, InfoEnv, info_env_fns

from chronogym import RayVectorEnv, SerialVectorEnv
from chronogym.vector.infos import InfoColumns, join_infos, to_columns

NUM_ENVS = 4
STEPS = 40


def rollout(vec: gym.vector.VectorEnv) -> list:
    rng = np.random.default_rng(3)
    out = [vec.reset(seed=11)]
    for _ in range(STEPS):
        out.append(vec.step(rng.uniform(-1, 1, (NUM_ENVS, 1)).astype(np.float32)))
    vec.close()
    return out


def reference(style: str, mode: str) -> list:
    fns = info_env_fns(style, NUM_ENVS)
    return rollout(gym.vector.SyncVectorEnv(fns, autoreset_mode=gym.vector.AutoresetMode(mode)))


@pytest.mark.parametrize("transport", ["socket", "fork"])
@pytest.mark.parametrize("mode", ["NextStep", "SameStep"])
@pytest.mark.parametrize("style", STYLES)
def test_ray_infos_match_sync_vector_env(ray_cluster, style, mode, transport):
    fns = info_env_fns(style, NUM_ENVS)
    vec = RayVectorEnv(fns, envs_per_worker=2, autoreset_mode=mode, transport=transport)
    assert data_equivalence(rollout(vec), reference(style, mode), exact=True)


@pytest.mark.parametrize("style", STYLES)
def test_serial_infos_match_sync_vector_env(style):
    vec = SerialVectorEnv(info_env_fns(style, NUM_ENVS), autoreset_mode="SameStep")
    assert data_equivalence(rollout(vec), reference(style, "SameStep"), exact=True)


def test_scalar_infos_become_columns_with_gymnasium_dtypes():
    env = InfoEnv()
    env.reset(seed=0)
    infos = [env.step(np.zeros(1, np.float32))[4] for _ in range(3)]
    columns = to_columns(infos)
    assert isinstance(columns, InfoColumns)
    assert columns.keys == ("x", "x32", "t", "done_soon")
    assert [np.dtype(k.removeprefix("py")) for k in columns.kinds] == [
        np.float64,
        np.float32,
        np.int64,
        np.bool_,
    ]
    assert [type(v) for v in columns.per_env()[0].values()] == [float, np.float32, int, bool]
    joined = join_infos([columns, columns], [3, 3])
    assert joined["t"].tolist() == [1, 2, 3, 1, 2, 3]
    assert joined["_t"].all() and joined["t"].flags.writeable


@pytest.mark.parametrize(
    "infos",
    [
        [{"a": 1}, {"b": 1}],  # different keys
        [{"a": 1}, {"a": 1.5}],  # one key, two types
        [{"a": np.bool_(True)}, {"a": np.bool_(False)}],  # Gymnasium: an object array
        [{"a": np.zeros(2)}, {"a": np.ones(2)}],  # arrays
        [{"a": 2**70}, {"a": 1}],  # beyond int64
    ],
)
def test_other_infos_stay_per_env(infos):
    assert to_columns(infos) == infos


def test_empty_infos_are_none():
    assert to_columns([{}, {}]) is None
    assert join_infos([None, to_columns([{"a": 1.0}])], [2, 1])["_a"].tolist() == [
        False,
        False,
        True,
    ]


@pytest.mark.parametrize("transport", ["socket", "fork"])
def test_infos_of_the_other_workers_survive_a_lost_one(ray_cluster, transport):
    """A step where one worker is lost (its envs truncated) and the others only add infos to
    their rows: their infos are in the step's vector info beside the lost worker's."""
    import os
    import signal
    import time

    vec = RayVectorEnv(info_env_fns("scalars", NUM_ENVS), envs_per_worker=2, transport=transport)
    try:
        vec.reset(seed=0)
        actions = np.zeros((NUM_ENVS, 1), np.float32)
        _, _, _, _, before = vec.step(actions)
        assert before["_t"].all() and before["t"].tolist() == [1, 1, 1, 1]
        os.kill(vec.worker_pids()[1], signal.SIGKILL)
        time.sleep(0.3)
        _, _, _, truncated, info = vec.step(actions)
        assert truncated.tolist() == [False, False, True, True]
        assert info["_t"].tolist() == [True, True, False, False]
        assert info["t"][:2].tolist() == [2, 2]
        assert info["worker_restarted"][2:].all()
    finally:
        vec.close()
