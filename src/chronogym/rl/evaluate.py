"""Roll a trained policy out in single envs: tracking errors per command, optional video."""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np

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
    total = 0.0
    vx: list[float] = []
    vy: list[float] = []
    step = 0
    if recorder is not None:
        recorder.add(env.render, step)
    while True:
        action = np.asarray(policy(obs), dtype=np.float32)
        obs, reward, terminated, truncated, info = env.step(action)
        total += float(reward)
        vx.append(float(task.base_lin_vel[0]))
        vy.append(float(task.base_lin_vel[1]))
        step += 1
        if recorder is not None and step <= record_steps:
            recorder.add(env.render, step)
        if terminated or truncated:
            break
    return _episode_result(task, command, seed, vx, vy, total, terminated, truncated, info)


def _episode_result(
    task: Any,
    command: Sequence[float],
    seed: int,
    vx: list[float],
    vy: list[float],
    total: float,
    terminated: bool,
    truncated: bool,
    info: dict[str, Any],
) -> EpisodeResult:
    """The :class:`EpisodeResult` of a finished episode from its velocity trace."""
    # The task logs its episode metrics when its own horizon ends the episode; a shorter
    # TimeLimit (``gym.make(..., max_episode_steps=N)``) ends it first: same errors from here.
    log = info.get("log", {})
    x_mse = float(np.mean((np.asarray(vx) - float(command[0])) ** 2))
    y_mse = float(np.mean((np.asarray(vy) - float(command[1])) ** 2))
    return EpisodeResult(
        command=tuple(float(c) for c in command),  # type: ignore[arg-type]
        seed=seed,
        survived=bool(truncated and not terminated),
        length_s=float(log.get("/metrics/episode_length_s", len(vx) * task.control_dt)),
        x_vel_mse=float(log.get("/metrics/x_vel_mse", x_mse)),
        y_vel_mse=float(log.get("/metrics/y_vel_mse", y_mse)),
        mean_vx=float(np.mean(vx)),
        mean_vy=float(np.mean(vy)),
        episode_return=total,
    )


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
    traces: list[tuple[list[float], list[float]]] = [([], []) for _ in jobs]
    totals = [0.0] * len(jobs)
    results: list[EpisodeResult | None] = [None] * len(jobs)
    running = list(range(len(jobs)))
    while running:
        actions = np.asarray(policy(obs[running]), dtype=np.float32)
        for action, i in zip(actions, list(running), strict=True):
            env, (command, seed) = envs[i], jobs[i]
            obs[i], reward, terminated, truncated, info = env.step(action)
            task = env.unwrapped.task
            totals[i] += float(reward)
            traces[i][0].append(float(task.base_lin_vel[0]))
            traces[i][1].append(float(task.base_lin_vel[1]))
            if terminated or truncated:
                vx, vy = traces[i]
                results[i] = _episode_result(
                    task, command, seed, vx, vy, totals[i], terminated, truncated, info
                )
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
    if episodes < 1:
        raise ValueError(f"episodes={episodes!r}: expected an integer >= 1")
    if not video_seconds > 0:
        raise ValueError(f"video_seconds={video_seconds!r}: expected a number > 0")
    fps = float(env.unwrapped.metadata.get("render_fps", 50))
    recorder = VideoRecorder(video, fps) if video is not None else None
    record_steps = math.ceil(video_seconds * fps)
    results = []
    runs = [(command, seed + i) for command in commands for i in range(episodes)]
    iterator: Any = runs
    if progress:
        from tqdm import tqdm

        iterator = tqdm(runs, desc="episodes", unit="ep")
    try:
        for command, episode_seed in iterator:
            record = recorder if episode_seed == seed else None
            results.append(run_episode(env, policy, command, episode_seed, record, record_steps))
    finally:
        if recorder is not None:
            recorder.close()
    return results


class VideoRecorder:
    """Rendered frames to a file, at most 25 frames per second of simulated time.

    ``.mp4`` (imageio-ffmpeg) is written as frames arrive; ``.gif`` keeps every recorded
    frame until :meth:`close`; ``.png`` is a film strip of 8 evenly spaced frames side by side
    (a still for docs and reviews), chosen from at most 64 kept frames, so memory stays bounded.
    """

    max_fps = 25.0
    strip_frames = 8
    strip_pool = 64

    def __init__(self, path: str | Path, fps: float) -> None:
        self.path = Path(path)
        self.kind = self.path.suffix.lower()
        if self.kind not in (".mp4", ".gif", ".png"):
            raise ValueError(f"video={str(path)!r}: expected a .mp4, .gif or .png path")
        self.stride = max(1, round(fps / self.max_fps))  # simulation steps per frame
        self.fps = fps / self.stride
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self.kept: list[np.ndarray] = []
        self.keep_every = 1  # of recorded frames (the film strip thins its pool)
        self.recorded = 0
        self.writer = None
        if self.kind == ".mp4":
            try:
                import imageio.v2 as imageio
            except ImportError as error:
                raise RuntimeError(
                    f"writing {self.path} needs imageio and imageio-ffmpeg "
                    "(pip install 'chronogym[rl]'), or give a .gif or .png path"
                ) from error
            self.writer = imageio.get_writer(self.path, fps=self.fps, macro_block_size=8)

    def add(self, render: Callable[[], np.ndarray], step: int) -> None:
        """Render and keep the frame of simulation ``step`` if it falls on the frame stride."""
        if step % self.stride:
            return
        index, self.recorded = self.recorded, self.recorded + 1
        if self.writer is not None:
            self.writer.append_data(render())
        elif index % self.keep_every == 0:
            self.kept.append(render())
            if self.kind == ".png" and len(self.kept) > self.strip_pool:
                self.kept = self.kept[::2]
                self.keep_every *= 2

    def close(self) -> Path:
        """Finish the file; return its path."""
        from PIL import Image

        if self.writer is not None:
            self.writer.close()
        elif self.kept and self.kind == ".png":
            count = min(self.strip_frames, len(self.kept))
            picks = np.linspace(0, len(self.kept) - 1, num=count).round().astype(int)
            strip = np.concatenate([self.kept[i] for i in picks], axis=1)
            Image.fromarray(strip).save(self.path)
        elif self.kept:
            images = [Image.fromarray(frame) for frame in self.kept]
            duration = round(1000 / self.fps)
            images[0].save(
                self.path, save_all=True, append_images=images[1:], duration=duration, loop=0
            )
        self.kept = []
        return self.path


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
            value = getattr(self, name)
            if isinstance(value, bool) or not isinstance(value, (int, float)) or not value > 0:
                raise ValueError(f"{name}={value!r}: expected a threshold > 0 in (m/s)^2")
        if isinstance(self.episodes, bool) or not isinstance(self.episodes, int):
            raise ValueError(f"episodes={self.episodes!r}: expected an integer >= 1")
        if self.episodes < 1:
            raise ValueError(f"episodes={self.episodes!r}: expected an integer >= 1")
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
        from chronogym.rl.checkpoint import load_policy

        policy = load_policy(checkpoint, torch_threads=None)
        rows = summarize(run_episodes_together(self.envs, policy, self.jobs))
        return score_walking(rows, self.criterion)

    def close(self) -> None:
        for env in self.envs:
            env.close()
        self.envs = []
