"""Test and benchmark utilities: scaffolding for chronogym's own tests and benchmarks.

Not part of the simulation API, and not imported by ``import chronogym``. Importing this
package is cheap (standard library only); Ray is imported when a cluster starts, Gymnasium
and NumPy when :class:`SyntheticEnv` is first used.

- :class:`LocalCluster` (:mod:`chronogym.testing.cluster`): a real multi-node Ray cluster on
  one machine, started with ``ray start`` subprocesses that it alone stops;
  :func:`ray_start_available` says why one cannot start here, if it cannot.
- :class:`SyntheticEnv` (:mod:`chronogym.testing.synthetic`, id ``chronogym/Synthetic-v0``):
  an env whose step sleeps a constant or lognormal drawn duration, to measure the vector
  envs' own cost and to size a run (``chronogym bench``).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from chronogym._lazy import lazy_exports
from chronogym.testing.cluster import LocalCluster, ray_start_available

_EXPORTS = {"SyntheticEnv": "chronogym.testing.synthetic"}

__all__ = ["LocalCluster", "SyntheticEnv", "ray_start_available"]

if TYPE_CHECKING:
    from chronogym.testing.synthetic import SyntheticEnv

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
