"""PPO training configuration for RSL-RL 5.x's ``OnPolicyRunner`` (legged_gym defaults)."""

from __future__ import annotations

import copy
from typing import Any

#: Conservative PPO settings for fine-tuning a trained policy (merge into ``"algorithm"``).
FINETUNE_PPO: dict[str, float] = dict(
    learning_rate=1e-5, clip_param=0.02, desired_kl=0.001, max_grad_norm=0.5
)

_HIDDEN_DIMS = [512, 256, 128]

_DEFAULTS: dict[str, Any] = {
    "num_steps_per_env": 24,
    "save_interval": 50,
    "check_for_nan": True,
    "logger": "tensorboard",
    "run_name": "",
    "torch_compile_mode": None,
    # Observation groups of RslRlVecEnv ("policy", "critic") feeding each model.
    "obs_groups": {"actor": ["policy"], "critic": ["critic"]},
    "actor": {
        "class_name": "MLPModel",
        "hidden_dims": _HIDDEN_DIMS,
        "activation": "elu",
        "obs_normalization": True,
        "distribution_cfg": {"class_name": "GaussianDistribution", "init_std": 1.0},
    },
    "critic": {
        "class_name": "MLPModel",
        "hidden_dims": _HIDDEN_DIMS,
        "activation": "elu",
        "obs_normalization": True,
    },
    "algorithm": {
        "class_name": "PPO",
        "learning_rate": 1e-3,
        "schedule": "adaptive",
        "desired_kl": 0.01,
        "clip_param": 0.2,
        "entropy_coef": 0.01,
        "num_learning_epochs": 5,
        "num_mini_batches": 4,
        "gamma": 0.99,
        "lam": 0.95,
        "value_loss_coef": 1.0,
        "use_clipped_value_loss": True,
        "max_grad_norm": 1.0,
    },
}


def _merge(base: dict[str, Any], overrides: dict[str, Any]) -> dict[str, Any]:
    for key, value in overrides.items():
        if isinstance(value, dict) and isinstance(base.get(key), dict):
            _merge(base[key], value)
        else:
            base[key] = copy.deepcopy(value)
    return base


def ppo_train_config(**overrides: Any) -> dict[str, Any]:
    """A fresh RSL-RL ``OnPolicyRunner`` config; nested dicts in ``overrides`` are deep-merged.

    Example: ``ppo_train_config(num_steps_per_env=8, algorithm=FINETUNE_PPO,
    actor={"hidden_dims": [32, 32]})``. Unknown top-level keys raise ValueError.
    """
    unknown = [key for key in overrides if key not in _DEFAULTS]
    if unknown:
        raise ValueError(
            f"ppo_train_config: unknown key {unknown[0]!r}; expected one of {sorted(_DEFAULTS)}"
        )
    return _merge(copy.deepcopy(_DEFAULTS), overrides)
