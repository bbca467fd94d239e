"""Each worker's latest observations, kept by the driver between steps."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import numpy as np


class LastObs:
    """Each worker's latest observations (None before its first reset).

    A shared-memory step keeps one array for all the envs (:meth:`set_all`) and cuts it into
    the workers' parts only when one is asked for: the driver's step then does no work per
    worker, and restarts, ``recv`` and masked resets, which do, read the parts as before.
    """

    def __init__(self, workers: int) -> None:
        self._parts: list[Any] | None = [None] * workers
        self._whole: np.ndarray | None = None
        self._slices: list[tuple[int, int]] = []

    def set_all(self, whole: np.ndarray, slices: list[tuple[int, int]]) -> None:
        """Every worker's part at once: rows ``lo:hi`` of ``whole`` for each ``(lo, hi)``."""
        self._whole, self._slices, self._parts = whole, slices, None

    def never_reset(self, w: int) -> bool:
        """Has worker ``w`` no observations yet (never reset)?"""
        return self._parts is not None and self._parts[w] is None

    def _cut(self) -> list[Any]:
        if self._parts is None:
            assert self._whole is not None
            self._parts = [self._whole[lo:hi] for lo, hi in self._slices]
            self._whole = None
        return self._parts

    def __getitem__(self, w: int) -> Any:
        return self._cut()[w]

    def __setitem__(self, w: int, part: Any) -> None:
        self._cut()[w] = part

    def __len__(self) -> int:
        return len(self._slices) if self._parts is None else len(self._parts)

    def __iter__(self) -> Iterator[Any]:
        return iter(self._cut())
