"""Stable-Baselines3: a chronogym vector env (or any Gymnasium one) as an SB3 ``VecEnv``.

:class:`SB3VecEnv` wraps a ``gymnasium.vector.VectorEnv`` whose ``autoreset_mode`` is
``SAME_STEP`` (``RayVectorEnv``, ``SerialVectorEnv``, Gymnasium's own) and speaks SB3's
``VecEnv`` API, with the numbers of SB3's ``DummyVecEnv`` on the same envs:
``dones = terminated | truncated``; an env that ended is reset within the step, and its
info holds ``"terminal_observation"`` (the episode's last observation) and its reset info
goes to ``reset_infos``; ``info["TimeLimit.truncated"] = truncated and not terminated``;
infos are one dict per env; rewards are float32. :func:`make_sb3_vec_env` builds one
from an env id.

:class:`RayVecEnv` and :class:`SerialVecEnv` take a list of env factories, as SB3's
``SubprocVecEnv`` and ``DummyVecEnv`` do, so either can be ``vec_env_cls`` of SB3's
``make_vec_env``; each env knows its index, so ``indices=`` reaches only the chosen envs.

Requires Stable-Baselines3: ``pip install "chronogym[sb3]"``.
"""

from __future__ import annotations

import functools
import re
import warnings
from collections.abc import Callable, Sequence
from typing import Any

import gymnasium as gym
import numpy as np
from gymnasium.envs.registration import EnvSpec
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
from chronogym.errors import BoolArgumentError
from chronogym.integrations._indexed import (
    HOOK,
    INDEX_ATTR,
    DriverRegistry,
    build_indexed_env,
    make_indexed_env,
)
from chronogym.integrations._sb3_batches import batch_actions, sb3_obs, split_info
from chronogym.validation import check_int, is_int
from chronogym.vector.factory import BACKENDS

__all__ = [
    "BACKENDS",
    "RayVecEnv",
    "SB3VecEnv",
    "SerialVecEnv",
    "make_sb3_vec_env",
    "split_info",
]

SAME_STEP = AutoresetMode.SAME_STEP

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
    vector env takes one options dict; :class:`RayVecEnv` and :class:`SerialVecEnv` take
    one per env). ``step_async`` keeps the actions and
    ``step_wait`` runs one ``step`` of the vector env. Actions are SB3's: an array with one
    row per env, or one action per env (a list of dicts or tuples for Dict and Tuple
    action spaces); they are batched with ``gymnasium.vector.utils``.

    ``get_attr``, ``set_attr``, ``env_method``, ``env_is_wrapped`` and ``has_attr`` act on
    the chosen envs only when each env knows its index (built by :func:`make_sb3_vec_env`,
    :class:`RayVecEnv` or :class:`SerialVecEnv`). With any other vector env: ``get_attr``
    reads every env and picks; ``set_attr`` reads the attribute of every env and writes it
    back unchanged to the others (with Ray: an equal copy); ``env_method`` runs on every
    env and returns the chosen results (a warning says so once per method name);
    ``env_is_wrapped`` matches the wrapper classes' names in each env's ``str()``
    (``<Monitor<TimeLimit<...>>>``).
    """

    #: Whether ``set_options`` may give envs different dicts (reset in groups by
    #: ``reset_mask``, which chronogym's vector envs take).
    _per_env_options = False

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
        # Envs that know their index let indices= reach only those envs.
        # Probed without raising: an error in a call shuts down AsyncVectorEnv's workers.
        self._indexed = all(vector_env.call("has_wrapper_attr", INDEX_ATTR)) and list(
            vector_env.get_attr(INDEX_ATTR)
        ) == list(range(n))
        self._actions: Any = None
        self._warned: set[str] = set()
        self._was_reset = False
        super().__init__(n, observation_space, vector_env.single_action_space)

    # -- stepping ----------------------------------------------------------------------
    def reset(self) -> VecEnvObs:
        """Reset every env (with the pending seeds and options, then forget them)."""
        seed = None if all(s is None for s in self._seeds) else list(self._seeds)
        reset_infos: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        for k, (options, members) in enumerate(self._option_groups()):
            if k == 0 and not self._was_reset:
                # A vector env's first reset covers every env (masked ones would have no
                # observation yet); the other groups' envs are reset again below.
                members = list(range(self.num_envs))
            elif len(members) < self.num_envs:
                mask = np.zeros(self.num_envs, dtype=np.bool_)
                mask[members] = True
                options = {**(options or {}), "reset_mask": mask}
            obs, info = self.vector_env.reset(seed=seed, options=options)
            infos = split_info(info, self.num_envs)
            for i in members:
                reset_infos[i] = infos[i]
        self.reset_infos = reset_infos
        self._was_reset = True
        self._reset_seeds()
        self._reset_options()
        self._actions = None
        return sb3_obs(self.observation_space, obs)

    def step_async(self, actions: np.ndarray) -> None:
        """Keep ``actions`` (one row, or one action, per env) for the next :meth:`step_wait`."""
        self._actions = actions

    def step_wait(self) -> VecEnvStepReturn:
        """Step every env: ``(obs, rewards, dones, infos)`` in SB3's format."""
        if self._actions is None:
            raise RuntimeError("step_wait() without step_async(actions) first")
        actions, self._actions = self._actions, None
        batch = batch_actions(self.action_space, actions, self.num_envs)
        obs, rewards, terminated, truncated, info = self.vector_env.step(batch)
        terminated = np.asarray(terminated, dtype=bool)
        truncated = np.asarray(truncated, dtype=bool)
        dones = terminated | truncated
        infos = split_info(info, self.num_envs)
        for i in np.flatnonzero(dones):
            infos[i] = self._ended(int(i), infos[i])
        for i, env_info in enumerate(infos):
            env_info["TimeLimit.truncated"] = bool(truncated[i] and not terminated[i])
        rewards = np.asarray(rewards, dtype=np.float32)
        return sb3_obs(self.observation_space, obs), rewards, dones, infos

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

    def _option_groups(self) -> list[tuple[dict[str, Any] | None, list[int]]]:
        """The envs to reset together: (their options or None, their indices)."""
        if not self._per_env_options:
            return [(self._common_options(), list(range(self.num_envs)))]
        groups: list[tuple[dict[str, Any], list[int]]] = []
        for i, options in enumerate(self._options):
            for shared, members in groups:
                if options is shared or _equal(options, shared):
                    members.append(i)
                    break
            else:
                groups.append((options, [i]))
        return [(options or None, members) for options, members in groups]

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
    def has_attr(self, attr_name: str) -> bool:
        """Whether every env has the attribute (a read of each, without calling it)."""
        if self._indexed:
            return all(self._on_envs("has", None, attr_name))
        return super().has_attr(attr_name)

    def get_attr(self, attr_name: str, indices: VecEnvIndices = None) -> list[Any]:
        """The attribute of each env in ``indices`` (default: all), in that order."""
        chosen = self._indices(indices)
        if self._indexed:
            return self._on_envs("get", chosen, attr_name)
        if self._is_all(chosen):
            return list(self.vector_env.get_attr(attr_name))
        return self._pick(self.vector_env.get_attr(attr_name), chosen)

    def set_attr(self, attr_name: str, value: Any, indices: VecEnvIndices = None) -> None:
        """Set the attribute to ``value`` on each env in ``indices`` (default: all)."""
        chosen = self._indices(indices)
        if self._indexed:
            self._on_envs("set", chosen, attr_name, value)
        elif self._is_all(chosen):
            self.vector_env.set_attr(attr_name, [value] * self.num_envs)
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
        if self._indexed:
            return self._on_envs("call", chosen, method_name, method_args, method_kwargs)
        if self._is_all(chosen):
            return list(self.vector_env.call(method_name, *method_args, **method_kwargs))
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
            return [bool(r) for r in self._on_envs("is_wrapped", chosen, wrapper_class)]
        names = {cls.__name__ for cls in _subclasses(wrapper_class)}
        texts = self._pick(self.vector_env.call("__str__"), chosen)
        return [bool(names & set(re.findall(r"<([A-Za-z_]\w*)", text))) for text in texts]

    def _on_envs(self, op: str, chosen: list[int] | None, *args: Any) -> list[Any]:
        """Run ``op`` of :class:`~chronogym.integrations._indexed.IndexedEnv` on the chosen
        envs (None: all) only, once per time an env is chosen; the results in ``chosen``
        order."""
        chosen = list(range(self.num_envs)) if chosen is None else chosen
        if not chosen:
            return []
        per_env = [iter(r or ()) for r in self.vector_env.call(HOOK, op, chosen, *args)]
        return [next(per_env[i]) for i in chosen]

    def _indices(self, indices: VecEnvIndices) -> list[int]:
        """``indices`` as a list of env indices in 0..num_envs-1, by SB3's convention.

        As ``VecEnv._get_indices`` and ``DummyVecEnv`` read it: None is every env, an
        integer one env, any other iterable its integers in order; an index counts from
        the end when negative (-1 is the last env), and one given twice is used twice.
        Out of range: ``IndexError``; not an integer: ``TypeError``, as with SB3 (a bool
        raises :class:`chronogym.BoolArgumentError`).
        """
        n = self.num_envs
        if indices is None:
            return list(range(n))
        expected = (
            f"expected None, an env index or an iterable of env indices, each an integer "
            f"with -num_envs <= index < num_envs={n} (negative counts from the end)"
        )
        scalar = is_int(indices) or isinstance(indices, (bool, np.bool_))
        items = [indices] if scalar else indices
        try:
            chosen = list(items)  # type: ignore[call-overload]
        except TypeError:
            raise TypeError(f"indices={indices!r}: {expected}") from None
        for i in chosen:
            if isinstance(i, (bool, np.bool_)):
                raise BoolArgumentError(f"indices={indices!r} holds the bool {i!r}; {expected}")
            if not is_int(i):
                raise TypeError(f"indices={indices!r} holds {i!r}, not an integer; {expected}")
            if not -n <= i < n:
                raise IndexError(f"indices={indices!r}: index {i} is out of range; {expected}")
        return [int(i) % n for i in chosen]

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
        return f"{type(self).__name__}({self.vector_env!r})"


class _FactoryVecEnv(SB3VecEnv):
    """An SB3VecEnv over a chronogym vector env built from ``env_fns``, each env indexed."""

    _per_env_options = True

    #: Whether the envs are built in other processes, which lack the ids registered in
    #: the user's script (the driver's registry travels with the factories).
    _remote = False

    def __init__(self, env_fns: Sequence[Callable[[], gym.Env]], **vector_kwargs: Any) -> None:
        fns = _indexed_env_fns(env_fns, vector_kwargs, type(self).__name__, self._remote)
        vector_env = self._vector_env(fns, vector_kwargs)
        try:
            everyone = list(range(vector_env.num_envs))
            identities = [r[0] for r in vector_env.call(HOOK, "identity", everyone)]
            if len(set(identities)) != len(identities):
                raise ValueError(
                    f"{type(self).__name__}: the factories returned the same env instance for "
                    "several envs; each factory must create a new env (e.g. lambda: "
                    "gymnasium.make(env_id), not lambda: env)"
                )
            super().__init__(vector_env)
        except BaseException:
            vector_env.close()
            raise

    @staticmethod
    def _vector_env(fns: list[Any], vector_kwargs: dict[str, Any]) -> gym.vector.VectorEnv:
        raise NotImplementedError


class RayVecEnv(_FactoryVecEnv):
    """SB3's ``SubprocVecEnv`` on Ray: the envs of ``env_fns`` in :class:`chronogym.RayVectorEnv`.

    Args:
        env_fns: one factory per env, each returning a new ``gymnasium.Env`` (as for
            ``SubprocVecEnv``); Ray pickles them with cloudpickle, closures included.
        **vector_kwargs: for :class:`chronogym.RayVectorEnv` (``envs_per_worker``,
            ``num_cpus``, ``address``, ``step_timeout``, ``transport``, ...);
            ``autoreset_mode`` is ``SAME_STEP``.

    Works as ``vec_env_cls`` of SB3's ``make_vec_env`` (``vec_env_kwargs`` go to the vector
    env). Same numbers as ``DummyVecEnv`` on the same factories. Each env knows its index,
    so ``get_attr``, ``set_attr``, ``env_method``, ``env_is_wrapped`` with ``indices``
    touch only those envs (attributes and methods only some envs have included);
    ``set_options`` may give each env its own dict. An env whose worker dies is rebuilt
    and its episode ends truncated (``worker_restarted`` in its info). A factory that
    makes an id registered in the user's script (as ``make_vec_env("newuser/Task-v0",
    vec_env_cls=RayVecEnv)`` does) works on the workers: the driver's registered ids
    travel with the factories.
    """

    _remote = True

    @staticmethod
    def _vector_env(fns: list[Any], vector_kwargs: dict[str, Any]) -> gym.vector.VectorEnv:
        return chronogym.RayVectorEnv(fns, autoreset_mode=SAME_STEP, **vector_kwargs)


class SerialVecEnv(_FactoryVecEnv):
    """:class:`RayVecEnv`'s twin in this process (:class:`chronogym.SerialVectorEnv`).

    Same arguments (``vector_kwargs`` for ``SerialVectorEnv``: ``envs_per_worker``,
    ``max_restarts``, ``invalid_action``), same numbers and the same per-env ``indices=`` as
    :class:`RayVecEnv`, SB3's ``DummyVecEnv`` and ``SubprocVecEnv``; no Ray.
    """

    @staticmethod
    def _vector_env(fns: list[Any], vector_kwargs: dict[str, Any]) -> gym.vector.VectorEnv:
        return chronogym.SerialVectorEnv(fns, autoreset_mode=SAME_STEP, **vector_kwargs)


def _indexed_env_fns(
    env_fns: Any, vector_kwargs: dict[str, Any], owner: str, remote: bool = False
) -> list[functools.partial]:
    """``env_fns`` checked, each wrapped to build its env in an ``IndexedEnv``.

    ``remote``: the envs are built in Ray workers, which get the driver's registry
    (:class:`~chronogym.integrations._indexed.DriverRegistry`) with the factories.
    """
    expected = (
        "expected a list of callables, each returning a new gymnasium.Env (as for "
        "SubprocVecEnv); for an env id use make_vec_env(env_id, n_envs, "
        f"vec_env_cls={owner}) or make_sb3_vec_env(env_id, num_envs)"
    )
    if isinstance(env_fns, (str, bytes)) or not isinstance(env_fns, Sequence):
        raise ValueError(f"{owner}(env_fns={env_fns!r}): {expected}")
    if len(env_fns) == 0:
        raise ValueError(f"{owner}(env_fns={env_fns!r}): no env factories; {expected}")
    for i, fn in enumerate(env_fns):
        if not callable(fn):
            raise ValueError(f"{owner}: env_fns[{i}]={fn!r} is not callable; {expected}")
    mode = vector_kwargs.pop("autoreset_mode", SAME_STEP)
    if not _is_same_step(mode):
        raise ValueError(
            f"{owner}(autoreset_mode={mode!r}): SB3 resets an env in the step that ends it, "
            "so the mode is AutoresetMode.SAME_STEP; leave autoreset_mode out"
        )
    if "env_kwargs" in vector_kwargs:
        raise ValueError(
            f"{owner}(env_kwargs={vector_kwargs['env_kwargs']!r}): env_kwargs apply to env ids; "
            "with factories, pass the keyword arguments inside each factory"
        )
    registry = DriverRegistry(_ray_dumps()) if remote else None
    return [functools.partial(build_indexed_env, fn, i, registry) for i, fn in enumerate(env_fns)]


def _ray_dumps() -> Callable[[Any], bytes]:
    """Ray's cloudpickle ``dumps`` (it honours ``register_pickle_by_value``)."""
    from ray import cloudpickle

    return cloudpickle.dumps


def make_sb3_vec_env(
    env_id: str | EnvSpec,
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
    ``env_id`` is looked up here and its spec sent to the envs, so an id registered in
    the user's script works on every backend.
    """
    if backend not in BACKENDS:
        raise ValueError(f"backend={backend!r}: expected one of {BACKENDS}")
    check_int("num_envs", num_envs, low=1)
    mode = vector_kwargs.pop("autoreset_mode", SAME_STEP)
    if not _is_same_step(mode):
        raise ValueError(
            f"autoreset_mode={mode!r}: make_sb3_vec_env needs AutoresetMode.SAME_STEP "
            "(SB3 resets an env in the step that ends it); leave autoreset_mode out"
        )
    spec = _env_spec(env_id)  # an unknown id fails here; workers get the spec, not the id
    env_fns = [functools.partial(make_indexed_env, spec, i, env_kwargs) for i in range(num_envs)]
    mode = SAME_STEP
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


def _env_spec(env_id: Any) -> EnvSpec:
    """The registered spec of ``env_id`` (an id or an ``EnvSpec``), looked up here."""
    if isinstance(env_id, EnvSpec):
        return env_id
    if not isinstance(env_id, str):
        raise TypeError(
            f"env_id={env_id!r}: expected a registered Gymnasium id (a str); for env "
            "factories use RayVecEnv(env_fns) or SerialVecEnv(env_fns)"
        )
    return gym.spec(env_id)


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
