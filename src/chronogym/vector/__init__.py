"""Vector envs: RayVectorEnv (Ray actors) and SerialVectorEnv (in process), same semantics.

``make_vec`` builds either of them (or Gymnasium's own); the errors of asynchronous
stepping are ``EnvsInFlightError`` and ``RecvTimeoutError``.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from chronogym._lazy import lazy_exports

_EXPORTS = {
    "RayVectorEnv": "chronogym.vector.ray_vector_env",
    "SerialVectorEnv": "chronogym.vector.serial",
    "make_vec": "chronogym.vector.factory",
    "EnvsInFlightError": "chronogym.errors",
    "RecvTimeoutError": "chronogym.errors",
}

__all__ = ["EnvsInFlightError", "RayVectorEnv", "RecvTimeoutError", "SerialVectorEnv", "make_vec"]

if TYPE_CHECKING:
    from chronogym.errors import EnvsInFlightError, RecvTimeoutError
    from chronogym.vector.factory import make_vec
    from chronogym.vector.ray_vector_env import RayVectorEnv
    from chronogym.vector.serial import SerialVectorEnv

__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
