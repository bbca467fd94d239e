"""How a PPO iteration collects its rollout and updates: synchronously, or overlapped.

Both strategies collect with a :class:`~chronogym.rl.overlap.BehaviorPolicy` (a copy of the
learner's actor and critic) and hand its rollout storage to the learner:

- :class:`SynchronousCollection` (policy lag 0): collect with the current policy, then update
  on that rollout while every simulation waits. This is RSL-RL's own ``OnPolicyRunner.learn``
  schedule, number for number.
- :class:`OverlappedCollection` (policy lag 1): update on the previous rollout in a thread
  while the next one is collected with the policy from before that update
  (:mod:`chronogym.rl.overlap` explains why PPO stays correct and runs stay deterministic).
"""

from __future__ import annotations

import time
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any, Protocol

import torch

from chronogym.rl.overlap import BehaviorPolicy, Learner

#: Called after every env step with the collecting PPO object, rewards, dones and extras.
StepHook = Callable[[Any, torch.Tensor, torch.Tensor, dict[str, Any]], None]

#: Offset of the behavior policy's noise seed from the run's seed (policy lag 1).
BEHAVIOR_SEED_OFFSET = 7919


@dataclass(frozen=True)
class Iteration:
    """What one iteration's collection and update did."""

    losses: dict[str, float]
    collect_s: float
    learn_s: float
    policy_lag: int


class Rollouts:
    """Steps ``env`` ``num_steps`` times per collection with a PPO object's ``act``, fills its
    rollout storage and computes its returns; ``on_step`` sees every step."""

    def __init__(self, env: Any, device: str, num_steps: int, on_step: StepHook) -> None:
        self.env = env
        self.device = device
        self.num_steps = num_steps
        self.on_step = on_step
        self.obs = env.get_observations().to(device)

    def collect(self, actor: Any) -> None:
        """One rollout with ``actor`` (a PPO object) into its storage, returns computed."""
        with torch.inference_mode():
            for _ in range(self.num_steps):
                actions = actor.act(self.obs)
                obs, rewards, dones, extras = self.env.step(actions.to(self.env.device))
                self.obs = obs.to(self.device)
                rewards, dones = rewards.to(self.device), dones.to(self.device)
                actor.process_env_step(self.obs, rewards, dones, extras)
                self.on_step(actor, rewards, dones, extras)
            actor.compute_returns(self.obs)


class Collection(Protocol):
    """A schedule of collection and update; :meth:`iterate` runs iteration ``it``."""

    policy_lag: int

    def start(self, it: int) -> None: ...

    def iterate(self, it: int) -> Iteration: ...


class SynchronousCollection:
    """Collect a rollout with the current policy, then update on it (policy lag 0).

    The update runs on ``update_threads`` torch threads, since every simulation waits for it;
    collection runs on ``torch_threads``.
    """

    policy_lag = 0

    def __init__(
        self, alg: Any, rollouts: Rollouts, *, torch_threads: int, update_threads: int
    ) -> None:
        self.alg = alg
        self.rollouts = rollouts
        self.torch_threads = torch_threads
        self.update_threads = update_threads
        self.behavior = BehaviorPolicy(alg, None)

    def start(self, it: int) -> None:
        """Nothing precedes the first iteration."""

    def iterate(self, it: int) -> Iteration:
        start = time.perf_counter()
        self.behavior.sync(self.alg, it)
        self.rollouts.collect(self.behavior.alg)
        collected = time.perf_counter()
        self.behavior.swap_storage(self.alg)
        torch.set_num_threads(self.update_threads)
        try:
            losses = self.alg.update()
        finally:
            torch.set_num_threads(self.torch_threads)
        return Iteration(losses, collected - start, time.perf_counter() - collected, 0)


class OverlappedCollection:
    """Update on the stored rollout in a thread while the next one is collected (policy lag 1).

    The behavior policy draws its action noise from its own generator, seeded with
    ``seed + BEHAVIOR_SEED_OFFSET``. Needs a feed-forward actor and critic without RND.
    """

    policy_lag = 1

    def __init__(self, alg: Any, rollouts: Rollouts, *, seed: int) -> None:
        if alg.rnd is not None or alg.actor.is_recurrent or alg.critic.is_recurrent:
            raise ValueError(
                f"policy_lag={self.policy_lag} needs feed-forward actor and critic without RND; "
                "expected policy_lag=0 for this config"
            )
        self.alg = alg
        self.rollouts = rollouts
        self.behavior = BehaviorPolicy(alg, seed + BEHAVIOR_SEED_OFFSET)

    def start(self, it: int) -> None:
        """Collect the first rollout, which no update can overlap."""
        self.behavior.sync(self.alg, it)
        self.rollouts.collect(self.behavior.alg)
        self.behavior.swap_storage(self.alg)

    def iterate(self, it: int) -> Iteration:
        start = time.perf_counter()
        rollout_version = self.behavior.version
        self.behavior.sync(self.alg, it)
        learner = Learner(self.alg)
        self.rollouts.collect(self.behavior.alg)
        collected = time.perf_counter()
        losses = learner.join()
        self.behavior.swap_storage(self.alg)
        lag = it - rollout_version
        if not 0 <= lag <= self.policy_lag:
            raise AssertionError(
                f"update {it} used a rollout of policy version {rollout_version}: "
                f"lag {lag}, expected 0..{self.policy_lag}"
            )
        return Iteration(losses, collected - start, learner.seconds, lag)


def make_collection(
    policy_lag: int,
    alg: Any,
    rollouts: Rollouts,
    *,
    seed: int,
    torch_threads: int,
    update_threads: int,
) -> Collection:
    """The strategy for ``policy_lag`` (0 or 1, checked by the caller)."""
    if policy_lag:
        return OverlappedCollection(alg, rollouts, seed=seed)
    return SynchronousCollection(
        alg, rollouts, torch_threads=torch_threads, update_threads=update_threads
    )
