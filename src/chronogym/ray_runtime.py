"""Ray plumbing shared by the vector envs and the parallel studies: connecting to (or
starting) a cluster, sizing actors, and starting actors that may die before they are ready."""

from __future__ import annotations

import importlib.abc
import importlib.util
import logging
import math
import os
import socket
import sys
import time
import warnings
from collections.abc import Callable
from typing import Any

from chronogym.validation import check_int, check_number

logger = logging.getLogger("chronogym")

#: The Ray logger that advises ``RAY_AUTH_MODE=disabled`` at every local start, and the
#: start of that one message. Token auth stays on (docs/guides/security.md); only the
#: advice to turn it off is dropped. Ray's other lines from that logger still print.
RAY_AUTH_LOGGER = "ray._private.authentication.authentication_token_setup"
RAY_AUTH_ADVICE = "Token authentication is enabled for this Ray cluster"

#: MuJoCo warnings that workers drop: deprecations in third-party models (Gymnasium's
#: half_cheetah.xml sets ``settotalmass``), which users cannot act on. Any other MuJoCo
#: warning is printed on stderr as one line.
MUJOCO_QUIET = ("compiler attribute 'settotalmass' is deprecated",)


class _DropRayAuthAdvice(logging.Filter):
    """Drops Ray's "Set RAY_AUTH_MODE=disabled to opt out" advice, nothing else."""

    def filter(self, record: logging.LogRecord) -> bool:
        return not str(record.msg).startswith(RAY_AUTH_ADVICE)


def quiet_ray_auth_advice() -> None:
    """Filter Ray's advice to disable token auth (idempotent; does not import Ray)."""
    ray_logger = logging.getLogger(RAY_AUTH_LOGGER)
    if not any(isinstance(f, _DropRayAuthAdvice) for f in ray_logger.filters):
        ray_logger.addFilter(_DropRayAuthAdvice())


def _mujoco_warning(message: str) -> None:
    """MuJoCo's warning callback in workers: drop ``MUJOCO_QUIET``, print the rest as one
    line (MuJoCo's own handler adds an empty line and writes MUJOCO_LOG.TXT to the cwd)."""
    if not message.startswith(MUJOCO_QUIET):
        print(f"MuJoCo warning: {message}", file=sys.stderr, flush=True)


class _QuietMujocoOnImport(importlib.abc.MetaPathFinder):
    """Installs :func:`_mujoco_warning` right after ``mujoco`` is first imported, so that a
    worker whose envs never use MuJoCo never pays for importing it."""

    def find_spec(self, name: str, path: Any = None, target: Any = None) -> Any:
        if name != "mujoco":
            return None
        sys.meta_path.remove(self)
        spec = importlib.util.find_spec(name)
        if spec is not None and spec.loader is not None:
            exec_module = spec.loader.exec_module

            def exec_and_quiet(module: Any) -> None:
                exec_module(module)
                module.set_mju_user_warning(_mujoco_warning)

            spec.loader.exec_module = exec_and_quiet  # type: ignore[method-assign]
        return spec


def quiet_mujoco_warnings() -> None:
    """Make :func:`_mujoco_warning` MuJoCo's warning handler: now if MuJoCo is imported,
    else as soon as it is (without importing it)."""
    if "mujoco" in sys.modules:
        sys.modules["mujoco"].set_mju_user_warning(_mujoco_warning)
    elif not any(isinstance(f, _QuietMujocoOnImport) for f in sys.meta_path):
        sys.meta_path.insert(0, _QuietMujocoOnImport())


quiet_ray_auth_advice()


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
            "(start one with `ray start --head`), or leave the address out (None) for a local "
            "cluster"
        ) from None


#: Nice value of the worker processes of a Ray cluster that chronogym starts. Ray's own
#: default (``RAY_worker_niceness``) is 15: its workers then lose their cores to any busy
#: process of normal priority, the driver included (README "Worker priority").
#: Measured by benchmarks/archive/throughput_priority.py (results/throughput_priority.json,
#: 16 Go1 envs, 2 workers, 2 cores): quiet, nice 0 gave 6,544 env-steps/s against 6,073 at
#: nice 15; beside one busy process 4,096 against 4,770 (why was not measured).
WORKER_NICENESS = 0


def check_worker_niceness(worker_niceness: int | None) -> int | None:
    """``worker_niceness`` validated: None (Ray's default, 15) or an integer in -20..19."""
    if worker_niceness is None:
        return None
    expected = (
        "an integer nice value in -20..19 (0: the driver's priority) or None for Ray's default (15)"
    )
    return check_int("worker_niceness", worker_niceness, low=-20, high=19, expected=expected)


def worker_niceness_env(worker_niceness: int | None) -> dict[str, str]:
    """Environment for Ray daemons so that they start workers at ``worker_niceness``
    (nothing for None, and nothing when ``RAY_worker_niceness`` is already set)."""
    if worker_niceness is None or "RAY_worker_niceness" in os.environ:
        return {}
    return {"RAY_worker_niceness": str(worker_niceness)}


def ensure_ray(address: str | None = None, worker_niceness: int | None = WORKER_NICENESS) -> None:
    """Connect to the cluster at ``address`` (or ``RAY_ADDRESS``), else start a local one.

    A local cluster is started without the dashboard, its workers at nice
    ``worker_niceness`` (default 0, the driver's priority; None: Ray's default 15;
    an explicit ``RAY_worker_niceness`` in the environment wins). A cluster that is
    joined keeps the priority it was started with. Does nothing when Ray is already
    initialized in this process.
    """
    import ray

    quiet_ray_auth_advice()
    check_worker_niceness(worker_niceness)
    if address:
        _check_reachable(address)
    if ray.is_initialized():
        return
    address = address or os.environ.get("RAY_ADDRESS") or None
    if address:
        _check_reachable(address)
        ray.init(address=address, log_to_driver=True)
        return
    extra = worker_niceness_env(worker_niceness)
    os.environ.update(extra)  # read by the raylet that ray.init starts
    try:
        ray.init(include_dashboard=False, log_to_driver=True, logging_level=logging.WARNING)
    finally:
        for key in extra:
            os.environ.pop(key, None)


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
    check_number("num_cpus", num_cpus, low=0, expected="a number >= 0 (fractions allowed)")
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

    check_number("num_gpus", num_gpus, low=0, expected="a number >= 0 (fractions allowed)")
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
