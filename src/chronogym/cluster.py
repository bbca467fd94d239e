"""Deprecated: :class:`LocalCluster` moved to :mod:`chronogym.testing`.

``from chronogym.cluster import LocalCluster`` still works and warns; import it from
``chronogym.testing`` instead.
"""

from __future__ import annotations

import warnings
from typing import Any

from chronogym.testing import cluster as _moved


def __getattr__(name: str) -> Any:
    value = getattr(_moved, name)  # AttributeError for a name the module never had
    warnings.warn(
        f"chronogym.cluster.{name} moved to chronogym.testing.cluster "
        f"(LocalCluster: `from chronogym.testing import LocalCluster`)",
        DeprecationWarning,
        stacklevel=2,
    )
    return value
