"""The PPO training loop: :class:`Runner`, built from RSL-RL's ``OnPolicyRunner`` parts.

RSL-RL's ``OnPolicyRunner`` supplies the PPO object and its logger (TensorBoard, console);
the :class:`Runner` adds what ``runner.learn()`` lacks: a collection strategy
(:mod:`chronogym.rl.collection`), a wall-clock :class:`Budget` checked between iterations,
``progress.csv`` (:class:`~chronogym.rl.progress.ProgressLog`) and checkpoints that resume
exactly where they left off.
"""

from __future__ import annotations

import contextlib
import copy
import io
import math
import shutil
import statistics
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from rsl_rl.runners import OnPolicyRunner

from chronogym.rl.best import BestCheckpoint, Evaluator
from chronogym.rl.checkpoint import read_checkpoint
from chronogym.rl.collection import Iteration, Rollouts, make_collection
from chronogym.rl.config import PROGRESS_METRICS
from chronogym.rl.progress import ProgressBar, ProgressLog
from chronogym.validation import check_int, check_positive


@dataclass(frozen=True)
class TrainResult:
    """What :func:`~chronogym.rl.train` did.

    ``iterations_done`` and ``env_steps`` count the whole run, including the
    iterations before a resumed checkpoint; ``wall_time`` is this call's seconds.
    ``last_row`` is the last row of ``progress.csv``. ``best``: which checkpoint is
    ``best.pt`` and why (empty when training evaluated no checkpoint).
    """

    iterations_done: int
    env_steps: int
    wall_time: float
    checkpoint: Path
    csv_path: Path
    last_row: dict[str, float]
    best: str = ""


@dataclass(frozen=True)
class Budget:
    """When training stops: after ``iterations`` iterations, or before starting one that is
    expected to end past ``seconds`` (at least one runs); whichever comes first."""

    iterations: int | None
    seconds: float

    @classmethod
    def of(cls, iterations: int | None, minutes: float | None) -> Budget:
        """The budget of ``train(iterations=..., minutes=...)``, checked: at least one given."""
        if iterations is None and minutes is None:
            raise ValueError("train: give iterations=..., minutes=..., or both")
        if iterations is not None:
            check_int("iterations", iterations, low=1)
        if minutes is not None:
            check_positive("minutes", minutes, expected="a number > 0")
        return cls(iterations, minutes * 60.0 if minutes is not None else math.inf)

    def exhausted(self, done: int, elapsed: float) -> bool:
        """After ``done`` iterations in ``elapsed`` seconds, is there no room for another?"""
        if self.iterations is not None and done >= self.iterations:
            return True
        return elapsed + elapsed / done > self.seconds


@contextlib.contextmanager
def _quiet(enabled: bool) -> Iterator[None]:
    """Swallow stdout (RSL-RL's model dumps and per-iteration console block)."""
    if not enabled:
        yield
        return
    with contextlib.redirect_stdout(io.StringIO()):
        yield


class Runner:
    """One PPO training run writing into ``out``.

    ``cfg`` is an RSL-RL ``OnPolicyRunner`` config; ``policy_lag`` picks the collection
    strategy (0: synchronous, 1: overlapped update); ``torch_threads`` / ``update_threads``
    are torch's threads while collecting and during a synchronous update. ``verbose`` lets
    RSL-RL print. :meth:`resume` continues a checkpoint; :meth:`learn` trains.
    """

    progress: ProgressLog  # this learn() call's progress.csv

    def __init__(
        self,
        env: Any,
        out: Path,
        cfg: dict[str, Any],
        *,
        seed: int,
        policy_lag: int,
        torch_threads: int,
        update_threads: int,
        verbose: bool = False,
        evaluator: Evaluator | None = None,
    ) -> None:
        self.env = env
        self.out = out
        self.cfg = copy.deepcopy(cfg)  # stored with checkpoints (OnPolicyRunner edits its copy)
        self.seed = seed
        self.policy_lag = policy_lag
        self.torch_threads = torch_threads
        self.update_threads = update_threads
        self.quiet = not verbose
        with _quiet(self.quiet):
            self.rsl = OnPolicyRunner(env, copy.deepcopy(cfg), log_dir=str(out), device="cpu")
        self.alg, self.logger = self.rsl.alg, self.rsl.logger
        self.steps_per_env = int(cfg["num_steps_per_env"])
        self.save_interval = int(cfg["save_interval"])
        self.start_it = 0
        self.env_steps = 0
        self.resumed = False
        self.evaluator = evaluator
        self.best: BestCheckpoint | None = None

    def resume(self, checkpoint: str | Path) -> None:
        """Continue ``checkpoint``: its models, optimizer, iteration and env-step counts. A
        learning rate in ``cfg`` other than the checkpoint run's replaces its adapted one."""
        saved = read_checkpoint(checkpoint, "resume")  # never unpickles, unlike RSL-RL's load
        if self.alg.load(saved, None, True):
            self.rsl.current_learning_iteration = saved["iter"]
        infos = saved.get("infos") or {}
        self.start_it = int(infos.get("iterations_done", self.rsl.current_learning_iteration + 1))
        self.env_steps = int(infos.get("env_steps", 0))
        self.resumed = True
        configured = self.cfg["algorithm"].get("learning_rate")
        previous = (infos.get("train_cfg") or {}).get("algorithm", {}).get("learning_rate")
        if configured is not None and configured != previous:
            self.alg.learning_rate = configured
            for group in self.alg.optimizer.param_groups:
                group["lr"] = configured

    def learn(self, budget: Budget, bar: ProgressBar) -> TrainResult:
        """Train until ``budget`` is spent; save every ``save_interval`` iterations and at the
        end; show each ``progress.csv`` row on ``bar``."""
        with _quiet(self.quiet):
            self.logger.init_logging_writer()
        if self.evaluator is not None:
            self.best = BestCheckpoint(self.out, self.evaluator, resumed=self.resumed)
        self.progress = ProgressLog(
            self.out / "progress.csv",
            PROGRESS_METRICS,
            append=self.resumed,
            extra=self.best.columns if self.best is not None else (),
        )
        t0 = time.perf_counter()
        rollouts = Rollouts(self.env, self.rsl.device, self.steps_per_env, self._on_step)
        self.alg.train_mode()
        collection = make_collection(
            self.policy_lag,
            self.alg,
            rollouts,
            seed=self.seed,
            torch_threads=self.torch_threads,
            update_threads=self.update_threads,
        )
        it, row = self.start_it, {}
        try:
            collection.start(it)
            while True:
                step = collection.iterate(it)
                self.env_steps += self.steps_per_env * self.env.num_envs
                elapsed = time.perf_counter() - t0
                last = budget.exhausted(it + 1 - self.start_it, elapsed)
                evaluation: dict[str, float] = {}
                if last or (it + 1) % self.save_interval == 0:
                    checkpoint = self.save(it)
                    evaluation = self._evaluate(it, checkpoint)
                row = self._record(it, step, elapsed, budget, evaluation)
                bar.update(row)
                if last:
                    break
                it += 1
        finally:
            bar.close()
            self._stop_logger()
        wall = time.perf_counter() - t0
        best = self.best.summary() if self.best is not None else ""
        return TrainResult(it + 1, self.env_steps, wall, checkpoint, self.progress.path, row, best)

    def _evaluate(self, it: int, checkpoint: Path) -> dict[str, float]:
        """Score ``checkpoint`` for ``best.pt`` (no evaluator: nothing); its CSV values."""
        if self.best is None:
            return {}
        return self.best.consider(it, self.env_steps, checkpoint)

    def _on_step(self, actor: Any, rewards: Any, dones: Any, extras: dict[str, Any]) -> None:
        """Episode bookkeeping of one env step: RSL-RL's logger and the progress log."""
        intrinsic = actor.intrinsic_rewards if actor.rnd is not None else None
        self.logger.process_env_step(rewards, dones, extras, intrinsic)
        self.progress.record(extras.get("log", {}))

    def _record(
        self,
        it: int,
        step: Iteration,
        elapsed: float,
        budget: Budget,
        evaluation: dict[str, float],
    ) -> dict[str, float]:
        """Log the iteration with RSL-RL's logger, write its row (with the ``evaluation`` of
        its checkpoint, if any)."""
        self.rsl.current_learning_iteration = it
        rnd = self.alg.rnd
        total_it = it + 1 if budget.iterations is None else self.start_it + budget.iterations
        with _quiet(self.quiet):
            self.logger.log(
                it=it,
                start_it=self.start_it,
                total_it=total_it,
                collect_time=step.collect_s,
                learn_time=step.learn_s,
                loss_dict=step.losses,
                learning_rate=self.alg.learning_rate,
                action_std=self.alg.get_policy().output_std,
                rnd_weight=rnd.weight if rnd is not None else None,
            )
        rewards = self.logger.rewbuffer
        return self.progress.write(
            {
                "wall_time": elapsed,
                "iteration": it,
                "env_steps": self.env_steps,
                "mean_reward": statistics.mean(rewards) if rewards else math.nan,
                "collect_s": step.collect_s,
                "learn_s": step.learn_s,
                "policy_lag": step.policy_lag,
                **evaluation,
            }
        )

    def save(self, it: int) -> Path:
        """Checkpoint iteration ``it`` as ``model_{it}.pt`` and copy it to ``latest.pt``."""
        self.rsl.current_learning_iteration = it
        path = self.out / f"model_{it}.pt"
        infos = {
            "iterations_done": it + 1,
            "env_steps": self.env_steps,
            "train_cfg": self.cfg,
            "observation_dim": self.env.num_obs,
            "num_actions": self.env.num_actions,
            "action_low": self.env.cfg["action_low"],
            "action_high": self.env.cfg["action_high"],
            "env": self.env.cfg,
        }
        self.rsl.save(str(path), infos=infos)
        shutil.copyfile(path, self.out / "latest.pt")
        return path

    def _stop_logger(self) -> None:
        with _quiet(self.quiet):
            self.logger.stop_logging_writer()
        writer = self.logger.writer
        if writer is not None and hasattr(writer, "close"):
            writer.close()
