"""RayVectorEnv transports: the same fault handling over sockets and actor calls.

Real Ray (2 CPUs), real MuJoCo cart-pole.
"""

from __future__ import annotations

import numpy as np
import pytest
from vector_rollouts import ENV_ID, kill_at, vector_rollout

from chronogym import RayVectorEnv, SerialVectorEnv

NUM_ENVS = 4
STEPS = 40


@pytest.mark.parametrize(
    ("transport", "mode"),
    [
        ("socket", "NextStep"),
        ("socket", "SameStep"),
        ("actor", "NextStep"),
    ],
)
def test_killed_worker_is_replaced(ray_cluster, transport, mode):
    kill_step = 15
    undisturbed = vector_rollout(SerialVectorEnv(ENV_ID, NUM_ENVS, autoreset_mode=mode), STEPS)
    vec = RayVectorEnv(
        ENV_ID, NUM_ENVS, envs_per_worker=2, autoreset_mode=mode, transport=transport
    )
    try:
        old_pids = vec.worker_pids()
        run = vector_rollout(vec, STEPS, kill=kill_at(old_pids[1], kill_step))
        new_pids = vec.worker_pids()
        assert new_pids[0] == old_pids[0] and new_pids[1] != old_pids[1]
        _, rewards, terminated, truncated, info = run[kill_step + 1]
        assert truncated[2:].all() and not terminated[2:].any() and (rewards[2:] == 0).all()
        assert info["worker_restarted"][2:].all() and not info["_worker_restarted"][:2].any()
        if transport == "socket":
            assert all(vec._backend.connected())  # the replacement serves a socket again
            error = info["worker_error"][2]
            assert "ActorDiedError" in error and "socket" in error
        if mode == "SameStep":
            np.testing.assert_array_equal(info["final_obs"][2], run[kill_step][0][2])
        assert [i for i, _ in vec.restarts] == [2, 3]
        for got, want in zip(run, undisturbed, strict=True):  # the other worker: unaffected
            np.testing.assert_array_equal(got[0][:2], want[0][:2])
        assert np.isfinite(run[-1][0]).all()
    finally:
        vec.close()


def test_bad_transport_is_a_value_error():
    expected = r"transport='shm': expected one of \('socket', 'actor', 'fork'\)"
    with pytest.raises(ValueError, match=expected):
        RayVectorEnv(ENV_ID, 2, transport="shm")
