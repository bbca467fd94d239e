"""Shared fixtures: one real local Ray cluster for the session (2 CPUs)."""

from __future__ import annotations

import os
from pathlib import Path

import pytest

import chronogym  # noqa: F401  (first: it picks MuJoCo's headless GL backend)

TESTS_DIR = Path(__file__).parent

# Ray workers import test-only tasks (tests/faulty_tasks.py) by module name.
os.environ["PYTHONPATH"] = os.pathsep.join(
    p for p in (str(TESTS_DIR), os.environ.get("PYTHONPATH", "")) if p
)


@pytest.fixture(scope="session")
def ray_cluster():
    """A real local Ray cluster with 2 CPUs, shared by every test that needs Ray."""
    import ray

    if not ray.is_initialized():
        ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
    yield ray
    ray.shutdown()
