"""LocalCluster's ports: distinct picks, and a retry with fresh ports when ``ray start``
refuses one (a real ``ray start``, handed a clashing set of ports on its first try)."""

from __future__ import annotations

import socket

import pytest
from local_clusters import without_session_ray

import chronogym.testing.cluster as cluster_module
from chronogym.testing import LocalCluster, ray_start_available
from chronogym.testing.cluster import NodeStartError, free_ports


def test_free_ports_are_distinct_and_skip_the_excluded():
    first = free_ports(20)
    assert len(set(first)) == 20
    again = free_ports(20, exclude=set(first))
    assert not set(again) & set(first)
    with socket.socket(socket.AF_INET, socket.SOCK_STREAM) as sock:
        sock.bind(("127.0.0.1", again[0]))  # each was free when it was handed out
    with pytest.raises(ValueError, match="count=-1"):
        free_ports(-1)


_UNAVAILABLE = ray_start_available()


@pytest.mark.skipif(_UNAVAILABLE is not None, reason=f"`ray start` unavailable: {_UNAVAILABLE}")
def test_a_port_clash_at_start_is_retried_with_fresh_ports(monkeypatch):
    calls = []
    real = cluster_module.free_ports

    def clashing_on_first_node(count, exclude=frozenset()):
        ports = real(count, exclude)
        calls.append(count)
        if len(calls) == 2:  # the head's own ports, first try: all the same number
            return [ports[0]] * count
        return ports

    monkeypatch.setattr(cluster_module, "free_ports", clashing_on_first_node)
    with without_session_ray(), LocalCluster(workers=0, num_cpus=1) as local:
        assert len(local._alive_nodes()) == 1
    assert len(calls) >= 4, calls  # a second try picked fresh ports


def test_node_start_error_says_whether_a_port_clashed():
    assert NodeStartError("x", port_clash=True).port_clash
    assert not NodeStartError("x").port_clash
    assert isinstance(NodeStartError("x"), RuntimeError)
