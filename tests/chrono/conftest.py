"""Shared by the Chrono tests: the ``chrono`` fixture skips a test without PyChrono, the
``vehicle`` fixture one without its vehicle module."""

from __future__ import annotations

import pytest

SKIP_REASON = "PyChrono is not installed (conda install projectchrono::pychrono -c conda-forge)"


@pytest.fixture(scope="module")
def chrono():
    """The ``pychrono`` module; skips the test (with :data:`SKIP_REASON`) without it."""
    return pytest.importorskip("pychrono", reason=SKIP_REASON)


@pytest.fixture(scope="module")
def vehicle(chrono):
    """The ``pychrono.vehicle`` module; skips the test without it."""
    reason = (
        "PyChrono's vehicle module is not installed (conda install projectchrono::pychrono "
        "-c conda-forge, or Chrono built with CH_ENABLE_MODULE_VEHICLE=ON)"
    )
    return pytest.importorskip("pychrono.vehicle", reason=reason)
