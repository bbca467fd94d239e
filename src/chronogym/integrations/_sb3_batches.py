"""Between Gymnasium's batches and Stable-Baselines3's layout: actions, observations, infos.

SB3 hands a vector env its actions as an array with one row per env, or (Dict and Tuple
action spaces) as one action per env; a Gymnasium vector env takes one batch
(``gymnasium.vector.utils``). Observations come back as SB3 stacks them, infos as one dict
per env. No SB3 import here.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.vector.utils import concatenate, create_empty_array

from chronogym.validation import show


def batch_actions(space: spaces.Space, actions: Any, num_envs: int) -> Any:
    """SB3's ``actions`` for ``num_envs`` envs as a Gymnasium batch of ``space``.

    An array (Box, Discrete, MultiDiscrete, MultiBinary) is already one: its rows are the
    envs' actions. Otherwise ``actions[i]`` is env i's action, as ``DummyVecEnv`` reads it
    (SB3's form for Dict and Tuple spaces: a list of dicts or tuples), and the actions are
    batched with ``gymnasium.vector.utils.concatenate``. A Dict space also takes a mapping
    of batched arrays (Gymnasium's own batch) as it is.
    """
    composite = isinstance(space, (spaces.Dict, spaces.Tuple))
    if isinstance(actions, np.ndarray) and not composite:
        return actions
    if isinstance(space, spaces.Dict) and isinstance(actions, Mapping):
        return actions
    expected = f"expected one action per env: a sequence of {num_envs} elements of {space}"
    if not composite:
        expected += f", or an array with {num_envs} rows"
    if isinstance(actions, (str, bytes, Mapping)) or not hasattr(actions, "__len__"):
        raise ValueError(f"actions={show(actions)}: {expected}")
    if len(actions) != num_envs:
        raise ValueError(f"actions={show(actions)} holds {len(actions)} actions; {expected}")
    try:
        items = [actions[i] for i in range(num_envs)]
        out = create_empty_array(space, num_envs, fn=np.zeros)
        return concatenate(space, items, out)
    except Exception as error:
        raise ValueError(f"actions={show(actions)}: {error!r}; {expected}") from None


def sb3_obs(space: spaces.Space, obs: Any) -> Any:
    """A Gymnasium observation batch in SB3's layout, copied (as DummyVecEnv does: a vector
    env may reuse its buffers)."""
    if isinstance(space, spaces.Dict):
        return {key: np.array(obs[key]) for key in space.spaces}
    if isinstance(space, spaces.Tuple):
        return tuple(np.array(part) for part in obs)
    return np.array(obs)


def split_info(info: dict[str, Any], num_envs: int) -> list[dict[str, Any]]:
    """Gymnasium's batched info dict (``key`` and ``_key`` mask) as one dict per env."""
    per_env: list[dict[str, Any]] = [{} for _ in range(num_envs)]
    for key, value in info.items():
        if isinstance(key, str) and key.startswith("_") and key[1:] in info:
            continue  # the mask of info[key[1:]]
        mask = info.get(f"_{key}")
        if isinstance(value, dict):
            parts = split_info(value, num_envs)
        elif mask is None and not _per_env(value, num_envs):
            parts = [value] * num_envs  # not batched: the same for every env
        else:
            parts = value
        for i in range(num_envs):
            if mask is None or mask[i]:
                per_env[i][key] = parts[i]
    return per_env


def _per_env(value: Any, num_envs: int) -> bool:
    return isinstance(value, np.ndarray) and value.ndim >= 1 and len(value) == num_envs
