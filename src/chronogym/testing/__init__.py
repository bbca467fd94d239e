"""Test and benchmark utilities: scaffolding for chronogym's own tests and benchmarks.

Not part of the simulation API, and not imported by ``import chronogym``. Importing this
package is cheap (standard library only); Ray is imported when a cluster starts.

- :class:`LocalCluster` (:mod:`chronogym.testing.cluster`): a real multi-node Ray cluster on
  one machine, started with ``ray start`` subprocesses that it alone stops;
  :func:`ray_start_available` says why one cannot start here, if it cannot.
"""

from __future__ import annotations

from chronogym.testing.cluster import LocalCluster, ray_start_available

__all__ = ["LocalCluster", "ray_start_available"]
