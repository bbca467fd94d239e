"""Deprecated: the Go1's training and play moved next to its task, :mod:`chronogym.tasks.quadruped`.

``chronogym.rl.quadruped.NAME`` still works and warns; import from the new home instead:
:mod:`chronogym.tasks.quadruped.training` (defaults, vector envs, ``train_quadruped``),
:mod:`chronogym.tasks.quadruped.play` (``play_quadruped``) and
:mod:`chronogym.tasks.quadruped.engines` (engines, terrains and Gymnasium ids). The public
names stay importable from :mod:`chronogym.rl`.
"""

from __future__ import annotations

import importlib
import warnings
from typing import Any

_TRAINING = "chronogym.tasks.quadruped.training"
_PLAY = "chronogym.tasks.quadruped.play"
_ENGINES = "chronogym.tasks.quadruped.engines"

#: Each old name -> the module that holds it now.
_MOVED: dict[str, str] = {
    **dict.fromkeys(
        (
            "BACKENDS",
            "TRAINING_ONLY",
            "QUADRUPED_TASK",
            "QUADRUPED_PPO",
            "quadruped_train_config",
            "make_quadruped_vec_env",
            "train_quadruped",
            "training_task_kwargs",
            "critic_input_size",
            "walking_evaluator",
            "default_update_threads",
        ),
        _TRAINING,
    ),
    **dict.fromkeys(("play_quadruped", "play_randomization", "check_can_render"), _PLAY),
    **dict.fromkeys(
        ("ENV_ID", "ENV_IDS", "ENGINE_TERRAINS", "check_engine", "env_kwargs_for"), _ENGINES
    ),
}


def __getattr__(name: str) -> Any:
    if name == "TERRAINS":  # the MuJoCo Go1's terrains
        value: Any = importlib.import_module(_ENGINES).ENGINE_TERRAINS["mujoco"]
        new = f"{_ENGINES}.ENGINE_TERRAINS['mujoco']"
    elif name in _MOVED:
        value = getattr(importlib.import_module(_MOVED[name]), name)
        new = f"{_MOVED[name]}.{name}"
    else:
        raise AttributeError(f"module {__name__!r} has no attribute {name!r}")
    warnings.warn(f"{__name__}.{name} moved to {new}", DeprecationWarning, stacklevel=2)
    return value
