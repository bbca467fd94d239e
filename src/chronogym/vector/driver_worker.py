"""``driver_worker=True``: the driver steps one worker's envs itself, in its own process.

On a small machine the driver otherwise sits idle through every barrier while the
workers compute, and each extra worker process competes with it for a core. With
this backend the last worker is an :class:`~chronogym.vector.group.EnvGroup` in
the driver's process: its calls are deferred until the driver waits, so the
driver steps its own envs while the Ray workers step theirs, and one round trip
fewer stands between a step and its answer. Same EnvGroup, same seeds, same
numbers.

The price is isolation: an env that crashes the process (a segfault in an engine)
takes the driver with it, where a Ray worker would have been replaced. An env
that raises is rebuilt as in any worker.
"""

from __future__ import annotations

import contextlib
import os
import traceback
from dataclasses import dataclass
from typing import Any

from chronogym.vector.backend import (
    Backend,
    Outcome,
    error_outcome,
    gather_split,
    split_handles,
)
from chronogym.vector.group import EnvGroup


@dataclass
class DeferredCall:
    """A call of the driver's own worker; it runs when the driver gathers or waits."""

    method: str
    args: tuple[Any, ...]
    outcome: Outcome | None = None


class DriverWorkerBackend:
    """``remote`` serves workers ``0 .. n-2``; worker ``n-1`` lives in this process."""

    def __init__(self, remote: Backend) -> None:
        self.remote = remote
        self.local: EnvGroup | None = None
        self.local_index = -1

    @property
    def step_timeout(self) -> float | None:
        return self.remote.step_timeout

    def shares_steps(self) -> bool:
        """No shared-memory step: the driver's own worker steps in this process."""
        return False

    def __getattr__(self, name: str) -> Any:
        """Anything else (``actors``, ``connected()``, ...) is the remote backend's."""
        if name == "remote":  # not set yet (e.g. during unpickling)
            raise AttributeError(name)
        return getattr(self.remote, name)

    def start(self, group_kwargs: list[dict[str, Any]]) -> None:
        self.local_index = len(group_kwargs) - 1
        self.remote.start(group_kwargs[:-1])
        self.local = EnvGroup(**group_kwargs[-1])

    def replace(self, worker: int, kwargs: dict[str, Any]) -> None:
        if worker != self.local_index:
            self.remote.replace(worker, kwargs)
            return
        if self.local is not None:
            with contextlib.suppress(Exception):  # a broken group may fail to close
                self.local.close()
        self.local = EnvGroup(**kwargs)

    def submit(self, worker: int, method: str, *args: Any) -> Any:
        if worker == self.local_index:
            return DeferredCall(method, args)
        return self.remote.submit(worker, method, *args)

    def _run(self, call: DeferredCall) -> Outcome:
        """Run a deferred call of the driver's worker (once)."""
        if call.outcome is None:
            try:
                call.outcome = Outcome(True, getattr(self.local, call.method)(*call.args))
            except Exception as error:
                call.outcome = error_outcome(error, traceback.format_exc())
        return call.outcome

    def gather(self, workers: list[int], handles: list[Any]) -> list[Outcome]:
        return gather_split(workers, handles, DeferredCall, self._run, self.remote.gather)

    def wait(self, handles: list[Any], num_returns: int, timeout: float | None) -> list[int]:
        """The driver's own calls run first (they are answered when they return)."""
        local, remote = split_handles(handles, DeferredCall)
        for k in local:
            self._run(handles[k])
        if not remote:
            return local
        need = num_returns - len(local)
        ready = self.remote.wait(
            [handles[k] for k in remote],
            need if need > 0 else len(remote),
            timeout if need > 0 else 0.0,
        )
        return sorted(local + [remote[i] for i in ready])

    def pid(self, worker: int) -> int:
        return os.getpid() if worker == self.local_index else self.remote.pid(worker)

    def shutdown(self) -> None:
        self.local = None
        self.remote.shutdown()
