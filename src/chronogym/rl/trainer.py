"""PPO training with RSL-RL on a chronogym vector env, under an iteration and/or wall-clock budget.

:func:`train` checks its arguments, seeds, and hands the run to a :class:`Runner`. The
training loop is :meth:`Runner.learn`, read top to bottom as RSL-RL's own
``OnPolicyRunner.learn``: collect a rollout with the current policy, compute its returns,
update, save (and score) a checkpoint on schedule, log. What each stage uses lives in:

- :mod:`chronogym.rl.rsl`: RSL-RL's runner parts (the PPO object, its logger, checkpoint
  writing), the one place that touches RSL-RL internals;
- :mod:`chronogym.rl.progress`: ``progress.csv`` and the progress bar;
- :mod:`chronogym.rl.checkpoint`: checkpoints read without unpickling, a policy from one;
- :mod:`chronogym.rl.best`: the best checkpoint so far (``best.pt``);
- :mod:`chronogym.rl.overlap`: the opt-in overlapped update (``policy_lag=1``), which replaces
  the collect-then-update stages.
"""

from __future__ import annotations

import copy
import math
import shutil
import time
from collections.abc import Callable, Mapping
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING, Any

import numpy as np
import torch
from gymnasium.vector import VectorEnv

from chronogym.rl.best import BestCheckpoint, Evaluator
from chronogym.rl.checkpoint import load_policy, read_checkpoint
from chronogym.rl.config import ppo_train_config
from chronogym.rl.overlap import OverlappedUpdate, check_policy_lag
from chronogym.rl.progress import METRIC_PREFIX, Iteration, ProgressBar, ProgressLog
from chronogym.rl.rsl import RslRunner
from chronogym.rl.vecenv import RslRlVecEnv
from chronogym.validation import check_int, check_positive, show

if TYPE_CHECKING:
    from rsl_rl.algorithms import PPO
    from tensordict import TensorDict

__all__ = ["Budget", "Runner", "TrainResult", "load_policy", "train"]


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


def _update_threads(torch_threads: int, update_threads: int | None, policy_lag: int) -> int:
    """The synchronous update's torch threads, after checking both thread arguments."""
    check_int("torch_threads", torch_threads, low=1)
    if update_threads is None:
        return torch_threads
    check_int("update_threads", update_threads, low=1)
    if policy_lag and update_threads != torch_threads:
        raise ValueError(
            f"update_threads={update_threads} with policy_lag={policy_lag}: the overlapped "
            f"update shares the process with the rollout; expected None or torch_threads"
        )
    return update_threads


def _seed(seed: int, torch_threads: int) -> None:
    """Seed torch's and NumPy's global generators; set torch's CPU threads."""
    torch.set_num_threads(torch_threads)
    torch.manual_seed(seed)
    np.random.seed(seed)


def _check_progress_metrics(progress_metrics: Mapping[str, str] | None) -> dict[str, str]:
    """``progress_metrics`` as a dict of column -> ``/metrics/...`` key."""
    pinned = dict(progress_metrics or {})
    for column, key in pinned.items():
        if not (isinstance(column, str) and isinstance(key, str) and key.startswith(METRIC_PREFIX)):
            raise ValueError(
                f"progress_metrics={show(progress_metrics)}: expected a mapping of column "
                f"name -> {METRIC_PREFIX}... key of info['log']"
            )
    return pinned


def train(
    vec_env_or_adapter: VectorEnv | RslRlVecEnv,
    out_dir: str | Path,
    *,
    iterations: int | None = None,
    minutes: float | None = None,
    resume: str | Path | None = None,
    train_cfg: dict[str, Any] | None = None,
    torch_threads: int = 1,
    progress: bool = True,
    seed: int = 0,
    policy_lag: int = 0,
    update_threads: int | None = None,
    log: Callable[[str], object] = print,
    verbose: bool = False,
    evaluator: Evaluator | None = None,
    progress_metrics: Mapping[str, str] | None = None,
) -> TrainResult:
    """Train a PPO policy on a vector env (or an :class:`RslRlVecEnv`); return what was done.

    Stops after ``iterations`` PPO iterations or, with ``minutes``, before starting an
    iteration expected to end past the wall-clock budget (at least one runs); with both,
    whichever comes first. Writes into ``out_dir``: ``progress.csv`` (a row per iteration;
    see :class:`~chronogym.rl.progress.ProgressLog`), TensorBoard events, ``model_{it}.pt``
    every ``save_interval`` iterations and at the end, and ``latest.pt`` (the newest of them).

    ``progress_metrics`` (column -> ``info["log"]`` key, e.g. the Go1's ``{"x_mse":
    "/metrics/x_vel_mse"}``): metric columns that every row has from the first on, NaN until
    the env reports them; other keys get a column named after the key when they first appear.

    ``resume``: a checkpoint of an earlier run; its models, optimizer, iteration count
    and env-step count carry on and rows are appended to ``progress.csv``. When
    ``train_cfg`` sets a learning rate other than the checkpoint run's (fine-tuning,
    e.g. ``ppo_train_config(algorithm=FINETUNE_PPO)``), that rate replaces the
    checkpoint's adapted one. The vector env is not closed here.

    ``policy_lag``: 0 runs synchronous PPO (collect, then update); 1 runs each update in
    a thread while the next rollout is collected with the policy from before that update
    (see :mod:`chronogym.rl.overlap`). ``progress.csv`` records the lag of every update.

    ``torch_threads``: torch's CPU threads in this process (the policy's forward pass while
    the simulations step). ``update_threads``: threads for the synchronous PPO update
    (``policy_lag=0``), which runs while every simulation waits, so it can take all the
    cores; ``None`` keeps ``torch_threads``. With ``policy_lag=1`` the update overlaps the
    rollout and runs on ``torch_threads``. ``verbose``: let RSL-RL print its model summary
    and per-iteration console block.

    ``evaluator``: scores every saved checkpoint (e.g. a
    :class:`~chronogym.tasks.quadruped.evaluation.WalkingEvaluator`); the best so far is copied to
    ``best.pt``, why is written to ``best.json`` (:mod:`chronogym.rl.best`), and each score
    and the seconds it took fill their own ``progress.csv`` columns at the save points.
    """
    budget = Budget.of(iterations, minutes)
    policy_lag = check_policy_lag(policy_lag)
    update_threads = _update_threads(torch_threads, update_threads, policy_lag)
    pinned = _check_progress_metrics(progress_metrics)
    _seed(seed, torch_threads)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    if not isinstance(vec_env_or_adapter, RslRlVecEnv):
        vec_env_or_adapter = RslRlVecEnv(vec_env_or_adapter, seed=seed)
    runner = Runner(
        vec_env_or_adapter,
        out,
        train_cfg if train_cfg is not None else ppo_train_config(),
        seed=seed,
        policy_lag=policy_lag,
        torch_threads=torch_threads,
        update_threads=update_threads,
        verbose=verbose,
        evaluator=evaluator,
        progress_metrics=pinned,
    )
    if resume is not None:
        runner.resume(resume)
    result = runner.learn(budget, ProgressBar(progress, iterations, budget.seconds, log))
    if progress:
        _report(result, runner.start_it, log)
    return result


def _report(result: TrainResult, start_it: int, log: Callable[[str], object]) -> None:
    """Say what a training call did: iterations, env steps, seconds, checkpoint, best."""
    log(
        f"trained iterations {start_it}..{result.iterations_done - 1} "
        f"({result.env_steps} env steps in total) in {result.wall_time:.1f} s; "
        f"checkpoint {result.checkpoint}"
    )
    if result.best:
        log(result.best)


class Runner:
    """One PPO training run of ``env`` writing into ``out``.

    ``cfg`` is an RSL-RL ``OnPolicyRunner`` config; ``policy_lag`` 0 is synchronous PPO,
    1 the overlapped update (:mod:`chronogym.rl.overlap`); ``torch_threads`` /
    ``update_threads`` are torch's threads while collecting and during a synchronous update.
    ``verbose`` lets RSL-RL print. ``evaluator`` scores each checkpoint for ``best.pt``;
    ``progress_metrics`` pins ``progress.csv`` columns (see :func:`train`). :meth:`resume`
    continues a checkpoint; :meth:`learn` trains.
    """

    progress: ProgressLog  # this learn() call's progress.csv
    obs: TensorDict  # the envs' current observations, during learn()

    def __init__(
        self,
        env: RslRlVecEnv,
        out: Path,
        cfg: dict[str, Any],
        *,
        seed: int,
        policy_lag: int,
        torch_threads: int,
        update_threads: int,
        verbose: bool = False,
        evaluator: Evaluator | None = None,
        progress_metrics: Mapping[str, str] | None = None,
    ) -> None:
        self.env = env
        self.out = out
        self.cfg = copy.deepcopy(cfg)  # stored with checkpoints (OnPolicyRunner edits its copy)
        self.seed = seed
        self.policy_lag = policy_lag
        self.torch_threads = torch_threads
        self.update_threads = update_threads
        self.progress_metrics = dict(progress_metrics or {})
        self.rsl = RslRunner(env, cfg, out, verbose=verbose)
        self.alg: PPO = self.rsl.alg
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
        saved_it = self.rsl.load(saved)
        infos = saved.get("infos") or {}
        self.start_it = int(infos.get("iterations_done", saved_it + 1))
        self.env_steps = int(infos.get("env_steps", 0))
        self.resumed = True
        configured = self.cfg["algorithm"].get("learning_rate")
        previous = (infos.get("train_cfg") or {}).get("algorithm", {}).get("learning_rate")
        if configured is not None and configured != previous:
            self.rsl.set_learning_rate(configured)

    def learn(self, budget: Budget, bar: ProgressBar) -> TrainResult:
        """Train until ``budget`` is spent; save every ``save_interval`` iterations and at the
        end; show each ``progress.csv`` row on ``bar``."""
        self._open_logs()
        start_time = time.perf_counter()
        self.obs = self.env.get_observations().to(self.rsl.device)
        alg = self.alg
        alg.train_mode()
        overlap = OverlappedUpdate(alg, self._collect, seed=self.seed) if self.policy_lag else None
        it, row = self.start_it, {}
        try:
            if overlap is not None:
                overlap.start(it)  # the first rollout, which no update overlaps
            while True:
                if overlap is None:
                    start = time.perf_counter()
                    # Collect a rollout with the current policy and compute its returns
                    self._collect(alg)
                    collected = time.perf_counter()
                    # Update the policy on it while every simulation waits: all update_threads
                    torch.set_num_threads(self.update_threads)
                    try:
                        losses = alg.update()
                    finally:
                        torch.set_num_threads(self.torch_threads)
                    step = Iteration(losses, collected - start, time.perf_counter() - collected, 0)
                else:
                    # Update on the previous rollout while collecting the next (policy lag 1)
                    step = overlap.iterate(it)
                self.env_steps += self.steps_per_env * self.env.num_envs
                elapsed = time.perf_counter() - start_time
                last = budget.exhausted(it + 1 - self.start_it, elapsed)
                # Save (and score) a checkpoint every save_interval iterations and at the end
                evaluation: dict[str, float] = {}
                if last or (it + 1) % self.save_interval == 0:
                    checkpoint = self.save(it)
                    if self.best is not None:
                        evaluation = self.best.consider(it, self.env_steps, checkpoint)
                # Log: RSL-RL's logger, then the progress.csv row
                row = self._log(it, step, elapsed, budget, evaluation)
                bar.update(row)
                if last:
                    break
                it += 1
        finally:
            bar.close()
            self.rsl.stop_logging()
        wall = time.perf_counter() - start_time
        best = self.best.summary() if self.best is not None else ""
        return TrainResult(it + 1, self.env_steps, wall, checkpoint, self.progress.path, row, best)

    def _open_logs(self) -> None:
        """Start RSL-RL's logger, ``best.pt`` keeping (with an evaluator) and progress.csv."""
        self.rsl.start_logging()
        if self.evaluator is not None:
            self.best = BestCheckpoint(self.out, self.evaluator, resumed=self.resumed)
        self.progress = ProgressLog(
            self.out / "progress.csv",
            self.progress_metrics,
            append=self.resumed,
            extra=self.best.columns if self.best is not None else (),
        )

    def _collect(self, alg: PPO) -> None:
        """One rollout of ``steps_per_env`` env steps with ``alg``'s policy into its storage,
        then its returns and advantages."""
        with torch.inference_mode():
            for _ in range(self.steps_per_env):
                # Sample actions and step the envs
                actions = alg.act(self.obs)
                obs, rewards, dones, extras = self.env.step(actions.to(self.env.device))
                self.obs = obs.to(self.rsl.device)
                rewards, dones = rewards.to(self.rsl.device), dones.to(self.rsl.device)
                # Store the transition; episode bookkeeping for RSL-RL's logger and progress.csv
                alg.process_env_step(self.obs, rewards, dones, extras)
                self.rsl.record_step(alg, rewards, dones, extras)
                self.progress.record(extras.get("log", {}))
            # Compute returns and advantages
            alg.compute_returns(self.obs)

    def _log(
        self,
        it: int,
        step: Iteration,
        elapsed: float,
        budget: Budget,
        evaluation: dict[str, float],
    ) -> dict[str, float]:
        """Log the iteration with RSL-RL's logger, write its row (with the ``evaluation`` of
        its checkpoint, if any)."""
        total_it = it + 1 if budget.iterations is None else self.start_it + budget.iterations
        self.rsl.log_iteration(
            it,
            start_it=self.start_it,
            total_it=total_it,
            collect_s=step.collect_s,
            learn_s=step.learn_s,
            losses=step.losses,
        )
        return self.progress.write(
            {
                "wall_time": elapsed,
                "iteration": it,
                "env_steps": self.env_steps,
                "mean_reward": self.rsl.mean_episode_return(),
                "collect_s": step.collect_s,
                "learn_s": step.learn_s,
                "policy_lag": step.policy_lag,
                **evaluation,
            }
        )

    def save(self, it: int) -> Path:
        """Checkpoint iteration ``it`` as ``model_{it}.pt`` and copy it to ``latest.pt``."""
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
        self.rsl.save(path, it, infos)
        shutil.copyfile(path, self.out / "latest.pt")
        return path
