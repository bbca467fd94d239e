"""Forked workers (``transport="fork"``) on real loopback Ray clusters of their own: a node
lost under them (its workers are reported truncated and forked again on a live node), and a
cluster with no CPUs for them."""

from __future__ import annotations

import time

import numpy as np
import pytest
from local_clusters import driving

from chronogym.testing import ray_start_available

_UNAVAILABLE = ray_start_available()
pytestmark = pytest.mark.skipif(
    _UNAVAILABLE is not None, reason=f"`ray start` unavailable: {_UNAVAILABLE}"
)


@pytest.fixture
def cluster():
    """Head + 1 worker node, 1 CPU each (this process is the driver); its own cluster, since
    the test kills a node."""
    with driving(workers=1, num_cpus=1) as local:
        yield local


def test_forked_workers_of_a_lost_node_are_forked_again_on_a_live_one(cluster):
    from chronogym.vector.ray_vector_env import RayVectorEnv

    vec = RayVectorEnv(
        "chronogym/Synthetic-v0",
        2,
        envs_per_worker=1,
        transport="fork",
        address=cluster.address,
        env_kwargs={"step_ms": 1.0},
    )
    actions = np.zeros((2, 2), dtype=np.float32)
    try:
        backend = vec._backend
        assert backend.relayed() == [False, True]  # one worker per node, by their CPUs
        assert cluster.node_of_pid(vec.worker_pids()[1]) == "node_1"
        vec.reset(seed=0)
        vec.step(actions)
        cluster.kill_node("node_1")
        start = time.perf_counter()
        _, _, _, truncated, info = vec.step(actions)
        assert truncated.tolist() == [False, True]
        assert "is lost with its node's relay" in info["worker_error"][1]
        _, _, _, truncated, _ = vec.step(actions)  # forked again, on the only live node
        assert not truncated.any()
        assert backend.node(1) is None and backend.connected() == [True, True]
        # a relay asked to fork on the lost node fails once Ray marks it dead (~15 s here)
        assert time.perf_counter() - start < 90
    finally:
        vec.close()


def test_a_cluster_without_cpus_for_forked_workers_is_a_clear_error():
    from chronogym.vector.ray_vector_env import RayVectorEnv

    nothing_here = pytest.raises(RuntimeError, match="no live node of the Ray cluster offers CPUs")
    with driving(workers=0, num_cpus=1, head_cpus=0) as cluster, nothing_here:
        RayVectorEnv("chronogym/Synthetic-v0", 2, transport="fork", address=cluster.address)
