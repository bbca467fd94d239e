"""How well a Go1 policy tracks its commands: rollouts, the summary table, and when it walks.

``chronogym play quadruped`` runs :func:`evaluate` and prints :func:`format_summary`; the
training keeps ``best.pt`` by :class:`WalkingEvaluator`'s score, which runs every episode of
a :class:`WalkingCriterion` in step (:func:`run_episodes_together`). Both kinds of rollout
note each step in an :class:`EpisodeTrace`, so a batched episode reports exactly what a
single one does.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from chronogym.rl.checkpoint import load_policy
from chronogym.validation import check_int, check_positive
from chronogym.video import VideoRecorder

Policy = Callable[[np.ndarray], np.ndarray]

#: Commands (vx, vy, yaw rate) that ``chronogym play quadruped`` reports by default.
DEFAULT_COMMANDS: tuple[tuple[float, float, float], ...] = (
    (0.5, 0.0, 0.0),
    (1.0, 0.0, 0.0),
    (0.0, 0.3, 0.0),
    (-0.3, 0.0, 0.0),
    (0.5, 0.0, 0.5),
    (0.0, 0.0, 0.0),
)


@dataclass(frozen=True)
class EpisodeResult:
    """One evaluation episode: its command and how well it was tracked."""

    command: tuple[float, float, float]
    seed: int
    survived: bool
    length_s: float
    x_vel_mse: float
    y_vel_mse: float
    mean_vx: float
    mean_vy: float
    episode_return: float


@dataclass
class EpisodeTrace:
    """What the steps of one episode leave behind: its return and the base's planar velocity
    after each step (body frame), turned into an :class:`EpisodeResult` when it ends."""

    command: Sequence[float]
    seed: int
    total: float = 0.0
    vx: list[float] = field(default_factory=list)
    vy: list[float] = field(default_factory=list)

    def record(self, task: Any, reward: float) -> None:
        """Note one step: its reward and the velocity of ``task`` (a Go1 task) after it."""
        self.total += float(reward)
        self.vx.append(float(task.base_lin_vel[0]))
        self.vy.append(float(task.base_lin_vel[1]))

    def result(
        self, task: Any, terminated: bool, truncated: bool, info: dict[str, Any]
    ) -> EpisodeResult:
        """The :class:`EpisodeResult` of the episode, ended by the step that returned
        ``terminated``, ``truncated`` and ``info``."""
        # The task logs its episode metrics when its own horizon ends the episode; a shorter
        # TimeLimit (``gym.make(..., max_episode_steps=N)``) ends it first: same errors from here.
        log = info.get("log", {})
        command, vx, vy = self.command, self.vx, self.vy
        x_mse = float(np.mean((np.asarray(vx) - float(command[0])) ** 2))
        y_mse = float(np.mean((np.asarray(vy) - float(command[1])) ** 2))
        return EpisodeResult(
            command=tuple(float(c) for c in command),  # type: ignore[arg-type]
            seed=self.seed,
            survived=bool(truncated and not terminated),
            length_s=float(log.get("/metrics/episode_length_s", len(vx) * task.control_dt)),
            x_vel_mse=float(log.get("/metrics/x_vel_mse", x_mse)),
            y_vel_mse=float(log.get("/metrics/y_vel_mse", y_mse)),
            mean_vx=float(np.mean(vx)),
            mean_vy=float(np.mean(vy)),
            episode_return=self.total,
        )


def run_episode(
    env: Any,
    policy: Policy,
    command: Sequence[float],
    seed: int,
    recorder: VideoRecorder | None = None,
    record_steps: int = 0,
) -> EpisodeResult:
    """Run one full episode of ``env`` (a SimEnv of a Go1VelocityTask) with a fixed command;
    with ``recorder``, render its first ``record_steps`` steps into it."""
    obs, _ = env.reset(seed=seed, options={"command": tuple(command)})
    task = env.unwrapped.task
    trace = EpisodeTrace(command, seed)
    step = 0
    if recorder is not None:
        recorder.add(env.render, step)
    while True:
        action = np.asarray(policy(obs), dtype=np.float32)
        obs, reward, terminated, truncated, info = env.step(action)
        trace.record(task, reward)
        step += 1
        if recorder is not None and step <= record_steps:
            recorder.add(env.render, step)
        if terminated or truncated:
            return trace.result(task, terminated, truncated, info)


def run_episodes_together(
    envs: Sequence[Any], policy: Policy, jobs: Sequence[tuple[Sequence[float], int]]
) -> list[EpisodeResult]:
    """Run one episode per ``(command, seed)`` job, each in its own env of ``envs`` (at least
    as many as jobs), all in step so that the policy sees one batch of observations per
    step: :func:`run_episode`'s results at a fraction of its cost per episode."""
    if len(envs) < len(jobs):
        raise ValueError(f"run_episodes_together: {len(jobs)} jobs but only {len(envs)} envs")
    envs = list(envs)[: len(jobs)]
    obs = np.stack(
        [
            env.reset(seed=seed, options={"command": tuple(c)})[0]
            for env, (c, seed) in zip(envs, jobs, strict=True)
        ]
    )
    traces = [EpisodeTrace(command, seed) for command, seed in jobs]
    results: list[EpisodeResult | None] = [None] * len(jobs)
    running = list(range(len(jobs)))
    while running:
        actions = np.asarray(policy(obs[running]), dtype=np.float32)
        for action, i in zip(actions, list(running), strict=True):
            env = envs[i]
            obs[i], reward, terminated, truncated, info = env.step(action)
            task = env.unwrapped.task
            traces[i].record(task, reward)
            if terminated or truncated:
                results[i] = traces[i].result(task, terminated, truncated, info)
                running.remove(i)
    return [r for r in results if r is not None]


def evaluate(
    env: Any,
    policy: Policy,
    commands: Sequence[Sequence[float]] = DEFAULT_COMMANDS,
    episodes: int = 1,
    seed: int = 0,
    video: str | Path | None = None,
    progress: bool = True,
    video_seconds: float = 5.0,
) -> list[EpisodeResult]:
    """Run ``episodes`` episodes per command; with ``video``, record the first
    ``video_seconds`` of the first episode of each command (see :class:`VideoRecorder`)."""
    check_int("episodes", episodes, low=1)
    check_positive("video_seconds", video_seconds, expected="a number > 0")
    fps = float(env.unwrapped.metadata.get("render_fps", 50))
    recorder = VideoRecorder(video, fps) if video is not None else None
    record_steps = math.ceil(video_seconds * fps)
    results = []
    runs = [(command, seed + i) for command in commands for i in range(episodes)]
    iterator: Any = tqdm(runs, desc="episodes", unit="ep") if progress else runs
    try:
        for command, episode_seed in iterator:
            record = recorder if episode_seed == seed else None
            results.append(run_episode(env, policy, command, episode_seed, record, record_steps))
    finally:
        if recorder is not None:
            recorder.close()
    return results


def summarize(results: Sequence[EpisodeResult]) -> list[dict[str, Any]]:
    """One row per command: survival rate and mean tracking errors over its episodes."""
    rows = []
    for command in dict.fromkeys(r.command for r in results):
        group = [r for r in results if r.command == command]
        rows.append(
            {
                "command": command,
                "episodes": len(group),
                "survival": float(np.mean([r.survived for r in group])),
                "x_vel_mse": float(np.mean([r.x_vel_mse for r in group])),
                "y_vel_mse": float(np.mean([r.y_vel_mse for r in group])),
                "mean_vx": float(np.mean([r.mean_vx for r in group])),
                "mean_vy": float(np.mean([r.mean_vy for r in group])),
            }
        )
    return rows


def format_summary(rows: Sequence[dict[str, Any]]) -> str:
    """The summary as an aligned text table."""
    lines = [
        f"{'command (vx, vy, wz)':>22} {'eps':>4} {'survival':>8} {'x_mse':>7} {'y_mse':>7} "
        f"{'mean vx':>7} {'mean vy':>7}"
    ]
    for row in rows:
        command = "(" + ", ".join(f"{c:+.2f}" for c in row["command"]) + ")"
        lines.append(
            f"{command:>22} {row['episodes']:4d} {row['survival']:8.2f} {row['x_vel_mse']:7.4f} "
            f"{row['y_vel_mse']:7.4f} {row['mean_vx']:7.3f} {row['mean_vy']:7.3f}"
        )
    return "\n".join(lines)


@dataclass(frozen=True)
class WalkingCriterion:
    """When a Go1 policy walks: for every command, ``episodes`` episodes (seeds ``seed``,
    ``seed + 1``, ...) all survive, and the mean episode x- and y-velocity MSEs are at most
    ``max_x_mse`` / ``max_y_mse`` (m/s)²."""

    max_x_mse: float = 0.01
    max_y_mse: float = 0.01
    episodes: int = 5
    seed: int = 0
    commands: tuple[tuple[float, float, float], ...] = DEFAULT_COMMANDS

    def __post_init__(self) -> None:
        for name in ("max_x_mse", "max_y_mse"):
            check_positive(name, getattr(self, name), expected="a threshold > 0 in (m/s)^2")
        check_int("episodes", self.episodes, low=1)
        if not self.commands:
            raise ValueError("commands=(): expected at least one (vx, vy, wz) command")

    def passes(self, row: dict[str, Any]) -> bool:
        """Does one command's :func:`summarize` row meet the criterion?"""
        return (
            row["survival"] >= 1.0
            and row["x_vel_mse"] <= self.max_x_mse
            and row["y_vel_mse"] <= self.max_y_mse
        )


def check_walking(
    env: Any, policy: Policy, criterion: WalkingCriterion
) -> tuple[bool, list[dict[str, Any]]]:
    """Whether ``policy`` walks by ``criterion``, and the summary rows evaluated.

    Commands are evaluated in order and the check stops at the first one that fails
    (and within it at the first fall), so a policy that does not walk costs little; the
    rows then cover the commands evaluated so far.
    """
    rows: list[dict[str, Any]] = []
    for command in criterion.commands:
        results = []
        for i in range(criterion.episodes):
            result = run_episode(env, policy, command, criterion.seed + i)
            results.append(result)
            if not result.survived:
                break
        row = summarize(results)[0]
        rows.append(row)
        if not criterion.passes(row) or len(results) < criterion.episodes:
            return False, rows
    return True, rows


@dataclass(frozen=True)
class WalkingScore:
    """How close a policy came to walking: commands passed in ``criterion.commands`` order
    before the first that failed, and the worst x/y MSE over the commands evaluated."""

    commands_passed: int
    commands: int
    worst_mse: float

    @property
    def walks(self) -> bool:
        """Did every command pass?"""
        return self.commands_passed == self.commands

    def key(self) -> tuple[int, float]:
        """Ranking key, larger is better: more commands passed, then a smaller worst MSE."""
        return (self.commands_passed, -self.worst_mse)

    def describe(self) -> str:
        """E.g. ``"6/6 commands pass, worst MSE 0.0041"``."""
        return (
            f"{self.commands_passed}/{self.commands} commands pass, worst MSE {self.worst_mse:.4f}"
        )

    def columns(self) -> dict[str, float]:
        """Its ``progress.csv`` values (:attr:`WalkingEvaluator.columns`)."""
        return {"eval_commands_passed": self.commands_passed, "eval_worst_mse": self.worst_mse}


def score_walking(rows: Sequence[dict[str, Any]], criterion: WalkingCriterion) -> WalkingScore:
    """The :class:`WalkingScore` of :func:`summarize` rows in ``criterion.commands`` order."""
    passed = 0
    for row in rows:
        if not criterion.passes(row):
            break
        passed += 1
    worst = max((max(r["x_vel_mse"], r["y_vel_mse"]) for r in rows), default=math.inf)
    return WalkingScore(passed, len(criterion.commands), worst)


class WalkingEvaluator:
    """Scores checkpoints on ``criterion`` during training, all its episodes in step
    (:func:`run_episodes_together`) in envs made once by ``make_env``."""

    columns = ("eval_commands_passed", "eval_worst_mse")

    def __init__(self, make_env: Callable[[], Any], criterion: WalkingCriterion) -> None:
        self.criterion = criterion
        self.jobs = [
            (command, criterion.seed + i)
            for command in criterion.commands
            for i in range(criterion.episodes)
        ]
        self.envs = [make_env() for _ in self.jobs]

    def __call__(self, checkpoint: str | Path) -> WalkingScore:
        """Score the policy of ``checkpoint`` (loaded as ``chronogym play`` loads it)."""
        policy = load_policy(checkpoint, torch_threads=None)
        rows = summarize(run_episodes_together(self.envs, policy, self.jobs))
        return score_walking(rows, self.criterion)

    def close(self) -> None:
        for env in self.envs:
            env.close()
        self.envs = []
