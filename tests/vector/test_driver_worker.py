"""``driver_worker=True``: the driver steps the last worker's envs itself; same numbers."""

from __future__ import annotations

import os
from functools import partial

import numpy as np
import pytest
from faulty_tasks import FailingEnv
from gymnasium.utils.env_checker import data_equivalence
from vector_rollouts import ENV_ID, STEPS, async_rollout, sync_replay, uneven_fns, vector_rollout

from chronogym import RayVectorEnv, SerialVectorEnv
from chronogym.vector.driver_worker import DriverWorkerBackend


@pytest.mark.parametrize("transport", ["socket", "actor", "fork"])
@pytest.mark.parametrize("mode", ["NextStep", "SameStep"])
def test_matches_serial_in_both_autoreset_modes(ray_cluster, mode, transport):
    reference = vector_rollout(SerialVectorEnv(ENV_ID, 5, autoreset_mode=mode), 80)
    vec = RayVectorEnv(
        ENV_ID, 5, envs_per_worker=2, autoreset_mode=mode, driver_worker=True, transport=transport
    )
    assert isinstance(vec._backend, DriverWorkerBackend)
    pids = vec.worker_pids()
    assert pids[-1] == os.getpid() and os.getpid() not in pids[:-1]
    assert data_equivalence(vector_rollout(vec, 80), reference, exact=True)
    vec.close()


def test_partial_batches_match_sync_per_env(ray_cluster):
    fns = uneven_fns()
    vec = RayVectorEnv(fns, envs_per_worker=2, autoreset_mode="SameStep", driver_worker=True)
    traj, acts, _ = async_rollout(vec, STEPS, min_envs=2)
    vec.close()
    reference = sync_replay(fns, acts, STEPS, "SameStep")
    for i in range(len(fns)):
        for t, (got, want) in enumerate(zip(traj[i], reference[i], strict=True)):
            assert data_equivalence(got, want, exact=True), f"env {i} differs at step {t}"


def test_an_env_raising_in_the_driver_is_rebuilt_and_truncated(ray_cluster):
    seed = 11
    fns = [partial(FailingEnv, fail_seed=seed + 3 if i == 3 else None) for i in range(4)]
    vec = RayVectorEnv(fns, envs_per_worker=2, driver_worker=True, env_errors="restart")
    run = vector_rollout(vec, 8, seed)
    vec.close()
    _, _, _, truncated, info = run[5]  # FailingEnv raises at its 5th step
    assert truncated.tolist() == [False, False, False, True]
    assert "injected failure at step 5" in info["worker_error"][3]


def test_a_killed_ray_worker_is_still_replaced(ray_cluster):
    vec = RayVectorEnv(ENV_ID, 4, envs_per_worker=2, driver_worker=True)
    vec.reset(seed=0)
    actions = np.zeros((4, 1), dtype=np.float32)
    vec.step(actions)
    os.kill(vec.worker_pids()[0], 9)
    _, _, _, truncated, info = vec.step(actions)
    assert truncated.tolist() == [True, True, False, False]
    assert info["_worker_restarted"].tolist() == [True, True, False, False]
    vec.step(actions)  # the run goes on
    vec.close()


def test_all_envs_in_the_driver_start_no_actor(ray_cluster):
    vec = RayVectorEnv(ENV_ID, 3, envs_per_worker=3, driver_worker=True)
    assert vec.worker_pids() == [os.getpid()]
    reference = vector_rollout(SerialVectorEnv(ENV_ID, 3), 20)
    assert data_equivalence(vector_rollout(vec, 20), reference, exact=True)
    vec.close()


def test_driver_worker_must_be_a_bool():
    with pytest.raises(TypeError, match="driver_worker='yes'"):
        RayVectorEnv(ENV_ID, 2, driver_worker="yes")
