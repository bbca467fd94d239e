"""Ray plumbing: connecting to (or starting) a cluster and hosting EnvGroups in actors."""

from __future__ import annotations

import contextlib
import logging
import math
import os
import socket
import time
import traceback
import warnings
from collections.abc import Callable
from typing import Any

from chronogym.vector.driver import Outcome
from chronogym.vector.group import DisabledAutoresetError, EnvGroup

logger = logging.getLogger("chronogym")


def _check_reachable(address: str, timeout: float = 5.0) -> None:
    """Fail fast, naming the address, when nothing listens at a Ray head's host:port."""
    if address in ("auto", "local"):
        return
    target = address.split("://", 1)[-1]
    host, sep, port = target.rpartition(":")
    if not sep or not port.isdigit():
        raise ValueError(
            f"Ray address {address!r}: expected 'host:port', 'ray://host:port' or 'auto'"
        )
    try:
        with socket.create_connection((host.strip("[]"), int(port)), timeout=timeout):
            pass
    except OSError as error:
        raise ConnectionError(
            f"Ray address {address!r} is unreachable ({error}); expected a running Ray head "
            "(start one with `ray start --head`), or pass address=None for a local cluster"
        ) from None


def ensure_ray(address: str | None = None) -> None:
    """Connect to the cluster at ``address`` (or ``RAY_ADDRESS``), else start a local one.

    A local cluster is started without the dashboard. Does nothing when Ray is
    already initialized in this process.
    """
    import ray

    if address:
        _check_reachable(address)
    if ray.is_initialized():
        return
    address = address or os.environ.get("RAY_ADDRESS") or None
    if address:
        _check_reachable(address)
        ray.init(address=address, log_to_driver=True)
    else:
        ray.init(include_dashboard=False, log_to_driver=True)


#: Seconds to wait before each new try of a replacement worker that died before it was ready.
REPLACE_BACKOFF_S: tuple[float, ...] = (0.5, 1.0, 2.0, 4.0)


def start_with_retries(
    create: Callable[[], Any],
    wait_ready: Callable[[Any], None],
    errors: tuple[type[BaseException], ...] = (RuntimeError,),
) -> Any:
    """Create an actor and wait until it is ready; if it dies first, try again after
    ``REPLACE_BACKOFF_S`` pauses. A node that was just killed still looks alive to Ray for a
    few seconds, and a replacement placed there dies with it; a worker whose envs cannot be
    built fails every try and the last error is raised."""
    for pause in (*REPLACE_BACKOFF_S, None):
        actor = create()
        try:
            wait_ready(actor)
            return actor
        except errors as error:
            if pause is None:
                raise
            logger.warning("replacement worker died before it was ready (%s); retrying", error)
            time.sleep(pause)
    raise AssertionError("unreachable")


def cluster_cpus() -> float:
    """CPUs the connected Ray cluster offers in total."""
    import ray

    return float(ray.cluster_resources().get("CPU", 0.0))


def _free_cpu_share(num_workers: int, wanted: float, wait: float = 5.0) -> float:
    """CPUs per worker the cluster can grant now: ``wanted`` if free within ``wait`` s.

    Actors killed a moment ago give their CPUs back asynchronously, hence the wait.
    """
    import ray

    deadline = time.monotonic() + wait
    while True:
        free = float(ray.available_resources().get("CPU", 0.0))
        if free >= wanted * num_workers - 1e-9 or time.monotonic() > deadline:
            return min(wanted, math.floor(free / num_workers * 100) / 100)
        time.sleep(0.05)


def resolve_worker_cpus(num_cpus: float | None, num_workers: int) -> float:
    """CPUs per worker: validate an explicit value, or share the cluster evenly (at most 1)."""
    import ray

    total = cluster_cpus()
    if num_cpus is None:
        share = _free_cpu_share(num_workers, min(1.0, math.floor(total / num_workers * 100) / 100))
        if share < 0.01:
            free = float(ray.available_resources().get("CPU", 0.0))
            warnings.warn(
                f"the Ray cluster has {free:g} free CPUs for {num_workers} workers (other "
                "actors hold the rest); starting them with num_cpus=0, which oversubscribes. "
                "Pass num_cpus explicitly to reserve CPUs.",
                stacklevel=3,
            )
            return 0.0
        return min(1.0, share)
    if isinstance(num_cpus, bool) or not isinstance(num_cpus, (int, float)) or num_cpus < 0:
        raise ValueError(f"num_cpus={num_cpus!r}: expected a number >= 0 (fractions allowed)")
    if num_workers * num_cpus > total + 1e-9:
        raise ValueError(
            f"num_cpus={num_cpus} per worker x {num_workers} workers = "
            f"{num_workers * num_cpus:g} CPUs, but the Ray cluster has {total:g}; Ray would "
            "leave the extra workers pending forever. Expected num_cpus <= "
            f"{total / num_workers:.3g} (fractions allowed), fewer workers (raise "
            "envs_per_worker), or a bigger cluster"
        )
    return float(num_cpus)


def check_worker_gpus(num_gpus: float, num_workers: int) -> float:
    """Validate GPUs per worker against the cluster."""
    import ray

    if isinstance(num_gpus, bool) or not isinstance(num_gpus, (int, float)) or num_gpus < 0:
        raise ValueError(f"num_gpus={num_gpus!r}: expected a number >= 0 (fractions allowed)")
    total = float(ray.cluster_resources().get("GPU", 0.0))
    if num_gpus and num_workers * num_gpus > total + 1e-9:
        raise ValueError(
            f"num_gpus={num_gpus} per worker x {num_workers} workers needs "
            f"{num_workers * num_gpus:g} GPUs, but the Ray cluster has {total:g}"
        )
    return float(num_gpus)


#: Values of the ``scheduling`` option of RayVectorEnv and run_parallel_study.
SCHEDULING = ("default", "spread")


def actor_scheduling(scheduling: str) -> dict[str, str]:
    """Actor options for ``scheduling``: ``"default"`` (Ray packs actors, nothing is
    passed) or ``"spread"`` (``scheduling_strategy="SPREAD"``: over as many nodes as
    possible)."""
    if scheduling not in SCHEDULING:
        raise ValueError(f"scheduling={scheduling!r}: expected one of {SCHEDULING}")
    return {} if scheduling == "default" else {"scheduling_strategy": "SPREAD"}


class RayBackend:
    """One Ray actor per worker, each owning an EnvGroup for its whole life."""

    def __init__(
        self,
        num_cpus: float,
        num_gpus: float,
        start_timeout: float,
        step_timeout: float | None,
        scheduling: str = "default",
    ) -> None:
        import ray

        self._ray = ray
        self._actor_cls = ray.remote(EnvGroup).options(
            num_cpus=num_cpus,
            num_gpus=num_gpus,
            max_restarts=0,
            max_task_retries=0,
            **actor_scheduling(scheduling),
        )
        self.start_timeout = start_timeout
        self.step_timeout = step_timeout
        self.actors: list[Any] = []
        self._pids: list[int | None] = []

    def _wait_ready(self, actors: list[Any]) -> None:
        ray = self._ray
        refs = [actor.ready.remote() for actor in actors]
        try:
            ray.get(refs, timeout=self.start_timeout)
        except ray.exceptions.GetTimeoutError:
            for actor in actors:
                ray.kill(actor)
            raise TimeoutError(
                f"Ray workers did not start within {self.start_timeout} s; the cluster may lack "
                "the CPUs/GPUs they request (see `ray status`)"
            ) from None
        except ray.exceptions.RayActorError as error:
            for actor in actors:
                ray.kill(actor)
            raise RuntimeError(f"a Ray worker failed while building its envs:\n{error}") from None

    def start(self, group_kwargs: list[dict[str, Any]]) -> None:
        actors = [self._actor_cls.remote(**kwargs) for kwargs in group_kwargs]
        self._wait_ready(actors)
        self.actors = actors
        self._pids = [None] * len(actors)

    def replace(self, worker: int, kwargs: dict[str, Any]) -> None:
        with contextlib.suppress(Exception):  # already dead
            self._ray.kill(self.actors[worker], no_restart=True)
        actor = start_with_retries(
            lambda: self._actor_cls.remote(**kwargs), lambda new: self._wait_ready([new])
        )
        self.actors[worker] = actor
        self._pids[worker] = None

    def submit(self, worker: int, method: str, *args: Any) -> Any:
        return getattr(self.actors[worker], method).remote(*args)

    def gather(self, workers: list[int], handles: list[Any]) -> list[Outcome]:
        ray = self._ray
        try:
            return [Outcome(True, value) for value in ray.get(handles, timeout=self.step_timeout)]
        except Exception:
            pass
        outcomes = []
        for handle in handles:
            try:
                outcomes.append(Outcome(True, ray.get(handle, timeout=self.step_timeout)))
            except DisabledAutoresetError as error:
                outcomes.append(Outcome(False, error, str(error)))
            except ray.exceptions.RayTaskError as error:
                outcomes.append(Outcome(False, error.as_instanceof_cause(), str(error)))
            except ray.exceptions.GetTimeoutError:
                message = f"no answer within step_timeout={self.step_timeout} s"
                outcomes.append(Outcome(False, None, message, lost=True))
            except ray.exceptions.RayError as error:
                outcomes.append(Outcome(False, error, f"{type(error).__name__}: {error}", True))
            except Exception as error:
                outcomes.append(Outcome(False, error, traceback.format_exc(), lost=True))
        return outcomes

    def wait(self, handles: list[Any], num_returns: int, timeout: float | None) -> list[int]:
        """Indices of ``handles`` that have answered (``ray.wait``; a dead worker counts)."""
        ready, _ = self._ray.wait(handles, num_returns=num_returns, timeout=timeout)
        done = set(ready)
        return [k for k, handle in enumerate(handles) if handle in done]

    def pid(self, worker: int) -> int:
        if self._pids[worker] is None:
            self._pids[worker] = self._ray.get(self.actors[worker].pid.remote())
        return self._pids[worker]  # type: ignore[return-value]

    def shutdown(self) -> None:
        for actor in self.actors:
            with contextlib.suppress(Exception):
                self._ray.kill(actor, no_restart=True)
        self.actors = []
