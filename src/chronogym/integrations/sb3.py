"""Stable-Baselines3: a chronogym vector env (or any Gymnasium one) as an SB3 ``VecEnv``.

:class:`SB3VecEnv` wraps a ``gymnasium.vector.VectorEnv`` whose ``autoreset_mode`` is
``SAME_STEP`` (``RayVectorEnv``, ``SerialVectorEnv``, Gymnasium's own) and speaks SB3's
``VecEnv`` API, with the numbers of SB3's ``DummyVecEnv`` on the same envs:
``dones = terminated | truncated``; an env that ended is reset within the step, and its
info holds ``"terminal_observation"`` (the episode's last observation) and its reset info
goes to ``reset_infos``; ``info["TimeLimit.truncated"] = truncated and not terminated``;
infos are one dict per env; rewards are float32. :func:`make_sb3_vec_env` builds one.

Requires Stable-Baselines3: ``pip install "chronogym[sb3]"``.
"""

from __future__ import annotations

import functools
import re
import warnings
from collections.abc import Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium import spaces
from gymnasium.vector import AutoresetMode

try:
    from stable_baselines3.common.preprocessing import check_for_nested_spaces
    from stable_baselines3.common.vec_env.base_vec_env import (
        VecEnv,
        VecEnvIndices,
        VecEnvObs,
        VecEnvStepReturn,
    )
except ImportError as error:  # pragma: no cover - exercised in a subprocess by the tests
    raise ImportError(
        "chronogym.integrations.sb3 needs Stable-Baselines3, which could not be imported "
        f'({error}); install it with: pip install "chronogym[sb3]"'
    ) from error

import chronogym
from chronogym.integrations._indexed import HOOK, INDEX_ATTR, make_indexed_env

__all__ = ["BACKENDS", "SB3VecEnv", "make_sb3_vec_env"]

BACKENDS = ("ray", "serial", "sync", "async")

# chronogym reports a replaced worker in the top-level info, next to the reset info;
# SB3 reads a step's info, so these are copied there too.
_RESTART_KEYS = ("worker_restarted", "worker_error")


def _autoreset_mode(vector_env: Any) -> Any:
    """The vector env's autoreset mode as it gives it (attribute, else ``metadata``)."""
    mode = getattr(vector_env, "autoreset_mode", None)
    if mode is None:
        mode = (getattr(vector_env, "metadata", None) or {}).get("autoreset_mode")
    return mode


def _is_same_step(mode: Any) -> bool:
    try:
        return mode is not None and AutoresetMode(mode) == AutoresetMode.SAME_STEP
    except ValueError:
        return False


class SB3VecEnv(VecEnv):
    """A Gymnasium vector env with ``AutoresetMode.SAME_STEP`` as a Stable-Baselines3 VecEnv.

    Args:
        vector_env: the vector env (``num_envs``, ``single_observation_space`` and
            ``single_action_space`` are taken from it); :meth:`close` closes it.

    ``reset()`` uses (once) the seeds of :meth:`seed` (env i gets ``seed + i``) and the
    options of :meth:`set_options`, which must be the same for every env (a Gymnasium
    vector env takes one options dict). ``step_async`` keeps the actions and
    ``step_wait`` runs one ``step`` of the vector env.

    ``get_attr``, ``set_attr``, ``env_method`` and ``env_is_wrapped`` with ``indices``
    act on those envs only when the envs were built by :func:`make_sb3_vec_env` (each
    knows its index). With any other vector env: ``get_attr`` reads every env and picks;
    ``set_attr`` reads the attribute of every env and writes it back unchanged to the
    others (with Ray: an equal copy); ``env_method`` runs on every env and returns the
    chosen results (a warning says so once per method name); ``env_is_wrapped`` matches
    the wrapper classes' names in each env's ``str()`` (``<Monitor<TimeLimit<...>>>``).
    """

    def __init__(self, vector_env: gym.vector.VectorEnv) -> None:
        mode = _autoreset_mode(vector_env)
        if not _is_same_step(mode):
            raise ValueError(
                f"SB3VecEnv needs a vector env with autoreset_mode=AutoresetMode.SAME_STEP "
                f"(SB3 resets an env in the step that ends it); got autoreset_mode={mode!r}. "
                "Create it with autoreset_mode=gymnasium.vector.AutoresetMode.SAME_STEP, or "
                "use chronogym.integrations.sb3.make_sb3_vec_env(env_id, num_envs)"
            )
        observation_space = vector_env.single_observation_space
        check_for_nested_spaces(observation_space)
        self.vector_env = vector_env
        n = int(vector_env.num_envs)
        # Envs that know their index (make_sb3_vec_env) let indices= reach only those envs.
        # Probed without raising: an error in a call shuts down AsyncVectorEnv's workers.
        self._indexed = all(vector_env.call("has_wrapper_attr", INDEX_ATTR)) and list(
            vector_env.get_attr(INDEX_ATTR)
        ) == list(range(n))
        self._actions: Any = None
        self._warned: set[str] = set()
        super().__init__(n, observation_space, vector_env.single_action_space)

    # -- stepping ----------------------------------------------------------------------
    def reset(self) -> VecEnvObs:
        """Reset every env (with the pending seeds and options, then forget them)."""
        seed = None if all(s is None for s in self._seeds) else list(self._seeds)
        obs, info = self.vector_env.reset(seed=seed, options=self._common_options())
        self.reset_infos = split_info(info, self.num_envs)
        self._reset_seeds()
        self._reset_options()
        self._actions = None
        return self._sb3_obs(obs)

    def step_async(self, actions: np.ndarray) -> None:
        """Keep ``actions`` (one row per env) for the next :meth:`step_wait`."""
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        """Step every env: ``(obs, rewards, dones, infos)`` in SB3's format."""
        if self._actions is None:
            raise RuntimeError("step_wait() without step_async(actions) first")
        actions, self._actions = self._actions, None
        obs, rewards, terminated, truncated, info = self.vector_env.step(actions)
        terminated = np.asarray(terminated, dtype=bool)
        truncated = np.asarray(truncated, dtype=bool)
        dones = terminated | truncated
        infos = split_info(info, self.num_envs)
        for i in np.flatnonzero(dones):
            infos[i] = self._ended(int(i), infos[i])
        for i, env_info in enumerate(infos):
            env_info["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
        return self._sb3_obs(obs), np.asarray(rewards, dtype=np.float32), dones, infos

    def _ended(self, i: int, top: dict[str, Any]) -> dict[str, Any]:
        """The step info of env ``i`` that just ended; its reset info goes to reset_infos."""
        if "final_obs" not in top:
            raise RuntimeError(
                f"env {i} ended but its info has no 'final_obs': the vector env does not "
                "autoreset with AutoresetMode.SAME_STEP semantics"
            )
        final_obs = top.pop("final_obs")
        step_info = dict(top.pop("final_info", None) or {})
        for key in _RESTART_KEYS:
            if key in top:
                step_info[key] = top[key]
        self.reset_infos[i] = top
        step_info["terminal_observation"] = final_obs
        return step_info

    def _sb3_obs(self, obs: Any) -> VecEnvObs:
        """SB3's layout, copied (as DummyVecEnv does: a vector env may reuse its buffers)."""
        space = self.observation_space
        if isinstance(space, spaces.Dict):
            return {key: np.array(obs[key]) for key in space.spaces}
        if isinstance(space, spaces.Tuple):
            return tuple(np.array(part) for part in obs)
        return np.array(obs)

    def _common_options(self) -> dict[str, Any] | None:
        """The one options dict of ``set_options`` for every env (None: no options)."""
        first = self._options[0]
        for i, options in enumerate(self._options):
            if options is not first and not _equal(options, first):
                raise ValueError(
                    f"set_options gave env {i} options={options!r} but env 0 options={first!r}; "
                    "a Gymnasium vector env takes one options dict for every env: pass a "
                    "single dict to set_options"
                )
        return first or None

    # -- attributes and methods --------------------------------------------------------
    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The attribute of each env in ``indices`` (default: all), in that order."""
        chosen = self._indices(indices)
        if self._is_all(chosen):
            return list(self.vector_env.get_attr(attr_name))
        if self._indexed:
            return self._pick(self.vector_env.call(HOOK, "get", chosen, attr_name), chosen)
        return self._pick(self.vector_env.get_attr(attr_name), chosen)

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set the attribute to ``value`` on each env in ``indices`` (default: all)."""
        chosen = self._indices(indices)
        if self._is_all(chosen):
            self.vector_env.set_attr(attr_name, [value] * self.num_envs)
        elif self._indexed:
            self.vector_env.call(HOOK, "set", chosen, attr_name, value)
        else:
            try:
                values = list(self.vector_env.get_attr(attr_name))
            except AttributeError as error:
                raise AttributeError(
                    f"set_attr({attr_name!r}, indices={chosen}): this vector env sets some envs "
                    f"only by writing the others' current {attr_name!r} back, and not every env "
                    "has it; build the vector env with make_sb3_vec_env to set only those envs"
                ) from error
            for i in chosen:
                values[i] = value
            self.vector_env.set_attr(attr_name, values)

    def env_method(
        self,
        method_name: str,
        *method_args: Any,
        indices: VecEnvIndices = None,
        **method_kwargs: Any,
    ) -> list[Any]:
        """Call the method on each env in ``indices`` (default: all); results in that order."""
        chosen = self._indices(indices)
        if self._is_all(chosen):
            return list(self.vector_env.call(method_name, *method_args, **method_kwargs))
        if self._indexed:
            results = self.vector_env.call(
                HOOK, "call", chosen, method_name, method_args, method_kwargs
            )
            return self._pick(results, chosen)
        if method_name not in self._warned:
            self._warned.add(method_name)
            warnings.warn(
                f"env_method({method_name!r}, indices={chosen}) ran on all {self.num_envs} "
                "envs (this vector env cannot call some envs only); build it with "
                "make_sb3_vec_env for per-env calls",
                stacklevel=2,
            )
        return self._pick(self.vector_env.call(method_name, *method_args, **method_kwargs), chosen)

    def env_is_wrapped(
        self, wrapper_class: type[gym.Wrapper], indices: VecEnvIndices = None
    ) -> list[bool]:
        """Whether each env in ``indices`` (default: all) is wrapped in ``wrapper_class``."""
        chosen = self._indices(indices)
        if self._indexed:
            results = self.vector_env.call(
                HOOK, "is_wrapped", list(range(self.num_envs)), wrapper_class
            )
            return [bool(r) for r in self._pick(results, chosen)]
        names = {cls.__name__ for cls in _subclasses(wrapper_class)}
        texts = self._pick(self.vector_env.call("__str__"), chosen)
        return [bool(names & set(re.findall(r"<([A-Za-z_]\w*)", text))) for text in texts]

    def _indices(self, indices: VecEnvIndices) -> list[int]:
        """``indices`` as a list of distinct env indices, checked."""
        n = self.num_envs
        if indices is None:
            return list(range(n))
        items = [indices] if isinstance(indices, (int, np.integer)) else indices
        try:
            chosen = list(items)  # type: ignore[arg-type]
        except TypeError:
            chosen = None
        bad = chosen is None or any(
            isinstance(i, (bool, np.bool_))
            or not isinstance(i, (int, np.integer))
            or not 0 <= i < n
            for i in chosen
        )
        if bad or len(set(chosen)) != len(chosen):  # type: ignore[arg-type]
            raise ValueError(
                f"indices={indices!r}: expected None, an env index or a sequence of distinct env "
                f"indices, each an integer with 0 <= index < num_envs={n}"
            )
        return [int(i) for i in chosen]  # type: ignore[union-attr]

    def _is_all(self, chosen: list[int]) -> bool:
        return chosen == list(range(self.num_envs))

    @staticmethod
    def _pick(values: Sequence[Any], chosen: list[int]) -> list[Any]:
        return [values[i] for i in chosen]

    # -- rendering and closing ---------------------------------------------------------
    def get_images(self) -> Sequence[np.ndarray | None]:
        """One RGB frame per env (``render_mode="rgb_array"``), else a warning and Nones."""
        if self.render_mode != "rgb_array":
            warnings.warn(
                f"The render mode is {self.render_mode!r}; get_images() needs 'rgb_array'",
                stacklevel=2,
            )
            return [None] * self.num_envs
        return list(self.vector_env.render())

    def close(self) -> None:
        """Close the wrapped vector env."""
        self.vector_env.close()

    def __repr__(self) -> str:
        return f"SB3VecEnv({self.vector_env!r})"


def make_sb3_vec_env(
    env_id: str,
    num_envs: int,
    backend: str = "ray",
    *,
    env_kwargs: dict[str, Any] | None = None,
    seed: int | None = None,
    **vector_kwargs: Any,
) -> SB3VecEnv:
    """``num_envs`` copies of ``env_id`` in a vector env with SAME_STEP autoreset, for SB3.

    ``backend``: ``"ray"`` (:class:`chronogym.RayVectorEnv`), ``"serial"``
    (:class:`chronogym.SerialVectorEnv`), or Gymnasium's ``"sync"`` / ``"async"``.
    ``env_kwargs`` go to ``gymnasium.make``, other keyword arguments to the vector env.
    Each env knows its index, so ``indices=`` reaches only those envs. ``seed``: as
    SB3's ``make_vec_env``, the first ``reset()`` seeds env i with ``seed + i``.
    """
    if backend not in BACKENDS:
        raise ValueError(f"backend={backend!r}: expected one of {BACKENDS}")
    if isinstance(num_envs, bool) or not isinstance(num_envs, (int, np.integer)) or num_envs < 1:
        raise ValueError(f"num_envs={num_envs!r}: expected an integer >= 1")
    mode = vector_kwargs.pop("autoreset_mode", AutoresetMode.SAME_STEP)
    if not _is_same_step(mode):
        raise ValueError(
            f"autoreset_mode={mode!r}: make_sb3_vec_env needs AutoresetMode.SAME_STEP "
            "(SB3 resets an env in the step that ends it); leave autoreset_mode out"
        )
    env_fns = [functools.partial(make_indexed_env, env_id, i, env_kwargs) for i in range(num_envs)]
    mode = AutoresetMode.SAME_STEP
    if backend == "ray":
        vector_env: gym.vector.VectorEnv = chronogym.RayVectorEnv(
            env_fns, autoreset_mode=mode, **vector_kwargs
        )
    elif backend == "serial":
        vector_env = chronogym.SerialVectorEnv(env_fns, autoreset_mode=mode, **vector_kwargs)
    elif backend == "sync":
        vector_env = gym.vector.SyncVectorEnv(env_fns, autoreset_mode=mode, **vector_kwargs)
    else:
        vector_env = gym.vector.AsyncVectorEnv(env_fns, autoreset_mode=mode, **vector_kwargs)
    try:
        venv = SB3VecEnv(vector_env)
    except BaseException:
        vector_env.close()
        raise
    if seed is not None:
        venv.seed(seed)
    return venv


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


def _equal(a: Any, b: Any) -> bool:
    try:
        return bool(a == b)
    except Exception:  # e.g. arrays in the dicts: treat as different
        return False


def _subclasses(cls: type) -> list[type]:
    found = [cls]
    for sub in cls.__subclasses__():
        found.extend(_subclasses(sub))
    return found
