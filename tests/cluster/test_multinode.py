"""A real 3-node Ray cluster (``ray start`` head + 2 worker nodes on loopback): the same
numbers as serial runs, with the workers spread over nodes."""

from __future__ import annotations

import csv
import math

import numpy as np
import pytest
from local_clusters import driving
from vector_rollouts import synthetic_rollout

from chronogym.testing import ray_start_available

_UNAVAILABLE = ray_start_available()
pytestmark = pytest.mark.skipif(
    _UNAVAILABLE is not None, reason=f"`ray start` unavailable: {_UNAVAILABLE}"
)

GO1 = "chronogym/Go1Velocity-v0"
SYNTHETIC = "chronogym/Synthetic-v0"
TIMING_COLUMNS = ("wall_time", "collect_s", "learn_s", "eval_s")


@pytest.fixture(scope="module")
def cluster():
    """Head + 2 worker nodes, 1 CPU each; this process is the driver (the session's local
    Ray set aside meanwhile)."""
    with driving(workers=2, num_cpus=1) as local:
        yield local


def go1_rollout(vec, steps: int, seed: int = 5) -> list[np.ndarray]:
    """Every array a seeded random-action rollout produces, in order."""
    obs, _ = vec.reset(seed=seed)
    rng = np.random.default_rng(seed)
    arrays = [obs]
    for _ in range(steps):
        actions = rng.uniform(-1.0, 1.0, (vec.num_envs, 12)).astype(np.float32)
        obs, rewards, terminated, truncated, _ = vec.step(actions)
        arrays += [obs, rewards, terminated, truncated]
    return arrays


def tcp_lines(vec) -> int:
    """Nodes whose relay answers the spread step over its TCP line (relay_channel.py)."""
    spread = vec._backend._spread
    return 0 if spread is None else len(spread.lines)


def spread_steps(vec) -> int:
    """Barrier steps made through every node's shared block (spread_step.py) so far."""
    spread = vec._backend._spread
    return 0 if spread is None else spread.steps


def test_cluster_has_three_live_nodes(cluster):
    import ray

    alive = [node for node in ray.nodes() if node["Alive"]]
    assert len(alive) == 3
    assert ray.cluster_resources()["CPU"] == 3.0
    assert {f"node_{k}" for k in range(3)} <= set(ray.cluster_resources())
    with pytest.raises(ValueError, match="is the head"):
        cluster.kill_node("node_0")
    with pytest.raises(ValueError, match="name='node_9'"):
        cluster.kill_node("node_9")


def test_spread_workers_on_distinct_nodes_match_serial(cluster):
    from chronogym.vector.ray_vector_env import RayVectorEnv
    from chronogym.vector.serial import SerialVectorEnv

    vec = RayVectorEnv(
        GO1,
        6,
        envs_per_worker=2,
        num_cpus=0.5,
        address=cluster.address,
        scheduling="spread",
    )
    try:
        nodes = [cluster.node_of_pid(pid) for pid in vec.worker_pids()]
        # the driver's node: its own sockets; every other node: that node's relay
        assert vec._backend.connected() == [node == "node_0" for node in nodes]
        assert vec._backend.relayed() == [node != "node_0" for node in nodes]
        distributed = go1_rollout(vec, steps=60)
        assert spread_steps(vec) == 60  # every node's block; one frame per other node
        remote = {node for node in nodes if node != "node_0"}
        assert tcp_lines(vec) == len(remote)  # over TCP, no Ray call
    finally:
        vec.close()
    assert None not in nodes, f"worker pids not found under any node: {nodes}"
    assert len(set(nodes)) >= 2, f"spread placement put every worker on {nodes}"
    serial = SerialVectorEnv(GO1, 6)
    try:
        reference = go1_rollout(serial, steps=60)
    finally:
        serial.close()
    assert len(distributed) == len(reference)
    for got, want in zip(distributed, reference, strict=True):
        assert got.dtype == want.dtype
        assert got.tobytes() == want.tobytes()


def test_relayed_workers_survive_a_kill_and_a_lost_relay(cluster):
    import os
    import signal
    import time

    import ray

    from chronogym.vector.ray_vector_env import RayVectorEnv

    vec = RayVectorEnv(
        "chronogym/CartPole-v0",
        3,
        envs_per_worker=1,
        num_cpus=0.5,
        address=cluster.address,
        scheduling="spread",
    )
    actions = np.zeros((3, 1), dtype=np.float32)
    try:
        relays = vec._backend._relays
        for actor in relays.by_node.values():  # each relay's socket folder is private
            mode = ray.get(actor.__ray_call__.remote(lambda self: os.stat(self.dir).st_mode))
            assert mode & 0o777 == 0o700
        relayed = [w for w, on in enumerate(vec._backend.relayed()) if on]
        assert relayed, "spread placement left no worker on another node"
        vec.reset(seed=0)
        vec.step(actions)
        assert tcp_lines(vec) == len(relays.by_node)  # a relay's death breaks its line
        victim = relayed[0]
        os.kill(vec.worker_pids()[victim], signal.SIGKILL)
        time.sleep(0.3)
        _, _, _, truncated, info = vec.step(actions)
        assert truncated.tolist() == [w == victim for w in range(3)]
        assert "ActorDiedError" in info["worker_error"][victim]
        before = spread_steps(vec)
        _, _, _, truncated, _ = vec.step(actions)  # the replacement steps, in a new spread step
        assert vec._backend.relayed()[victim] or vec._backend.connected()[victim]
        assert spread_steps(vec) == 1 and before > 1 and not truncated.any()

        node = next(iter(relays.node_of.values()))  # a relay that still serves a worker
        relay = relays.by_node[node]
        served = [w for w, n in relays.node_of.items() if n == node]
        relay_pid = ray.get(relay.pid.remote(), timeout=10)
        ray.kill(relay)
        with pytest.raises(ray.exceptions.RayActorError):  # wait until Ray knows it gone
            for _ in range(100):
                ray.get(relay.pid.remote(), timeout=10)
                time.sleep(0.1)
        with pytest.raises(ProcessLookupError):  # and its process (its TCP line) is gone
            for _ in range(100):
                os.kill(relay_pid, 0)
                time.sleep(0.1)
        _, _, _, truncated, info = vec.step(actions)
        assert all(truncated[w] for w in served)
        assert f"the relay of node {node} failed" in info["worker_error"][served[0]]
        vec.step(actions)
        _, _, _, truncated, _ = vec.step(actions)  # replaced, with a new relay where needed
        assert all(vec._backend.relayed()[w] or vec._backend.connected()[w] for w in range(3))
        assert spread_steps(vec) == 2 and not truncated.any()
    finally:
        vec.close()
    assert vec._backend._relays is None  # closed: the relays are gone too


def test_a_relayed_worker_silent_past_step_timeout_is_replaced(cluster):
    import time

    from chronogym.vector.ray_vector_env import RayVectorEnv

    vec = RayVectorEnv(
        "chronogym/Synthetic-v0",
        3,
        envs_per_worker=1,
        num_cpus=0.5,
        address=cluster.address,
        scheduling="spread",
        step_timeout=1.5,
        env_kwargs={"step_ms": 1.0},
    )
    try:
        slow = vec._backend.relayed().index(True)
        vec.reset(seed=0)
        vec.set_attr("step_ms", [5000.0 if w == slow else 1.0 for w in range(3)])
        start = time.perf_counter()
        _, _, _, truncated, info = vec.step(np.zeros((3, 2), dtype=np.float32))
        assert time.perf_counter() - start < 15
        assert truncated.tolist() == [w == slow for w in range(3)]
        assert "step_timeout=1.5" in info["worker_error"][slow]
        vec.step(np.zeros((3, 2), dtype=np.float32))  # the replacement answers
    finally:
        vec.close()


@pytest.mark.parametrize("info_floats", [0, 3, 20_000])  # none; a relay's tail slot; its socket
def test_spread_step_carries_infos_and_resets_like_serial(cluster, info_floats):
    """Workers on every node (spread), episodes of 7 steps; infos travel whole from a
    relay, in its block's tail slot or, too long for it (80 kB), over the worker's socket.
    With the relays on Ray calls, and with the shared step off (the relays' per-worker
    messages), the same numbers."""
    from chronogym.vector.ray_vector_env import RayVectorEnv
    from chronogym.vector.serial import SerialVectorEnv

    kwargs = {"step_ms": 0.0, "info_floats": info_floats, "max_steps": 7}
    options = {"envs_per_worker": 2, "env_kwargs": kwargs}
    serial = synthetic_rollout(SerialVectorEnv(SYNTHETIC, 6, **options), 20)
    spread = {"address": cluster.address, "scheduling": "spread", "num_cpus": 0.5, **options}
    seen = {}
    for name, extra in (("tcp", {}), ("calls", {"relay_tcp": False}),
                        ("messages", {"shared_memory": False})):  # fmt: skip
        vec = RayVectorEnv(SYNTHETIC, 6, **spread, **extra)  # one at a time: 3 CPUs
        try:
            assert any(vec._backend.relayed()), "spread placement left every worker here"
            got = synthetic_rollout(vec, 20)
            seen[name] = (spread_steps(vec), tcp_lines(vec))
        finally:
            vec.close()
        for mine, theirs in zip(got, serial, strict=True):
            arrays = 4 if len(mine) == 5 else 1  # a step's four arrays; a reset's obs
            for a, b in zip(mine[:arrays], theirs[:arrays], strict=True):
                np.testing.assert_array_equal(a, b)
            if info_floats:
                np.testing.assert_array_equal(mine[-1]["payload"], theirs[-1]["payload"])
    assert seen["tcp"][0] == seen["calls"][0] == 20 and seen["messages"][0] == 0
    assert seen["tcp"][1] >= 1 and seen["calls"][1] == 0


@pytest.mark.parametrize("transport", ["socket", "fork"])
def test_scalar_infos_cross_the_nodes_as_rows_and_survive_a_lost_worker(
    cluster, monkeypatch, transport
):
    """Ant-v5's nine scalar infos, workers on every node: each node's infos come as records
    of one schema (info_rows.py) and join to what a serial run gives, dtypes and all; profiled
    steps go as messages, with every worker's times. With a relayed worker killed, the other
    workers' infos still come, as columns each."""
    import os
    import signal
    import time

    from gymnasium.utils.env_checker import data_equivalence

    from chronogym.vector import spread_step
    from chronogym.vector.ray_vector_env import RayVectorEnv
    from chronogym.vector.serial import SerialVectorEnv

    took = []  # per step with node rows: did they join as one batch of records?
    join = spread_step._take_node_rows

    def watched(nodes, answers, num_envs):
        join(nodes, answers, num_envs)
        took.append((len(nodes), answers.rows is not None))

    monkeypatch.setattr(spread_step, "_take_node_rows", watched)
    where = {"fork": {}, "socket": {"scheduling": "spread", "num_cpus": 0.5}}[transport]
    options = {"envs_per_worker": 2, "autoreset_mode": "SameStep"}
    vec = RayVectorEnv("Ant-v5", 6, address=cluster.address, transport=transport, **where,
                       **options)  # fmt: skip
    rng = np.random.default_rng(4)
    actions = [rng.uniform(-1, 1, (6, 8)).astype(np.float32) for _ in range(14)]
    try:
        relayed = [w for w, on in enumerate(vec._backend.relayed()) if on]
        assert relayed, "no worker on another node"
        got = [vec.reset(seed=2)] + [vec.step(a) for a in actions[:12]]
        relays = vec._backend._relays
        nodes = len(set(relays.node_of.values())) + (len(relayed) < vec.num_workers)
        assert took[-10:] == [(nodes, True)] * 10 and nodes > 1
        spread_steps, profile = vec._backend._spread.steps, vec.profile_steps()
        got += [vec.step(a) for a in actions[12:]]
        vec.profile_steps(enabled=False)
        assert vec._backend._spread.steps == spread_steps and profile.steps == 2
        assert profile.compute_sum > 0 and profile.per_step_us()["wait"] > 0
        os.kill(vec.worker_pids()[relayed[0]], signal.SIGKILL)
        time.sleep(0.3)
        _, _, _, truncated, info = vec.step(actions[0])
        lost = truncated.copy()
        assert lost.sum() == 2 and took[-1][1] is False
        assert info["_reward_forward"].tolist() == (~lost).tolist()  # a step's, not a reset's
        assert info["worker_restarted"][lost].all()
    finally:
        vec.close()
    serial = SerialVectorEnv("Ant-v5", 6, **options)
    try:
        want = [serial.reset(seed=2)] + [serial.step(a) for a in actions]
    finally:
        serial.close()
    assert data_equivalence(got, want, exact=True)


@pytest.mark.parametrize("fails", ["block", "line"])
def test_a_spread_step_falls_back_where_it_cannot_open(cluster, monkeypatch, fails):
    """A node's block that cannot be opened turns shared memory off (with a warning): the
    relays' messages carry every step. A relay's line that cannot be dialled (a firewalled
    port) leaves its node on Ray calls. The same numbers either way."""
    from chronogym.vector.ray_vector_env import RayVectorEnv
    from chronogym.vector.relay_channel import DriverLine
    from chronogym.vector.serial import SerialVectorEnv
    from chronogym.vector.spread_step import SpreadStep

    target = SpreadStep if fails == "block" else DriverLine
    monkeypatch.setattr(target, {"block": "open", "line": "dial"}[fails],
                        classmethod(lambda cls, *args: None))  # fmt: skip
    options = {"envs_per_worker": 1, "env_kwargs": {"step_ms": 0.0, "max_steps": 5}}
    serial = synthetic_rollout(SerialVectorEnv(SYNTHETIC, 3, **options), 12)
    vec = RayVectorEnv(
        SYNTHETIC, 3, address=cluster.address, scheduling="spread", num_cpus=0.5, **options
    )
    try:
        got = synthetic_rollout(vec, 12)
        assert any(vec._backend.relayed())
        assert vec._backend.shared_memory == (fails == "line") and tcp_lines(vec) == 0
        assert spread_steps(vec) == (12 if fails == "line" else 0)
        relays = vec._backend._relays
        if fails == "line":  # not dialled again at the next spread step
            assert relays.lineless == set(relays.by_node)
    finally:
        vec.close()
    for mine, theirs in zip(got[1:], serial[1:], strict=True):
        for a, b in zip(mine[:4], theirs[:4], strict=True):
            np.testing.assert_array_equal(a, b)


def test_forked_workers_spread_over_the_nodes_match_serial(cluster):
    """transport="fork" with an address: the workers spread over the 3 nodes by their CPUs
    (2 each), those of other nodes forked by their node's relay; no Ray actor per worker;
    steps, resets and calls through the relays; the same numbers as serial."""
    import time

    from chronogym.vector.fork_zygote import running
    from chronogym.vector.ray_vector_env import RayVectorEnv
    from chronogym.vector.serial import SerialVectorEnv

    vec = RayVectorEnv(GO1, 6, envs_per_worker=1, transport="fork", address=cluster.address)
    try:
        nodes = [cluster.node_of_pid(pid) for pid in vec.worker_pids()]
        # the driver's node: forked by the driver's zygote (no Ray process is their parent)
        assert nodes[:2] == [None, None] and nodes[2] == nodes[3] and nodes[4] == nodes[5]
        assert sorted(nodes[2:]) == ["node_1", "node_1", "node_2", "node_2"]  # in blocks
        assert [vec._backend.node(w) is None for w in range(6)] == [True] * 2 + [False] * 4
        assert vec._backend.actors == []
        assert vec._backend.connected() == [node is None for node in nodes]
        assert vec._backend.relayed() == [node is not None for node in nodes]
        distributed = go1_rollout(vec, steps=40)
        assert spread_steps(vec) == 40 and tcp_lines(vec) == 2
        assert vec.get_attr("spec")[4].id == GO1  # a call through node_2's relay
        vec.set_attr("marker", list(range(6)))
        assert list(vec.get_attr("marker")) == list(range(6))
        pids = vec.worker_pids()
    finally:
        vec.close()
    deadline = time.monotonic() + 10  # the relays' zygotes kill their workers as they close
    while any(running(pid) for pid in pids) and time.monotonic() < deadline:
        time.sleep(0.1)
    assert not any(running(pid) for pid in pids)
    serial = SerialVectorEnv(GO1, 6)
    try:
        reference = go1_rollout(serial, steps=40)
    finally:
        serial.close()
    for got, want in zip(distributed, reference, strict=True):
        assert got.dtype == want.dtype
        assert got.tobytes() == want.tobytes()


def test_forked_workers_elsewhere_are_replaced_after_a_kill_a_hang_and_a_lost_relay(cluster):
    import os
    import signal
    import time

    import ray

    from chronogym.vector.ray_vector_env import RayVectorEnv

    vec = RayVectorEnv(
        SYNTHETIC,
        3,
        envs_per_worker=1,
        transport="fork",
        address=cluster.address,
        step_timeout=2.0,
        env_kwargs={"step_ms": 1.0},
    )
    actions = np.zeros((3, 2), dtype=np.float32)
    try:
        backend = vec._backend
        assert backend.relayed() == [False, True, True]
        vec.reset(seed=0)
        vec.step(actions)
        node_1 = cluster.node_of_pid(vec.worker_pids()[1])
        os.kill(vec.worker_pids()[1], signal.SIGKILL)  # a forked worker on another node
        time.sleep(0.3)
        _, _, _, truncated, info = vec.step(actions)
        assert truncated.tolist() == [False, True, False]
        assert f"on node {backend.node(1)}) was killed by SIGKILL" in info["worker_error"][1]
        _, _, _, truncated, _ = vec.step(actions)  # its replacement, forked there again
        assert not truncated.any() and backend.relayed() == [False, True, True]
        assert cluster.node_of_pid(vec.worker_pids()[1]) == node_1
        assert "(worker 1's socket on its node failed: EOFError" in info["worker_error"][1]

        vec.set_attr("step_ms", [1.0, 1.0, 60_000.0])  # worker 2 hangs past step_timeout
        start = time.perf_counter()
        _, _, _, truncated, info = vec.step(actions)
        assert time.perf_counter() - start < 20
        assert truncated.tolist() == [False, False, True]
        assert "step_timeout=2.0" in info["worker_error"][2]
        _, _, _, truncated, _ = vec.step(actions)  # replaced (its step_ms: the default)
        assert not truncated.any()

        relay = backend._relays.by_node[backend.node(2)]
        relay_pid = ray.get(relay.pid.remote(), timeout=10)
        ray.kill(relay)
        with pytest.raises(ProcessLookupError):  # wait until its process (its line) is gone
            for _ in range(100):
                os.kill(relay_pid, 0)
                time.sleep(0.1)
        _, _, _, truncated, info = vec.step(actions)
        assert truncated.tolist() == [False, False, True]
        assert "failed" in info["worker_error"][2]
        vec.step(actions)
        _, _, _, truncated, _ = vec.step(actions)  # forked by a new relay on its node
        assert not truncated.any() and backend.relayed() == [False, True, True]
    finally:
        vec.close()
    assert vec._backend._relays is None


def test_a_forked_worker_that_dies_building_on_another_node_is_a_clear_error(cluster):
    import os
    from functools import partial

    import gymnasium as gym

    from chronogym.vector.ray_vector_env import RayVectorEnv

    fns = [partial(gym.make, SYNTHETIC), partial(gym.make, SYNTHETIC), lambda: os._exit(5)]
    pattern = r"(?s)forked worker 2 on node \w+ failed while building.*exited with code 5"
    with pytest.raises(RuntimeError, match=pattern):
        RayVectorEnv(fns, envs_per_worker=1, transport="fork", address=cluster.address)


@pytest.mark.parametrize("transport", ["socket", "fork"])
def test_batch_mode_with_workers_on_other_nodes_matches_sync(cluster, transport):
    """EnvPool's batch (``recv(min_envs=2, max_envs=2)``) with workers on every node: Ray
    workers through their relays' calls, or forked ones; the same numbers per env."""
    from gymnasium.utils.env_checker import data_equivalence
    from vector_rollouts import STEPS, async_rollout, sync_replay, uneven_fns

    from chronogym.vector.ray_vector_env import RayVectorEnv

    fns = uneven_fns()
    options = {"transport": "fork"}
    if transport == "socket":
        options = {"scheduling": "spread", "num_cpus": 0.5}
    vec = RayVectorEnv(fns, envs_per_worker=1, address=cluster.address, **options)
    try:
        assert sum(vec._backend.relayed()) >= 2
        traj, acts, (batches, _) = async_rollout(vec, STEPS, min_envs=2, max_envs=2)
    finally:
        vec.close()
    assert len(batches[0]) == 2 and {len(b) for b in batches} <= {1, 2}
    reference = sync_replay(fns, acts, STEPS, "NextStep")
    for i in range(len(fns)):
        for t, (got, want) in enumerate(zip(traj[i], reference[i], strict=True)):
            assert data_equivalence(got, want, exact=True), f"env {i} differs at step {t}"


def test_bench_sizes_forked_workers_on_the_cluster(cluster):
    from chronogym.sizing import format_report, run_bench

    report = run_bench(
        "chronogym/CartPole-v0",
        seconds=0.2,
        max_workers=3,
        address=cluster.address,
        transport="fork",
        log=lambda *_: None,
    )
    assert report.cpus == 3 and report.where == "the cluster"
    assert [run.workers for run in report.runs][:2] == [1, 2] and report.check is not None
    assert "the cluster has 3 CPUs" in format_report(report)


def test_workers_group_by_node_with_their_rows():
    from chronogym.vector.spread_step import HERE, by_node

    groups = by_node([(0, 2), (2, 3), (3, 5), (5, 6)], {1: "b", 2: "a", 3: "b"})
    assert [g.node for g in groups] == [HERE, "b", "a"]
    assert [g.workers for g in groups] == [[0], [1, 3], [2]]
    assert [g.slices for g in groups] == [[(0, 2)], [(0, 1), (1, 2)], [(0, 2)]]
    assert [g.rows.tolist() for g in groups] == [[0, 1], [2, 5], [3, 4]]


def test_bad_scheduling_is_rejected_by_name(cluster):
    from chronogym.vector.ray_vector_env import RayVectorEnv

    with pytest.raises(ValueError, match="scheduling='packed'"):
        RayVectorEnv(GO1, 2, address=cluster.address, scheduling="packed")


def read_progress(path) -> list[dict[str, float]]:
    with open(path) as handle:
        return [{k: float(v) for k, v in row.items()} for row in csv.DictReader(handle)]


def assert_same_rows(got_rows: list[dict], want_rows: list[dict]) -> None:
    """progress.csv rows equal in every column but the timings (NaN equals NaN)."""
    assert len(got_rows) == len(want_rows)
    for got, want in zip(got_rows, want_rows, strict=True):
        for key in set(want) - set(TIMING_COLUMNS):
            same = got[key] == want[key] or (math.isnan(got[key]) and math.isnan(want[key]))
            assert same, f"{key}: {got[key]} on the cluster, {want[key]} serial"


def test_train_quadruped_on_the_cluster_matches_serial(cluster, tmp_path):
    import torch

    from chronogym.tasks.quadruped.training import quadruped_train_config, train_quadruped

    def run(backend: str, address: str | None):
        cfg = quadruped_train_config(num_steps_per_env=16, save_interval=100)
        out = tmp_path / backend
        result = train_quadruped(
            out,
            num_envs=4,
            backend=backend,
            iterations=2,
            seed=3,
            address=address,
            train_cfg=cfg,
            progress=False,
        )
        state = torch.load(result.checkpoint, map_location="cpu", weights_only=True)
        return read_progress(result.csv_path), state["actor_state_dict"]

    ray_rows, ray_actor = run("ray", cluster.address)
    serial_rows, serial_actor = run("serial", None)
    assert [r["iteration"] for r in ray_rows] == [0.0, 1.0]
    assert [r["env_steps"] for r in ray_rows] == [64.0, 128.0]
    assert_same_rows(ray_rows, serial_rows)
    # the strongest check: PPO saw the same data, so the updated weights are identical
    assert ray_actor.keys() == serial_actor.keys()
    for name, tensor in ray_actor.items():
        assert torch.equal(tensor, serial_actor[name]), name


def test_short_episodes_give_the_same_rewards_on_the_cluster(cluster, tmp_path):
    """8-step episodes, so progress.csv holds real episode rewards and tracking errors
    (the 1000-step episodes above never end in 2 short iterations: those columns are NaN)."""
    from chronogym.rl.trainer import train
    from chronogym.rl.vecenv import RslRlVecEnv
    from chronogym.tasks.quadruped.training import make_quadruped_vec_env, quadruped_train_config

    def run(backend: str, address: str | None) -> list[dict[str, float]]:
        extra = {"address": address} if address else {}
        vec = make_quadruped_vec_env(4, backend, env_kwargs={"max_episode_steps": 8}, **extra)
        env = RslRlVecEnv(vec, seed=3)
        try:
            cfg = quadruped_train_config(num_steps_per_env=16, save_interval=100)
            result = train(
                env, tmp_path / backend, iterations=2, train_cfg=cfg, seed=3, progress=False
            )
        finally:
            env.close()
        return read_progress(result.csv_path)

    ray_rows = run("ray", cluster.address)
    serial_rows = run("serial", None)
    assert all(math.isfinite(row["mean_reward"]) for row in ray_rows)
    assert_same_rows(ray_rows, serial_rows)


def lander_study(tmp_path, name: str, workers: int, backend: str, address: str | None):
    import optuna

    from chronogym.optim import open_storage, run_parallel_study
    from chronogym.optim.lander import LanderObjective, suggest_lander_design

    optuna.logging.set_verbosity(optuna.logging.WARNING)
    # every trial is a startup trial: its design depends only on the seed and its number,
    # never on which worker answered first
    sampler = optuna.samplers.TPESampler(seed=7, n_startup_trials=6, constant_liar=True)
    study = optuna.create_study(
        storage=open_storage(f"sqlite:///{tmp_path}/{name}.db"),
        study_name=name,
        sampler=sampler,
    )
    report = run_parallel_study(
        study,
        suggest_lander_design,
        LanderObjective("rigid", seed=0),
        6,
        workers=workers,
        backend=backend,
        address=address,
        scheduling="spread" if backend == "ray" else "default",
        progress=False,
    )
    return report, {t.number: (t.params, t.value, t.state.name) for t in study.trials}


def test_lander_study_on_the_cluster_matches_serial(cluster, tmp_path):
    report, trials = lander_study(tmp_path, "cluster", 2, "ray", cluster.address)
    _, reference = lander_study(tmp_path, "serial", 1, "serial", None)
    assert report.completed == 6 and report.failed == 0
    assert sorted(trials) == list(range(6))
    assert all(state == "COMPLETE" for _, _, state in trials.values())
    assert trials == reference
