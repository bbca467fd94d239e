"""Checking actions before they reach a simulation: shape, dtype, finiteness."""

from __future__ import annotations

from typing import Any, Literal

import numpy as np
from gymnasium import spaces

InvalidActionMode = Literal["raise", "clip"]
INVALID_ACTION_MODES = ("raise", "clip")


def check_invalid_action_mode(mode: str) -> None:
    """Raise ValueError unless ``mode`` is one of INVALID_ACTION_MODES."""
    if mode not in INVALID_ACTION_MODES:
        raise ValueError(f"invalid_action={mode!r}: expected one of {INVALID_ACTION_MODES}")


def prepare_box_action(
    action: Any,
    space: spaces.Box,
    batch: int | None,
    mode: InvalidActionMode,
) -> np.ndarray:
    """Return ``action`` as an array of ``space``'s dtype, checked.

    ``batch`` is the number of envs for a vector action, None for one env.
    Wrong shape or a non-numeric dtype always raises; NaN/Inf raise with
    ``mode="raise"``, and with ``mode="clip"`` are replaced (NaN -> 0, +-Inf ->
    the bound) and the whole action is clipped to the space's bounds.
    """
    expected = space.shape if batch is None else (batch, *space.shape)
    array = np.asarray(action)
    if array.dtype.kind not in "biuf":
        raise TypeError(
            f"action dtype {array.dtype} is not numeric; expected values castable to {space.dtype}"
        )
    if array.shape != expected:
        raise ValueError(f"action shape {array.shape} is wrong; expected {expected}")
    array = array.astype(space.dtype, copy=False)
    if array.dtype.kind == "f":
        finite = np.isfinite(array)
        if not finite.all() or mode == "clip":
            if mode == "raise":
                bad = np.argwhere(~finite)
                where = bad[:, 0].tolist() if batch is not None else bad.tolist()
                label = "envs" if batch is not None else "indices"
                raise ValueError(
                    f"action contains NaN/Inf at {label} {sorted(set(map(str, where)))[:8]}; "
                    "expected finite values (or invalid_action='clip')"
                )
            array = np.clip(np.nan_to_num(array, nan=0.0), space.low, space.high).astype(
                space.dtype, copy=False
            )
    return array


def prepare_action(action: Any, space: spaces.Space, batch: int | None, mode: str) -> Any:
    """Check an action against a single-env space; Box gets full checks, others ``contains``."""
    if isinstance(space, spaces.Box):
        return prepare_box_action(action, space, batch, mode)  # type: ignore[arg-type]
    if batch is None and not space.contains(action):
        raise ValueError(f"action {action!r} is not in the action space {space}")
    return action
