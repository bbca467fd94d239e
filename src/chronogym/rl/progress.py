"""Training progress: ``progress.csv`` (:class:`ProgressLog`) and a bar (:class:`ProgressBar`).

An :class:`Iteration` is what one PPO iteration's collection and update did: the losses for
RSL-RL's logger and the timing columns of its row.

A row of ``progress.csv`` has the :data:`RUN_COLUMNS`, one column per metric, then the
:data:`TIMING_COLUMNS`. A metric is a key under ``/metrics/`` of the ``info["log"]`` that a
task reports when an episode ends (``RslRlVecEnv`` gathers them into ``extras["log"]``); its
column holds the mean over the episodes that ended since the previous row, NaN if none did.
"""

from __future__ import annotations

import csv
import math
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

if TYPE_CHECKING:
    import torch

#: Columns before the metrics: seconds since the start, PPO iteration, env steps of the whole
#: run, and RSL-RL's mean episode return (over its last 100 episodes).
RUN_COLUMNS = ("wall_time", "iteration", "env_steps", "mean_reward")
#: Columns after the metrics: seconds collecting and updating, and the update's policy lag.
TIMING_COLUMNS = ("collect_s", "learn_s", "policy_lag")
METRIC_PREFIX = "/metrics/"


@dataclass(frozen=True)
class Iteration:
    """What one iteration's collection and update did: the update's mean losses, the seconds
    spent collecting (returns included) and updating, and the update's policy lag."""

    losses: dict[str, float]
    collect_s: float
    learn_s: float
    policy_lag: int


def progress_columns(metric_columns: Iterable[str], extra: Iterable[str] = ()) -> tuple[str, ...]:
    """The header of a ``progress.csv`` with these metric columns (and ``extra`` columns,
    such as a checkpoint evaluation's, before the timing ones)."""
    return (*RUN_COLUMNS, *metric_columns, *extra, *TIMING_COLUMNS)


class ProgressLog:
    """``progress.csv``: one row per PPO iteration, a column for every metric the env reports.

    ``pinned`` (column -> metric key) names metric columns that every row has from the first
    on. Any other metric gets a column when it is first reported, named by the key without
    ``/metrics/`` (the whole key if that name is taken); the file is then rewritten with the
    wider header and the earlier rows read NaN there. ``append`` continues an existing file
    and its columns; otherwise the file starts anew. ``extra`` columns (e.g. a checkpoint
    evaluation's) are filled from the values given to :meth:`write`, NaN in rows without them.
    """

    def __init__(
        self,
        path: Path,
        pinned: Mapping[str, str],
        *,
        append: bool = False,
        extra: Sequence[str] = (),
    ) -> None:
        self.path = Path(path)
        self.metrics: dict[str, str] = {key: column for column, key in pinned.items()}
        self.extra = tuple(extra)
        self._episodes: dict[str, list[float]] = {}
        rows: list[dict[str, str]] = []
        if append and self.path.exists() and self.path.stat().st_size > 0:
            header, rows = self._read()
            fixed = (*RUN_COLUMNS, *TIMING_COLUMNS, *self.extra)
            found = [c for c in header if c not in fixed]
            self.metrics = {pinned.get(c, _metric_key(c)): c for c in found} | self.metrics
            if header == self.columns:
                return
        self._rewrite(rows)

    @property
    def columns(self) -> tuple[str, ...]:
        """The header, in order."""
        return progress_columns(self.metrics.values(), self.extra)

    def record(self, log: Mapping[str, torch.Tensor | np.ndarray]) -> None:
        """Keep the metrics of the episodes that ended in one env step (``extras["log"]``:
        key -> values of those episodes)."""
        for key, values in log.items():
            if key.startswith(METRIC_PREFIX):
                self._episodes.setdefault(key, []).extend(values.tolist())

    def write(self, values: Mapping[str, float]) -> dict[str, float]:
        """Append one row: ``values`` of the run and timing columns, with the mean of every
        metric recorded since the last row; return the row."""
        new = [key for key in self._episodes if key not in self.metrics]
        if new:
            for key in new:
                self.metrics[key] = self._column_for(key)
            self._rewrite(self._read()[1])
        means = {column: _mean(self._episodes.get(key, [])) for key, column in self.metrics.items()}
        self._episodes.clear()
        merged = {**dict.fromkeys(self.extra, math.nan), **values, **means}
        row = {column: merged[column] for column in self.columns}
        with self.path.open("a", newline="") as handle:
            csv.writer(handle).writerow(row.values())
        return row

    def _column_for(self, key: str) -> str:
        name = key[len(METRIC_PREFIX) :]
        return key if name in self.columns else name

    def _read(self) -> tuple[tuple[str, ...], list[dict[str, str]]]:
        with self.path.open(newline="") as handle:
            reader = csv.DictReader(handle)
            rows = list(reader)
        return tuple(reader.fieldnames or ()), rows

    def _rewrite(self, rows: list[dict[str, str]]) -> None:
        with self.path.open("w", newline="") as handle:
            writer = csv.writer(handle)
            writer.writerow(self.columns)
            writer.writerows([row.get(c) or "nan" for c in self.columns] for row in rows)


def _metric_key(column: str) -> str:
    return column if column.startswith(METRIC_PREFIX) else METRIC_PREFIX + column


def _mean(values: list[float]) -> float:
    return float(np.mean(values)) if values else math.nan


_TIME_BAR = "{l_bar}{bar}| {n_fmt}/{total_fmt} s [{elapsed}<{remaining}{postfix}]"


class ProgressBar:
    """A tqdm bar over the iterations (or, with only a time budget, over its seconds); without
    tqdm, one short line through ``log`` every 5 % of the iterations. Silent unless
    ``enabled``."""

    def __init__(
        self,
        enabled: bool,
        iterations: int | None,
        budget_s: float,
        log: Callable[[str], object],
    ) -> None:
        self.bar = None
        self.log = log if enabled else None
        self.every = max(1, (iterations or 100) // 20)
        self.count = 0
        self.by_time = iterations is None
        self.shown_s = 0
        if not enabled:
            return
        try:
            from tqdm import tqdm
        except ImportError:
            return
        if self.by_time:
            self.bar = tqdm(total=round(budget_s), desc="train", bar_format=_TIME_BAR)
        else:
            self.bar = tqdm(total=iterations, desc="train", unit="it")
        self.log = None

    def update(self, row: Mapping[str, float]) -> None:
        """Show one ``progress.csv`` row."""
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
