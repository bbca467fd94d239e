"""Asynchronous stepping of RayVectorEnv: send/recv partial batches, step_async/step_wait.

Real Ray (the session's 2-CPU cluster), real MuJoCo cart-poles, no mocks.
"""

from __future__ import annotations

import multiprocessing
import os
import signal
import time
from functools import partial

import numpy as np
import pytest
from gymnasium.error import AlreadyPendingCallError, NoAsyncCallError
from gymnasium.utils.env_checker import data_equivalence
from vector_rollouts import (
    ENV_ID,
    SEED,
    STEPS,
    async_rollout,
    sync_replay,
    uneven_fns,
    vector_rollout,
)

from chronogym import RayVectorEnv, SerialVectorEnv
from chronogym.vector import EnvsInFlightError, RecvTimeoutError


@pytest.mark.parametrize("mode", ["NextStep", "SameStep"])
def test_partial_batches_match_sync_per_env(ray_cluster, mode):
    fns = uneven_fns()
    vec = RayVectorEnv(fns, envs_per_worker=2, autoreset_mode=mode)
    traj, acts, (batches, skew) = async_rollout(vec, STEPS, min_envs=2)
    vec.close()
    # the arrival order really differed from lockstep stepping
    assert any(len(b) < len(fns) for b in batches)
    assert skew >= 2, f"workers never drifted apart (batches: {batches[:20]})"
    reference = sync_replay(fns, acts, STEPS, mode)
    ends = 0
    for i in range(len(fns)):
        assert len(traj[i]) == len(reference[i]) == STEPS + 1
        for t, (got, want) in enumerate(zip(traj[i], reference[i], strict=True)):
            assert data_equivalence(got, want, exact=True), f"env {i} differs at step {t}"
            ends += int(got[2] or got[3])
    assert ends >= len(fns)  # autoresets are covered


@pytest.mark.parametrize("backend", ["socket", "actor", "fork"])
def test_batch_mode_returns_exactly_max_envs_and_matches_sync(ray_cluster, backend):
    fns = uneven_fns()
    vec = RayVectorEnv(fns, envs_per_worker=1, transport=backend)
    traj, acts, (batches, skew) = async_rollout(vec, STEPS, min_envs=2, max_envs=2)
    vec.close()
    # EnvPool's batch: exactly min(2, envs in flight) every time (async_rollout checks
    # min(2, in flight) <= len(ids) <= 2), although all 6 envs were in flight at first. How
    # many batches come at the tail, with one env left in flight, depends on the machine's load.
    assert len(batches[0]) == 2 and {len(b) for b in batches} <= {1, 2}
    assert sum(len(b) == 2 for b in batches) >= len(batches) // 2
    assert skew >= 2, f"workers never drifted apart (batches: {batches[:20]})"
    reference = sync_replay(fns, acts, STEPS, "NextStep")
    for i in range(len(fns)):
        for t, (got, want) in enumerate(zip(traj[i], reference[i], strict=True)):
            assert data_equivalence(got, want, exact=True), f"env {i} differs at step {t}"


def test_answers_beyond_max_envs_wait_for_the_next_recv(ray_cluster):
    vec = SerialVectorEnv(uneven_fns((5, 5)), envs_per_worker=2)
    vec.reset(seed=0)
    vec.send(np.zeros((4, 1), np.float32))  # both workers answer at once (serial)
    assert vec.recv(max_envs=2)[5].tolist() == [0, 1]  # the earliest sent first
    assert vec.envs_in_flight.tolist() == [2, 3]  # answered, not yet received
    with pytest.raises(EnvsInFlightError):
        vec.step(np.zeros((4, 1), np.float32))
    assert vec.recv()[5].tolist() == [2, 3]
    vec.send(np.zeros((4, 1), np.float32))
    with pytest.raises(ValueError, match=r"max_envs=3: expected None or a multiple of"):
        vec.recv(max_envs=3)
    with pytest.raises(ValueError, match=r"min_envs=4 > max_envs=2"):
        vec.recv(min_envs=4, max_envs=2)
    vec.recv()
    vec.close()


def async_vector_rollout(vec, steps: int, seed: int = 11) -> list:
    """vector_rollout, with step_async/step_wait instead of step."""
    out = [vec.reset(seed=seed)]
    rng = np.random.default_rng(1)
    for _ in range(steps):
        vec.step_async(rng.uniform(-1, 1, (vec.num_envs, 1)).astype(np.float32))
        out.append(vec.step_wait(timeout=60))
    return out


def test_step_async_step_wait_equals_step(ray_cluster):
    reference = vector_rollout(SerialVectorEnv(ENV_ID, 5), 40)
    vec = RayVectorEnv(ENV_ID, 5, envs_per_worker=2)  # workers of 2, 2 and 1 envs
    assert data_equivalence(async_vector_rollout(vec, 40), reference, exact=True)
    vec.step(np.zeros((5, 1), np.float32))  # the barrier still works afterwards
    vec.close()


@pytest.mark.parametrize("mode", ["NextStep", "SameStep"])
def test_worker_killed_in_flight_is_replaced(ray_cluster, mode):
    fns = uneven_fns((5, 2000))  # worker 1: ~10 ms per call, so the kill lands mid-call
    vec = RayVectorEnv(fns, envs_per_worker=2, autoreset_mode=mode)
    undisturbed = SerialVectorEnv(fns, autoreset_mode=mode)
    vec.reset(seed=SEED)
    undisturbed.reset(seed=SEED)
    old_pids = vec.worker_pids()
    actions = np.full((4, 1), 0.1, np.float32)
    for _ in range(3):
        vec.send(actions)
        last_obs = vec.recv()[0]
        undisturbed.step(actions)
    vec.send(actions)
    os.kill(old_pids[1], signal.SIGKILL)
    obs, rewards, terms, truncs, info, ids = vec.recv()
    want = undisturbed.step(actions)
    assert ids.tolist() == [0, 1, 2, 3]
    assert truncs.tolist() == [False, False, True, True]
    assert not terms[2:].any() and (rewards[2:] == 0).all()
    assert info["worker_restarted"][2:].all() and not info["_worker_restarted"][:2].any()
    assert "ActorDiedError" in info["worker_error"][2]
    np.testing.assert_array_equal(obs[:2], want[0][:2])  # the other worker is unaffected
    if mode == "SameStep":
        np.testing.assert_array_equal(info["final_obs"][2], last_obs[2])
    new_pids = vec.worker_pids()
    assert new_pids[0] == old_pids[0] and new_pids[1] != old_pids[1]
    for _ in range(3):  # the replacement keeps stepping, asynchronously
        vec.send(actions[2:], [2, 3])
        assert vec.recv()[5].tolist() == [2, 3]
    assert [i for i, _ in vec.restarts] == [2, 3]
    vec.close()
    undisturbed.close()


def test_hung_worker_is_replaced_while_others_step(ray_cluster):
    from faulty_tasks import HangingCartPole

    from chronogym import SimEnv

    fns = [partial(SimEnv, HangingCartPole(hang_at=3)), partial(SimEnv, HangingCartPole(10**9))]
    vec = RayVectorEnv(fns, envs_per_worker=1, step_timeout=2.0)
    vec.reset(seed=0)
    vec.send(np.zeros((2, 1), np.float32))
    steps, start, hung = [0, 0], time.perf_counter(), None
    while hung is None:
        _, _, _, truncs, info, ids = vec.recv(min_envs=1)
        for j, i in enumerate(ids):
            steps[i] += 1
            if truncs[j] and info.get("_worker_restarted", [False] * len(ids))[j]:
                hung = (i, info["worker_error"][j])
        vec.send(np.zeros((len(ids), 1), np.float32), ids)
    assert hung[0] == 0 and "step_timeout=2.0" in hung[1]
    assert 2.0 <= time.perf_counter() - start < 30
    assert steps[0] == 3 and steps[1] > 10  # env 1 kept stepping while env 0 hung
    vec.recv()
    vec.close()


@pytest.fixture(scope="module")
def slow_vec(ray_cluster):
    """Four envs in two workers; worker 1 steps ~100 ms per call."""
    vec = RayVectorEnv(uneven_fns((5, 20000)), envs_per_worker=2)
    with pytest.raises(RuntimeError, match=r"send\(\) to envs \[0, 1\] before their first reset"):
        vec.send(np.zeros((2, 1), np.float32), [0, 1])
    vec.reset(seed=0)
    yield vec
    vec.close()


@pytest.mark.parametrize(
    ("env_ids", "match"),
    [
        ([0, 9], r"env_ids=\[0, 9\]: ids \[9\] are out of range; expected integers in 0\.\.3"),
        ([-1], r"ids \[-1\] are out of range"),
        ([0, 1, 1], r"ids \[1\] appear more than once"),
        (
            [1, 2, 3],
            r"worker 0 holds envs \[0, 1\] but envs \[0\] are missing; send\(\) steps whole "
            r"workers \(envs_per_worker=2\)",
        ),
        ([0.0, 1.0], r"env_ids=\[0\.0, 1\.0\]: expected .*integer env ids"),
        ([], r"env_ids=\[\]: expected a non-empty"),
    ],
)
def test_bad_env_ids_are_named(slow_vec, env_ids, match):
    with pytest.raises(ValueError, match=match):
        slow_vec.send(np.zeros((len(env_ids), 1), np.float32), env_ids)
    assert slow_vec.envs_in_flight.size == 0


def test_wrong_action_rows(slow_vec):
    with pytest.raises(ValueError, match=r"action shape \(4, 1\) is wrong; expected \(2, 1\)"):
        slow_vec.send(np.zeros((4, 1), np.float32), [2, 3])


def test_in_flight_misuse_raises(slow_vec):
    vec, actions = slow_vec, np.zeros((2, 1), np.float32)
    with pytest.raises(NoAsyncCallError, match="no envs in flight"):
        vec.recv()
    vec.send(actions, [3, 2])
    try:
        with pytest.raises(EnvsInFlightError, match=r"envs \[2, 3\] are already in flight"):
            vec.send(actions, [2, 3])
        with pytest.raises(AlreadyPendingCallError, match=r"step\(\) called while envs \[2, 3\]"):
            vec.step(np.zeros((4, 1), np.float32))
        for call in (vec.reset, partial(vec.get_attr, "k"), partial(vec.step_async, actions)):
            with pytest.raises(EnvsInFlightError, match="in flight"):
                call()
        with pytest.raises(NoAsyncCallError, match=r"step_wait\(\) expects a step of every env"):
            vec.step_wait()
        with pytest.raises(ValueError, match=r"min_envs=3: expected .* <= 2"):
            vec.recv(min_envs=3)
    finally:
        vec.recv()
    assert vec.envs_in_flight.size == 0


def test_recv_timeout_keeps_envs_in_flight(slow_vec):
    vec = slow_vec
    vec.reset(seed=0)  # so that the next step runs physics (not a NEXT_STEP autoreset)
    vec.send(np.zeros((4, 1), np.float32))
    start = time.perf_counter()
    with pytest.raises(RecvTimeoutError, match=r"recv\(min_envs=4\) timed out after 0.01 s") as e:
        vec.recv(min_envs=4, timeout=0.01)
    assert isinstance(e.value, multiprocessing.TimeoutError)  # as Gymnasium's step_wait
    assert time.perf_counter() - start < 1.0
    assert vec.envs_in_flight.tolist() == [0, 1, 2, 3]
    out = vec.recv(min_envs=1)  # the fast worker answers first
    assert 0 in out[5] and 1 in out[5]
    if out[5].size < 4:
        assert vec.recv()[5].tolist() == [2, 3]
    assert vec.envs_in_flight.size == 0
