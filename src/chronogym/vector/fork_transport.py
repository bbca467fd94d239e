"""The ``transport="fork"`` backend: workers forked from a warm process, on this machine.

Each worker is an EnvGroup in a process forked by the zygote
(:mod:`chronogym.vector.fork_zygote`), not a Ray actor: it starts in ~15 ms of CPU where a
Ray worker takes ~0.7 s, and it carries none of Ray's threads while it steps. It serves one
Unix socket in the driver's private directory exactly as a socket-transport worker does
(packed steps, the shared-memory barrier step), and every other call (reset, ``call``,
``render``...) travels over the same socket as a pickled ``(method, args)``
(:data:`~chronogym.vector.wire_format.CALL`). Everything the driver does with the answers
is the socket transport's, so the numbers are the same.

Without an ``address``, workers live on the driver's machine, and no Ray cluster is started
(Ray is not even imported). With one, the workers are spread over the cluster's live nodes
in proportion to their CPUs (:func:`spread_by_cpus`), in blocks of consecutive workers: those
of the driver's node forked here, those of every other node by that node's relay, from a
zygote of its own there (:meth:`~chronogym.vector.relay.NodeRelay.fork`), their steps and
calls batched into one relay call per node, and their barrier steps through a shared block per
node (:mod:`chronogym.vector.spread_step`), as the socket transport's relayed workers.

A worker that dies is seen as the end of its socket, and the zygote, its parent, names its
signal or exit code; a worker that stops answering for ``step_timeout`` is killed. Either is
replaced and its envs reported truncated, as with Ray's workers; one whose node is gone is
forked again on the live node with the most CPUs per worker.
"""

from __future__ import annotations

import contextlib
import functools
import os
import pickle
import re
import signal
import socket
import time
from dataclasses import dataclass
from typing import Any

from gymnasium.envs.registration import EnvSpec

from chronogym.vector.actor_transport import ActorGroup
from chronogym.vector.backend import Outcome
from chronogym.vector.fork_placement import cluster_nodes, spread_by_cpus
from chronogym.vector.fork_zygote import Zygote, fork_worker, how_ended
from chronogym.vector.relay import Relays
from chronogym.vector.relay_channel import ANSWERED
from chronogym.vector.socket_transport import (
    ACCEPT_TIMEOUT_S,
    DEATH_PROBE_S,
    RELAY_MARGIN_S,
    STEP_METHOD,
    SocketBackend,
    SockHandle,
    poller_of,
    serve_listener,
)
from chronogym.vector.wire_format import CALL, CALL_ANSWER, REQUEST, read_call_answer

ENTRY = re.compile(r"^[A-Za-z_][\w.]*:[A-Za-z_][\w.]*$")  # "module:attr", as an entry point
START_TIMEOUT_S = 120.0  # start_timeout=None: still give up on a worker that never listens


def serve_forked(payload: bytes, path: str, spin_s: float) -> None:
    """In a forked worker: listen at ``path``, build the EnvGroup pickled in ``payload``
    (an env that fails to build is reported by the first call), and serve the driver
    until it hangs up."""
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    listener.bind(path)  # first, so that the driver can connect while the envs build
    listener.listen(1)
    listener.settimeout(ACCEPT_TIMEOUT_S)
    group = ActorGroup(**pickle.loads(payload))  # trusted: own driver (its zygote's line)
    serve_listener(group, listener, path, spin_s)


def preload_modules(env_fns: list[Any]) -> list[str]:
    """The modules the envs' factories will import, for the zygote to import once: an id's
    entry point, a factory's module, and for a ``functools.partial`` those of its function,
    of the id it makes and of its arguments' types (a task object's class)."""
    names: list[str] = []
    for fn in env_fns:
        names += _modules_of(fn)
        if isinstance(fn, functools.partial):
            names += _modules_of(fn.func)
            for arg in [*fn.args, *fn.keywords.values()]:
                names += _modules_of(arg if isinstance(arg, (str, EnvSpec)) else type(arg))
    return [n for n in dict.fromkeys(names) if n not in ("__main__", "builtins")]


def _modules_of(target: Any) -> list[str]:
    """The module behind an id, a spec, an entry point or a callable (none if unknown)."""
    if isinstance(target, str) and not ENTRY.match(target):
        try:
            import gymnasium as gym

            target = gym.spec(target)
        except Exception:  # not an id (any other string argument)
            return []
    if isinstance(target, EnvSpec):  # its entry point, and a task it names ("module:Class")
        named = [v for v in target.kwargs.values() if isinstance(v, str) and ENTRY.match(v)]
        return [*_modules_of(target.entry_point), *(v.split(":")[0] for v in named)]
    if isinstance(target, str):
        return [target.split(":")[0]]
    module = getattr(target, "__module__", None)
    return [module] if isinstance(module, str) else []


@dataclass
class CallHandle(SockHandle):
    """A call other than the packed step, sent over a forked worker's socket."""


class ForkBackend(SocketBackend):
    """Workers forked by a zygote on this machine (and, on a cluster, by each other node's
    relay); every call over their sockets."""

    def __init__(
        self,
        start_timeout: float | None,
        step_timeout: float | None,
        *,
        spin_us: float | None = None,
        shared_memory: bool = True,
        relay_tcp: bool = True,
        modules: list[str] | None = None,
        cluster: bool = False,
    ) -> None:
        """``cluster``: spread the workers over the connected Ray cluster's nodes (else all
        on this machine, without Ray)."""
        self.start_timeout = start_timeout
        self.step_timeout = step_timeout
        self.actors: list[Any] = []  # no Ray actors: the inherited actor paths see none
        self._init_sockets(spin_us, shared_memory, relay_tcp)
        self._modules = list(modules or [])
        self._zygote: Zygote | None = None
        self._pids: list[int | None] = []
        self._paths: list[str] = []
        self.cluster = cluster
        self._nodes: list[str | None] = []  # each worker's node (None: this machine)
        self._payloads: dict[int, bytes] = {}  # to fork on other nodes at the next _connect
        if cluster:
            import ray

            self._ray = ray

    # -- processes ------------------------------------------------------------------------
    def start(self, group_kwargs: list[dict[str, Any]]) -> None:
        workers = len(group_kwargs)
        self._open_directory(workers)
        self._pids = [None] * workers
        self._paths = [""] * workers
        self._nodes = [None] * workers
        if self.cluster:
            here = self._ray.get_runtime_context().get_node_id()
            nodes = cluster_nodes()
            if not nodes:
                raise RuntimeError(
                    "transport='fork': no live node of the Ray cluster offers CPUs for the "
                    "workers (ray.nodes(); a node started with --num-cpus=0 gets none)"
                )
            placed = spread_by_cpus(workers, nodes)
            self._nodes = [None if node == here else node for node in placed]
            accept_timeout = self.start_timeout or START_TIMEOUT_S
            self._relays = Relays(self.spin_us, self.step_timeout, accept_timeout)
        try:
            for w, kwargs in enumerate(group_kwargs):
                self._fork(w, kwargs)
            self._connect(list(range(workers)))
        except BaseException:
            self.shutdown()
            raise

    def _fork(self, w: int, kwargs: dict[str, Any]) -> None:
        """Fork worker ``w`` here, or keep its payload for its node's relay (:meth:`_connect`)."""
        import cloudpickle  # as Ray sends an actor's arguments (lambdas, closures)

        payload = cloudpickle.dumps(kwargs)
        if self._nodes[w] is not None:
            self._payloads[w] = payload
            return
        self._fork_here(w, payload)

    def _fork_here(self, w: int, payload: bytes) -> None:
        """Fork worker ``w`` (its pickled EnvGroup arguments ``payload``) on this machine."""
        assert self._dir is not None
        self._opened += 1
        self._paths[w] = os.path.join(self._dir, f"w{w}-{self._opened}.sock")
        request = (payload, self._paths[w], self.spin_us * 1e-6)
        self._zygote, self._pids[w] = fork_worker(
            self._zygote, self._modules, self.start_timeout, request
        )

    def _replace_process(self, worker: int, kwargs: dict[str, Any]) -> None:
        self._kill(worker)
        if self._nodes[worker] is not None and self._nodes[worker] not in cluster_nodes():
            self._move(worker, set())  # its node is gone
        self._fork(worker, kwargs)

    def _move(self, worker: int, avoid: set[str]) -> bool:
        """Place ``worker`` on the live node, not in ``avoid``, with the most CPUs per worker
        placed there; False if there is none."""
        nodes = {n: cpus for n, cpus in cluster_nodes().items() if n not in avoid}
        if not nodes:
            return False
        here = self._ray.get_runtime_context().get_node_id()
        placed = [here if node is None else node for node in self._nodes]
        node = max(nodes, key=lambda n: nodes[n] / (1 + placed.count(n)))
        self._nodes[worker] = None if node == here else node
        return True

    def _kill(self, w: int) -> None:
        pid = self._pids[w]
        node = self._nodes[w] if w < len(self._nodes) else None
        if node is not None:  # its node's relay forked it
            relay = self._relays.by_node.get(node) if self._relays is not None else None
            if relay is not None:
                with contextlib.suppress(Exception):
                    relay.kill.remote(w)
        elif pid is not None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)

    def pid(self, worker: int) -> int:
        """Worker ``worker``'s process id (on its own node)."""
        return self._pids[worker]  # type: ignore[return-value]

    def node(self, worker: int) -> str | None:
        """The Ray node id of worker ``worker`` (None: the driver's machine)."""
        return self._nodes[worker]

    def shutdown(self) -> None:
        super().shutdown()  # closes every socket, and the relays (they kill their workers)
        for w in range(len(self._pids)):
            if self._nodes[w] is None:
                self._kill(w)
        self._pids = []
        if self._zygote is not None:
            self._zygote.close()
            self._zygote = None

    # -- connections ----------------------------------------------------------------------
    def _connect(self, workers: list[int]) -> None:
        """Connect to ``workers`` as they listen (those of other nodes: their relays fork
        and connect them), then wait until each has built its envs."""
        failed = self._fork_elsewhere([w for w in workers if self._nodes[w] is not None])
        here = [w for w in workers if self._nodes[w] is None and w not in failed]
        for w in here:
            if w in self._payloads:  # moved here from a node whose relay failed
                self._fork_here(w, self._payloads.pop(w))
            sock = self._socks[w] = self._dial(w)
            self._pollers[w] = poller_of(sock)
        self._all_here = None not in self._socks
        saved, self.step_timeout = self.step_timeout, self.start_timeout
        try:  # building the envs may take longer than a step
            outcomes = [self._resolve(self.submit(w, "ready")) for w in here]
        finally:
            self.step_timeout = saved
        failed.update({w: o.error for w, o in zip(here, outcomes, strict=True) if not o.ok})
        for w in sorted(failed):
            where = "" if self._nodes[w] is None else f" on node {self._nodes[w]}"
            raise RuntimeError(
                f"forked worker {w}{where} failed while building its envs "
                f"(start_timeout={self.start_timeout} s):\n{failed[w]}"
            )
        for w in here:
            self._socks[w].settimeout(self.step_timeout)  # type: ignore[union-attr]

    def _fork_elsewhere(self, workers: list[int]) -> dict[int, str]:
        """Have each node's relay fork and connect its ``workers`` (one call per node); a
        node whose relay fails (a node lost meanwhile) has its workers placed again, on the
        other live nodes (this machine's kept for :meth:`_connect` to fork). The workers
        that failed, with why."""
        assert self._relays is not None or not workers
        failed: dict[int, str] = {}
        avoid: set[str] = set()
        while workers:
            by_node: dict[str, list[int]] = {}
            for w in workers:
                by_node.setdefault(self._nodes[w], []).append(w)  # type: ignore[arg-type]
            spin_s, relays = self.spin_us * 1e-6, self._relays
            refs = {  # every node's relay forks at once
                node: relays.relay(node).fork.remote(  # type: ignore[union-attr]
                    [(w, self._payloads[w]) for w in group], spin_s, self._modules
                )
                for node, group in by_node.items()
            }
            workers = []
            for node, group in by_node.items():
                why = self._forked_on(node, refs[node], failed)
                if why is None:
                    continue
                avoid.add(node)
                for w in group:
                    if not self._move(w, avoid):
                        failed[w] = why
                        self._payloads.pop(w, None)
                    elif self._nodes[w] is not None:
                        workers.append(w)
        return failed

    def _forked_on(self, node: str, ref: Any, failed: dict[int, str]) -> str | None:
        """The answer of ``node``'s relay to its fork call ``ref``: the workers that failed go
        in ``failed``. Why the relay itself failed (then it is dropped), else None."""
        assert self._relays is not None
        timeout = None if self.start_timeout is None else 2 * self.start_timeout + RELAY_MARGIN_S
        try:
            replies = self._ray.get(ref, timeout=timeout)
        except Exception as error:
            self._relays.drop_node(node)
            return f"the relay of node {node} failed: {type(error).__name__}: {error}"
        for w, pid, (_, kind, value) in replies:
            self._pids[w] = pid
            del self._payloads[w]
            outcome = self._call_outcome(value) if kind == ANSWERED else None
            if outcome is not None and outcome.ok:
                self._relays.node_of[w] = node
            else:
                failed[w] = value if outcome is None else outcome.error
        return None

    def _dial(self, w: int) -> socket.socket:  # type: ignore[override]
        """A connection to worker ``w``'s socket, once it listens."""
        assert self._zygote is not None
        try:
            return self._zygote.connect(
                self._pids[w],  # type: ignore[arg-type]
                self._paths[w],
                self.start_timeout or START_TIMEOUT_S,
            )
        except RuntimeError as error:
            raise RuntimeError(
                f"forked worker {w} {error}; its error, if any, is above on stderr"
            ) from None

    def _death_cause(self, w: int) -> str:
        """How worker ``w``'s process ended, as its parent, the zygote, saw it."""
        pid, node = self._pids[w], self._nodes[w]
        if node is not None:
            return self._death_elsewhere(w, node)
        ended = None if pid is None else how_ended(self._zygote, pid, DEATH_PROBE_S)
        if ended is not None:
            return f"the worker process (pid {pid}) {ended}"
        return f"the worker process (pid {pid}) is alive but closed its socket"

    def _death_elsewhere(self, w: int, node: str) -> str:
        """How worker ``w``, forked on ``node`` by its relay, ended, as the relay says."""
        pid = self._pids[w]
        relay = self._relays.by_node.get(node) if self._relays is not None else None
        if relay is None:
            return f"the worker process (pid {pid} on node {node}) is lost with its node's relay"
        try:
            ended = self._ray.get(
                relay.ending.remote(w, DEATH_PROBE_S), timeout=DEATH_PROBE_S + RELAY_MARGIN_S
            )
        except Exception as error:
            return f"the worker process (pid {pid} on node {node}): its relay failed ({error})"
        if ended is not None:
            return f"the worker process (pid {pid} on node {node}) {ended}"
        return f"the worker process (pid {pid} on node {node}) is alive but closed its socket"

    # -- calls ----------------------------------------------------------------------------
    def submit(self, worker: int, method: str, *args: Any) -> Any:
        """The packed step as the socket transport sends it (through its node's relay for a
        worker of another node); anything else as a call."""
        sock, relayed = self._socks[worker], self._relayed(worker)
        if method == STEP_METHOD and (sock is not None or relayed):
            return super().submit(worker, method, *args)
        import cloudpickle

        request = cloudpickle.dumps((method, args))
        if relayed:
            return self._relays.submit(worker, request, CALL)  # type: ignore[union-attr]
        deadline = None if self.step_timeout is None else time.monotonic() + self.step_timeout
        handle = CallHandle(worker, deadline)
        if sock is None:
            handle.outcome = Outcome(False, None, f"worker {worker} is not connected", lost=True)
            return handle
        try:
            sock.sendall(REQUEST.pack(len(request), CALL) + request)
        except OSError as error:
            handle.outcome = self._lost(worker, error)
        return handle

    def _resolve(self, handle: SockHandle) -> Outcome:
        if not isinstance(handle, CallHandle):
            return super()._resolve(handle)
        if handle.outcome is None:
            try:
                handle.outcome = self._read_call(handle.worker, handle.deadline)
            except (OSError, EOFError) as error:
                handle.outcome = self._lost(handle.worker, error)
        return handle.outcome

    def _relayed_outcome(self, w: int, relayed: tuple[str, Any], kind: int = 0) -> Outcome:
        """A relayed worker's answer: a call's (``kind`` CALL) is its pickled Outcome."""
        status, value = relayed
        if kind == CALL and status == ANSWERED:
            return self._call_outcome(value)
        return super()._relayed_outcome(w, relayed, kind)

    @staticmethod
    def _call_outcome(answer: bytes) -> Outcome:
        """The Outcome in a call's answer as the worker wrote it (length, pickle)."""
        return pickle.loads(memoryview(answer)[CALL_ANSWER.size :])  # trusted: own worker

    def _read_call(self, w: int, deadline: float | None) -> Outcome:
        """One call's answer from worker ``w``'s socket: the Outcome it pickled."""
        sock = self._socks[w]
        if sock is None:
            raise EOFError(f"worker {w}'s socket was closed before its answer came")
        if deadline is not None:
            sock.settimeout(max(deadline - time.monotonic(), 1e-3))
        return self._call_outcome(read_call_answer(sock))
