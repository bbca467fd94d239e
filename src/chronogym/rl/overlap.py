"""Overlapping PPO's update with the next rollout: a policy lag of one update.

Synchronous PPO alternates: collect rollout k with the policy θ_k, then update on it
(θ_k -> θ_{k+1}) while every simulation waits. With ``policy_lag=1`` the update of
θ_k runs in a thread while the main thread collects rollout k+1 with a frozen copy of
θ_k (the *behavior* policy). That rollout is then learned from θ_{k+1}: one update
stale. PPO stays correct because its importance ratio divides by the log-probabilities
stored at collection time (the behavior policy's), so the clipped surrogate bounds how
far θ_{k+1} moves from the policy that produced the data, exactly as for the later
epochs of a synchronous update; returns and advantages are computed with the behavior
critic that produced the stored values. The lag is tracked per update (the learner's
version minus the behavior policy's) and never exceeds 1.

Determinism: the behavior policy draws its action noise from its own ``torch.Generator``
(seeded from the run's seed); the learner thread alone uses torch's global generator
(mini-batch permutation). So the interleaving of the two threads changes no number:
the same seed gives the same run. With ``policy_lag=0`` the same machinery runs the
synchronous loop and reproduces RSL-RL's own (``OnPolicyRunner.learn``) number for number.
"""

from __future__ import annotations

import copy
import threading
import time
from typing import Any

import torch

#: Policy lags ``train`` supports: 0 (synchronous PPO) and 1 (update overlapped with the
#: next rollout).
POLICY_LAGS = (0, 1)


def check_policy_lag(policy_lag: int) -> int:
    """``policy_lag`` validated: 0 or 1."""
    if isinstance(policy_lag, bool) or not isinstance(policy_lag, int) or policy_lag < 0:
        raise ValueError(
            f"policy_lag={policy_lag!r}: expected 0 (synchronous PPO) or 1 (the update "
            "overlapped with the next rollout)"
        )
    if policy_lag not in POLICY_LAGS:
        raise ValueError(
            f"policy_lag={policy_lag}: at most 1 update of lag is supported; expected 0 or 1"
        )
    return policy_lag


class BehaviorPolicy:
    """A frozen copy of the learner's actor and critic that collects rollouts.

    It is a shallow copy of the learner's PPO object with its own actor, critic,
    rollout storage and transition, so RSL-RL's own ``act`` / ``process_env_step`` /
    ``compute_returns`` fill its storage while the learner updates. ``version`` is the
    learner version (updates done) whose weights it holds.
    """

    def __init__(self, alg: Any, seed: int | None) -> None:
        self.alg = copy.copy(alg)
        self.alg.actor = copy.deepcopy(alg.actor)
        self.alg.critic = copy.deepcopy(alg.critic)
        self.alg.storage = copy.deepcopy(alg.storage)
        self.alg.transition = type(alg.transition)()
        self.version = -1
        if seed is not None:
            self._private_noise(torch.Generator().manual_seed(int(seed)))

    def _private_noise(self, generator: torch.Generator) -> None:
        """Draw the actor's action noise from ``generator`` instead of torch's global one."""
        distribution = self.alg.actor.distribution
        if not hasattr(distribution, "_distribution"):
            raise TypeError(
                f"policy_lag=1 needs a Gaussian action distribution; got {type(distribution)}"
            )

        def sample() -> torch.Tensor:
            normal = distribution._distribution
            shape = normal.batch_shape
            loc, scale = normal.loc.expand(shape), normal.scale.expand(shape)
            return torch.normal(loc, scale, generator=generator)

        distribution.sample = sample

    def sync(self, alg: Any, version: int) -> None:
        """Take the learner's current weights (and observation normalizers)."""
        self.alg.actor.load_state_dict(alg.actor.state_dict())
        self.alg.critic.load_state_dict(alg.critic.state_dict())
        self.version = version

    def swap_storage(self, alg: Any) -> None:
        """Hand the collected rollout to the learner; take its used storage back."""
        alg.storage, self.alg.storage = self.alg.storage, alg.storage


class Learner:
    """``alg.update()`` in a background thread; :meth:`join` returns its loss dict and
    ``seconds`` is how long the update took."""

    def __init__(self, alg: Any) -> None:
        self._result: dict[str, float] | None = None
        self._error: BaseException | None = None
        self.seconds = 0.0
        self._thread = threading.Thread(target=self._run, args=(alg,), daemon=True)
        self._thread.start()

    def _run(self, alg: Any) -> None:
        start = time.perf_counter()
        try:
            self._result = alg.update()
        except BaseException as error:  # re-raised in the main thread by join()
            self._error = error
        self.seconds = time.perf_counter() - start

    def join(self) -> dict[str, float]:
        self._thread.join()
        if self._error is not None:
            raise self._error
        assert self._result is not None
        return self._result
