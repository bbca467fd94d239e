"""Tasks that misbehave on purpose, for fault-handling tests (importable by Ray workers)."""

from __future__ import annotations

import os
import threading

import numpy as np

from chronogym.env import SimEnv
from chronogym.tasks.cartpole import CartPoleTask


class FailingCartPole(CartPoleTask):
    """Raises in apply_action at step ``fail_at`` of an episode reset with seed ``fail_seed``."""

    def __init__(self, fail_seed: int | None = None, fail_at: int = 5, **kwargs) -> None:
        super().__init__(**kwargs)
        self.fail_seed = fail_seed
        self.fail_at = fail_at
        self.armed = False
        self.steps = 0

    def reset(self, rng: np.random.Generator, options) -> None:
        super().reset(rng, options)
        self.steps = 0

    def apply_action(self, action: np.ndarray) -> None:
        self.steps += 1
        if self.armed and self.steps == self.fail_at:
            raise RuntimeError(f"injected failure at step {self.steps}")
        super().apply_action(action)


class FailingEnv(SimEnv):
    """Arms its task's failure when reset with ``fail_seed`` (or always, with ``fail_always``)."""

    def __init__(self, fail_seed: int | None, fail_always: bool = False) -> None:
        super().__init__(FailingCartPole(fail_seed=fail_seed))
        self.fail_always = fail_always

    def reset(self, *, seed=None, options=None):
        if seed is not None or self.fail_always:
            self.task.armed = self.fail_always or seed == self.task.fail_seed
        return super().reset(seed=seed, options=options)


class ExplodingCartPole(CartPoleTask):
    """Applies a huge force after ``explode_at`` steps so the state becomes non-finite."""

    def __init__(self, explode_at: int = 3, **kwargs) -> None:
        super().__init__(**kwargs)
        self.explode_at = explode_at
        self.steps = 0

    def reset(self, rng, options) -> None:
        super().reset(rng, options)
        self.steps = 0

    def apply_action(self, action: np.ndarray) -> None:
        self.steps += 1
        super().apply_action(action)
        if self.steps >= self.explode_at:
            self.data.qvel[:] = 1e300


class HangingCartPole(CartPoleTask):
    """Stops answering (sleeps) at step ``hang_at`` of its first episode."""

    def __init__(self, hang_at: int = 3, **kwargs) -> None:
        super().__init__(**kwargs)
        self.hang_at = hang_at
        self.steps = 0
        self.episodes = 0

    def reset(self, rng, options) -> None:
        super().reset(rng, options)
        self.steps = 0
        self.episodes += 1

    def apply_action(self, action: np.ndarray) -> None:
        self.steps += 1
        if self.episodes == 1 and self.steps == self.hang_at:
            import time

            time.sleep(600)
        super().apply_action(action)


class UserBug(Exception):
    """An exception class of the user's own (workers import it from this module)."""


class UnpicklableError(Exception):
    """An exception that cannot be pickled (it holds a lock)."""

    def __init__(self, message: str) -> None:
        super().__init__(message)
        self.lock = threading.Lock()


class BuggyCartPole(CartPoleTask):
    """A task with a bug of the user's: ``bug`` says where it raises.

    ``"init"``: in its constructor; ``"reset"``: in every reset; ``"step"``: at step ``at``;
    ``"unpicklable"``: an unpicklable exception at step ``at``; ``"shape"``: observations
    of the wrong shape from step ``at`` on; ``"exit_in_reset"``: its process exits (code 3)
    in every reset (a fault, not a Python error).
    """

    def __init__(self, bug: str, at: int = 3, **kwargs) -> None:
        if bug == "init":
            raise UserBug("cannot load the model 'nowhere.xml'")
        super().__init__(**kwargs)
        self.bug, self.at, self.steps = bug, at, 0

    def reset(self, rng, options) -> None:
        if self.bug == "reset":
            raise UserBug("the reset pose is out of range")
        if self.bug == "exit_in_reset":
            os._exit(3)
        super().reset(rng, options)
        self.steps = 0

    def apply_action(self, action: np.ndarray) -> None:
        self.steps += 1
        if self.bug == "step" and self.steps == self.at:
            raise UserBug(f"the controller diverged at step {self.steps}")
        if self.bug == "unpicklable" and self.steps == self.at:
            raise UnpicklableError(f"unpicklable failure at step {self.steps}")
        super().apply_action(action)

    def observe(self) -> np.ndarray:
        obs = super().observe()
        return obs[:2] if self.bug == "shape" and self.steps >= self.at else obs


class BuggyEnv(SimEnv):
    """``SimEnv(BuggyCartPole(bug, at))`` on the env ``bug_env`` (others: no bug), with a
    method ``boom`` that raises."""

    def __init__(self, bug: str, at: int = 3, bug_env: bool = True) -> None:
        super().__init__(BuggyCartPole(bug if bug_env else "none", at))

    def boom(self) -> None:
        raise UserBug("boom() was called")
