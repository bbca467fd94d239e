"""Checks of the vector envs' constructor and call arguments, each naming the bad value."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from chronogym.vector.wire import EnvFactory


def normalize_env_fns(
    env_fns: str | EnvFactory | Sequence[str | EnvFactory], num_envs: int | None
) -> list[str | EnvFactory]:
    """One factory (or registered id) per env, from the forms Gymnasium users know."""
    if isinstance(env_fns, str) or callable(env_fns):
        if num_envs is None:
            raise ValueError("num_envs is required when a single env id or factory is given")
        count = num_envs
        fns: list[str | EnvFactory] = [env_fns] * max(count, 0)  # type: ignore[list-item]
    elif isinstance(env_fns, Sequence):
        fns = list(env_fns)
        count = len(fns) if num_envs is None else num_envs
        if num_envs is not None and num_envs != len(fns):
            raise ValueError(f"num_envs={num_envs} but {len(fns)} env factories were given")
        for i, fn in enumerate(fns):
            if not (isinstance(fn, str) or callable(fn)):
                raise TypeError(f"env_fns[{i}]={fn!r}: expected a callable or an env id string")
    else:
        raise TypeError(
            f"env_fns={env_fns!r}: expected an env id, a factory, or a list of factories"
        )
    if isinstance(count, bool) or not isinstance(count, (int, np.integer)) or count < 1:
        raise ValueError(f"num_envs={count!r}: expected an integer >= 1")
    return fns


def check_envs_per_worker(envs_per_worker: int, num_envs: int) -> int:
    """Validate ``envs_per_worker`` against ``num_envs``."""
    if (
        isinstance(envs_per_worker, bool)
        or not isinstance(envs_per_worker, (int, np.integer))
        or envs_per_worker < 1
    ):
        raise ValueError(f"envs_per_worker={envs_per_worker!r}: expected an integer >= 1")
    if envs_per_worker > num_envs:
        raise ValueError(
            f"envs_per_worker={envs_per_worker} is larger than num_envs={num_envs}; "
            f"expected 1 <= envs_per_worker <= {num_envs}"
        )
    return int(envs_per_worker)


def check_reset_mask(reset_mask: Any, num_envs: int) -> np.ndarray:
    """``options["reset_mask"]``: a bool array of shape (num_envs,) with a True value.

    The exception types are Gymnasium's (TypeError for type and dtype, ValueError
    for shape and an all-False mask).
    """
    expected = f"expected a numpy bool array of shape ({num_envs},) with at least one True"
    shown = _show(reset_mask)
    if not isinstance(reset_mask, np.ndarray):
        raise TypeError(
            f"options['reset_mask']={shown} is a {type(reset_mask).__name__}; {expected}"
        )
    if reset_mask.shape != (num_envs,):
        raise ValueError(f"options['reset_mask']={shown} has shape {reset_mask.shape}; {expected}")
    if reset_mask.dtype != np.bool_:
        raise TypeError(f"options['reset_mask']={shown} has dtype {reset_mask.dtype}; {expected}")
    if not reset_mask.any():
        raise ValueError(f"options['reset_mask']={shown} is all False; {expected}")
    return reset_mask


def _show(value: Any) -> str:
    text = repr(value.tolist() if isinstance(value, np.ndarray) else value)
    return text if len(text) <= 80 else text[:77] + "..."


def check_max_restarts(max_restarts: int) -> int:
    """Restarts allowed per env: an integer >= 0, or -1 for no limit."""
    if isinstance(max_restarts, bool) or not isinstance(max_restarts, int) or max_restarts < -1:
        raise ValueError(
            f"max_restarts={max_restarts!r}: expected an integer >= 0, or -1 for no limit"
        )
    return max_restarts


def check_min_envs(min_envs: int | None, in_flight: int) -> int:
    """``recv``'s ``min_envs``: None (every env in flight) or 1..in_flight."""
    if min_envs is None:
        return in_flight
    if (
        isinstance(min_envs, bool)
        or not isinstance(min_envs, (int, np.integer))
        or not 1 <= min_envs <= in_flight
    ):
        raise ValueError(
            f"min_envs={min_envs!r}: expected an integer with 1 <= min_envs <= {in_flight} "
            "(the envs in flight)"
        )
    return int(min_envs)
