"""Registers the ``slow`` marker of the docs examples."""

from __future__ import annotations

import pytest


def pytest_configure(config: pytest.Config) -> None:
    config.addinivalue_line(
        "markers", "slow: a docs example that runs only with CHRONOGYM_DOCS_SLOW=1"
    )
