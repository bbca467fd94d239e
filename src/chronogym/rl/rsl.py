"""Every use of RSL-RL's internals, in one place. Written against ``rsl-rl-lib`` 5.5.1.

chronogym's trainer (:mod:`chronogym.rl.trainer`) runs its own loop instead of
``OnPolicyRunner.learn`` (for a wall-clock budget, ``progress.csv``, checkpoints that resume
exactly, an overlapped update), so it borrows the runner's parts: the PPO object
(``runner.alg``), its logger (TensorBoard, the console block and the mean episode return in
``logger.rewbuffer``) and the iteration count that checkpoints store
(``runner.current_learning_iteration``). The overlapped update (:mod:`chronogym.rl.overlap`)
also copies the PPO object's actor, critic, rollout storage and transition, and redirects the
Gaussian action distribution's sampling (``distribution._distribution``).

None of that is RSL-RL's documented API. After upgrading RSL-RL, check this module first:
``tests/rl/test_overlap.py`` compares the synchronous loop with ``OnPolicyRunner.learn``
weight for weight.
"""

from __future__ import annotations

import contextlib
import copy
import io
import math
import statistics
from collections.abc import Iterator
from pathlib import Path
from typing import TYPE_CHECKING, Any

import torch
from rsl_rl.env import VecEnv
from rsl_rl.runners import OnPolicyRunner

if TYPE_CHECKING:
    from rsl_rl.algorithms import PPO


@contextlib.contextmanager
def quiet(enabled: bool) -> Iterator[None]:
    """Swallow stdout (RSL-RL's model dumps and per-iteration console block)."""
    if not enabled:
        yield
        return
    with contextlib.redirect_stdout(io.StringIO()):
        yield


class RslRunner:
    """An RSL-RL ``OnPolicyRunner`` on the CPU, writing TensorBoard events into ``out``.

    ``alg`` is its PPO object; the methods are what chronogym's loop needs of the runner and
    its logger. ``verbose`` lets RSL-RL print.
    """

    def __init__(self, env: VecEnv, cfg: dict[str, Any], out: Path, *, verbose: bool) -> None:
        self.quiet = not verbose
        with quiet(self.quiet):
            self.runner = OnPolicyRunner(env, copy.deepcopy(cfg), log_dir=str(out), device="cpu")
        self.alg: PPO = self.runner.alg
        self.device: str = self.runner.device

    # -- checkpoints ----------------------------------------------------------------------
    def load(self, saved: dict[str, Any]) -> int:
        """Load a checkpoint's models and optimizer; return its iteration (RSL-RL's ``iter``)."""
        if self.alg.load(saved, None, True):
            self.runner.current_learning_iteration = saved["iter"]
        return self.runner.current_learning_iteration

    def set_learning_rate(self, learning_rate: float) -> None:
        """Replace the PPO learning rate (and the optimizer's) with ``learning_rate``."""
        self.alg.learning_rate = learning_rate
        for group in self.alg.optimizer.param_groups:
            group["lr"] = learning_rate

    def save(self, path: Path, it: int, infos: dict[str, Any]) -> None:
        """Write iteration ``it``'s models, optimizer and ``infos`` to ``path``."""
        self.runner.current_learning_iteration = it
        self.runner.save(str(path), infos=infos)

    # -- the logger -----------------------------------------------------------------------
    def start_logging(self) -> None:
        """Open the TensorBoard writer."""
        with quiet(self.quiet):
            self.runner.logger.init_logging_writer()

    def record_step(
        self, alg: PPO, rewards: torch.Tensor, dones: torch.Tensor, extras: dict[str, Any]
    ) -> None:
        """Episode bookkeeping of one env step collected by ``alg`` (returns, lengths)."""
        intrinsic = alg.intrinsic_rewards if alg.rnd is not None else None
        self.runner.logger.process_env_step(rewards, dones, extras, intrinsic)

    def log_iteration(
        self,
        it: int,
        *,
        start_it: int,
        total_it: int,
        collect_s: float,
        learn_s: float,
        losses: dict[str, float],
    ) -> None:
        """Log iteration ``it`` to TensorBoard (and, verbose, the console)."""
        self.runner.current_learning_iteration = it
        rnd = self.alg.rnd
        with quiet(self.quiet):
            self.runner.logger.log(
                it=it,
                start_it=start_it,
                total_it=total_it,
                collect_time=collect_s,
                learn_time=learn_s,
                loss_dict=losses,
                learning_rate=self.alg.learning_rate,
                action_std=self.alg.get_policy().output_std,
                rnd_weight=rnd.weight if rnd is not None else None,
            )

    def mean_episode_return(self) -> float:
        """The mean return of the last 100 episodes (NaN before any ended)."""
        returns = self.runner.logger.rewbuffer
        return statistics.mean(returns) if returns else math.nan

    def stop_logging(self) -> None:
        """Flush and close the TensorBoard writer."""
        logger = self.runner.logger
        with quiet(self.quiet):
            logger.stop_logging_writer()
        if logger.writer is not None and hasattr(logger.writer, "close"):
            logger.writer.close()


# -- a second PPO object that collects while the first updates (policy lag 1) ---------------
def can_overlap(alg: PPO) -> bool:
    """Whether ``alg`` can collect with a copy while it updates: feed-forward actor and
    critic, no RND."""
    return alg.rnd is None and not alg.actor.is_recurrent and not alg.critic.is_recurrent


def behavior_copy(alg: PPO) -> PPO:
    """A shallow copy of ``alg`` with its own actor, critic, rollout storage and transition,
    so its ``act`` / ``process_env_step`` / ``compute_returns`` leave ``alg`` untouched."""
    behavior = copy.copy(alg)
    behavior.actor = copy.deepcopy(alg.actor)
    behavior.critic = copy.deepcopy(alg.critic)
    behavior.storage = copy.deepcopy(alg.storage)
    behavior.transition = type(alg.transition)()
    return behavior


def copy_weights(source: PPO, target: PPO) -> None:
    """Give ``target`` the actor and critic weights (and observation normalizers) of
    ``source``."""
    target.actor.load_state_dict(source.actor.state_dict())
    target.critic.load_state_dict(source.critic.state_dict())


def swap_storage(first: PPO, second: PPO) -> None:
    """Exchange the rollout storages of two PPO objects."""
    first.storage, second.storage = second.storage, first.storage


def sample_actions_with(alg: PPO, generator: torch.Generator) -> None:
    """Make ``alg``'s Gaussian actor draw its action noise from ``generator`` instead of
    torch's global generator."""
    distribution = alg.actor.distribution
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
