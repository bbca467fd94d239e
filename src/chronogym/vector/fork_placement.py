"""Where ``transport="fork"`` puts its workers, and the arguments that mean nothing to them.

Without a cluster (no ``address``, no ``RAY_ADDRESS``) every forked worker is on the
driver's machine and Ray is not used. With one, the workers are spread over the live nodes
that offer CPUs, in proportion to those CPUs, in blocks of consecutive workers, the driver's
node first: each block is forked by its node's relay (:mod:`chronogym.vector.relay`).
Nothing is reserved for them, so Ray's placement arguments are refused by name.
"""

from __future__ import annotations

import os
from typing import Any

from chronogym.ray_runtime import WORKER_NICENESS


def check_fork_arguments(**given: Any) -> None:
    """Reject the Ray arguments that mean nothing to forked workers, by name."""
    ray_only = {
        "num_cpus": None,
        "num_gpus": 0,
        "worker_niceness": WORKER_NICENESS,
        "scheduling": "default",
    }
    for name, value in given.items():
        if name in ray_only and value != ray_only[name]:
            raise ValueError(
                f"{name}={value!r} with transport='fork': forked workers are not Ray actors "
                "(nothing is reserved for them, they are spread over the nodes by their CPUs "
                "and run at their parent's priority); expected "
                f"{name}={ray_only[name]!r} (or a Ray transport, 'socket' or 'actor')"
            )


def forks_here_only(address: str | None) -> bool:
    """Will ``transport="fork"`` keep every worker on this machine, without Ray? Yes unless
    a cluster is named (``address``, else ``RAY_ADDRESS``)."""
    return not (address or os.environ.get("RAY_ADDRESS"))


def spread_by_cpus(workers: int, cpus: dict[str, float]) -> list[str]:
    """Each worker's node: ``workers`` spread over the nodes of ``cpus`` (node -> CPUs) in
    proportion to their CPUs (largest remainders first, ties in ``cpus``' order), in
    blocks of consecutive workers, in ``cpus``' order."""
    total = sum(cpus.values())
    if workers < 1 or total <= 0:
        raise ValueError(f"cannot spread {workers} workers over nodes with CPUs {cpus}")
    shares = {node: workers * n / total for node, n in cpus.items()}
    counts = {node: int(share) for node, share in shares.items()}
    by_remainder = sorted(cpus, key=lambda node: counts[node] - shares[node])  # stable
    for node in by_remainder[: workers - sum(counts.values())]:
        counts[node] += 1
    return [node for node in cpus for _ in range(counts[node])]


def cluster_nodes() -> dict[str, float]:
    """The live nodes of the connected Ray cluster that offer CPUs (node id -> CPUs), the
    driver's own first."""
    import ray

    here = ray.get_runtime_context().get_node_id()
    nodes = {
        node["NodeID"]: float(node["Resources"].get("CPU", 0.0))
        for node in ray.nodes()
        if node["Alive"] and node["Resources"].get("CPU", 0.0) > 0
    }
    return dict(sorted(nodes.items(), key=lambda item: item[0] != here))
