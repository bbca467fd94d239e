"""PPO training with RSL-RL on a chronogym vector env, under an iteration and/or wall-clock budget.

:func:`train` runs RSL-RL's ``OnPolicyRunner`` components (PPO, rollout storage,
logger) with its own loop instead of ``runner.learn()``, so it can stop on a time
budget between iterations, write ``progress.csv`` and resume exactly where a
checkpoint left off. :func:`load_policy` turns a checkpoint into a NumPy policy.
"""

from __future__ import annotations

import contextlib
import copy
import csv
import io
import math
import shutil
import statistics
import time
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

CSV_HEADER = (
    "wall_time",
    "iteration",
    "env_steps",
    "mean_reward",
    "x_mse",
    "y_mse",
    "collect_s",
    "learn_s",
    "policy_lag",
)
X_KEY = "/metrics/x_vel_mse"
Y_KEY = "/metrics/y_vel_mse"


@dataclass(frozen=True)
class TrainResult:
    """What :func:`train` did.

    ``iterations_done`` and ``env_steps`` count the whole run, including the
    iterations before a resumed checkpoint; ``wall_time`` is this call's seconds.
    """

    iterations_done: int
    env_steps: int
    wall_time: float
    checkpoint: Path
    csv_path: Path
    last_row: dict[str, float]


@contextlib.contextmanager
def _quiet(enabled: bool) -> Iterator[None]:
    """Swallow stdout (RSL-RL's model dumps and per-iteration console block)."""
    if not enabled:
        yield
        return
    with contextlib.redirect_stdout(io.StringIO()):
        yield


def _check_budget(iterations: int | None, minutes: float | None) -> None:
    if iterations is None and minutes is None:
        raise ValueError("train: give iterations=..., minutes=..., or both")
    if iterations is not None and (
        isinstance(iterations, bool) or not isinstance(iterations, int) or iterations < 1
    ):
        raise ValueError(f"iterations={iterations!r}: expected an integer >= 1")
    if minutes is not None and (
        isinstance(minutes, bool)
        or not isinstance(minutes, (int, float))
        or not math.isfinite(minutes)
        or minutes <= 0
    ):
        raise ValueError(f"minutes={minutes!r}: expected a number > 0")


def _check_threads(name: str, value: object) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"{name}={value!r}: expected an integer >= 1")


def _mean(values: list[float]) -> float:
    return float(np.mean(values)) if values else math.nan


_TIME_BAR = "{l_bar}{bar}| {n_fmt}/{total_fmt} s [{elapsed}<{remaining}{postfix}]"


class _Progress:
    """A tqdm bar over iterations (or, with only a time budget, over its seconds); without
    tqdm, one short line every ``every`` iterations."""

    def __init__(
        self,
        enabled: bool,
        iterations: int | None,
        budget_s: float,
        log: Callable[[str], Any],
    ) -> None:
        self.bar = None
        self.log = log if enabled else None
        self.every = max(1, (iterations or 100) // 20)
        self.count = 0
        self.by_time = iterations is None
        self.shown_s = 0
        if enabled:
            try:
                from tqdm import tqdm
            except ImportError:
                return
            if self.by_time:
                self.bar = tqdm(
                    total=round(budget_s),
                    desc="train",
                    bar_format=_TIME_BAR,
                )
            else:
                self.bar = tqdm(total=iterations, desc="train", unit="it")
            self.log = None

    def update(self, row: dict[str, float]) -> None:
        self.count += 1
        text = f"it {int(row['iteration'])} steps {int(row['env_steps'])} "
        text += f"reward {row['mean_reward']:.2f}"
        if self.bar is not None:
            self.bar.set_postfix_str(text, refresh=False)
            if self.by_time:
                seconds = min(int(row["wall_time"]), self.bar.total)
                self.bar.update(seconds - self.shown_s)
                self.shown_s = seconds
            else:
                self.bar.update(1)
        elif self.log is not None and self.count % self.every == 0:
            self.log(text)

    def close(self) -> None:
        if self.bar is not None:
            self.bar.close()


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
) -> TrainResult:
    """Train a PPO policy on a vector env (or an :class:`RslRlVecEnv`); return what was done.

    Stops after ``iterations`` PPO iterations or, with ``minutes``, before starting an
    iteration that is expected to end past the wall-clock budget (at least one runs);
    with both, whichever comes first. Writes into ``out_dir``: ``progress.csv`` (one
    row per iteration), TensorBoard events, ``model_{it}.pt`` every ``save_interval``
    iterations and at the end, and ``latest.pt`` (a copy of the newest checkpoint).

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
    rollout and runs on ``torch_threads``.

    ``verbose``: let RSL-RL print its model summary and per-iteration console block.
    """
    import torch
    from rsl_rl.runners import OnPolicyRunner

    from chronogym.rl.config import ppo_train_config
    from chronogym.rl.overlap import BehaviorPolicy, Learner, check_policy_lag
    from chronogym.rl.vecenv import RslRlVecEnv

    _check_budget(iterations, minutes)
    check_policy_lag(policy_lag)
    _check_threads("torch_threads", torch_threads)
    if update_threads is not None:
        _check_threads("update_threads", update_threads)
        if policy_lag and update_threads != torch_threads:
            raise ValueError(
                f"update_threads={update_threads} with policy_lag={policy_lag}: the overlapped "
                f"update shares the process with the rollout; expected None or torch_threads"
            )
    update_threads = update_threads or torch_threads
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
    cfg = copy.deepcopy(train_cfg) if train_cfg is not None else ppo_train_config()
    run_cfg = copy.deepcopy(cfg)  # what gets stored with checkpoints (the runner edits cfg)
    quiet = not verbose
    with _quiet(quiet):
        runner = OnPolicyRunner(env, cfg, log_dir=str(out), device="cpu")

    start_it, env_steps = 0, 0
    if resume is not None:
        infos = _load_checkpoint(runner, resume)
        start_it = int(infos.get("iterations_done", runner.current_learning_iteration + 1))
        env_steps = int(infos.get("env_steps", 0))
        configured_lr = cfg["algorithm"].get("learning_rate")
        previous_lr = (infos.get("train_cfg") or {}).get("algorithm", {}).get("learning_rate")
        if configured_lr is not None and configured_lr != previous_lr:
            runner.alg.learning_rate = configured_lr
            for group in runner.alg.optimizer.param_groups:
                group["lr"] = configured_lr

    csv_path = out / "progress.csv"
    new_csv = resume is None or not csv_path.exists() or csv_path.stat().st_size == 0
    with _quiet(quiet):
        runner.logger.init_logging_writer()
    alg, logger = runner.alg, runner.logger
    steps_per_env = int(cfg["num_steps_per_env"])
    save_interval = int(cfg["save_interval"])
    budget_s = minutes * 60.0 if minutes is not None else math.inf
    total_it = start_it + iterations if iterations is not None else None
    rnd = bool(cfg["algorithm"].get("rnd_cfg"))
    if policy_lag and (rnd or alg.actor.is_recurrent or alg.critic.is_recurrent):
        raise ValueError(
            f"policy_lag={policy_lag} needs feed-forward actor and critic without RND; "
            "expected policy_lag=0 for this config"
        )
    env_info = {
        "observation_dim": env.num_obs,
        "num_actions": env.num_actions,
        "action_low": env.cfg["action_low"],
        "action_high": env.cfg["action_high"],
        "env": env.cfg,
    }

    def save(it: int) -> Path:
        runner.current_learning_iteration = it
        path = out / f"model_{it}.pt"
        infos = {
            "iterations_done": it + 1,
            "env_steps": env_steps,
            "train_cfg": run_cfg,
            **env_info,
        }
        runner.save(str(path), infos=infos)
        shutil.copyfile(path, out / "latest.pt")
        return path

    bar = _Progress(progress, iterations, budget_s, log)
    t0 = time.perf_counter()
    row: dict[str, float] = {}
    checkpoint: Path | None = None
    it = start_it - 1
    obs = env.get_observations().to(runner.device)
    alg.train_mode()
    behavior = BehaviorPolicy(alg, seed + 7919 if policy_lag else None)

    def collect() -> tuple[list[float], list[float]]:
        """One rollout with the behavior policy into its storage, returns computed; the
        x/y velocity MSEs of the episodes that ended meanwhile."""
        nonlocal obs
        x_errors: list[float] = []
        y_errors: list[float] = []
        actor = behavior.alg
        with torch.inference_mode():
            for _ in range(steps_per_env):
                actions = actor.act(obs)
                obs, rewards, dones, extras = env.step(actions.to(env.device))
                obs = obs.to(runner.device)
                rewards, dones = rewards.to(runner.device), dones.to(runner.device)
                actor.process_env_step(obs, rewards, dones, extras)
                intrinsic = actor.intrinsic_rewards if rnd else None
                logger.process_env_step(rewards, dones, extras, intrinsic)
                episode_log = extras.get("log", {})
                if X_KEY in episode_log:
                    x_errors.extend(episode_log[X_KEY].tolist())
                if Y_KEY in episode_log:
                    y_errors.extend(episode_log[Y_KEY].tolist())
            actor.compute_returns(obs)
        return x_errors, y_errors

    try:
        with csv_path.open("w" if new_csv else "a", newline="") as handle:
            writer = csv.writer(handle)
            if new_csv:
                writer.writerow(CSV_HEADER)
            it = start_it
            errors: tuple[list[float], list[float]] = ([], [])
            if policy_lag:  # the first rollout, before any update can overlap it
                behavior.sync(alg, it)
                errors = collect()
                behavior.swap_storage(alg)
            while True:
                it_start = time.perf_counter()
                rollout_version = behavior.version
                behavior.sync(alg, it)
                if policy_lag:  # update on the stored rollout while the next one is collected
                    learner = Learner(alg)
                    new_errors = collect()
                    collect_end = time.perf_counter()
                    loss_dict = learner.join()
                    learn_s = learner.seconds
                    behavior.swap_storage(alg)
                    errors = (errors[0] + new_errors[0], errors[1] + new_errors[1])
                else:
                    rollout_version = it
                    errors = collect()
                    collect_end = time.perf_counter()
                    behavior.swap_storage(alg)
                    torch.set_num_threads(update_threads)
                    try:
                        loss_dict = alg.update()
                    finally:
                        torch.set_num_threads(torch_threads)
                    learn_s = time.perf_counter() - collect_end
                lag = it - rollout_version
                if not 0 <= lag <= policy_lag:
                    raise AssertionError(
                        f"update {it} used a rollout of policy version {rollout_version}: "
                        f"lag {lag}, expected 0..{policy_lag}"
                    )
                learn_end = time.perf_counter()
                env_steps += steps_per_env * env.num_envs
                runner.current_learning_iteration = it
                with _quiet(quiet):
                    logger.log(
                        it=it,
                        start_it=start_it,
                        total_it=total_it if total_it is not None else it + 1,
                        collect_time=collect_end - it_start,
                        learn_time=learn_s,
                        loss_dict=loss_dict,
                        learning_rate=alg.learning_rate,
                        action_std=alg.get_policy().output_std,
                        rnd_weight=alg.rnd.weight if rnd else None,
                    )
                elapsed = learn_end - t0
                row = {
                    "wall_time": elapsed,
                    "iteration": it,
                    "env_steps": env_steps,
                    "mean_reward": (
                        statistics.mean(logger.rewbuffer) if logger.rewbuffer else math.nan
                    ),
                    "x_mse": _mean(errors[0]),
                    "y_mse": _mean(errors[1]),
                    "collect_s": collect_end - it_start,
                    "learn_s": learn_s,
                    "policy_lag": lag,
                }
                errors = ([], [])
                writer.writerow([row[key] for key in CSV_HEADER])
                handle.flush()
                bar.update(row)
                done_here = it + 1 - start_it
                finished = (total_it is not None and it + 1 >= total_it) or (
                    elapsed + elapsed / done_here > budget_s
                )
                if finished:
                    break
                if (it + 1) % save_interval == 0:
                    checkpoint = save(it)
                it += 1
        checkpoint = save(it)
    finally:
        bar.close()
        with _quiet(quiet):
            logger.stop_logging_writer()
        if logger.writer is not None and hasattr(logger.writer, "close"):
            logger.writer.close()
    wall = time.perf_counter() - t0
    if progress:
        log(
            f"trained iterations {start_it}..{it} ({env_steps} env steps in total) in "
            f"{wall:.1f} s; checkpoint {checkpoint}"
        )
    return TrainResult(
        iterations_done=it + 1,
        env_steps=env_steps,
        wall_time=wall,
        checkpoint=checkpoint,
        csv_path=csv_path,
        last_row=row,
    )


def _read_checkpoint(path: str | Path, name: str) -> dict[str, Any]:
    """A checkpoint's dict, read with ``weights_only=True``: never unpickles objects."""
    import torch

    try:
        saved = torch.load(str(path), map_location="cpu", weights_only=True)
    except Exception as error:  # an arbitrary pickle, or not a checkpoint at all
        first_line = (str(error).splitlines() or [""])[0][:200]
        raise ValueError(
            f"{name}={str(path)!r}: expected a chronogym/RSL-RL checkpoint of tensors and plain "
            f"data ({type(error).__name__}: {first_line})"
        ) from error
    if not isinstance(saved, dict):
        raise ValueError(f"{name}={str(path)!r}: expected a checkpoint dict, got {type(saved)}")
    return saved


def _load_checkpoint(runner: Any, path: str | Path) -> dict[str, Any]:
    """``runner.load`` without unpickling: tensors, numbers, strings and containers only
    (``weights_only=True``; RSL-RL's own loader unpickles whatever the file holds)."""
    saved = _read_checkpoint(path, "resume")
    if runner.alg.load(saved, None, True):
        runner.current_learning_iteration = saved["iter"]
    return saved.get("infos") or {}


def load_policy(
    checkpoint: str | Path,
    obs_dim: int | None = None,
    num_actions: int | None = None,
    *,
    train_cfg: dict[str, Any] | None = None,
    clip_actions: bool = True,
    torch_threads: int | None = 1,
) -> Callable[[np.ndarray], np.ndarray]:
    """The deterministic policy (action mean) of a :func:`train` checkpoint, on NumPy arrays.

    The returned callable maps observations ``(obs_dim,)`` or ``(n, obs_dim)`` to float32
    actions ``(num_actions,)`` or ``(n, num_actions)``, clipped to the action bounds the
    policy was trained with (``clip_actions``). No vector env is needed: the actor is
    rebuilt from the checkpoint's stored config (else ``train_cfg``, else the default
    config); ``obs_dim`` / ``num_actions`` default to the dimensions stored in it and,
    when given, are checked against them.
    """
    import torch
    from rsl_rl.utils import resolve_class
    from tensordict import TensorDict

    from chronogym.rl.config import ppo_train_config

    if torch_threads is not None:
        torch.set_num_threads(torch_threads)
    saved = _read_checkpoint(checkpoint, "checkpoint")  # no unpickling
    infos = saved.get("infos") or {}
    cfg = train_cfg or infos.get("train_cfg") or ppo_train_config()
    state = saved["actor_state_dict"]
    stored_obs, stored_act = infos.get("observation_dim"), infos.get("num_actions")
    for name, given, stored in (
        ("obs_dim", obs_dim, stored_obs),
        ("num_actions", num_actions, stored_act),
    ):
        if given is not None and stored is not None and int(given) != int(stored):
            raise ValueError(
                f"load_policy: {name}={given} but {checkpoint} was trained with {name}={stored}"
            )
    obs_dim = obs_dim if obs_dim is not None else stored_obs
    num_actions = num_actions if num_actions is not None else stored_act
    if obs_dim is None or num_actions is None:
        raise ValueError(f"load_policy: pass obs_dim and num_actions for {checkpoint}")
    obs_dim, num_actions = int(obs_dim), int(num_actions)
    actor_class, actor_cfg = resolve_class(cfg["actor"])
    groups = list(cfg.get("obs_groups", {}).get("actor", ["policy"]))
    if len(groups) != 1:
        raise ValueError(f"load_policy: expected one actor observation group, got {groups}")
    dummy = TensorDict({groups[0]: torch.zeros(1, obs_dim)}, batch_size=[1])
    actor = actor_class(dummy, {"actor": groups}, "actor", num_actions, **actor_cfg)
    actor.load_state_dict(state)
    actor.eval()
    low = high = None
    if clip_actions and "action_low" in infos:
        low = np.asarray(infos["action_low"], dtype=np.float32).reshape(-1)
        high = np.asarray(infos["action_high"], dtype=np.float32).reshape(-1)

    def policy(obs: np.ndarray) -> np.ndarray:
        array = np.asarray(obs, dtype=np.float32)
        single = array.ndim == 1
        batch = torch.as_tensor(array.reshape(1 if single else array.shape[0], -1))
        with torch.inference_mode():
            actions = actor(TensorDict({groups[0]: batch}, batch_size=[batch.shape[0]]))
        result = actions.numpy().astype(np.float32)
        if low is not None:
            result = np.clip(result, low, high)
        return result[0] if single else result

    return policy
