"""Keep the best checkpoint of a training run: ``best.pt`` and ``best.json``.

At every save point the :class:`~chronogym.rl.trainer.Runner` hands the new checkpoint to an
evaluator (for the Go1,
:class:`~chronogym.tasks.quadruped.evaluation.WalkingEvaluator`), which returns a score;
:class:`BestCheckpoint` copies the checkpoint to ``best.pt`` whenever its score beats every
earlier one and records why in ``best.json``.
"""

from __future__ import annotations

import json
import math
import shutil
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Protocol

BEST_CHECKPOINT = "best.pt"
BEST_RECORD = "best.json"
#: ``progress.csv`` column with the seconds each evaluation took.
EVAL_SECONDS = "eval_s"


class Score(Protocol):
    """What an evaluator returns: a ranking key (larger is better), a one-line description,
    and the values of its ``progress.csv`` columns."""

    def key(self) -> tuple[float, ...]: ...

    def describe(self) -> str: ...

    def columns(self) -> dict[str, float]: ...


class Evaluator(Protocol):
    """Scores a checkpoint file; ``columns`` names the values its scores put in
    ``progress.csv``."""

    columns: tuple[str, ...]

    def __call__(self, checkpoint: Path) -> Score: ...


@dataclass(frozen=True)
class BestSoFar:
    """The best checkpoint of the run so far."""

    iteration: int
    env_steps: int
    source: str
    key: tuple[float, ...]
    description: str


class BestCheckpoint:
    """Evaluates each saved checkpoint with ``evaluator``; keeps the best as ``best.pt``.

    A later checkpoint replaces the best only with a strictly larger key, so among equals the
    earliest stays. ``best.json`` holds the best's iteration, env steps, source file, key and
    description; on resume it is read back so the best of the whole run is kept.
    """

    def __init__(self, out: Path, evaluator: Evaluator, *, resumed: bool = False) -> None:
        self.out = Path(out)
        self.evaluator = evaluator
        self.best: BestSoFar | None = self._read() if resumed else None

    @property
    def columns(self) -> tuple[str, ...]:
        """The ``progress.csv`` columns of an evaluation."""
        return (*self.evaluator.columns, EVAL_SECONDS)

    def consider(self, iteration: int, env_steps: int, checkpoint: Path) -> dict[str, float]:
        """Evaluate ``checkpoint``; make it ``best.pt`` if it beats the best so far. Returns
        its ``progress.csv`` values."""
        start = time.perf_counter()
        score = self.evaluator(checkpoint)
        key = tuple(float(k) for k in score.key())
        if self.best is None or key > self.best.key:
            shutil.copyfile(checkpoint, self.out / BEST_CHECKPOINT)
            self.best = BestSoFar(iteration, env_steps, checkpoint.name, key, score.describe())
            self._write()
        return {**score.columns(), EVAL_SECONDS: time.perf_counter() - start}

    def summary(self) -> str:
        """One line: which checkpoint is best and why (empty before any evaluation)."""
        if self.best is None:
            return ""
        b = self.best
        return (
            f"best checkpoint {self.out / BEST_CHECKPOINT} = {b.source} "
            f"(iteration {b.iteration}, {b.env_steps} env steps): {b.description}"
        )

    def _write(self) -> None:
        assert self.best is not None
        record = {
            "iteration": self.best.iteration,
            "env_steps": self.best.env_steps,
            "source": self.best.source,
            "key": [k if math.isfinite(k) else None for k in self.best.key],
            "description": self.best.description,
        }
        (self.out / BEST_RECORD).write_text(json.dumps(record, indent=2) + "\n")

    def _read(self) -> BestSoFar | None:
        path = self.out / BEST_RECORD
        if not path.exists() or not (self.out / BEST_CHECKPOINT).exists():
            return None
        record: dict[str, Any] = json.loads(path.read_text())
        key = tuple(-math.inf if k is None else float(k) for k in record["key"])
        return BestSoFar(
            int(record["iteration"]),
            int(record["env_steps"]),
            str(record["source"]),
            key,
            str(record["description"]),
        )


def read_best(run: str | Path) -> dict[str, Any] | None:
    """The ``best.json`` record of a run folder, or None if it has none."""
    path = Path(run) / BEST_RECORD
    return json.loads(path.read_text()) if path.exists() else None
