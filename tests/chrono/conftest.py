"""Shared by the Chrono tests: the ``chrono`` fixture skips a test without PyChrono."""

from __future__ import annotations

import pytest

SKIP_REASON = "PyChrono is not installed (conda install projectchrono::pychrono -c conda-forge)"


@pytest.fixture(scope="module")
def chrono():
    """The ``pychrono`` module; skips the test (with :data:`SKIP_REASON`) without it."""
    return pytest.importorskip("pychrono", reason=SKIP_REASON)
