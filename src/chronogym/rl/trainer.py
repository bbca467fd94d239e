"""PPO training with RSL-RL on a chronogym vector env, under an iteration and/or wall-clock budget.

:func:`train` checks its arguments, seeds, and hands the run to a
:class:`~chronogym.rl.runner.Runner`. :func:`load_policy` turns a checkpoint into a NumPy
policy.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np
import torch

from chronogym.rl.best import Evaluator
from chronogym.rl.checkpoint import load_policy
from chronogym.rl.config import PROGRESS_METRICS, ppo_train_config
from chronogym.rl.overlap import check_policy_lag
from chronogym.rl.progress import ProgressBar, progress_columns
from chronogym.rl.runner import Budget, Runner, TrainResult
from chronogym.rl.vecenv import RslRlVecEnv

__all__ = ["CSV_HEADER", "TrainResult", "load_policy", "train"]

#: The columns of ``progress.csv`` for an env that reports no metric beyond
#: :data:`~chronogym.rl.config.PROGRESS_METRICS`.
CSV_HEADER = progress_columns(PROGRESS_METRICS)


def _check_threads(name: str, value: object) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"{name}={value!r}: expected an integer >= 1")


def _update_threads(torch_threads: int, update_threads: int | None, policy_lag: int) -> int:
    """The synchronous update's torch threads, after checking both thread arguments."""
    _check_threads("torch_threads", torch_threads)
    if update_threads is None:
        return torch_threads
    _check_threads("update_threads", update_threads)
    if policy_lag and update_threads != torch_threads:
        raise ValueError(
            f"update_threads={update_threads} with policy_lag={policy_lag}: the overlapped "
            f"update shares the process with the rollout; expected None or torch_threads"
        )
    return update_threads


def train(
    vec_env_or_adapter: Any,
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
    log: Callable[[str], Any] = print,
    verbose: bool = False,
    evaluator: Evaluator | None = None,
) -> TrainResult:
    """Train a PPO policy on a vector env (or an :class:`RslRlVecEnv`); return what was done.

    Stops after ``iterations`` PPO iterations or, with ``minutes``, before starting an
    iteration that is expected to end past the wall-clock budget (at least one runs);
    with both, whichever comes first. Writes into ``out_dir``: ``progress.csv`` (one
    row per iteration, a column per ``/metrics/*`` key the env reports; see
    :class:`~chronogym.rl.progress.ProgressLog`), TensorBoard events, ``model_{it}.pt``
    every ``save_interval`` iterations and at the end, and ``latest.pt`` (a copy of the
    newest checkpoint).

    ``resume``: a checkpoint of an earlier run; its models, optimizer, iteration count
    and env-step count carry on and rows are appended to ``progress.csv``. When
    ``train_cfg`` sets a learning rate other than the checkpoint run's (fine-tuning,
    e.g. ``ppo_train_config(algorithm=FINETUNE_PPO)``), that rate replaces the
    checkpoint's adapted one. The vector env is not closed here.

    ``policy_lag``: 0 runs synchronous PPO (collect, then update); 1 runs each update in
    a thread while the next rollout is collected with the policy from before that update
    (see :mod:`chronogym.rl.collection`). ``progress.csv`` records the lag of every update.

    ``torch_threads``: torch's CPU threads in this process (the policy's forward pass while
    the simulations step). ``update_threads``: threads for the synchronous PPO update
    (``policy_lag=0``), which runs while every simulation waits, so it can take all the
    cores; ``None`` keeps ``torch_threads``. With ``policy_lag=1`` the update overlaps the
    rollout and runs on ``torch_threads``.

    ``verbose``: let RSL-RL print its model summary and per-iteration console block.

    ``evaluator``: scores every saved checkpoint (e.g. a
    :class:`~chronogym.rl.evaluate.WalkingEvaluator`); the best so far is copied to
    ``best.pt``, why is written to ``best.json`` (:mod:`chronogym.rl.best`), and each score
    and the seconds it took fill their own ``progress.csv`` columns at the save points.
    """
    budget = Budget.of(iterations, minutes)
    check_policy_lag(policy_lag)
    update_threads = _update_threads(torch_threads, update_threads, policy_lag)
    torch.set_num_threads(torch_threads)
    torch.manual_seed(seed)
    np.random.seed(seed)
    out = Path(out_dir)
    out.mkdir(parents=True, exist_ok=True)
    env = (
        vec_env_or_adapter
        if isinstance(vec_env_or_adapter, RslRlVecEnv)
        else RslRlVecEnv(vec_env_or_adapter, seed=seed)
    )
    runner = Runner(
        env,
        out,
        train_cfg if train_cfg is not None else ppo_train_config(),
        seed=seed,
        policy_lag=policy_lag,
        torch_threads=torch_threads,
        update_threads=update_threads,
        verbose=verbose,
        evaluator=evaluator,
    )
    if resume is not None:
        runner.resume(resume)
    result = runner.learn(budget, ProgressBar(progress, iterations, budget.seconds, log))
    if progress:
        log(
            f"trained iterations {runner.start_it}..{result.iterations_done - 1} "
            f"({result.env_steps} env steps in total) in {result.wall_time:.1f} s; "
            f"checkpoint {result.checkpoint}"
        )
        if result.best:
            log(result.best)
    return result
