"""Splitting batched actions into per-env actions and joining per-env results into batches.

Everything goes through ``gymnasium.vector.utils`` (``batch_space``, ``iterate``,
``concatenate``, ``create_empty_array``), as in Gymnasium's own vector envs, so
every space type batches exactly as there. The one fast path: Box actions and
observations travel between driver and workers as raw bytes (see
:mod:`chronogym.vector.wire_format`), and their batches are joined with
``np.concatenate``.
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.error import CustomSpaceError
from gymnasium.vector.utils import concatenate, create_empty_array, iterate

from chronogym.validation import show


def split_actions(batched: spaces.Space, actions: Any, count: int) -> list[Any]:
    """``actions``, a batch of ``batched`` (``batch_space`` of one env's action space for
    ``count`` envs), as one action per env."""
    try:
        rows = list(iterate(batched, actions))
    except Exception as error:
        message = (
            f"actions {show(actions)} are not a batch of {count} actions: {error}; "
            f"expected an element of {batched}"
        )
        if isinstance(error, CustomSpaceError):  # Gymnasium's class for this case
            raise CustomSpaceError(message) from None
        raise ValueError(message) from None
    if len(rows) != count:
        raise ValueError(
            f"got {len(rows)} actions for {count} envs; expected one action per env "
            f"(an element of {batched})"
        )
    return rows


def join_obs(space: spaces.Space, parts: Sequence[Any]) -> Any:
    """One batch from per-worker parts: packed arrays (Box rows) or lists of per-env obs."""
    if all(isinstance(part, np.ndarray) for part in parts):
        return np.concatenate(parts)
    items = [row for part in parts for row in part]
    return concatenate(space, items, create_empty_array(space, len(items), fn=np.zeros))


def rows_of(part: Any) -> list[Any]:
    """A worker's part as one observation per env (packed rows are copied)."""
    if isinstance(part, np.ndarray):
        return [row.copy() for row in part]
    return list(part)
