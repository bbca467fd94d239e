"""SerialVectorEnv: every env in this process, with RayVectorEnv's exact semantics."""

from __future__ import annotations

import contextlib
import traceback
from collections.abc import Sequence
from typing import Any

from gymnasium.vector import AutoresetMode

from chronogym.validation import is_int
from chronogym.vector.backend import EnvFactory, Outcome, error_outcome
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
    ``gymnasium.vector.SyncVectorEnv``), with no Ray involved.
    """

    def __init__(
        self,
        env_fns: str | EnvFactory | Sequence[str | EnvFactory],
        num_envs: int | None = None,
        *,
        autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP,
        max_restarts: int = 3,
        invalid_action: str = "raise",
        env_kwargs: dict[str, Any] | None = None,
    ) -> None:
        count = num_envs if num_envs is not None else _count(env_fns)
        super().__init__(
            env_fns,
            num_envs,
            backend=LocalBackend(),
            envs_per_worker=count if is_int(count) and count >= 1 else 1,
            autoreset_mode=autoreset_mode,
            max_restarts=max_restarts,
            invalid_action=invalid_action,
            env_kwargs=env_kwargs,
        )


def _count(env_fns: Any) -> int | None:
    if isinstance(env_fns, Sequence) and not isinstance(env_fns, str):
        return len(env_fns)
    return None
