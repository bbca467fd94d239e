"""Vector envs: RayVectorEnv (Ray actors) and SerialVectorEnv (in process), same semantics."""

from chronogym.vector.pending import EnvsInFlightError, RecvTimeoutError

__all__ = ["EnvsInFlightError", "RecvTimeoutError"]
