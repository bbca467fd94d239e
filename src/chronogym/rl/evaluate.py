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
    frames: list[np.ndarray] | None = None,
) -> EpisodeResult:
    """Run one full episode of ``env`` (a SimEnv of a Go1VelocityTask) with a fixed command."""
    obs, _ = env.reset(seed=seed, options={"command": tuple(command)})
    task = env.unwrapped.task
    total = 0.0
    vx: list[float] = []
    vy: list[float] = []
    if frames is not None:
        frames.append(env.render())
    while True:
        action = np.asarray(policy(obs), dtype=np.float32)
        obs, reward, terminated, truncated, info = env.step(action)
        total += float(reward)
        vx.append(float(task.base_lin_vel[0]))
        vy.append(float(task.base_lin_vel[1]))
        if frames is not None:
            frames.append(env.render())
        if terminated or truncated:
            break
    log = info.get("log", {})
    return EpisodeResult(
        command=tuple(float(c) for c in command),  # type: ignore[arg-type]
        seed=seed,
        survived=bool(truncated and not terminated),
        length_s=float(log.get("/metrics/episode_length_s", len(vx) * task.control_dt)),
        x_vel_mse=float(log.get("/metrics/x_vel_mse", math.nan)),
        y_vel_mse=float(log.get("/metrics/y_vel_mse", math.nan)),
        mean_vx=float(np.mean(vx)),
        mean_vy=float(np.mean(vy)),
        episode_return=total,
    )


def evaluate(
    env: Any,
    policy: Policy,
    commands: Sequence[Sequence[float]] = DEFAULT_COMMANDS,
    episodes: int = 1,
    seed: int = 0,
    video: str | Path | None = None,
    progress: bool = True,
) -> list[EpisodeResult]:
    """Run ``episodes`` episodes per command; with ``video``, record the first of each."""
    if episodes < 1:
        raise ValueError(f"episodes={episodes!r}: expected an integer >= 1")
    frames: list[np.ndarray] | None = [] if video is not None else None
    results = []
    runs = [(command, seed + i) for command in commands for i in range(episodes)]
    iterator: Any = runs
    if progress:
        from tqdm import tqdm

        iterator = tqdm(runs, desc="episodes", unit="ep")
    for command, episode_seed in iterator:
        record = frames if (frames is not None and episode_seed == seed) else None
        results.append(run_episode(env, policy, command, episode_seed, record))
    if video is not None and frames:
        fps = env.unwrapped.metadata.get("render_fps", 50)
        write_video(video, frames, fps)
    return results


def write_video(path: str | Path, frames: Sequence[np.ndarray], fps: float) -> Path:
    """Write RGB frames as MP4 (imageio + imageio-ffmpeg), a GIF (``.gif``) or, for a ``.png``
    path, a film strip of 8 evenly spaced frames side by side (a still for docs and reviews)."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    if path.suffix.lower() == ".png":
        from PIL import Image

        picks = np.linspace(0, len(frames) - 1, num=min(8, len(frames))).round().astype(int)
        Image.fromarray(np.concatenate([frames[i] for i in picks], axis=1)).save(path)
        return path
    if path.suffix.lower() == ".gif":
        from PIL import Image

        images = [Image.fromarray(frame) for frame in frames[::2]]  # 25 fps is plenty for a GIF
        images[0].save(
            path, save_all=True, append_images=images[1:], duration=int(2000 / fps), loop=0
        )
        return path
    try:
        import imageio.v2 as imageio
    except ImportError as error:
        raise RuntimeError(
            f"writing {path} needs imageio and imageio-ffmpeg "
            "(pip install 'chronogym[rl]'), or give a .gif path"
        ) from error
    with imageio.get_writer(path, fps=fps, macro_block_size=8) as writer:
        for frame in frames:
            writer.append_data(frame)
    return path


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
