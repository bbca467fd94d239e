"""EnvGroup: several environments stepped in one process with Gymnasium's autoreset rules.

The same class runs inside every Ray worker and inside SerialVectorEnv, so the
two give identical numbers. It mirrors ``gymnasium.vector.SyncVectorEnv`` step
for step and adds what ``env_errors`` asks of an env whose code raises
(:mod:`chronogym.vector.env_errors`): with ``"raise"`` (the default) the call
answers with an :class:`~chronogym.vector.env_errors.EnvRaised` that the driver
re-raises; with ``"restart"`` the env is rebuilt, reseeded with a fresh
deterministic seed, and reported as truncated with
``info["worker_restarted"] = True`` and the traceback in ``info["worker_error"]``.
"""

from __future__ import annotations

import contextlib
import functools
import os
import threading
import time
import traceback
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.envs.registration import EnvSpec
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import concatenate, create_empty_array

import chronogym  # noqa: F401  (registers the chronogym/... ids that resolve_env_id looks up)
from chronogym.errors import DisabledAutoresetError
from chronogym.seeding import restart_seed
from chronogym.vector.backend import EnvFactory, ResetAnswer, Restart, StepAnswer
from chronogym.vector.driver_registry import DriverRegistry, make_with_driver_ids
from chronogym.vector.env_errors import EnvRaised, check_env_errors, env_label
from chronogym.vector.infos import to_columns


def locked(method: Callable[..., Any]) -> Callable[..., Any]:
    """Run ``method`` holding the group's lock: Ray calls and a socket thread take turns."""

    @functools.wraps(method)
    def run(self: EnvGroup, *args: Any, **kwargs: Any) -> Any:
        with self._lock:
            self.check_built()
            return method(self, *args, **kwargs)

    return run


def resolve_env_id(env_id: str) -> EnvSpec:
    """The registered spec of ``env_id`` (entry point and keyword arguments), looked up here.

    Workers get the spec, not the id, so an env registered by the user's script
    (which the workers never run) is made the same way there. Raises Gymnasium's
    error for an unknown id at once, in the driver.
    """
    return gym.spec(env_id)


def build_env(
    env_fn: EnvFactory | EnvSpec | str,
    env_kwargs: dict[str, Any] | None = None,
    registry: DriverRegistry | None = None,
):
    """Create one env from a factory, a registered spec or an id. A factory that makes an id
    of the driver's script gets it from ``registry`` (:mod:`chronogym.vector.driver_registry`)."""
    if isinstance(env_fn, str):
        env_fn = resolve_env_id(env_fn)
    if not isinstance(env_fn, EnvSpec):
        return make_with_driver_ids(env_fn, registry)
    try:
        return gym.make(env_fn, **(env_kwargs or {}))
    except ModuleNotFoundError as error:
        raise ModuleNotFoundError(
            f"env {env_fn.id!r} needs module {error.name!r}, which this worker process "
            f"(pid {os.getpid()}) cannot import: {error}. Workers import an env's code by "
            "module name: make it importable on every worker (install it as a package, or "
            "put its folder on PYTHONPATH before Ray starts, or "
            "ray.init(runtime_env={'working_dir': ...})), or register the env with the "
            "class itself, defined in the script, instead of an import path",
            name=error.name,
        ) from error


class EnvGroup:
    """Environments ``indices`` of a vector env, owned by one process."""

    def __init__(
        self,
        env_fns: Sequence[EnvFactory | EnvSpec | str],
        indices: Sequence[int],
        autoreset_mode: AutoresetMode,
        seed_roots: Sequence[int],
        restart_counts: Sequence[int] | None = None,
        env_kwargs: dict[str, Any] | None = None,
        env_errors: str = "raise",
        registry: DriverRegistry | None = None,
    ) -> None:
        if len(env_fns) != len(indices):
            raise ValueError(f"{len(env_fns)} env factories for {len(indices)} env indices")
        self.env_fns = list(env_fns)
        self.env_kwargs = env_kwargs
        self.registry = registry
        self.indices = list(indices)
        self.autoreset_mode = AutoresetMode(autoreset_mode)
        self.env_errors = check_env_errors(env_errors)
        self.labels = [env_label(fn) for fn in self.env_fns]
        # an env that fails to build is reported by the first call (the actor stays alive, so
        # the driver gets the env's own exception rather than a dead worker)
        self.build_error: EnvRaised | None = None
        self.envs = []
        for j, fn in enumerate(self.env_fns):
            try:
                self.envs.append(build_env(fn, env_kwargs, registry))
            except Exception as error:
                self.build_error = EnvRaised.capture(error, self.indices[j], "make", self.labels[j])
                break
        n = len(self.env_fns)
        if self.build_error is None:
            self.single_observation_space = self.envs[0].observation_space
            self.single_action_space = self.envs[0].action_space
        self.seed_roots = list(seed_roots)
        self.restart_counts = list(restart_counts) if restart_counts else [0] * n
        self.pending_seeds: list[int | None] = [None] * n
        self.autoreset = np.zeros(n, dtype=np.bool_)
        self.last_obs: list[Any] = [None] * n
        self._lock = threading.RLock()  # see locked(): a socket thread may serve steps

    def check_built(self) -> None:
        """Raise the construction error of an env that failed to build."""
        if self.build_error is not None:
            raise self.build_error

    def raised(self, error: BaseException, j: int, method: str, crash_loop=False) -> EnvRaised:
        """Env ``j``'s ``error``, to send to the driver."""
        return EnvRaised.capture(error, self.indices[j], method, self.labels[j], crash_loop)

    # -- introspection -----------------------------------------------------------------
    def spaces(self) -> tuple[gym.Space, gym.Space, dict[str, Any], str | None]:
        """Spaces, metadata and render mode, checked to be the same for every env here."""
        self.check_built()
        env = self.envs[0]
        for index, other in zip(self.indices, self.envs, strict=True):
            if (other.observation_space, other.action_space) != (
                env.observation_space,
                env.action_space,
            ):
                raise RuntimeError(
                    f"env {index} has spaces ({other.observation_space}, {other.action_space}); "
                    f"expected those of env {self.indices[0]}: "
                    f"({env.observation_space}, {env.action_space})"
                )
        return env.observation_space, env.action_space, dict(env.metadata), env.render_mode

    def pid(self) -> int:
        return os.getpid()

    def ready(self) -> bool:
        return True

    # -- restarts ----------------------------------------------------------------------
    def _rebuild(self, j: int) -> int:
        with contextlib.suppress(Exception):  # a broken env may fail to close
            self.envs[j].close()
        self.envs[j] = build_env(self.env_fns[j], self.env_kwargs, self.registry)
        self.restart_counts[j] += 1
        return restart_seed(self.seed_roots[j], self.indices[j], self.restart_counts[j])

    @locked
    def mark_restarted(self, seeds: Sequence[int], last_obs: Sequence[Any]) -> None:
        """After the whole process was replaced: the next reset of each env uses ``seeds``."""
        self.pending_seeds = list(seeds)
        self.last_obs = list(last_obs)
        self.autoreset[:] = True

    @locked
    def reset_restarted(self, seeds: Sequence[int], last_obs: Sequence[Any]) -> ResetAnswer:
        """After the whole process was replaced (SAME_STEP): reset now with ``seeds``."""
        self.pending_seeds = list(seeds)
        answer = self._reset([None] * len(self.envs), None)
        for j, info in enumerate(answer.infos):
            answer.infos[j] = {"final_obs": last_obs[j], "final_info": {}, **info}
        return answer

    # -- reset / step ------------------------------------------------------------------
    def _batch(self, items: list[Any]) -> Any:
        """Observations of every env here as one batch (as ``SyncVectorEnv`` joins them); one
        that does not fit is its env's error, sent to the driver."""
        space = self.single_observation_space
        out = create_empty_array(space, n=len(items), fn=np.zeros)
        try:
            return concatenate(space, items, out)
        except Exception as error:
            j, why = _misfit(space, items, error)
            raise self.raised(why, j, "step") from None

    def _reset_one(self, j: int, seed: int | None, options: dict[str, Any] | None):
        """Reset env j; a user seed becomes its restart-seed root, a pending restart seed not."""
        if seed is not None:
            self.seed_roots[j] = seed
        elif self.pending_seeds[j] is not None:
            seed = self.pending_seeds[j]
        self.pending_seeds[j] = None
        return self.envs[j].reset(seed=seed, options=options)

    @locked
    def reset(
        self,
        seeds: Sequence[int | None],
        options: dict[str, Any] | None,
        mask: Sequence[bool] | None = None,
    ) -> ResetAnswer:
        """Reset the envs (those where ``mask`` is True); return per-env obs, infos, restarts."""
        return self._reset(seeds, options, mask)

    def _reset(
        self,
        seeds: Sequence[int | None],
        options: dict[str, Any] | None,
        mask: Sequence[bool] | None = None,
    ) -> ResetAnswer:
        infos: list[dict[str, Any]] = [{} for _ in self.envs]
        restarts: list[Restart] = []
        for j in range(len(self.envs)):
            if mask is not None and not mask[j]:
                continue
            self.autoreset[j] = False
            try:
                obs, info = self._reset_one(j, seeds[j], options)
            except Exception as error:
                if self.env_errors == "raise":
                    raise self.raised(error, j, "reset") from None
                restarts.append(Restart(self.indices[j], traceback.format_exc()))
                obs, info = self._again_after_rebuild(j, "reset", seeds[j], options)
            self.last_obs[j] = obs
            infos[j] = info
        return ResetAnswer(list(self.last_obs), infos, restarts)

    @locked
    def step(self, actions: Sequence[Any]) -> StepAnswer:
        """Step every env with its action (one per env), autoresetting as Gymnasium does.

        Returns per-env observations, then rewards, terminations, truncations,
        per-env infos and the restarts.
        """
        return self._step(actions)

    def _step(self, actions: Sequence[Any]) -> StepAnswer:
        n = len(self.envs)
        if len(actions) != n:
            raise ValueError(f"{len(actions)} actions for the {n} envs of this worker")
        rewards, terminations, truncations = [0.0] * n, [False] * n, [False] * n
        infos: list[dict[str, Any]] = [{}] * n
        restarts: list[Restart] = []
        mode = self.autoreset_mode
        next_step, same_step = mode is AutoresetMode.NEXT_STEP, mode is AutoresetMode.SAME_STEP
        ended = self.autoreset.tolist()
        for j, env in enumerate(self.envs):
            try:
                if ended[j] and next_step:
                    obs, info = self._reset_one(j, None, None)
                else:
                    if ended[j] and mode is AutoresetMode.DISABLED:
                        raise_disabled(self.indices[j])
                    obs, rewards[j], terminations[j], truncations[j], info = env.step(actions[j])
                    if same_step and (terminations[j] or truncations[j]):
                        final = {"final_obs": obs, "final_info": info}
                        obs, reset_info = self._reset_one(j, None, None)
                        info = {**final, **reset_info}
            except DisabledAutoresetError:
                raise
            except Exception as raised:
                if self.env_errors == "raise":
                    raise self.raised(raised, j, "step") from None
                error = traceback.format_exc()
                restarts.append(Restart(self.indices[j], error))
                obs, info = self._restart_in_step(j)
                rewards[j], terminations[j], truncations[j] = 0.0, False, True
                info.update(worker_restarted=True, worker_error=error)
            self.last_obs[j] = obs
            infos[j] = info
        out = _as_array(rewards, np.float64), _as_array(terminations, np.bool_)
        flags = (*out, _as_array(truncations, np.bool_))
        self.autoreset = np.logical_or(flags[1], flags[2])
        return StepAnswer(list(self.last_obs), *flags, infos, restarts)

    @locked
    def step_packed(
        self, action_bytes: bytes | memoryview, timed: bool = False, raw_infos: bool = False
    ) -> StepAnswer:
        """``step`` for Box spaces with raw bytes in and out (cheaper to send than arrays).

        Returns (obs, rewards, terminations, truncations) as bytes, then the
        infos (:func:`~chronogym.vector.infos.to_columns`: None when all are
        empty, else columns or per-env dicts; ``raw_infos``: the envs' own dicts, for
        the shared step to lay out) and the restarts (None when none). With
        ``timed``, also ``timings``: (seconds of (de)serialization, seconds in ``step``).
        """
        start = time.perf_counter()
        space = self.single_action_space
        actions = (
            np.frombuffer(action_bytes, dtype=space.dtype)
            .reshape(len(self.envs), *space.shape)
            .copy()
        )
        stepped = time.perf_counter()
        result = self._step(actions)
        computed = time.perf_counter()
        out = StepAnswer(
            self._batch(result.obs).tobytes(),
            result.rewards.tobytes(),
            result.terminations.tobytes(),
            result.truncations.tobytes(),
            result.infos if raw_infos else to_columns(result.infos),
            result.restarts or None,
        )
        if timed:
            out.timings = (stepped - start + time.perf_counter() - computed, computed - stepped)
        return out

    def _restart_in_step(self, j: int) -> tuple[Any, dict[str, Any]]:
        final_obs = self.last_obs[j]
        if self.autoreset_mode == AutoresetMode.SAME_STEP:
            obs, reset_info = self._again_after_rebuild(j, "reset", None, None)
            return obs, {"final_obs": final_obs, "final_info": {}, **reset_info}
        self._rebuilt(j, "make")
        return final_obs, {}

    def _rebuilt(self, j: int, method: str) -> None:
        """Rebuild env ``j`` (its next reset takes a fresh seed); a failure is a crash loop."""
        try:
            self.pending_seeds[j] = self._rebuild(j)
        except Exception as error:
            raise self.raised(error, j, method, crash_loop=True) from None

    def _again_after_rebuild(self, j: int, method: str, seed: int | None, options: Any):
        """Rebuild env ``j`` and reset it (with ``seed``, else its fresh restart seed); a
        failure right after the rebuild is a crash loop, reported as such."""
        self._rebuilt(j, "make")
        try:
            return self._reset_one(j, seed, options)
        except Exception as error:
            raise self.raised(error, j, method, crash_loop=True) from None

    # -- generic access ----------------------------------------------------------------
    @locked
    def call(self, name: str, args: tuple[Any, ...], kwargs: dict[str, Any]) -> list[Any]:
        """``name`` called (or read) on every env; an env's exception goes to the driver."""
        results = []
        for j, env in enumerate(self.envs):
            try:
                attr = env.get_wrapper_attr(name)
                results.append(attr(*args, **kwargs) if callable(attr) else attr)
            except Exception as error:
                raise self.raised(error, j, name) from None
        return results

    @locked
    def set_attr(self, name: str, values: Sequence[Any]) -> None:
        for j, (env, value) in enumerate(zip(self.envs, values, strict=True)):
            try:
                env.set_wrapper_attr(name, value)
            except Exception as error:
                raise self.raised(error, j, f"set_attr {name!r}") from None

    def close(self) -> None:
        """Close the envs that were built (also after a construction error)."""
        with self._lock:
            for env in self.envs:
                env.close()


def _misfit(space: gym.Space, items: list[Any], error: Exception) -> tuple[int, Exception]:
    """The first env whose observation does not fit ``space``, and why (for Box spaces;
    otherwise env 0 of the group and numpy's own error)."""
    shape = getattr(space, "shape", None)
    if isinstance(space, gym.spaces.Box):
        for j, item in enumerate(items):
            if np.shape(item) != shape:
                return j, ValueError(
                    f"the observation has shape {np.shape(item)}; expected {shape}, the shape "
                    f"of its observation_space {space}"
                )
    return 0, error


def _as_array(values: list[Any], dtype: type) -> np.ndarray:
    """Per-env scalars as one array, each converted as ``array[j] = value`` would."""
    array = np.array(values, dtype=dtype)
    if array.shape != (len(values),):  # e.g. rewards given as 1-element arrays
        array = np.zeros(len(values), dtype=dtype)
        for j, value in enumerate(values):
            array[j] = value
    return array


def raise_disabled(env_index: int) -> None:
    raise DisabledAutoresetError(
        f"env {env_index} ended and autoreset_mode is DISABLED; reset it with "
        "reset(options={'reset_mask': mask}) before stepping it again"
    )
