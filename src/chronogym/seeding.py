"""Seeds for vector envs: Gymnasium's convention plus fresh streams after restarts."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np

from chronogym.validation import is_int


def vector_seeds(seed: int | Sequence[int | None] | None, num_envs: int) -> list[int | None]:
    """Per-env reset seeds, as Gymnasium's vector envs do: int s -> [s, s+1, ...]."""
    if seed is None:
        return [None] * num_envs
    if is_int(seed):
        return [int(seed) + i for i in range(num_envs)]
    if isinstance(seed, (list, tuple, np.ndarray)):
        seeds = list(seed)
        if len(seeds) != num_envs:
            raise ValueError(
                f"seed list has length {len(seeds)}; expected num_envs={num_envs} seeds"
            )
        return [None if s is None else int(s) for s in seeds]
    raise TypeError(f"seed={seed!r}: expected None, an int, or a list of {num_envs} ints")


def restart_seed(root: int, env_index: int, restart_count: int) -> int:
    """A fresh, deterministic seed for env ``env_index`` after its ``restart_count``-th restart.

    Derived from (root, env index, restart count) with NumPy's SeedSequence, so
    it never replays the stream the env had before the restart.
    """
    sequence = np.random.SeedSequence([root, env_index, restart_count, 0x5EED])
    return int(sequence.generate_state(1, dtype=np.uint32)[0])
