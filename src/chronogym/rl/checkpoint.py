"""Checkpoints of :func:`~chronogym.rl.train`: read without unpickling, and a policy from one."""

from __future__ import annotations

from collections.abc import Callable
from pathlib import Path
from typing import Any

import numpy as np

from chronogym.rl.config import ppo_train_config


def read_checkpoint(path: str | Path, name: str) -> dict[str, Any]:
    """A checkpoint's dict, read with ``weights_only=True``: never unpickles objects.

    ``name`` is the argument that gave ``path``; a file that is not a checkpoint raises a
    ValueError naming both.
    """
    import torch

    try:
        saved = torch.load(str(path), map_location="cpu", weights_only=True)
    except Exception as error:  # an arbitrary pickle, or not a checkpoint at all
        first_line = (str(error).splitlines() or [""])[0][:200]
        raise ValueError(
            f"{name}={str(path)!r}: expected a chronogym/RSL-RL checkpoint of tensors and plain "
            f"data ({type(error).__name__}: {first_line})"
        ) from error
    if not isinstance(saved, dict):
        raise ValueError(
            f"{name}={str(path)!r}: expected a checkpoint dict, got {type(saved).__name__}"
        )
    return saved


def load_policy(
    checkpoint: str | Path,
    obs_dim: int | None = None,
    num_actions: int | None = None,
    *,
    train_cfg: dict[str, Any] | None = None,
    clip_actions: bool = True,
    torch_threads: int | None = 1,
) -> Callable[[np.ndarray], np.ndarray]:
    """The deterministic policy (action mean) of a training checkpoint, on NumPy arrays.

    The returned callable maps observations ``(obs_dim,)`` or ``(n, obs_dim)`` to float32
    actions ``(num_actions,)`` or ``(n, num_actions)``, clipped to the action bounds the
    policy was trained with (``clip_actions``). No vector env is needed: the actor is
    rebuilt from the checkpoint's stored config (else ``train_cfg``, else the default
    config); ``obs_dim`` / ``num_actions`` default to the dimensions stored in it and,
    when given, are checked against them.
    """
    import torch
    from rsl_rl.utils import resolve_class
    from tensordict import TensorDict

    if torch_threads is not None:
        torch.set_num_threads(torch_threads)
    saved = read_checkpoint(checkpoint, "checkpoint")  # no unpickling
    infos = saved.get("infos") or {}
    cfg = train_cfg or infos.get("train_cfg") or ppo_train_config()
    if "actor_state_dict" not in saved:
        raise ValueError(
            f"checkpoint={str(checkpoint)!r}: expected a checkpoint with 'actor_state_dict' "
            f"(keys: {sorted(map(str, saved))[:8]})"
        )
    state = saved["actor_state_dict"]
    stored_obs, stored_act = infos.get("observation_dim"), infos.get("num_actions")
    for name, given, stored in (
        ("obs_dim", obs_dim, stored_obs),
        ("num_actions", num_actions, stored_act),
    ):
        if given is not None and stored is not None and int(given) != int(stored):
            raise ValueError(
                f"load_policy: {name}={given} but {checkpoint} was trained with {name}={stored}"
            )
    obs_dim = obs_dim if obs_dim is not None else stored_obs
    num_actions = num_actions if num_actions is not None else stored_act
    if obs_dim is None or num_actions is None:
        raise ValueError(f"load_policy: pass obs_dim and num_actions for {checkpoint}")
    obs_dim, num_actions = int(obs_dim), int(num_actions)
    actor_class, actor_cfg = resolve_class(cfg["actor"])
    groups = list(cfg.get("obs_groups", {}).get("actor", ["policy"]))
    if len(groups) != 1:
        raise ValueError(f"load_policy: expected one actor observation group, got {groups}")
    dummy = TensorDict({groups[0]: torch.zeros(1, obs_dim)}, batch_size=[1])
    actor = actor_class(dummy, {"actor": groups}, "actor", num_actions, **actor_cfg)
    actor.load_state_dict(state)
    actor.eval()
    low = high = None
    if clip_actions and "action_low" in infos:
        low = np.asarray(infos["action_low"], dtype=np.float32).reshape(-1)
        high = np.asarray(infos["action_high"], dtype=np.float32).reshape(-1)

    def policy(obs: np.ndarray) -> np.ndarray:
        array = np.asarray(obs, dtype=np.float32)
        single = array.ndim == 1
        batch = torch.as_tensor(array.reshape(1 if single else array.shape[0], -1))
        with torch.inference_mode():
            actions = actor(TensorDict({groups[0]: batch}, batch_size=[batch.shape[0]]))
        result = actions.numpy().astype(np.float32)
        if low is not None:
            result = np.clip(result, low, high)
        return result[0] if single else result

    return policy
