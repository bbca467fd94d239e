"""Deformed soil outside a moving window: a sparse store of fixed-size tiles of node state.

A soil whose window follows the bodies (``SoilGrid.shift``) keeps dense arrays only for the
window. Before the window moves, the nodes it leaves are written here, tile by tile, but only
tiles that hold deformation (or were stored before); when the window comes back over them they
are read back. A tile holds the rows of per-node state that outlive a contact (``level0`` and
the plastic sinkage) for ``TILE x TILE`` nodes, keyed by global node index ``// TILE``; an
untouched node needs no storage (its level is the uniform reset level, its sinkage 0). A Go1
walking 20 m at 1 cm leaves ~2 MB of tiles; a window of 4 m x 4 m at 1 cm is 5 MB.
"""

from __future__ import annotations

import numpy as np

__all__ = ["TILE", "TileArchive"]

#: Nodes per tile side.
TILE = 32


def _tile_spans(start: int, stop: int) -> list[tuple[int, int, int]]:
    """(tile index, first global node, end global node) of the tiles covering [start, stop)."""
    spans = []
    for tile in range(start // TILE, (stop - 1) // TILE + 1):
        spans.append((tile, max(start, tile * TILE), min(stop, (tile + 1) * TILE)))
    return spans


class TileArchive:
    """Tiles of ``rows`` per-node arrays outside a window, defaults ``fill`` (one per row)."""

    def __init__(self, fill: tuple[float, ...]) -> None:
        self.fill = np.asarray(fill, dtype=np.float64)
        self.tiles: dict[tuple[int, int], np.ndarray] = {}

    def __len__(self) -> int:
        return len(self.tiles)

    @property
    def nbytes(self) -> int:
        """Memory held by the stored tiles (bytes)."""
        return sum(tile.nbytes for tile in self.tiles.values())

    def clear(self) -> None:
        """Forget every stored tile."""
        self.tiles.clear()

    def store(self, rows: list[np.ndarray], start: tuple[int, int]) -> None:
        """Save a window of state (``rows``: arrays ``(nx, ny)`` whose node ``(0, 0)`` has the
        global index ``start``) into the tiles it covers that hold deformation or exist."""
        nx, ny = rows[0].shape
        i0, j0 = start
        fill = self.fill
        for ti, a, b in _tile_spans(i0, i0 + nx):
            for tj, c, d in _tile_spans(j0, j0 + ny):
                parts = [row[a - i0 : b - i0, c - j0 : d - j0] for row in rows]
                tile = self.tiles.get((ti, tj))
                if tile is None:
                    if all((part == value).all() for part, value in zip(parts, fill, strict=True)):
                        continue  # untouched soil: nothing to keep
                    tile = np.empty((len(rows), TILE, TILE))
                    tile[:] = fill[:, None, None]
                    self.tiles[(ti, tj)] = tile
                for r, part in enumerate(parts):
                    tile[r, a - ti * TILE : b - ti * TILE, c - tj * TILE : d - tj * TILE] = part

    def load(self, rows: list[np.ndarray], start: tuple[int, int]) -> None:
        """Fill a window of state from the tiles (``fill`` where no tile is stored)."""
        nx, ny = rows[0].shape
        i0, j0 = start
        for row, value in zip(rows, self.fill, strict=True):
            row.fill(value)
        for ti, a, b in _tile_spans(i0, i0 + nx):
            for tj, c, d in _tile_spans(j0, j0 + ny):
                tile = self.tiles.get((ti, tj))
                if tile is None:
                    continue
                for r, row in enumerate(rows):
                    row[a - i0 : b - i0, c - j0 : d - j0] = tile[
                        r, a - ti * TILE : b - ti * TILE, c - tj * TILE : d - tj * TILE
                    ]
