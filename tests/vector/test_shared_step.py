"""The barrier step through shared memory (``RayVectorEnv(shared_memory=True)``, the default
with workers on the driver's node): the same numbers as serially, answers with infos in the
tail slot and on the socket, faults, and the switch. Real Ray (2 CPUs), real MuJoCo."""

from __future__ import annotations

import os
import signal
import time
from functools import partial
from pathlib import Path

import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence
from vector_rollouts import ENV_ID, assert_same_rollouts, synthetic_rollout, vector_rollout

from chronogym import BoolArgumentError, RayVectorEnv, SerialVectorEnv
from chronogym.testing.synthetic import ENV_ID as SYNTHETIC_ID
from chronogym.testing.synthetic import SyntheticEnv
from chronogym.vector.shared_step import (
    FANOUT,
    TAIL_BYTES,
    TREE_MIN_WORKERS,
    SharedLayout,
    wake_plan,
    wants_tree,
)


def cpu_seconds(pid: int) -> float:
    """User + system CPU seconds of process ``pid`` so far (Linux /proc)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def shared_steps(vec: RayVectorEnv) -> int:
    """Barrier steps the vector env made through shared memory so far."""
    shared = vec._backend._shared
    return 0 if shared is None else shared.gen


@pytest.mark.parametrize("mode", ["NextStep", "SameStep"])
def test_shared_step_matches_serial(ray_cluster, mode):
    """5 envs on workers of 2, 2 and 1 (uneven rows); episodes end, so SameStep's final_obs
    infos travel in the tail slots."""
    serial = vector_rollout(SerialVectorEnv(ENV_ID, 5, autoreset_mode=mode), 200)
    vec = RayVectorEnv(ENV_ID, 5, envs_per_worker=2, autoreset_mode=mode)
    try:
        assert_same_rollouts(vector_rollout(vec, 200), serial)
        assert shared_steps(vec) == 200
        assert vec._backend._shared.attached == {0, 1, 2}
    finally:
        vec.close()


@pytest.mark.parametrize(
    "info_floats",
    [0, 3, TAIL_BYTES // 4],  # no info; one in the tail slot; one too long for it (the socket)
)
def test_infos_of_every_size_come_back(ray_cluster, info_floats):
    kwargs = {"step_ms": 0.0, "info_floats": info_floats, "max_steps": 7}
    serial = SerialVectorEnv(SYNTHETIC_ID, 4, envs_per_worker=2, env_kwargs=kwargs)
    vec = RayVectorEnv(SYNTHETIC_ID, 4, envs_per_worker=2, env_kwargs=kwargs)
    try:
        assert_same_rollouts(synthetic_rollout(vec, 20), synthetic_rollout(serial, 20))
        assert shared_steps(vec) == 20
        if info_floats:
            _, _, _, _, info = vec.step(np.zeros((4, 2), np.float32))
            assert info["payload"].shape == (4, info_floats)
    finally:
        vec.close()


@pytest.mark.parametrize("transport", ["socket", "fork"])
def test_profiled_steps_time_the_shared_block(ray_cluster, transport):
    """profile_steps() times the path step takes: the block, with each worker's compute
    read from it; the numbers stay serial's, and the workers stop timing once it is off."""
    kwargs = {"step_ms": 2.0, "max_steps": 7, "info_scalars": 2}
    serial = SerialVectorEnv(SYNTHETIC_ID, 4, envs_per_worker=2, env_kwargs=kwargs)
    vec = RayVectorEnv(SYNTHETIC_ID, 4, envs_per_worker=2, env_kwargs=kwargs, transport=transport)
    try:
        profile = vec.profile_steps()
        assert_same_rollouts(synthetic_rollout(vec, 12), synthetic_rollout(serial, 12))
        assert shared_steps(vec) == 12 and profile.steps == 12
        times = profile.per_step_us()
        assert times["compute"] > 1000  # two envs of 2 ms each per worker, timed there
        assert times["compute_sum"] > 1.5 * times["compute"]  # both workers reported
        assert times["wait"] >= times["compute"] > 0 and times["get"] > 0
        vec.profile_steps(enabled=False)
        vec.step(np.zeros((4, 2), np.float32))
        assert shared_steps(vec) == 13 and profile.steps == 12
        assert vec._backend._shared.views.timed[0] == 0
    finally:
        vec.close()


def test_a_worker_killed_between_shared_steps_is_replaced_and_attached(ray_cluster):
    vec = RayVectorEnv(ENV_ID, 4, envs_per_worker=2)
    try:
        vec.reset(seed=0)
        actions = np.zeros((4, 1), np.float32)
        vec.step(actions)
        os.kill(vec.worker_pids()[1], signal.SIGKILL)
        time.sleep(0.3)
        _, rewards, _, truncated, info = vec.step(actions)
        assert (rewards[2:] == 0).all()
        assert truncated.tolist() == [False, False, True, True]
        assert info["worker_restarted"][2:].all()
        before = shared_steps(vec)
        _, _, _, truncated, _ = vec.step(actions)  # the replacement steps in shared memory
        assert shared_steps(vec) == before + 1 and not truncated.any()
        assert vec._backend._shared.attached == {0, 1}
    finally:
        vec.close()


def test_shared_memory_off_steps_over_sockets_with_the_same_numbers(ray_cluster):
    on = RayVectorEnv(ENV_ID, 3, envs_per_worker=1, num_cpus=0.3)
    off = RayVectorEnv(ENV_ID, 3, envs_per_worker=1, num_cpus=0.3, shared_memory=False)
    try:
        assert_same_rollouts(vector_rollout(off, 60), vector_rollout(on, 60))
        assert shared_steps(off) == 0 and shared_steps(on) == 60
        assert all(off._backend.connected())
    finally:
        on.close()
        off.close()


def test_actor_transport_and_driver_worker_take_no_shared_step(ray_cluster):
    vec = RayVectorEnv(ENV_ID, 2, envs_per_worker=1, driver_worker=True)
    try:
        vector_rollout(vec, 5)
        assert shared_steps(vec) == 0
    finally:
        vec.close()


def test_layout_parts_do_not_overlap():
    layout = SharedLayout(((0, 2), (2, 3)), action_row=8, obs_row=12)
    starts = sorted(v for k, v in layout.offsets.items() if k != "end")
    assert starts == sorted(set(starts)) and all(s % 64 == 0 for s in starts)
    assert layout.offsets["obs"] - layout.offsets["actions"] >= 3 * 8
    assert layout.size >= layout.offsets["tails"] + 2 * TAIL_BYTES


@pytest.mark.parametrize("value", ["yes", 1, None])
def test_bad_shared_memory_is_named(value):
    with pytest.raises(BoolArgumentError, match=rf"^shared_memory={value!r}: expected True or"):
        RayVectorEnv(ENV_ID, 2, shared_memory=value)


def test_a_worker_that_cannot_attach_turns_the_shared_step_off(ray_cluster, monkeypatch):
    """The fallback: a refused attach closes that worker's socket (Ray calls), the rest keep
    their sockets, and every step is still exact."""
    from chronogym.vector import shared_step

    attach = shared_step.SharedStep.attach

    def refuse_worker_1(self, w, sock, timeout):
        return False if w == 1 else attach(self, w, sock, timeout)

    monkeypatch.setattr(shared_step.SharedStep, "attach", refuse_worker_1)
    serial = vector_rollout(SerialVectorEnv(ENV_ID, 3), 30)
    vec = RayVectorEnv(ENV_ID, 3, envs_per_worker=1, num_cpus=0.3)
    try:
        assert_same_rollouts(vector_rollout(vec, 30), serial)
        assert vec._backend._shared is None and not vec._backend.shared_memory
        assert vec._backend.connected() == [True, False, True]
        # worker 0 had attached: its go pipe hung up, and it went back to waiting, not spinning
        busy = cpu_seconds(vec.worker_pids()[0])
        time.sleep(2.0)
        assert cpu_seconds(vec.worker_pids()[0]) - busy < 0.5
    finally:
        vec.close()


def test_wake_plan_groups_many_workers_with_a_core_each():
    assert wake_plan(3, tree=False) == [[0, 1, 2]]
    groups = wake_plan(TREE_MIN_WORKERS + 1, tree=True)
    assert [w for g in groups for w in g] == list(range(TREE_MIN_WORKERS + 1))
    assert {len(g) for g in groups[:-1]} == {FANOUT}
    assert wants_tree(TREE_MIN_WORKERS, cpus=64) and not wants_tree(TREE_MIN_WORKERS - 1, 64)
    assert not wants_tree(TREE_MIN_WORKERS, cpus=2)  # more workers than cores: flat


@pytest.fixture
def small_groups(monkeypatch):
    """Groups of 2 (the driver's side decides who wakes whom)."""
    from chronogym.vector import shared_step

    monkeypatch.setattr(shared_step, "FANOUT", 2)


def grouped(vec: RayVectorEnv) -> RayVectorEnv:
    vec._backend.wake_tree = True  # read at the first step
    return vec


def test_leaders_wake_their_groups_with_the_same_numbers(ray_cluster, small_groups):
    serial = vector_rollout(SerialVectorEnv(ENV_ID, 5, autoreset_mode="SameStep"), 80)
    vec = grouped(
        RayVectorEnv(ENV_ID, 5, envs_per_worker=1, num_cpus=0.2, autoreset_mode="SameStep")
    )
    try:
        assert_same_rollouts(vector_rollout(vec, 80), serial)
        shared = vec._backend._shared
        assert shared.groups == [[0, 1], [2, 3], [4]] and shared_steps(vec) == 80
        assert [shared.role(w) for w in range(5)] == ["leader", "member"] * 2 + ["leader"]
    finally:
        vec.close()


def test_a_dead_leader_does_not_strand_its_group(ray_cluster, small_groups):
    """Worker 2 leads worker 3: killed, the driver wakes 3 itself; 2's replacement leads."""
    vec = grouped(RayVectorEnv(ENV_ID, 4, envs_per_worker=1, num_cpus=0.2))
    try:
        vec.reset(seed=0)
        actions = np.zeros((4, 1), np.float32)
        vec.step(actions)
        assert vec._backend._shared.role(2) == "leader"
        os.kill(vec.worker_pids()[2], signal.SIGKILL)
        time.sleep(0.3)
        _, _, _, truncated, _ = vec.step(actions)
        assert truncated.tolist() == [False, False, True, False]
        for _ in range(3):  # the replacement wakes worker 3 again
            _, _, _, truncated, _ = vec.step(actions)
            assert not truncated.any()
        assert vec._backend._shared.attached == {0, 1, 2, 3}
    finally:
        vec.close()


def test_rows_and_tail_slots_mix_in_one_step(ray_cluster):
    """Episodes that end at different steps (SameStep): on such a step the ended env's worker
    sends ``final_obs`` in its tail slot while the other workers write their scalar infos as
    rows; the vector info is serial's, key by key, at every step."""
    fns = [
        partial(SyntheticEnv, step_ms=0.0, info_scalars=3, max_steps=k) for k in (3, 3, 4, 4, 6, 6)
    ]
    serial = SerialVectorEnv(fns, autoreset_mode="SameStep")
    vec = RayVectorEnv(fns, envs_per_worker=2, autoreset_mode="SameStep")
    try:
        got, want = synthetic_rollout(vec, 14), synthetic_rollout(serial, 14)
        assert_same_rollouts(got, want)
        for a, b in zip(got[1:], want[1:], strict=True):
            assert data_equivalence(a[4], b[4], exact=True), (a[4], b[4])
        ended = [int(out[3].sum()) for out in want[1:]]
        assert ended[2] == 2 and ended[3] == 2 and ended[5] == 4  # steps 3, 4, 6: mixed
        assert "final_obs" in want[3][4] and "info_0" in want[3][4]
        assert shared_steps(vec) == 14
    finally:
        vec.close()
        serial.close()
