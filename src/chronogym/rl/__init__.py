"""Reinforcement learning with RSL-RL on chronogym vector envs (``pip install 'chronogym[rl]'``).

Public names are imported lazily: ``import chronogym.rl`` imports neither torch nor rsl_rl.
"""

from __future__ import annotations

import importlib
from typing import TYPE_CHECKING, Any

_EXPORTS = {
    "RslRlVecEnv": "chronogym.rl.vecenv",
    "ppo_train_config": "chronogym.rl.config",
    "FINETUNE_PPO": "chronogym.rl.config",
    "train": "chronogym.rl.trainer",
    "TrainResult": "chronogym.rl.trainer",
    "load_policy": "chronogym.rl.trainer",
}

__all__ = [
    "FINETUNE_PPO",
    "RslRlVecEnv",
    "TrainResult",
    "load_policy",
    "ppo_train_config",
    "train",
]

if TYPE_CHECKING:
    from chronogym.rl.config import FINETUNE_PPO, ppo_train_config
    from chronogym.rl.trainer import TrainResult, load_policy, train
    from chronogym.rl.vecenv import RslRlVecEnv


def __getattr__(name: str) -> Any:
    module = _EXPORTS.get(name)
    if module is None:
        raise AttributeError(f"module 'chronogym.rl' has no attribute {name!r}")
    value = getattr(importlib.import_module(module), name)
    globals()[name] = value
    return value


def __dir__() -> list[str]:
    return sorted(set(globals()) | set(_EXPORTS))
