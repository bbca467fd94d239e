"""RayVectorEnv transport="socket": same numbers, same fault handling, a private socket dir.

Real Ray (2 CPUs), real MuJoCo cart-pole, real SIGKILLs.
"""

from __future__ import annotations

import os
import stat
from functools import partial

import numpy as np
import pytest
from faulty_tasks import FailingEnv
from gymnasium.utils.env_checker import data_equivalence
from vector_rollouts import (
    ENV_ID,
    STEPS,
    assert_same_rollouts,
    async_rollout,
    sync_replay,
    uneven_fns,
    vector_rollout,
)

from chronogym import RayVectorEnv, SerialVectorEnv

NUM_ENVS = 4


def socket_env(*args, **kwargs) -> RayVectorEnv:
    vec = RayVectorEnv(*args, transport="socket", **kwargs)
    assert all(vec._backend.connected()), "workers on the driver's node step over sockets"
    return vec


@pytest.mark.parametrize("mode", ["NextStep", "SameStep"])
def test_socket_matches_serial(ray_cluster, mode):
    serial = vector_rollout(SerialVectorEnv(ENV_ID, NUM_ENVS, autoreset_mode=mode), 300)
    vec = socket_env(ENV_ID, NUM_ENVS, envs_per_worker=2, autoreset_mode=mode)
    try:
        assert_same_rollouts(vector_rollout(vec, 300), serial)
    finally:
        vec.close()


def test_env_exception_comes_back_with_its_infos(ray_cluster):
    seed = 11
    fns = [partial(FailingEnv, fail_seed=seed + 1 if i == 1 else None) for i in range(3)]
    undisturbed = vector_rollout(SerialVectorEnv([partial(FailingEnv, None)] * 3), 20, seed)
    vec = socket_env(fns, envs_per_worker=3, env_errors="restart")
    try:
        run = vector_rollout(vec, 20, seed)
        _, _, _, truncated, info = run[5]  # FailingCartPole raises at its 5th step
        assert truncated.tolist() == [False, True, False]
        assert "injected failure at step 5" in info["worker_error"][1]
        assert vec.restarts[0][0] == 1
        for got, want in zip(run, undisturbed, strict=True):
            np.testing.assert_array_equal(got[0][[0, 2]], want[0][[0, 2]])
    finally:
        vec.close()


def test_socket_dir_is_private_and_removed_on_close(ray_cluster):
    vec = socket_env(ENV_ID, 2, envs_per_worker=1)
    directory = vec._backend.socket_dir
    try:
        assert stat.S_IMODE(os.stat(directory).st_mode) == 0o700
        assert os.listdir(directory) == []  # each worker unlinks its socket once connected
    finally:
        vec.close()
    assert not os.path.exists(directory)


@pytest.mark.parametrize(
    ("spin_us", "plain_worker"),
    [(None, None), (0, None), (None, 1)],
    ids=["spin", "block", "mixed"],
)
def test_send_recv_over_sockets_match_sync_per_env(ray_cluster, spin_us, plain_worker):
    """Partial batches (min_envs < N) read from sockets: each env's trajectory is Gymnasium's.

    ``mixed``: one worker falls back to actor calls (as a worker on another node would), so
    recv waits on sockets and Ray object refs at once.
    """
    fns = uneven_fns()
    vec = socket_env(fns, envs_per_worker=2, spin_us=spin_us)
    try:
        if plain_worker is not None:
            vec._backend._disconnect(plain_worker)
        vec.reset(seed=0)
        vec.send(np.zeros((len(fns), 1), dtype=np.float32))
        kinds = [type(call.handle).__name__ for _, call in sorted(vec._in_flight.calls.items())]
        want = ["SockHandle"] * 3
        if plain_worker is not None:
            want[plain_worker] = "ObjectRef"
        assert kinds == want
        vec.recv()
        traj, acts, (batches, skew) = async_rollout(vec, STEPS, min_envs=2)
    finally:
        vec.close()
    assert any(len(b) < len(fns) for b in batches) and skew >= 2
    reference = sync_replay(fns, acts, STEPS, "NextStep")
    for i in range(len(fns)):
        for t, (got, want_row) in enumerate(zip(traj[i], reference[i], strict=True)):
            assert data_equivalence(got, want_row, exact=True), f"env {i} differs at step {t}"


def test_profiled_steps_go_over_sockets_too(ray_cluster):
    """Messages only (shared memory off): each worker's times come with its answer."""
    vec = socket_env(ENV_ID, NUM_ENVS, envs_per_worker=2, shared_memory=False)
    try:
        profile = vec.profile_steps()
        vector_rollout(vec, 10)
        times = profile.per_step_us()
        assert vec._backend._shared is None
        assert profile.steps == 10 and times["compute"] > 0 and times["wait"] > 0
        vec.profile_steps(enabled=False)
        obs, *_ = vec.step(np.zeros((NUM_ENVS, 1), dtype=np.float32))
        assert np.isfinite(obs).all()
        assert len(vec.get_attr("dt")) == NUM_ENVS
    finally:
        vec.close()


@pytest.mark.parametrize(
    ("kwargs", "match"),
    [
        ({"spin_us": -1}, r"spin_us=-1: expected None \(default 250\) or microseconds in \[0,"),
        ({"spin_us": "fast"}, r"spin_us='fast': expected None"),
        ({"spin_us": True}, r"spin_us=True: expected None"),
        ({"spin_us": 10, "transport": "actor"}, r"spin_us=10 with transport='actor'"),
    ],
)
def test_bad_spin_us_is_named(kwargs, match):
    with pytest.raises(ValueError, match=match):
        RayVectorEnv(ENV_ID, 2, **kwargs)


def test_bogus_transport_is_a_value_error():
    with pytest.raises(ValueError, match=r"transport='bogus': expected one of .*'socket'"):
        RayVectorEnv(ENV_ID, 2, transport="bogus")


class CountingPoller:
    """A poll object that is never readable and counts how often it was asked."""

    def __init__(self) -> None:
        self.polls = 0

    def poll(self, timeout):
        self.polls += 1
        return []


def test_adaptive_spin_follows_the_last_wait():
    from chronogym.vector.socket_transport import AdaptiveSpin

    spinner = AdaptiveSpin(cap_s=1e-3)
    first = CountingPoller()
    spinner.spin(first)  # the first wait spins (then the caller blocks)
    assert first.polls > 1
    spinner.last_s = 5e-3  # a wait longer than the cap: spinning turns off
    off = CountingPoller()
    spinner.spin(off)
    assert off.polls == 0
    spinner.last_s = 1e-4  # a short wait again: it spins
    again = CountingPoller()
    spinner.spin(again)
    assert again.polls > 1
    spinner.arrived()
    assert 0 <= spinner.last_s < 1.0
    never = AdaptiveSpin(cap_s=0.0)  # spin_us=0
    zero = CountingPoller()
    never.spin(zero)
    assert zero.polls == 0
