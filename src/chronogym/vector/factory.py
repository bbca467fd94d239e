"""make_vec: one call for every way chronogym can batch an env, with one set of arguments."""

from __future__ import annotations

import difflib
import functools
import inspect
from collections.abc import Sequence
from typing import Any

import gymnasium as gym

import chronogym  # noqa: F401  (registers the chronogym/... ids)
from chronogym.validation import show
from chronogym.vector.backend import EnvFactory
from chronogym.vector.checks import normalize_env_fns
from chronogym.vector.ray_vector_env import RayVectorEnv
from chronogym.vector.serial import RAY_ONLY_ARGUMENTS, SerialVectorEnv

#: The ``backend`` names of make_vec (and of the SB3 adapter's make_sb3_vec_env).
BACKENDS = ("ray", "serial", "sync", "async")

#: The class each backend builds.
BACKEND_CLASSES: dict[str, type[gym.vector.VectorEnv]] = {
    "ray": RayVectorEnv,
    "serial": SerialVectorEnv,
    "sync": gym.vector.SyncVectorEnv,
    "async": gym.vector.AsyncVectorEnv,
}


@functools.cache
def backend_arguments(backend: str) -> tuple[str, ...]:
    """The keyword arguments ``make_vec`` forwards with ``backend``, in signature order."""
    parameters = inspect.signature(BACKEND_CLASSES[backend].__init__).parameters
    names = tuple(
        name
        for name, p in parameters.items()
        if name not in ("self", "env_fns", "num_envs") and p.kind is not p.VAR_KEYWORD
    )
    # chronogym's own backends take env_kwargs; make_vec gives Gymnasium's to gymnasium.make
    return names if "env_kwargs" in names else (*names, "env_kwargs")


def check_backend_arguments(backend: str, kwargs: dict[str, Any]) -> None:
    """Raise a TypeError naming the first keyword argument ``backend`` does not take."""
    takes = backend_arguments(backend)
    for name, value in kwargs.items():
        if name in takes:
            continue
        where = f"make_vec(backend={backend!r}, {name}={show(value)})"
        others = [b for b in BACKENDS if name in backend_arguments(b)]
        if others:
            why = ""
            if backend == "serial" and name in RAY_ONLY_ARGUMENTS:
                why = f" (one process; it sets {RAY_ONLY_ARGUMENTS[name]})"
            raise TypeError(
                f"{where}: {name} does not apply to {_class_name(backend)}{why}; it is an "
                f"argument of backend={_names(others)} only"
            )
        everything = sorted({n for b in BACKENDS for n in backend_arguments(b)})
        close = difflib.get_close_matches(name, everything, n=1)
        hint = f"did you mean {close[0]!r}? " if close else ""
        raise TypeError(
            f"{where}: unexpected keyword argument {name!r}; {hint}backend={backend!r} takes "
            f"{', '.join(takes)}"
        )


def _class_name(backend: str) -> str:
    name = BACKEND_CLASSES[backend].__name__
    return name if backend in ("ray", "serial") else f"Gymnasium's {name}"


def _names(backends: list[str]) -> str:
    quoted = [repr(b) for b in backends]
    return quoted[0] if len(quoted) == 1 else f"{', '.join(quoted[:-1])} or {quoted[-1]}"


def make_vec(
    env_fns: str | EnvFactory | Sequence[str | EnvFactory],
    num_envs: int | None = None,
    backend: str = "ray",
    **kwargs: Any,
) -> gym.vector.VectorEnv:
    """``num_envs`` envs batched by ``backend``, from an env id, one factory or a list of them.

    Args:
        env_fns: a registered env id, one env factory, or a list of factories
            (or ids), one per env: the same forms with every backend.
        num_envs: number of envs (required with an id or a single factory;
            with a list, None or its length).
        backend: ``"ray"``: :class:`chronogym.RayVectorEnv`; ``"serial"``:
            :class:`chronogym.SerialVectorEnv`; ``"sync"`` / ``"async"``:
            Gymnasium's own ``SyncVectorEnv`` / ``AsyncVectorEnv`` (for
            comparison; an id goes through ``gymnasium.make_vec``).
        **kwargs: the arguments of the class ``backend`` builds, forwarded as
            they are; ``env_kwargs`` (every backend) go to ``gymnasium.make``
            for each env given by an id. An argument the backend does not take
            is a TypeError naming it and the backends that do take it (for
            example ``envs_per_worker`` with ``backend="sync"``: ``"ray"`` or
            ``"serial"``).

    Same seeds give the same numbers with every backend.
    """
    if backend not in BACKENDS:
        raise ValueError(f"backend={backend!r}: expected one of {BACKENDS}")
    check_backend_arguments(backend, kwargs)
    if backend == "ray":
        return RayVectorEnv(env_fns, num_envs, **kwargs)
    if backend == "serial":
        return SerialVectorEnv(env_fns, num_envs, **kwargs)
    fns = normalize_env_fns(env_fns, num_envs)
    env_kwargs = kwargs.pop("env_kwargs", None) or {}
    if isinstance(env_fns, str):
        return gym.make_vec(
            env_fns, len(fns), vectorization_mode=backend, vector_kwargs=kwargs, **env_kwargs
        )
    makers = [
        functools.partial(gym.make, fn, **env_kwargs) if isinstance(fn, str) else fn for fn in fns
    ]
    return BACKEND_CLASSES[backend](makers, **kwargs)
