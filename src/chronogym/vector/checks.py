"""Checks of the vector envs' constructor and call arguments, each naming the bad value."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np

from chronogym.validation import check_int, show
from chronogym.vector.backend import EnvFactory


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
    check_int("num_envs", count, low=1)
    return fns


def check_envs_per_worker(envs_per_worker: int, num_envs: int) -> int:
    """Validate ``envs_per_worker`` against ``num_envs``."""
    check_int("envs_per_worker", envs_per_worker, low=1)
    if envs_per_worker > num_envs:
        raise ValueError(
            f"envs_per_worker={envs_per_worker} is larger than num_envs={num_envs}; "
            f"expected 1 <= envs_per_worker <= {num_envs}"
        )
    return int(envs_per_worker)


def check_reset_mask(reset_mask: Any, num_envs: int) -> np.ndarray:
    """``options["reset_mask"]``: a bool array of shape (num_envs,) with a True value.

    Each error is Gymnasium's (its class and its text, as ``SyncVectorEnv`` raises
    it), followed by what was expected.
    """
    expected = f"; expected a numpy bool array of shape ({num_envs},) with at least one True"
    if not isinstance(reset_mask, np.ndarray):
        raise TypeError(
            f"`options['reset_mask']` must be a numpy array, got {type(reset_mask)}{expected}"
        )
    if reset_mask.shape != (num_envs,):
        raise ValueError(
            f"`options['reset_mask']` must have shape `({num_envs},)`, got {reset_mask.shape}"
            + expected
        )
    if reset_mask.dtype != np.bool_:
        raise TypeError(
            f"`options['reset_mask']` must have `dtype=np.bool_`, got {reset_mask.dtype}" + expected
        )
    if not reset_mask.any():
        raise ValueError(
            "`options['reset_mask']` must contain a boolean array with at least one True "
            f"value, got reset_mask={reset_mask}{expected}"
        )
    return reset_mask


def check_max_restarts(max_restarts: int) -> int:
    """Restarts allowed per env: an integer >= 0, or -1 for no limit."""
    expected = "an integer >= 0, or -1 for no limit"
    return check_int("max_restarts", max_restarts, low=-1, expected=expected)


def check_max_envs(max_envs: Any, in_flight: int, envs_per_worker: int) -> int | None:
    """``max_envs`` of ``recv``: None, or a multiple of ``envs_per_worker`` >= 1."""
    if max_envs is None:
        return None
    expected = (
        f"None or a multiple of envs_per_worker={envs_per_worker} >= 1 (calls are per "
        f"worker; {in_flight} envs are in flight)"
    )
    check_int("max_envs", max_envs, low=1, expected=expected)
    if max_envs % envs_per_worker:
        raise ValueError(f"max_envs={max_envs}: expected {expected}")
    return int(max_envs)


def check_min_envs(min_envs: int | None, in_flight: int) -> int:
    """``recv``'s ``min_envs``: None (every env in flight) or 1..in_flight."""
    if min_envs is None:
        return in_flight
    expected = f"an integer with 1 <= min_envs <= {in_flight} (the envs in flight)"
    return check_int("min_envs", min_envs, low=1, high=in_flight, expected=expected)


def check_env_ids(env_ids: Any, num_envs: int) -> np.ndarray:
    """``env_ids`` as a 1-D int64 array of distinct ids in ``0..num_envs-1`` (None: all)."""
    if env_ids is None:
        return np.arange(num_envs, dtype=np.int64)
    array = np.asarray(env_ids)
    if array.ndim == 0:
        array = array.reshape(1)
    if array.ndim != 1 or array.size == 0 or array.dtype.kind not in "iu":
        raise ValueError(
            f"env_ids={show(env_ids)}: expected a non-empty list or 1-D array of integer env "
            f"ids in 0..{num_envs - 1}"
        )
    bad = sorted({int(i) for i in array if not 0 <= i < num_envs})
    if bad:
        raise ValueError(
            f"env_ids={show(env_ids)}: ids {bad} are out of range; expected integers in "
            f"0..{num_envs - 1} (num_envs={num_envs})"
        )
    values, counts = np.unique(array, return_counts=True)
    if (counts > 1).any():
        raise ValueError(
            f"env_ids={show(env_ids)}: ids {values[counts > 1].tolist()} appear more than "
            "once; expected each env at most once"
        )
    return array.astype(np.int64, copy=False)


def workers_of(
    env_ids: np.ndarray, slices: Sequence[tuple[int, int]], envs_per_worker: int
) -> list[int]:
    """The workers holding ``env_ids`` (ascending); the ids must cover each of them whole."""
    chosen = set(env_ids.tolist())
    workers = sorted({i // envs_per_worker for i in chosen})
    for w in workers:
        lo, hi = slices[w]
        missing = [i for i in range(lo, hi) if i not in chosen]
        if missing:
            raise ValueError(
                f"env_ids={show(env_ids)}: worker {w} holds envs {list(range(lo, hi))} but "
                f"envs {missing} are missing; send() steps whole workers "
                f"(envs_per_worker={envs_per_worker}), so expected every env of each worker "
                "it touches"
            )
    return workers
