"""Step an SB3 VecEnv next to SB3's own DummyVecEnv and assert the same numbers."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

import numpy as np


def assert_same_obs(a: Any, b: Any) -> None:
    if isinstance(b, dict):
        assert isinstance(a, dict) and list(a) == list(b)
        for key in b:
            np.testing.assert_array_equal(a[key], b[key])
            assert np.asarray(a[key]).dtype == np.asarray(b[key]).dtype, key
    elif isinstance(b, tuple):
        assert isinstance(a, tuple) and len(a) == len(b)
        for x, y in zip(a, b, strict=True):
            np.testing.assert_array_equal(x, y)
            assert np.asarray(x).dtype == np.asarray(y).dtype
    else:
        np.testing.assert_array_equal(a, b)
        assert np.asarray(a).dtype == np.asarray(b).dtype


def assert_same_info(a: dict, b: dict, clock_keys: frozenset[str] = frozenset()) -> None:
    """Equal infos; keys in ``clock_keys`` (wall-clock times) need only be in both."""
    assert set(a) == set(b), (a, b)
    for key, value in b.items():
        if key == "terminal_observation":
            assert_same_obs(a[key], value)
        elif isinstance(value, dict):
            assert_same_info(a[key], value, clock_keys)
        elif key in clock_keys:
            continue
        else:
            assert a[key] == value, (key, a[key], value)


def compare_with_dummy(
    venv: Any,
    ref: Any,
    actions: Sequence[Any],
    seed: int,
    clock_keys: frozenset[str] = frozenset(),
) -> dict:
    """Step both with the same seeds and actions; return counts of the episode ends seen.

    ``clock_keys``: info keys holding wall-clock times (SB3's Monitor: ``"t"``).
    """
    assert venv.seed(seed) == ref.seed(seed) == [seed + i for i in range(ref.num_envs)]
    assert_same_obs(venv.reset(), ref.reset())
    assert venv.reset_infos == ref.reset_infos
    ends = {"terminated": 0, "truncated": 0}
    for a in actions:
        obs, rewards, dones, infos = venv.step(a)
        obs_ref, rewards_ref, dones_ref, infos_ref = ref.step(a)
        assert_same_obs(obs, obs_ref)
        np.testing.assert_array_equal(rewards, rewards_ref)
        assert rewards.dtype == rewards_ref.dtype
        np.testing.assert_array_equal(dones, dones_ref)
        assert dones.dtype == np.bool_
        assert len(infos) == len(infos_ref)
        for info, info_ref in zip(infos, infos_ref, strict=True):
            assert_same_info(info, info_ref, clock_keys)
        for i in np.flatnonzero(dones):
            ends["truncated" if infos[i]["TimeLimit.truncated"] else "terminated"] += 1
        assert_same_info({"r": venv.reset_infos}, {"r": list(ref.reset_infos)})
    # seeds are used once: a second reset continues each env's stream
    assert_same_obs(venv.reset(), ref.reset())
    return ends
