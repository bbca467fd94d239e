"""RslRlVecEnv: a Gymnasium vector env (Box spaces, SAME_STEP autoreset) as an RSL-RL VecEnv."""

from __future__ import annotations

import math
from typing import Any

import numpy as np
import torch
from gymnasium import spaces
from gymnasium.vector import AutoresetMode, VectorEnv
from rsl_rl.env import VecEnv
from tensordict import TensorDict

from chronogym.validation import check_int, is_int


class RslRlVecEnv(VecEnv):
    """Wrap a ``gymnasium.vector.VectorEnv`` (chronogym's RayVectorEnv / SerialVectorEnv, or
    Gymnasium's own) for RSL-RL's ``OnPolicyRunner``.

    The vector env must have Box observation and action spaces and use
    ``AutoresetMode.SAME_STEP`` (the observation returned for an env that just ended
    is already the first one of its next episode, as RSL-RL assumes). Observations are
    flattened to ``(num_envs, obs_dim)`` float32 and returned as the TensorDict groups
    ``"policy"`` and ``"critic"`` (the critic group comes from a per-env
    ``info["critic_obs"]`` when the env provides one, else it repeats the policy group).

    ``step`` returns ``dones = terminated | truncated`` (long) and ``extras`` with
    ``"time_outs"`` (truncated and not terminated, bool, for value bootstrapping) and,
    on steps where episodes ended, ``"log"``: each key of the tasks' ``info["log"]``
    mapped to a 1-D float tensor of the values of the envs that reported it.

    ``episode_length_buf`` counts each env's steps in its current episode and is set to 0
    when the episode ends. It is writable, as RSL-RL's ``VecEnv`` requires, but the count is
    the adapter's: writing it (``OnPolicyRunner.learn(init_at_random_ep_len=True)``) does not
    move the envs' own time limits, so episodes are not desynchronized that way.

    Args:
        vec_env: the vector env; the adapter resets it (with ``seed``) and closes it on
            :meth:`close`.
        device: torch device of the returned tensors.
        clip_actions: clip actions to the action space's bounds before stepping.
        max_episode_length: episode horizon in steps; default: read from the envs
            (their ``TimeLimit`` spec and chronogym's ``SimEnv.max_episode_steps``).
        seed: seed of the first ``reset``.
    """

    def __init__(
        self,
        vec_env: VectorEnv,
        *,
        device: str | torch.device = "cpu",
        clip_actions: bool = True,
        max_episode_length: int | None = None,
        seed: int | list[int] | None = None,
    ) -> None:
        mode = vec_env.metadata.get("autoreset_mode")
        if mode is None or AutoresetMode(mode) != AutoresetMode.SAME_STEP:
            raise ValueError(
                f"RslRlVecEnv needs a vector env with autoreset_mode=AutoresetMode.SAME_STEP; "
                f"got autoreset_mode={mode!r} (create it with "
                "make_vec(..., autoreset_mode=gymnasium.vector.AutoresetMode.SAME_STEP))"
            )
        obs_space = vec_env.single_observation_space
        act_space = vec_env.single_action_space
        if not isinstance(obs_space, spaces.Box) or not isinstance(act_space, spaces.Box):
            raise TypeError(
                f"RslRlVecEnv needs Box observation and action spaces; got {obs_space} and "
                f"{act_space}"
            )
        self.vec_env = vec_env
        self.device = torch.device(device)
        self.clip_actions = clip_actions
        self.num_envs = int(vec_env.num_envs)
        self.action_shape = tuple(act_space.shape)
        self.num_actions = math.prod(self.action_shape)
        self.num_obs = math.prod(obs_space.shape)
        self._action_dtype = act_space.dtype
        self._low = np.broadcast_to(act_space.low, self.action_shape).astype(np.float32)
        self._high = np.broadcast_to(act_space.high, self.action_shape).astype(np.float32)
        env_id = _env_id(vec_env)
        if max_episode_length is None:
            max_episode_length = _read_horizon(vec_env)
            if max_episode_length is None:
                raise ValueError(
                    f"RslRlVecEnv could not find the episode horizon of {env_id or vec_env}; "
                    "pass max_episode_length=... (or give the envs a max_episode_steps)"
                )
        self.max_episode_length = check_int("max_episode_length", max_episode_length, low=1)
        self.episode_length_buf = torch.zeros(self.num_envs, dtype=torch.long, device=self.device)
        self.episodes_done = 0  # episodes finished (terminated or truncated) so far
        self.cfg: dict[str, Any] = {
            "id": env_id,
            "num_envs": self.num_envs,
            "backend": type(vec_env).__name__,
            "max_episode_length": self.max_episode_length,
            "observation_shape": tuple(obs_space.shape),
            "action_shape": self.action_shape,
            "action_low": self._low.tolist(),
            "action_high": self._high.tolist(),
        }
        obs, infos = vec_env.reset(seed=seed)
        self._obs = self._flatten(obs)
        self._critic: np.ndarray | None = None
        self._update_critic(infos)

    # -- observations ------------------------------------------------------------------
    def _flatten(self, obs: np.ndarray) -> np.ndarray:
        return np.array(obs, dtype=np.float32).reshape(self.num_envs, -1)

    def _update_critic(self, infos: dict[str, Any]) -> None:
        if "critic_obs" not in infos:
            return
        values, mask = infos["critic_obs"], infos.get("_critic_obs")
        rows = np.ones(self.num_envs, dtype=bool) if mask is None else np.asarray(mask, bool)
        if self._critic is None:
            if not rows.all():
                return  # start the critic group only once every env provides it
            self._critic = np.zeros((self.num_envs, np.asarray(values[0]).size), np.float32)
        for i in np.flatnonzero(rows):
            self._critic[i] = np.asarray(values[i], dtype=np.float32).reshape(-1)

    def _tensor(self, array: np.ndarray) -> torch.Tensor:
        return torch.tensor(array, dtype=torch.float32, device=self.device)  # always a copy

    def get_observations(self) -> TensorDict:
        """The current observations as ``{"policy", "critic"}`` (fresh tensors every call)."""
        critic = self._obs if self._critic is None else self._critic
        return TensorDict(
            {"policy": self._tensor(self._obs), "critic": self._tensor(critic)},
            batch_size=[self.num_envs],
            device=self.device,
        )

    # -- stepping ----------------------------------------------------------------------
    def step(self, actions: torch.Tensor) -> tuple[TensorDict, torch.Tensor, torch.Tensor, dict]:
        array = actions.detach().to("cpu", torch.float32).numpy()
        array = array.reshape(self.num_envs, *self.action_shape)
        if self.clip_actions:
            array = np.clip(array, self._low, self._high)
        array = np.ascontiguousarray(array, dtype=self._action_dtype)
        obs, rewards, terminated, truncated, infos = self.vec_env.step(array)
        self._obs = self._flatten(obs)
        self._update_critic(infos)
        terminated = np.asarray(terminated, dtype=bool)
        truncated = np.asarray(truncated, dtype=bool)
        done = terminated | truncated
        dones = torch.tensor(done, dtype=torch.long, device=self.device)
        self.episode_length_buf += 1
        self.episode_length_buf[dones.bool()] = 0
        self.episodes_done += int(done.sum())
        extras: dict[str, Any] = {
            "time_outs": torch.tensor(truncated & ~terminated, device=self.device)
        }
        log = self._episode_log(infos)
        if log:
            extras["log"] = log
        rewards_t = torch.tensor(np.asarray(rewards), dtype=torch.float32, device=self.device)
        return self.get_observations(), rewards_t, dones, extras

    def _episode_log(self, infos: dict[str, Any]) -> dict[str, torch.Tensor]:
        """The ``info["log"]`` entries of the envs that reported one, one tensor per key.

        With SAME_STEP autoreset the last step's info of an env that ended sits in
        ``infos["final_info"]``; a log in the top-level info is collected too.
        """
        found: dict[str, list[np.ndarray]] = {}
        final = infos.get("final_info")
        for source in (infos, final if isinstance(final, dict) else {}):
            log = source.get("log")
            if not isinstance(log, dict):
                continue
            for key, values in log.items():
                if key.startswith("_") and key[1:] in log:
                    continue  # a Gymnasium mask
                mask = log.get(f"_{key}")
                values = np.asarray(values)
                picked = values if mask is None else values[np.asarray(mask, dtype=bool)]
                if picked.size:
                    found.setdefault(key, []).append(picked.astype(np.float32).reshape(-1))
        return {key: self._tensor(np.concatenate(parts)) for key, parts in found.items()}

    def close(self) -> None:
        """Close the wrapped vector env."""
        self.vec_env.close()


def _env_id(vec_env: VectorEnv) -> str | None:
    spec = getattr(vec_env, "spec", None)
    if spec is not None and getattr(spec, "id", None):
        return spec.id
    fns = getattr(vec_env, "_env_fns", None)  # chronogym's WorkerVectorEnv
    if fns and isinstance(fns[0], str):
        return fns[0]
    try:
        specs = vec_env.get_attr("spec")
        return specs[0].id if specs and specs[0] is not None else None
    except Exception:
        return None


def _read_horizon(vec_env: VectorEnv) -> int | None:
    """The shortest horizon among the envs' TimeLimit spec and SimEnv's max_episode_steps."""
    candidates: list[int] = []
    for name in ("spec", "max_episode_steps"):
        try:
            values = vec_env.get_attr(name)
        except Exception:
            continue
        for value in values:
            steps = getattr(value, "max_episode_steps", None) if name == "spec" else value
            if is_int(steps) and steps > 0:
                candidates.append(int(steps))
    return min(candidates) if candidates else None
