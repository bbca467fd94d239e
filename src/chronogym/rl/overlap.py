"""Overlapping PPO's update with the next rollout: a policy lag of one update (opt-in).

Synchronous PPO (:meth:`chronogym.rl.trainer.Runner.learn`) alternates: collect rollout k with
the policy θ_k, then update on it (θ_k -> θ_{k+1}) while every simulation waits. With
``policy_lag=1`` the update of θ_k runs in a thread while the main thread collects rollout
k+1 with a frozen copy of θ_k (the *behavior* policy). That rollout is then learned from
θ_{k+1}: one update stale. PPO stays correct because its importance ratio divides by the
log-probabilities stored at collection time (the behavior policy's), so the clipped surrogate
bounds how far θ_{k+1} moves from the policy that produced the data, exactly as for the later
epochs of a synchronous update; returns and advantages are computed with the behavior critic
that produced the stored values. The lag is tracked per update (the learner's version minus
the behavior policy's) and never exceeds 1.

Determinism: the behavior policy draws its action noise from its own ``torch.Generator``
(seeded from the run's seed); the learner thread alone uses torch's global generator
(mini-batch permutation). So the interleaving of the two threads changes no number: the same
seed gives the same run.
"""

from __future__ import annotations

import threading
import time
from collections.abc import Callable
from typing import TYPE_CHECKING

import torch

from chronogym.rl import rsl
from chronogym.rl.progress import Iteration
from chronogym.validation import check_int

if TYPE_CHECKING:
    from rsl_rl.algorithms import PPO

#: Policy lags ``train`` supports: 0 (synchronous PPO) and 1 (update overlapped with the
#: next rollout).
POLICY_LAGS = (0, 1)

#: Offset of the behavior policy's noise seed from the run's seed.
BEHAVIOR_SEED_OFFSET = 7919


def check_policy_lag(policy_lag: int) -> int:
    """``policy_lag`` validated: 0 or 1."""
    expected = "0 (synchronous PPO) or 1 (the update overlapped with the next rollout)"
    check_int("policy_lag", policy_lag, low=0, expected=expected)
    if policy_lag not in POLICY_LAGS:
        raise ValueError(
            f"policy_lag={policy_lag}: at most 1 update of lag is supported; expected 0 or 1"
        )
    return int(policy_lag)


class BehaviorPolicy:
    """A frozen copy of the learner's actor and critic that collects rollouts.

    ``alg`` is a copy of the learner's PPO object with its own actor, critic, rollout storage
    and transition (:func:`chronogym.rl.rsl.behavior_copy`), so RSL-RL's own ``act`` /
    ``process_env_step`` / ``compute_returns`` fill its storage while the learner updates. Its
    action noise comes from a generator seeded with ``seed``. ``version`` is the learner
    version (updates done) whose weights it holds.
    """

    def __init__(self, alg: PPO, seed: int) -> None:
        self.alg = rsl.behavior_copy(alg)
        self.version = -1
        rsl.sample_actions_with(self.alg, torch.Generator().manual_seed(int(seed)))

    def sync(self, learner: PPO, version: int) -> None:
        """Take the learner's current weights (and observation normalizers)."""
        rsl.copy_weights(learner, self.alg)
        self.version = version

    def hand_over(self, learner: PPO) -> None:
        """Hand the collected rollout to the learner; take its used storage back."""
        rsl.swap_storage(self.alg, learner)


class Learner:
    """``alg.update()`` in a background thread; :meth:`join` returns its loss dict and
    ``seconds`` is how long the update took."""

    def __init__(self, alg: PPO) -> None:
        self._result: dict[str, float] | None = None
        self._error: BaseException | None = None
        self.seconds = 0.0
        self._thread = threading.Thread(target=self._run, args=(alg,), daemon=True)
        self._thread.start()

    def _run(self, alg: PPO) -> None:
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


class OverlappedUpdate:
    """Each iteration updates ``alg`` on the stored rollout in a thread while ``collect``
    fills the behavior policy's storage with the next one (policy lag 1).

    ``collect(alg)`` runs one rollout with a PPO object and computes its returns (the
    trainer's). The behavior policy's noise is seeded with ``seed + BEHAVIOR_SEED_OFFSET``.
    Needs a feed-forward actor and critic without RND.
    """

    policy_lag = 1

    def __init__(self, alg: PPO, collect: Callable[[PPO], None], *, seed: int) -> None:
        if not rsl.can_overlap(alg):
            raise ValueError(
                f"policy_lag={self.policy_lag} needs feed-forward actor and critic without RND; "
                "expected policy_lag=0 for this config"
            )
        self.alg = alg
        self.collect = collect
        self.behavior = BehaviorPolicy(alg, seed + BEHAVIOR_SEED_OFFSET)

    def start(self, it: int) -> None:
        """Collect the first rollout, which no update can overlap."""
        self.behavior.sync(self.alg, it)
        self.collect(self.behavior.alg)
        self.behavior.hand_over(self.alg)

    def iterate(self, it: int) -> Iteration:
        """Update ``it``: learn from the stored rollout while collecting the next one."""
        start = time.perf_counter()
        rollout_version = self.behavior.version
        self.behavior.sync(self.alg, it)
        learner = Learner(self.alg)
        self.collect(self.behavior.alg)
        collected = time.perf_counter()
        losses = learner.join()
        self.behavior.hand_over(self.alg)
        lag = it - rollout_version
        if not 0 <= lag <= self.policy_lag:
            raise AssertionError(
                f"update {it} used a rollout of policy version {rollout_version}: "
                f"lag {lag}, expected 0..{self.policy_lag}"
            )
        return Iteration(losses, collected - start, learner.seconds, lag)
