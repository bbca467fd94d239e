"""RayVectorEnv transports ("actor", "compiled"): same numbers, same fault handling.

Real Ray (2 CPUs), real MuJoCo cart-pole.
"""

from __future__ import annotations

import os
import signal
import time

import gymnasium as gym
import numpy as np
import pytest
from vector_rollouts import ENV_ID, vector_rollout

from chronogym import RayVectorEnv, SerialVectorEnv

NUM_ENVS = 4
STEPS = 40


def assert_same_rollouts(got: list, want: list) -> None:
    """Observations, rewards and flags identical, step by step."""
    assert len(got) == len(want)
    for a, b in zip(got, want, strict=True):
        np.testing.assert_array_equal(a[0], b[0])
        if len(a) == 5:
            for k in (1, 2, 3):
                np.testing.assert_array_equal(a[k], b[k])


@pytest.mark.parametrize("mode", ["NextStep", "SameStep"])
def test_compiled_matches_serial_and_sync(ray_cluster, mode):
    serial = vector_rollout(SerialVectorEnv(ENV_ID, NUM_ENVS, autoreset_mode=mode), STEPS)
    vec = RayVectorEnv(
        ENV_ID, NUM_ENVS, envs_per_worker=2, autoreset_mode=mode, transport="compiled"
    )
    try:
        assert_same_rollouts(vector_rollout(vec, STEPS), serial)
    finally:
        vec.close()
    sync = gym.make_vec(
        ENV_ID, NUM_ENVS, vectorization_mode="sync", vector_kwargs={"autoreset_mode": mode}
    )
    assert_same_rollouts(vector_rollout(sync, STEPS), serial)
    sync.close()


def test_compiled_profile_and_send_recv_fallback(ray_cluster):
    vec = RayVectorEnv(ENV_ID, NUM_ENVS, envs_per_worker=2, transport="compiled")
    try:
        profile = vec.profile_steps()
        run = vector_rollout(vec, 10)
        times = profile.per_step_us()
        assert profile.steps == 10 and times["compute"] > 0 and times["wait"] > 0
        vec.profile_steps(enabled=False)
        vec.send(np.zeros((NUM_ENVS, 1), dtype=np.float32))  # plain actor calls
        obs, *_, ids = vec.recv()
        assert ids.tolist() == list(range(NUM_ENVS)) and np.isfinite(obs).all()
        vec.step(np.zeros((NUM_ENVS, 1), dtype=np.float32))  # back on the graph
        assert np.isfinite(run[-1][0]).all()
    finally:
        vec.close()


@pytest.mark.parametrize("transport", ["actor", "compiled"])
def test_killed_worker_is_replaced(ray_cluster, transport):
    kill_at = 15
    undisturbed = vector_rollout(SerialVectorEnv(ENV_ID, NUM_ENVS), STEPS)
    vec = RayVectorEnv(ENV_ID, NUM_ENVS, envs_per_worker=2, transport=transport)
    try:
        old_pids = vec.worker_pids()

        def kill(t, v):
            if t == kill_at:
                os.kill(old_pids[1], signal.SIGKILL)
                time.sleep(0.3)

        run = vector_rollout(vec, STEPS, kill=kill)
        new_pids = vec.worker_pids()
        assert new_pids[0] == old_pids[0] and new_pids[1] != old_pids[1]
        _, rewards, terminated, truncated, info = run[kill_at + 1]
        assert truncated[2:].all() and not terminated[2:].any() and (rewards[2:] == 0).all()
        assert info["worker_restarted"][2:].all() and not info["_worker_restarted"][:2].any()
        assert [i for i, _ in vec.restarts] == [2, 3]
        for got, want in zip(run, undisturbed, strict=True):  # the other worker: unaffected
            np.testing.assert_array_equal(got[0][:2], want[0][:2])
        assert np.isfinite(run[-1][0]).all()
    finally:
        vec.close()


def test_bad_transport_is_a_value_error():
    expected = r"transport='shm': expected one of \('actor', 'compiled'\)"
    with pytest.raises(ValueError, match=expected):
        RayVectorEnv(ENV_ID, 2, transport="shm")


def test_compiled_hung_worker_is_replaced_after_step_timeout(ray_cluster):
    from functools import partial

    from faulty_tasks import HangingCartPole

    from chronogym import SimEnv

    vec = RayVectorEnv(
        [partial(SimEnv, HangingCartPole(hang_at=3)), partial(SimEnv, HangingCartPole(hang_at=0))],
        envs_per_worker=1,
        step_timeout=2.0,
        transport="compiled",
    )
    try:
        vec.reset(seed=0)
        actions = np.zeros((2, 1), dtype=np.float32)
        vec.step(actions)
        vec.step(actions)
        start = time.perf_counter()
        _, _, _, truncated, info = vec.step(actions)  # env 0 hangs here
        assert time.perf_counter() - start < 30
        assert truncated.tolist() == [True, False]
        assert "step_timeout=2.0" in info["worker_error"][0]
        _, _, _, truncated, _ = vec.step(actions)  # recompiled with the replacement
        assert not truncated.any()
    finally:
        vec.close()
