"""RayVectorEnv: a Gymnasium vector env whose simulations live in Ray actors (or, with
``transport="fork"``, in forked processes, on this machine or a cluster's nodes)."""

from __future__ import annotations

import math
import os
import socket
from collections.abc import Sequence
from typing import Any

from gymnasium.envs.registration import EnvSpec
from gymnasium.vector import AutoresetMode

from chronogym.ray_runtime import (
    WORKER_NICENESS,
    actor_scheduling,
    check_worker_gpus,
    cluster_cpus,
    ensure_ray,
    resolve_worker_cpus,
)
from chronogym.validation import check_bool, check_int, check_number
from chronogym.vector.actor_transport import ActorBackend
from chronogym.vector.backend import Backend, EnvFactory
from chronogym.vector.checks import normalize_env_fns
from chronogym.vector.driver_registry import DriverRegistry, script_registered_ids
from chronogym.vector.driver_worker import DriverWorkerBackend
from chronogym.vector.env_errors import check_env_errors
from chronogym.vector.fork_placement import check_fork_arguments, forks_here_only
from chronogym.vector.fork_transport import ForkBackend, preload_modules
from chronogym.vector.shared_step import usable_cpus
from chronogym.vector.socket_transport import SocketBackend, check_spin_us
from chronogym.vector.worker_vector_env import WorkerVectorEnv

#: The ``transport`` names and the backend class of each.
TRANSPORTS: dict[str, type[ActorBackend]] = {
    "socket": SocketBackend,
    "actor": ActorBackend,
    "fork": ForkBackend,
}


def default_transport() -> str:
    """The transport of ``transport=None``: "socket" where Unix sockets exist, else "actor"."""
    return "socket" if hasattr(socket, "AF_UNIX") else "actor"


def check_transport(transport: str | None) -> str:
    """``transport`` validated (None: the default)."""
    if transport is None:
        return default_transport()
    if transport == "fork" and not (hasattr(os, "fork") and hasattr(socket, "AF_UNIX")):
        raise ValueError(
            "transport='fork' needs os.fork and Unix sockets, which this platform lacks; "
            f"expected 'actor' or None (the default, {default_transport()!r})"
        )
    if transport not in TRANSPORTS:
        raise ValueError(
            f"transport={transport!r}: expected one of {tuple(TRANSPORTS)} ('socket': Unix sockets "
            "to workers on this node; 'actor': Ray actor calls; 'fork': workers forked on this "
            f"machine, no Ray) or None (the default, {default_transport()!r})"
        )
    return transport


class RayVectorEnv(WorkerVectorEnv):
    """A drop-in ``gymnasium.vector.VectorEnv`` running its envs in Ray actors.

    Args:
        env_fns: a registered env id, one env factory, or a list of factories
            (one per env, as for ``SyncVectorEnv``).
        num_envs: number of envs (required with an id or a single factory).
        envs_per_worker: simulations per actor; one remote call steps them all.
            Default: spread the envs over the cluster's CPUs
            (``ceil(num_envs / CPUs)``).
        num_cpus: CPUs per actor (fractions allowed). Default: the cluster's
            CPUs shared evenly, at most 1 each.
        num_gpus: GPUs per actor (fractions allowed). Default 0.
        address: Ray cluster address; default ``RAY_ADDRESS``, else a local
            cluster is started (no dashboard).
        worker_niceness: nice value of the workers of a local cluster this
            call starts: 0 (default), the driver's own priority; None keeps
            Ray's default of 15, at which the workers yield their cores to any
            busy process. A cluster that is joined (or already running) keeps
            its own; start it with ``RAY_worker_niceness=0 ray start ...``.
        scheduling: ``"default"`` (Ray's own placement: nodes with room,
            the driver's first) or ``"spread"`` (``scheduling_strategy="SPREAD"``: the
            workers go to as many nodes as possible).
        autoreset_mode: Gymnasium's ``AutoresetMode`` (NEXT_STEP default).
        max_restarts: restarts allowed per env before WorkerCrashLoopError
            (-1: no limit): a worker process lost, or (``env_errors="restart"``)
            an env's exception, each count one.
        invalid_action: ``"raise"`` (default) or ``"clip"`` for NaN/Inf actions.
        env_errors: what a Python exception raised by an env's own code
            (construction, ``reset``, ``step``, ``call``, ``render``) does.
            ``"raise"`` (default, as Gymnasium's vector envs): it is raised
            here, from the call that met it, as its own class (or
            ``WorkerEnvError`` where it does not pickle), naming the env
            index and id, with the worker's traceback chained; the call's
            results are lost, so the next ``step`` needs a ``reset()``.
            ``"restart"`` (long unattended runs): the env is rebuilt,
            reseeded and reported truncated with ``info["worker_error"]``, up
            to ``max_restarts`` times; one that fails again right after its
            rebuild ends the run with ``WorkerCrashLoopError``. A worker
            process that dies is replaced either way.
        step_timeout: seconds a worker may take for one call before it is
            treated as lost and replaced (default: wait forever).
        start_timeout: seconds the workers may take to start and build their
            envs before the cluster is taken to lack room for them (an error
            says so). Default 120.
        env_kwargs: keyword arguments for ``gymnasium.make`` when ``env_fns``
            is an id.
        transport: how the barrier ``step`` reaches the workers. ``"socket"``
            (the default, ``None``, where Unix sockets exist): workers on the
            driver's node serve a Unix domain socket in a private (mode 0700)
            temporary directory and each step's bytes (``step``, ``send`` /
            ``recv``) go over it, several times cheaper than a Ray call;
            workers on other nodes use plain calls. ``"actor"``: one plain Ray
            actor call per worker. See ``docs/performance/vector.md``. Box spaces
            only; other calls (reset, ``call``, other spaces) always use plain
            actor calls, and faults are handled the same way with both
            transports. ``"fork"``: workers are not Ray actors; every worker is
            a process forked from one warm process that imported the envs'
            modules once (:mod:`chronogym.vector.fork_transport`), and every
            call goes over its socket. A worker starts in ~15 ms of CPU
            instead of a Ray worker's ~0.7 s (64 MuJoCo cart-poles on 2 cores:
            7 s to the first reset instead of 57-60 s) and carries no Ray
            threads while it steps. Same numbers and fault handling. Without
            ``address`` (or ``RAY_ADDRESS``), every worker is on this machine and
            Ray is not used at all; with one, the workers are spread over the cluster's live nodes
            in proportion to their CPUs, each other node's forked by its relay.
            Nothing is reserved for them, so ``scheduling``,
            ``worker_niceness`` and the CPUs and GPUs per worker keep their
            defaults (a ValueError names one that does not).
        spin_us: ``transport="socket"`` or ``"fork"`` only: µs each end of a socket spins
            (polling, yielding its core to other processes) before it blocks
            on a read; an answer caught while spinning saves the wake-up of
            an idle core (~40 µs each way on a VM). Default 250; 0 never spins
            (no CPU at all while waiting).
        shared_memory: ``transport="socket"`` or ``"fork"`` only: the barrier ``step`` goes
            through one shared memory block and one wake-up for all workers
            on a node (:mod:`chronogym.vector.shared_step`): the driver's for
            its node, each other node's relay's for that node, one message
            per node (:mod:`chronogym.vector.spread_step`), so the driver's
            CPU per worker no longer holds a message each way; ``send`` /
            ``recv`` still use one socket message per worker, and so does
            ``profile_steps()`` with workers on other nodes (on the driver's
            node it times the block). Default True; False: messages only.
            Same numbers either way.
        relay_tcp: ``transport="socket"`` or ``"fork"`` with workers on other nodes only:
            each node's relay answers the shared-memory barrier ``step`` over
            a direct TCP connection to the driver, not a Ray call per node
            and step (:mod:`chronogym.vector.relay_channel`; a Ray call costs
            the driver ~1.5 ms of CPU). The relay listens on an ephemeral
            port of its node for that one connection and admits only the
            driver, which holds a token handed over through Ray. A node that
            cannot be reached that way (a firewall) stays on Ray calls.
            Default True; False: Ray calls only, no port opened. Same numbers
            either way.
        driver_worker: the driver steps the last worker's envs itself, in its
            own process, while the Ray workers step theirs
            (:mod:`chronogym.vector.driver_worker`): one process and one round
            trip fewer, for small machines and cheap steps. Same numbers; but
            an env that crashes its process (a segfault) then ends the run, and
            ``worker_pids()`` lists the driver's own pid for that worker.

    ``step`` is one barrier over every worker. For algorithms that tolerate it,
    stepping can also be asynchronous (EnvPool-style):

    - ``send(actions, env_ids=None)`` starts stepping some envs; ``actions``
      rows follow ``env_ids``. One remote call steps a whole worker, so
      ``env_ids`` must hold every env of each worker it touches (else a
      ValueError names the missing ids), and none may be in flight already.
    - ``recv(min_envs=None, timeout=None)`` returns as soon as the workers
      that answered hold ``min_envs`` envs (default: every env in flight),
      with every env answered by then: ``(obs, rewards, terminations,
      truncations, infos, env_ids)``, rows in ascending ``env_ids``, infos
      batched over those rows as Gymnasium does. On ``timeout`` it raises
      ``RecvTimeoutError`` and the envs stay in flight.
    - ``step_async(actions)`` / ``step_wait(timeout=None)``: ``step`` in two
      halves, as in Gymnasium's ``AsyncVectorEnv``; the same numbers as ``step``.
    - ``async_reset(seed=None, options=None)`` resets every env (seeds as in
      ``reset``); results come through ``recv`` with reward 0, flags False.
    - Nothing is drained implicitly: while envs are in flight, ``step``,
      ``reset``, ``step_async``, ``call``, ``get_attr``, ``set_attr`` and
      ``render`` raise ``EnvsInFlightError`` (a Gymnasium
      ``AlreadyPendingCallError``); ``close`` is allowed.
    - Autoreset (NEXT_STEP, SAME_STEP) runs per env inside its worker, so each
      env's trajectory depends only on its seed and its own actions, never on
      arrival order. A worker found dead when its answer is collected, or
      silent for ``step_timeout`` s after its send, is replaced and its envs
      come back truncated, as with ``step``.
    """

    def __init__(
        self,
        env_fns: str | EnvFactory | Sequence[str | EnvFactory],
        num_envs: int | None = None,
        *,
        envs_per_worker: int | None = None,
        num_cpus: float | None = None,
        num_gpus: float = 0,
        address: str | None = None,
        worker_niceness: int | None = WORKER_NICENESS,
        scheduling: str = "default",
        autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP,
        max_restarts: int = 3,
        invalid_action: str = "raise",
        step_timeout: float | None = None,
        start_timeout: float = 120.0,
        env_kwargs: dict[str, Any] | None = None,
        env_errors: str = "raise",
        transport: str | None = None,
        spin_us: float | None = None,
        shared_memory: bool = True,
        relay_tcp: bool = True,
        driver_worker: bool = False,
    ) -> None:
        count = len(normalize_env_fns(env_fns, num_envs))
        self.transport = transport = check_transport(transport)
        options: dict[str, Any] = {}
        check_bool("shared_memory", shared_memory)
        check_bool("relay_tcp", relay_tcp)
        if transport == "fork":
            check_fork_arguments(
                num_cpus=num_cpus,
                num_gpus=num_gpus,
                worker_niceness=worker_niceness,
                scheduling=scheduling,
            )
        if transport in ("socket", "fork"):
            options["spin_us"] = check_spin_us(spin_us)
            options["shared_memory"] = shared_memory
            options["relay_tcp"] = relay_tcp
        elif spin_us is not None:
            raise ValueError(
                f"spin_us={spin_us!r} with transport={transport!r}: spin_us applies to "
                "transport='socket' or 'fork' only; expected spin_us=None"
            )
        if envs_per_worker is not None:
            expected = f"an integer with 1 <= envs_per_worker <= num_envs={count}"
            check_int("envs_per_worker", envs_per_worker, low=1, high=count, expected=expected)
        check_bool("driver_worker", driver_worker)
        if step_timeout is not None:
            check_number("step_timeout", step_timeout, low=1e-9, expected="None or seconds > 0")
        actor_scheduling(scheduling)  # validate before starting Ray
        check_env_errors(env_errors)
        forked = transport == "fork"
        local = forked and forks_here_only(address)  # forked on this machine: no Ray at all
        if not local:
            ensure_ray(address, worker_niceness)
        if envs_per_worker is None:
            cpus = max(1, usable_cpus() if local else int(cluster_cpus()))
            envs_per_worker = math.ceil(count / cpus)
        num_actors = math.ceil(count / envs_per_worker) - int(driver_worker)
        self.driver_worker = driver_worker
        backend: Backend
        if forked:  # no Ray: nothing reserved per worker
            self.num_cpus_per_worker, self.num_gpus_per_worker = 0.0, 0.0
            modules = preload_modules(normalize_env_fns(env_fns, num_envs))
            backend = ForkBackend(
                start_timeout, step_timeout, modules=modules, cluster=not local, **options
            )
        else:
            self.num_cpus_per_worker = resolve_worker_cpus(num_cpus, max(num_actors, 1))
            self.num_gpus_per_worker = check_worker_gpus(num_gpus, max(num_actors, 1))
            backend = TRANSPORTS[transport](
                self.num_cpus_per_worker,
                self.num_gpus_per_worker,
                start_timeout,
                step_timeout,
                scheduling=scheduling,
                **options,
            )
        if driver_worker:
            backend = DriverWorkerBackend(backend)
        super().__init__(
            env_fns,
            num_envs,
            backend=backend,
            envs_per_worker=envs_per_worker,
            autoreset_mode=autoreset_mode,
            max_restarts=max_restarts,
            invalid_action=invalid_action,
            env_kwargs=env_kwargs,
            env_errors=env_errors,
        )

    def _driver_registry(self, env_fns: list[Any]) -> DriverRegistry | None:
        """The specs of the ids this script registered, for factories that make them in a
        worker (:mod:`chronogym.vector.driver_registry`); None when no factory or no id."""
        ids = script_registered_ids()
        if not ids or all(isinstance(fn, (str, EnvSpec)) for fn in env_fns):
            return None
        if self.transport == "fork":  # forked workers see this machine's modules
            import cloudpickle
        else:
            from ray import cloudpickle  # honours register_pickle_by_value
        return DriverRegistry(cloudpickle.dumps, ids)
