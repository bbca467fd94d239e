"""Rendered frames to a video file or a film strip, for any env that renders ``rgb_array``.

Generic on purpose: the Go1's ``chronogym play --video`` uses it, and so can any task.
"""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path

import numpy as np

__all__ = ["VideoRecorder"]


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
            try:  # optional: the rl extra
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
        from PIL import Image  # optional: Pillow comes with imageio and matplotlib

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
