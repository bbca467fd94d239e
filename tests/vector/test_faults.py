"""Worker faults: SIGKILL, task exceptions, crash loops. Real Ray, real processes."""

from __future__ import annotations

import os
import signal
import time
from functools import partial

import numpy as np
import pytest
from faulty_tasks import FailingEnv
from vector_rollouts import ENV_ID, kill_and_step, vector_rollout

from chronogym import RayVectorEnv, SerialVectorEnv, WorkerCrashLoopError

NUM_ENVS = 4
STEPS = 60
KILL_AT = 25


def sigkill_worker(worker: int, at: int):
    def kill(t, vec):
        if t == at:
            pid = vec.worker_pids()[worker]
            os.kill(pid, signal.SIGKILL)
            time.sleep(0.3)  # let the process die before the next call reaches it

    return kill


@pytest.mark.parametrize("mode", ["NextStep", "SameStep"])
def test_sigkilled_worker_is_replaced(ray_cluster, mode):
    undisturbed = vector_rollout(SerialVectorEnv(ENV_ID, NUM_ENVS, autoreset_mode=mode), STEPS)
    vec = RayVectorEnv(ENV_ID, NUM_ENVS, envs_per_worker=2, autoreset_mode=mode)
    old_pids = vec.worker_pids()
    run = vector_rollout(vec, STEPS, kill=sigkill_worker(1, KILL_AT))
    new_pids = vec.worker_pids()
    assert new_pids[0] == old_pids[0] and new_pids[1] != old_pids[1]

    _, rewards, terminated, truncated, info = run[KILL_AT + 1]
    assert truncated[2:].all() and not terminated[2:].any()
    assert (rewards[2:] == 0).all()
    assert info["worker_restarted"][2:].all() and not info["_worker_restarted"][:2].any()
    assert "ActorDiedError" in info["worker_error"][2]
    assert "died without recording a signal" in info["worker_error"][2]  # SIGKILL leaves none
    if mode == "SameStep":
        # the last observation before the crash is the episode's final observation
        np.testing.assert_array_equal(info["final_obs"][2], run[KILL_AT][0][2])
    # envs 0 and 1 (the other worker) are identical to an undisturbed run
    for got, want in zip(run, undisturbed, strict=True):
        np.testing.assert_array_equal(got[0][:2], want[0][:2])
        if len(got) == 5:
            np.testing.assert_array_equal(got[1][:2], want[1][:2])
            np.testing.assert_array_equal(got[3][:2], want[3][:2])
    # the run goes on: the restarted envs keep stepping and produce finite observations
    assert np.isfinite(run[-1][0]).all()
    assert [i for i, _ in vec.restarts] == [2, 3]
    vec.close()


@pytest.mark.parametrize("transport", ["socket", "actor"])
def test_a_segfaulted_worker_is_replaced_and_the_signal_named(ray_cluster, transport):
    vec = RayVectorEnv(ENV_ID, 2, envs_per_worker=1, transport=transport)
    try:
        vec.reset(seed=0)
        actions = np.zeros((2, 1), dtype=np.float32)
        vec.step(actions)
        truncated, info = kill_and_step(vec, vec.worker_pids()[1], actions, signal.SIGSEGV)
        assert truncated.tolist() == [False, True]
        assert "died of SIGSEGV, as its Ray log records" in info["worker_error"][1]
        vec.step(actions)  # the run goes on
    finally:
        vec.close()


def test_restart_seeds_are_fresh_and_deterministic(ray_cluster):
    runs = []
    for _ in range(2):
        vec = RayVectorEnv(ENV_ID, 2, envs_per_worker=1)
        runs.append(vector_rollout(vec, 12, kill=sigkill_worker(0, 5)))
        vec.close()
    # NEXT_STEP: the step after the restart resets env 0 with its fresh seed
    np.testing.assert_array_equal(runs[0][7][0][0], runs[1][7][0][0])
    undisturbed = vector_rollout(SerialVectorEnv(ENV_ID, 2), 12)
    assert not any(np.array_equal(runs[0][7][0][0], step[0][0]) for step in undisturbed)


@pytest.mark.parametrize("backend", ["serial", "ray"])
def test_task_exception_restarts_only_that_env(ray_cluster, backend):
    seed = 11
    fns = [partial(FailingEnv, fail_seed=seed + 1 if i == 1 else None) for i in range(3)]
    undisturbed = vector_rollout(SerialVectorEnv([partial(FailingEnv, None)] * 3), 20, seed)
    kwargs = {"env_errors": "restart"}
    vec = (
        RayVectorEnv(fns, envs_per_worker=3, **kwargs)
        if backend == "ray"
        else SerialVectorEnv(fns, **kwargs)
    )
    run = vector_rollout(vec, 20, seed)
    _, _, _, truncated, info = run[5]  # FailingCartPole raises at its 5th step
    assert truncated.tolist() == [False, True, False]
    assert info["_worker_restarted"].tolist() == [False, True, False]
    assert "injected failure at step 5" in info["worker_error"][1]
    assert "Traceback" in info["worker_error"][1]
    assert vec.restarts[0][0] == 1
    for got, want in zip(run, undisturbed, strict=True):  # envs 0 and 2 unaffected
        np.testing.assert_array_equal(got[0][[0, 2]], want[0][[0, 2]])
    vec.close()


def test_crash_loop_becomes_a_clear_error():
    vec = SerialVectorEnv(
        [partial(FailingEnv, None, fail_always=True)] * 2, max_restarts=2, env_errors="restart"
    )
    vec.reset(seed=0)
    actions = np.zeros((2, 1), dtype=np.float32)
    with pytest.raises(WorkerCrashLoopError, match=r"env 0 failed 3 times.*max_restarts=2"):
        for _ in range(200):
            vec.step(actions)


@pytest.mark.parametrize("transport", ["actor", "socket"])
def test_hung_worker_is_replaced_after_step_timeout(ray_cluster, transport):
    from faulty_tasks import HangingCartPole

    from chronogym import SimEnv

    vec = RayVectorEnv(
        [partial(SimEnv, HangingCartPole(hang_at=3)), partial(SimEnv, HangingCartPole(hang_at=0))],
        envs_per_worker=1,
        step_timeout=2.0,
        transport=transport,
    )
    vec.reset(seed=0)
    actions = np.zeros((2, 1), dtype=np.float32)
    vec.step(actions)
    vec.step(actions)
    start = time.perf_counter()
    _, _, _, truncated, info = vec.step(actions)  # env 0 hangs here
    assert time.perf_counter() - start < 30
    assert truncated.tolist() == [True, False]
    assert "step_timeout=2.0" in info["worker_error"][0]
    _, _, _, truncated, _ = vec.step(actions)  # the replacement answers: NEXT_STEP resets env 0
    assert not truncated.any()
    if transport == "socket":  # the replacement serves a socket again
        assert all(vec._backend.connected())
    vec.close()
