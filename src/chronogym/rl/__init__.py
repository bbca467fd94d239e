"""Reinforcement learning with RSL-RL on chronogym vector envs (``pip install 'chronogym[rl]'``).

Public names are imported lazily: ``import chronogym.rl`` imports neither torch nor rsl_rl.

A training iteration, stage by stage (``Runner.learn`` in ``trainer.py``, which
:func:`train` runs):

1. collect a rollout and compute its returns (``trainer.py``), stepping the vector env through
   the RSL-RL ``VecEnv`` adapter (``vecenv.py``);
2. update the policy with RSL-RL's PPO (``trainer.py``); with ``policy_lag=1`` the update of
   one rollout overlaps the collection of the next instead (``overlap.py``);
3. every ``save_interval`` iterations, save a checkpoint (``trainer.py``) and score it for
   ``best.pt`` (``best.py``);
4. log: RSL-RL's logger and a ``progress.csv`` row (``progress.py``).

``rsl.py`` is the one place that reaches into RSL-RL's runner, logger and PPO object;
``checkpoint.py`` reads checkpoints back (``load_policy``); ``config.py`` holds the PPO config.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

from chronogym._lazy import lazy_exports

_EXPORTS = {
    "RslRlVecEnv": "chronogym.rl.vecenv",
    "ppo_train_config": "chronogym.rl.config",
    "FINETUNE_PPO": "chronogym.rl.config",
    "train": "chronogym.rl.trainer",
    "TrainResult": "chronogym.rl.trainer",
    "load_policy": "chronogym.rl.checkpoint",
    "make_quadruped_vec_env": "chronogym.tasks.quadruped.training",
    "train_quadruped": "chronogym.tasks.quadruped.training",
    "play_quadruped": "chronogym.tasks.quadruped.play",
    "quadruped_train_config": "chronogym.tasks.quadruped.training",
    "evaluate": "chronogym.tasks.quadruped.evaluation",
    "VideoRecorder": "chronogym.video",
    "WalkingCriterion": "chronogym.tasks.quadruped.walking",
    "WalkingCriterionV1": "chronogym.tasks.quadruped.walking",
    "WalkingVerdict": "chronogym.tasks.quadruped.walking",
    "WalkingEvaluator": "chronogym.tasks.quadruped.evaluation",
    "BestCheckpoint": "chronogym.rl.best",
}

__all__ = [
    "FINETUNE_PPO",
    "BestCheckpoint",
    "RslRlVecEnv",
    "TrainResult",
    "VideoRecorder",
    "WalkingCriterion",
    "WalkingCriterionV1",
    "WalkingEvaluator",
    "WalkingVerdict",
    "evaluate",
    "load_policy",
    "make_quadruped_vec_env",
    "play_quadruped",
    "ppo_train_config",
    "quadruped_train_config",
    "train",
    "train_quadruped",
]

if TYPE_CHECKING:
    from chronogym.rl.best import BestCheckpoint
    from chronogym.rl.checkpoint import load_policy
    from chronogym.rl.config import FINETUNE_PPO, ppo_train_config
    from chronogym.rl.trainer import TrainResult, train
    from chronogym.rl.vecenv import RslRlVecEnv
    from chronogym.tasks.quadruped.evaluation import WalkingEvaluator, evaluate
    from chronogym.tasks.quadruped.play import play_quadruped
    from chronogym.tasks.quadruped.training import (
        make_quadruped_vec_env,
        quadruped_train_config,
        train_quadruped,
    )
    from chronogym.tasks.quadruped.walking import (
        WalkingCriterion,
        WalkingCriterionV1,
        WalkingVerdict,
    )
    from chronogym.video import VideoRecorder


__getattr__, __dir__ = lazy_exports(__name__, _EXPORTS, globals())
