"""transport="fork": workers forked from a warm process, no Ray. Real processes, real MuJoCo."""

from __future__ import annotations

import os
import signal
import time
from functools import partial

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence
from vector_rollouts import ENV_ID, kill_and_step, synthetic_rollout, vector_rollout

from chronogym import RayVectorEnv, SerialVectorEnv

NUM_ENVS = 5
STEPS = 120  # several episodes end (the random policy drops the pole in ~20 steps)


def fork_vec(fns=ENV_ID, num_envs=NUM_ENVS, **kwargs) -> RayVectorEnv:
    return RayVectorEnv(fns, num_envs, transport="fork", **kwargs)


def alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    with open(f"/proc/{pid}/stat") as stat:  # a zombie is not alive
        return stat.read().rsplit(")", 1)[1].split()[0] != "Z"


@pytest.mark.parametrize("mode", ["NextStep", "SameStep"])
@pytest.mark.parametrize("envs_per_worker", [1, 2])
def test_fork_matches_gymnasium_sync(mode, envs_per_worker):
    sync = gym.make_vec(
        ENV_ID, NUM_ENVS, vectorization_mode="sync", vector_kwargs={"autoreset_mode": mode}
    )
    reference = vector_rollout(sync, STEPS)
    sync.close()
    vec = fork_vec(envs_per_worker=envs_per_worker, autoreset_mode=mode)
    try:
        assert vec.num_workers == -(-NUM_ENVS // envs_per_worker)
        assert all(vec._backend.connected())
        assert data_equivalence(vector_rollout(vec, STEPS), reference, exact=True)
        assert vec._backend._shared is not None  # the barrier went through shared memory
    finally:
        vec.close()


def test_calls_and_attributes_match_serial():
    serial = SerialVectorEnv(ENV_ID, 3)
    vec = fork_vec(num_envs=3, envs_per_worker=1)
    try:
        assert data_equivalence(vec.reset(seed=4), serial.reset(seed=4), exact=True)
        assert vec.get_attr("spec")[0].id == ENV_ID
        vec.set_attr("marker", [1, 2, 3])
        assert list(vec.get_attr("marker")) == [1, 2, 3]
        assert data_equivalence(vec.call("reset", seed=9), serial.call("reset", seed=9))
        pids = vec.worker_pids()
        assert len(set(pids)) == 3 and os.getpid() not in pids
    finally:
        vec.close()
        serial.close()


def test_factories_and_the_synthetic_env_match_serial():
    fns = [partial(gym.make, "chronogym/Synthetic-v0", step_ms=0.0)] * 4
    vec = RayVectorEnv(fns, envs_per_worker=2, transport="fork")
    serial = SerialVectorEnv(fns)
    try:
        got, want = synthetic_rollout(vec, 20), synthetic_rollout(serial, 20)
        assert data_equivalence(got, want, exact=True)
    finally:
        vec.close()
        serial.close()


def test_a_sigkilled_worker_is_replaced_and_its_signal_named():
    undisturbed = vector_rollout(SerialVectorEnv(ENV_ID, 4), 40)
    vec = fork_vec(num_envs=4, envs_per_worker=2)
    old = vec.worker_pids()

    def kill(t, vec):
        if t == 15:
            os.kill(old[1], signal.SIGKILL)
            time.sleep(0.2)

    try:
        run = vector_rollout(vec, 40, kill=kill)
        _, rewards, terminated, truncated, info = run[16]
        assert truncated[2:].all() and not terminated[2:].any() and (rewards[2:] == 0).all()
        assert f"(pid {old[1]}) was killed by SIGKILL" in info["worker_error"][2]
        new = vec.worker_pids()
        assert new[0] == old[0] and new[1] != old[1] and alive(new[1])
        for got, want in zip(run, undisturbed, strict=True):  # the other worker: unaffected
            np.testing.assert_array_equal(got[0][:2], want[0][:2])
        assert np.isfinite(run[-1][0]).all()
        assert all(vec._backend.connected()) and vec._backend._shared is not None
    finally:
        vec.close()


def test_a_hung_worker_is_killed_and_replaced_after_step_timeout():
    from faulty_tasks import HangingCartPole

    from chronogym import SimEnv

    fns = [partial(SimEnv, HangingCartPole(hang_at=3)), partial(SimEnv, HangingCartPole(hang_at=0))]
    vec = RayVectorEnv(fns, envs_per_worker=1, step_timeout=2.0, transport="fork")
    try:
        vec.reset(seed=0)
        hung = vec.worker_pids()[0]
        actions = np.zeros((2, 1), dtype=np.float32)
        vec.step(actions)
        vec.step(actions)
        _, _, _, truncated, info = vec.step(actions)  # env 0 hangs here
        assert truncated.tolist() == [True, False]
        assert "step_timeout=2.0" in info["worker_error"][0]
        _, _, _, truncated, _ = vec.step(actions)  # the replacement answers
        assert not truncated.any()
        time.sleep(0.2)
        assert not alive(hung) and vec.worker_pids()[0] != hung
    finally:
        vec.close()


def test_a_dead_zygote_is_replaced_when_a_worker_needs_forking():
    vec = fork_vec(num_envs=2, envs_per_worker=1)
    try:
        vec.reset(seed=0)
        actions = np.zeros((2, 1), dtype=np.float32)
        old_zygote = vec._backend._zygote.pid
        os.kill(old_zygote, signal.SIGKILL)  # its workers live on, orphaned
        vec.step(actions)
        truncated, info = kill_and_step(vec, vec.worker_pids()[1], actions)
        assert truncated.tolist() == [False, True]
        assert "the worker process (pid" in info["worker_error"][1]
        assert vec._backend._zygote.pid != old_zygote and alive(vec.worker_pids()[1])
        start = time.perf_counter()  # worker 0 is an orphan of the dead zygote
        truncated, info = kill_and_step(vec, vec.worker_pids()[0], actions)
        assert truncated.tolist() == [True, False] and time.perf_counter() - start < 5
        assert "an earlier zygote, is gone" in info["worker_error"][0]
        _, _, _, truncated, _ = vec.step(actions)  # the replacement steps
        assert not truncated.any()
    finally:
        vec.close()


def test_close_ends_every_worker_and_the_zygote():
    vec = fork_vec(num_envs=6, envs_per_worker=1)
    vec.reset(seed=0)
    pids = vec.worker_pids()
    zygote = vec._backend._zygote.pid
    socket_dir = vec._backend.socket_dir
    vec.close()
    time.sleep(0.2)
    assert not any(alive(pid) for pid in [*pids, zygote])
    assert not os.path.exists(socket_dir)


def test_a_worker_that_cannot_start_is_a_clear_error():
    fns = [partial(gym.make, ENV_ID), lambda: os._exit(5)]
    with pytest.raises(RuntimeError, match=r"(?s)forked worker 1 .*exited with code 5"):
        RayVectorEnv(fns, envs_per_worker=1, transport="fork")


def test_the_zygote_preloads_the_modules_the_factories_import():
    from chronogym import SimEnv
    from chronogym.tasks.cartpole.mujoco import CartPoleTask
    from chronogym.vector.fork_transport import preload_modules

    fns = [
        ENV_ID,
        partial(gym.make, "chronogym/Go1Velocity-v0", k=2),
        partial(SimEnv, CartPoleTask()),
        lambda: gym.make(ENV_ID),  # defined here: nothing to name
    ]
    modules = preload_modules(fns)
    for name in (
        "chronogym.registration",  # the ids' entry point
        "chronogym.tasks.cartpole.mujoco",  # the task an id names, and a task object's class
        "chronogym.tasks.quadruped.task",  # the task of the id a partial makes
        "chronogym.env",  # a partial's function
    ):
        assert name in modules, modules
    assert len(modules) == len(set(modules)) and "__main__" not in modules


@pytest.mark.parametrize(
    ("name", "value"),
    [
        ("num_gpus", 1),
        ("num_cpus", 1),
        ("scheduling", "spread"),
        ("worker_niceness", 5),
    ],
)
def test_ray_arguments_are_rejected_by_name(name, value):
    with pytest.raises(ValueError, match=rf"{name}=.*transport='fork'.*expected {name}="):
        fork_vec(**{name: value})


def test_workers_spread_over_nodes_by_their_cpus():
    from chronogym.vector.fork_placement import spread_by_cpus

    assert spread_by_cpus(6, {"a": 1, "b": 1, "c": 1}) == ["a", "a", "b", "b", "c", "c"]
    assert spread_by_cpus(5, {"a": 1, "b": 2, "c": 2}) == ["a", "b", "b", "c", "c"]
    assert spread_by_cpus(4, {"a": 1, "b": 2}) == ["a", "b", "b", "b"]  # 1.33 / 2.67
    assert spread_by_cpus(2, {"a": 4, "b": 4, "c": 4}) == ["a", "b"]  # ties: in order
    with pytest.raises(ValueError, match="cannot spread 2 workers over nodes with CPUs"):
        spread_by_cpus(2, {})
