"""Tests' multi-node clusters: the session's local Ray set aside while one runs."""

from __future__ import annotations

import contextlib
from collections.abc import Iterator
from typing import Any

from chronogym.testing import LocalCluster


@contextlib.contextmanager
def without_session_ray() -> Iterator[None]:
    """The local Ray of other tests (conftest.py's ``ray_cluster``), if initialized, shut
    down for the block and started again after it, as conftest.py starts it."""
    import ray

    was_local = ray.is_initialized()
    if was_local:
        ray.shutdown()
    try:
        yield
    finally:
        if was_local:
            ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)


@contextlib.contextmanager
def driving(workers: int, num_cpus: int, **options: Any) -> Iterator[LocalCluster]:
    """A head and ``workers`` worker nodes of ``num_cpus`` CPUs each (``options``: more of
    LocalCluster's), this process their driver (connected) for the block."""
    cluster = LocalCluster(workers=workers, num_cpus=num_cpus, **options)
    with without_session_ray(), cluster as local:
        local.connect()
        try:
            yield local
        finally:
            local.disconnect()
