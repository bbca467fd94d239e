"""Splitting batched actions and joining batched observations across workers."""

from __future__ import annotations

from typing import Any

import numpy as np
from gymnasium import spaces


def slice_batch(batch: Any, start: int, stop: int) -> Any:
    """Rows ``start:stop`` of a batched structure (array, dict or tuple of arrays)."""
    if isinstance(batch, dict):
        return {key: slice_batch(value, start, stop) for key, value in batch.items()}
    if isinstance(batch, tuple):
        return tuple(slice_batch(value, start, stop) for value in batch)
    return batch[start:stop]


def concat_batches(space: spaces.Space, parts: list[Any]) -> Any:
    """Join per-worker batches of ``space`` observations into one batch."""
    if isinstance(space, spaces.Dict):
        return {
            key: concat_batches(sub, [part[key] for part in parts])
            for key, sub in space.spaces.items()
        }
    if isinstance(space, spaces.Tuple):
        return tuple(
            concat_batches(sub, [part[i] for part in parts]) for i, sub in enumerate(space.spaces)
        )
    if isinstance(space, (spaces.Box, spaces.Discrete, spaces.MultiDiscrete, spaces.MultiBinary)):
        return np.concatenate(parts, axis=0)
    return tuple(item for part in parts for item in part)


def take_rows(batch: Any, rows: np.ndarray) -> Any:
    """Rows ``rows`` (in that order) of a batched structure (array, dict or tuple of arrays)."""
    if isinstance(batch, dict):
        return {key: take_rows(value, rows) for key, value in batch.items()}
    if isinstance(batch, tuple):
        return tuple(take_rows(value, rows) for value in batch)
    if isinstance(batch, np.ndarray):
        return batch[rows]
    return [batch[int(i)] for i in rows]
