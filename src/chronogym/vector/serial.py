"""SerialVectorEnv: every env in this process, with RayVectorEnv's exact semantics.

It takes RayVectorEnv's arguments that mean something in one process
(``SERIAL_ARGUMENTS``) and rejects, by name, those about Ray and processes
(``RAY_ONLY_ARGUMENTS``); a test checks that the two cover RayVectorEnv's signature.
"""

from __future__ import annotations

import contextlib
import difflib
import traceback
from collections.abc import Sequence
from typing import Any

from gymnasium.vector import AutoresetMode

from chronogym.validation import check_int, show
from chronogym.vector.backend import EnvFactory, Outcome, error_outcome
from chronogym.vector.checks import normalize_env_fns
from chronogym.vector.group import EnvGroup
from chronogym.vector.worker_vector_env import WorkerVectorEnv


class LocalBackend:
    """Workers (EnvGroups) held in this process; a call runs when it is submitted."""

    step_timeout = None  # a call here cannot hang apart from the driver
    worker_cls: type = EnvGroup  # what each worker is (an EnvGroup, or optim's TrialWorker)

    def __init__(self) -> None:
        self.groups: list[Any] = []

    def start(self, group_kwargs: list[dict[str, Any]]) -> None:
        self.groups = [self.worker_cls(**kwargs) for kwargs in group_kwargs]

    def replace(self, worker: int, kwargs: dict[str, Any]) -> None:
        with contextlib.suppress(Exception):  # a broken group may fail to close
            self.groups[worker].close()
        self.groups[worker] = self.worker_cls(**kwargs)

    def submit(self, worker: int, method: str, *args: Any) -> Outcome:
        try:
            return Outcome(True, getattr(self.groups[worker], method)(*args))
        except Exception as error:
            return error_outcome(error, traceback.format_exc())

    def gather(self, workers: list[int], handles: list[Outcome]) -> list[Outcome]:
        return handles

    def wait(self, handles: list[Outcome], num_returns: int, timeout: float | None) -> list[int]:
        return list(range(len(handles)))  # every call ran when it was submitted

    def pid(self, worker: int) -> int:
        return self.groups[worker].pid()

    def shutdown(self) -> None:
        self.groups = []


class SerialVectorEnv(WorkerVectorEnv):
    """All envs stepped one after another in this process: for debugging and serial baselines.

    Same arguments and numbers as :class:`chronogym.RayVectorEnv` (and as
    ``gymnasium.vector.SyncVectorEnv``), with no Ray involved: switch a
    ``RayVectorEnv`` to this class to debug it, keeping every argument that
    means something in one process.

    Args:
        env_fns: a registered env id, one env factory, or a list of factories
            (one per env, as for ``SyncVectorEnv``).
        num_envs: number of envs (required with an id or a single factory).
        envs_per_worker: envs per group, as ``RayVectorEnv``'s envs per
            worker: ``send`` steps whole groups, and a group whose call fails
            is rebuilt whole. Numbers never depend on it. Default (None):
            every env in one group; ``RayVectorEnv``'s default depends on
            the cluster's CPUs, so pass the same value to both when
            ``send`` / ``recv`` code is being debugged.
        autoreset_mode: Gymnasium's ``AutoresetMode`` (NEXT_STEP default).
        max_restarts: restarts allowed per env before WorkerCrashLoopError
            (-1: no limit), with ``env_errors="restart"``.
        invalid_action: ``"raise"`` (default) or ``"clip"`` for NaN/Inf actions.
        env_errors: ``"raise"`` (default) or ``"restart"``: what an env's own
            exception does, as in :class:`chronogym.RayVectorEnv`.
        env_kwargs: keyword arguments for ``gymnasium.make`` when ``env_fns``
            is an id.
        **ray_only: ``RayVectorEnv``'s arguments about Ray and processes
            (``num_cpus``, ``num_gpus``, ``address``, ``worker_niceness``,
            ``scheduling``, ``step_timeout``, ``start_timeout``, ``transport``,
            ``spin_us``, ``shared_memory``, ``relay_tcp``, ``driver_worker``) have
            no meaning here: each raises a TypeError that names it, as does any
            other unknown name.
    """

    def __init__(
        self,
        env_fns: str | EnvFactory | Sequence[str | EnvFactory],
        num_envs: int | None = None,
        *,
        envs_per_worker: int | None = None,
        autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP,
        max_restarts: int = 3,
        invalid_action: str = "raise",
        env_kwargs: dict[str, Any] | None = None,
        env_errors: str = "raise",
        **ray_only: Any,
    ) -> None:
        check_no_ray_arguments(ray_only)
        count = len(normalize_env_fns(env_fns, num_envs))
        if envs_per_worker is None:
            envs_per_worker = count
        expected = f"an integer with 1 <= envs_per_worker <= num_envs={count}"
        check_int("envs_per_worker", envs_per_worker, low=1, high=count, expected=expected)
        super().__init__(
            env_fns,
            num_envs,
            backend=LocalBackend(),
            envs_per_worker=envs_per_worker,
            autoreset_mode=autoreset_mode,
            max_restarts=max_restarts,
            invalid_action=invalid_action,
            env_kwargs=env_kwargs,
            env_errors=env_errors,
        )


#: RayVectorEnv's arguments that SerialVectorEnv rejects, and what each sets in Ray.
RAY_ONLY_ARGUMENTS: dict[str, str] = {
    "num_cpus": "the CPUs reserved for each Ray worker",
    "num_gpus": "the GPUs reserved for each Ray worker",
    "address": "the Ray cluster to join",
    "worker_niceness": "the priority of the Ray worker processes",
    "scheduling": "where Ray places its workers",
    "step_timeout": "how long a worker process may take before it is replaced; a call in "
    "this process cannot be timed out",
    "start_timeout": "how long the Ray workers may take to start",
    "transport": "how the driver reaches the worker processes",
    "spin_us": "how long the driver's socket spins waiting for a worker process",
    "shared_memory": "whether the worker processes answer a step through shared memory",
    "relay_tcp": "whether the relays of other nodes answer a step over a TCP connection",
    "driver_worker": "whether the driver steps the last worker's envs itself; here it steps "
    "them all",
}

#: SerialVectorEnv's own keyword arguments.
SERIAL_ARGUMENTS = (
    "envs_per_worker",
    "autoreset_mode",
    "max_restarts",
    "invalid_action",
    "env_kwargs",
    "env_errors",
)


def ray_only_message(name: str, value: Any) -> str:
    """Why ``name=value`` (a RayVectorEnv argument) has no meaning in one process."""
    return (
        f"{name}={show(value)}: has no meaning for SerialVectorEnv (one process; it sets "
        f"{RAY_ONLY_ARGUMENTS[name]}); it is a RayVectorEnv argument: leave it out"
    )


def check_no_ray_arguments(kwargs: dict[str, Any]) -> None:
    """Raise a TypeError naming the first keyword argument SerialVectorEnv does not take."""
    for name, value in kwargs.items():
        if name in RAY_ONLY_ARGUMENTS:
            raise TypeError(ray_only_message(name, value))
        close = difflib.get_close_matches(name, SERIAL_ARGUMENTS, n=1)
        hint = f"did you mean {close[0]!r}? " if close else ""
        raise TypeError(
            f"SerialVectorEnv() got an unexpected keyword argument {name!r}; {hint}expected "
            f"one of {', '.join(SERIAL_ARGUMENTS)}"
        )
