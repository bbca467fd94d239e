"""Per-node relays: one Ray call per node and step, not one per worker.

A worker on the driver's node gets its steps over a Unix socket
(:mod:`chronogym.vector.socket_transport`). A worker on another node cannot: a Unix socket
does not cross machines, and a plain Ray actor call costs the driver ~0.4-0.8 ms of CPU per
worker and step, which caps a 64-worker cluster run at ~20 vector steps/s whatever the
physics costs (``benchmarks/results/scaling.json``). So each other node gets a
:class:`NodeRelay`, a Ray actor pinned to that node. The driver sends it the action bytes of
all its node's workers in *one* actor call; the relay writes them to the workers' Unix
sockets on its node (a private mode-0700 folder there, as on the driver's node), reads the
answers and returns them as raw bytes, which the driver decodes as if it had read them from
a socket (:func:`~chronogym.vector.wire_format.decode_answer`). The driver's work per step
is then one call per node plus a decode per worker.

The barrier step goes further (:mod:`chronogym.vector.spread_step`): a relay holds a
shared-memory step for its node's workers (:meth:`NodeRelay.open_shared`, the driver's own
block of :mod:`chronogym.vector.shared_step`, opened on this node), and
:meth:`NodeRelay.shared_step` returns the rows of all of them as four arrays, plus the
answers of the few workers with more to say: nothing per worker on the driver's side. Those
steps go over a direct TCP line to the driver (:meth:`NodeRelay.open_line`,
:mod:`chronogym.vector.relay_channel`), not a Ray call each.

Security: the driver and a relay talk through Ray's own (authenticated) channel, and for
the barrier step over a TCP line that the relay accepts only from the peer holding a token
it handed out through Ray; a relay and its workers through Unix sockets in a private folder
of their node.

Forked workers (``transport="fork"`` with an ``address``): a relay also forks its node's
workers itself (:meth:`NodeRelay.fork`), from a zygote of its own on that node
(:mod:`chronogym.vector.fork_zygote`), so they are not Ray actors: their other calls (reset,
``call``...) travel through the relay as pickled calls over the same sockets (kind
:data:`~chronogym.vector.wire_format.CALL`), one Ray call per node for a whole batch of them.

Faults: a worker whose socket fails (EOF, a reset, ``step_timeout``) is reported lost by the
relay, and the driver replaces it as any lost worker, then connects its replacement. A relay
that dies (its node is lost) makes every worker it served lost; a new relay is started for
their replacements' nodes.
"""

from __future__ import annotations

import contextlib
import functools
import os
import pickle
import shutil
import signal
import socket
import tempfile
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, TypeVar

import numpy as np

from chronogym.vector.fork_zygote import fork_worker, how_ended
from chronogym.vector.info_rows import INFO_ROW, pack_node_rows
from chronogym.vector.relay_channel import (
    ANSWERED,
    LOST,
    ROWS,
    SILENT,
    RelayAnswer,
    RelayLine,
    SharedRows,
)
from chronogym.vector.shared_step import SharedAnswers, SharedLayout, SharedStep
from chronogym.vector.wire_format import (
    ANSWER,
    CALL,
    REQUEST,
    encode_answer,
    fill,
    read_call_answer,
)

T = TypeVar("T")
FORK_DEATH_PROBE_S = 2.0  # how long a relay waits to learn how a forked worker that hung up ended


def locked(method: Callable[..., T]) -> Callable[..., T]:
    """Run ``method`` under the relay's lock: its TCP line's thread steps too, so one thing
    at a time touches the sockets and the block."""

    @functools.wraps(method)
    def under_lock(self: NodeRelay, *args: Any, **kwargs: Any) -> T:
        with self.lock:
            return method(self, *args, **kwargs)

    return under_lock


class NodeRelay:
    """A Ray actor on one node: steps that node's workers over their Unix sockets."""

    def __init__(self, spin_us: float, step_timeout: float | None, accept_timeout: float) -> None:
        self.spin_us = spin_us
        self.step_timeout = step_timeout
        self.accept_timeout = accept_timeout
        self.dir = tempfile.mkdtemp(prefix="chronogym-relay-")
        os.chmod(self.dir, 0o700)
        self.socks: dict[int, socket.socket] = {}
        self.bufs: dict[int, bytearray] = {}
        self.opened = 0
        self.shared: SharedStep | None = None  # the shared-memory step of some workers here
        self.shared_workers: list[int] = []  # its workers, in the order of its block
        self.line: RelayLine | None = None  # the driver's TCP line for the shared step
        self.lock = threading.RLock()  # see :func:`locked`
        self.zygote: Any = None  # forks this node's workers (transport="fork"), once asked
        self.forked: dict[int, int] = {}  # forked worker -> its pid

    def node_id(self) -> str:
        import ray

        return ray.get_runtime_context().get_node_id()

    def pid(self) -> int:
        return os.getpid()

    def connect(self, worker: int, actor: Any) -> bool:
        """Ask ``actor`` (worker ``worker``, on this node) to serve a socket here; dial it."""
        import ray

        self.disconnect(worker)
        self.opened += 1
        path = os.path.join(self.dir, f"w{worker}-{self.opened}.sock")
        if not ray.get(actor.open_socket.remote(path, self.node_id(), self.spin_us)):
            return False  # not on this node after all
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            sock.settimeout(self.accept_timeout)
            sock.connect(path)
        except OSError:
            sock.close()
            return False
        sock.settimeout(self.step_timeout)
        with self.lock:
            self.socks[worker] = sock
            self.bufs[worker] = bytearray(4096)
        return True

    @locked
    def disconnect(self, worker: int) -> None:
        sock = self.socks.pop(worker, None)
        self.bufs.pop(worker, None)
        if sock is not None:
            with contextlib.suppress(OSError):
                sock.close()

    @locked
    def step(self, requests: list[tuple[int, bytes, int]]) -> list[RelayAnswer]:
        """Send each worker its request (``kind``: a step, 0 or 1 timed, or a forked
        worker's :data:`~chronogym.vector.wire_format.CALL`), then read every answer (its
        raw bytes, as the worker wrote them)."""
        failed: dict[int, RelayAnswer] = {}
        for worker, data, kind in requests:
            sock = self.socks.get(worker)
            if sock is None:
                failed[worker] = (worker, LOST, "the relay holds no socket to this worker")
                continue
            try:
                sock.sendall(REQUEST.pack(len(data), kind) + data)
            except OSError as error:
                failed[worker] = self._failed(worker, error)
        answers: list[RelayAnswer] = []
        for worker, _, kind in requests:
            if worker in failed:
                answers.append(failed[worker])
                continue
            try:
                if kind == CALL:  # a forked worker's call: its answer as it wrote it
                    answers.append((worker, ANSWERED, read_call_answer(self.socks[worker])))
                else:
                    answers.append((worker, ANSWERED, self._read(worker)))
            except (OSError, EOFError) as error:
                answers.append(self._failed(worker, error))
        return answers

    # -- forked workers (transport="fork") ------------------------------------------------
    @locked
    def fork(
        self, requests: list[tuple[int, bytes]], spin_s: float, modules: list[str]
    ) -> list[tuple[int, int | None, RelayAnswer]]:
        """Fork each ``(worker, payload)`` on this node from this relay's zygote (started at
        the first fork, ``modules`` imported once), connect to it, and ask it ``ready``
        (its envs built, within ``accept_timeout``): per worker, its pid (None if it never
        started) and the ready call's answer, as :meth:`step` gives it."""
        started: dict[int, tuple[int, str]] = {}
        replies: dict[int, tuple[int, int | None, RelayAnswer]] = {}
        for worker, payload in requests:
            self.disconnect(worker)
            self.kill(worker)
            self.opened += 1
            path = os.path.join(self.dir, f"w{worker}-{self.opened}.sock")
            try:
                request = (payload, path, spin_s)
                self.zygote, pid = fork_worker(self.zygote, modules, self.accept_timeout, request)
            except (OSError, EOFError, RuntimeError) as error:
                why = f"could not fork worker {worker} on its node: {error}"
                replies[worker] = (worker, None, (worker, LOST, why))
                continue
            self.forked[worker] = pid
            started[worker] = (pid, path)
        ready = pickle.dumps(("ready", ()))
        for worker, (pid, path) in started.items():
            try:
                sock = self.zygote.connect(pid, path, self.accept_timeout)
            except RuntimeError as error:
                replies[worker] = (worker, pid, (worker, LOST, f"forked worker {worker} {error}"))
                continue
            sock.settimeout(self.accept_timeout)  # building its envs may outlast a step
            self.socks[worker], self.bufs[worker] = sock, bytearray(4096)
        asked = [(w, ready, CALL) for w in started if w not in replies]
        for answer in self.step(asked):
            worker, status, value = answer
            pid = started[worker][0]
            if status != ANSWERED:  # it died building its envs: name how, as its zygote saw
                ended = None
                with contextlib.suppress(OSError, EOFError):
                    ended = self.zygote.ending(pid, FORK_DEATH_PROBE_S)
                if ended is not None:
                    answer = (worker, status, f"the worker process (pid {pid}) {ended} ({value})")
            replies[worker] = (worker, pid, answer)
            if worker in self.socks:
                self.socks[worker].settimeout(self.step_timeout)
        return [replies[worker] for worker, _ in requests]

    @locked
    def ending(self, worker: int, wait_s: float) -> str | None:
        """How forked worker ``worker``'s process ended (None: it runs), as
        :func:`~chronogym.vector.fork_zygote.how_ended` says."""
        pid = self.forked.get(worker)
        return None if pid is None else how_ended(self.zygote, pid, wait_s)

    @locked
    def kill(self, worker: int) -> None:
        """SIGKILL forked worker ``worker`` (a replacement is forked next)."""
        pid = self.forked.pop(worker, None)
        if pid is not None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)

    @locked
    def open_shared(
        self,
        workers: list[int],
        slices: list[tuple[int, int]],
        action_row: int,
        obs_row: int,
        tree: bool | None,
    ) -> bool:
        """Attach ``workers`` (env rows ``slices`` of a new block, in this order) to one
        shared-memory barrier step on this node; False if one could not attach (its socket
        is then closed, so its next step reports it lost)."""
        self.close_shared()
        try:
            layout = SharedLayout(tuple(slices), action_row, obs_row, info_row=INFO_ROW)
            shared = SharedStep(layout, self.dir, self.spin_us * 1e-6, tree)
        except OSError:
            return False
        self.shared, self.shared_workers = shared, list(workers)
        for i, worker in enumerate(workers):
            sock = self.socks.get(worker)
            if sock is None or not shared.attach(i, sock, self.accept_timeout):
                self.disconnect(worker)
                self.close_shared()
                return False
            sock.settimeout(self.step_timeout)
        return True

    @locked
    def open_line(self) -> tuple[tuple[str, int], bytes] | None:
        """A TCP listener on this node for one driver connection that serves the shared
        step (:mod:`chronogym.vector.relay_channel`): its address and the token the driver
        must send; None without a shared step, or if no listener could be opened."""
        import ray

        if self.shared is None:
            return None
        self.close_line()
        try:
            line = RelayLine(ray.util.get_node_ip_address(), self.accept_timeout)
        except OSError:
            return None
        layout = self.shared.layout
        line.serve(layout.num_envs, layout.action_row, self.shared_step)
        self.line = line
        return line.address, line.token

    @locked
    def close_line(self) -> None:
        line, self.line = self.line, None
        if line is not None:
            line.close()

    @locked
    def shared_step(self, actions: np.ndarray | memoryview) -> SharedRows:
        """One barrier step of the attached workers (``actions``: their rows' bytes, in
        block order); the line's thread calls it too."""
        shared, workers = self.shared, self.shared_workers
        if shared is None:
            raise RuntimeError("this relay holds no shared step: open_shared() first")
        deadline = None if self.step_timeout is None else time.monotonic() + self.step_timeout
        answers = shared.step(
            actions,
            [self.socks.get(worker) for worker in workers],
            deadline,
            lost=lambda i, error: self._failed(workers[i], error),
            read=lambda i, _deadline: (workers[i], ANSWERED, self._read(workers[i])),
            decode=lambda i, view: (workers[i], ANSWERED, bytes(view)),
        )
        rows = (answers.obs, answers.rewards, answers.terminations, answers.truncations)
        return (*rows, self._extras(answers, shared.layout.slices, workers))

    @staticmethod
    def _extras(
        answers: SharedAnswers, slices: tuple[tuple[int, int], ...], workers: list[int]
    ) -> list[RelayAnswer]:
        """What the driver hears beyond the rows: the workers' whole answers, and the node's
        infos as records of one schema where every worker wrote them so (else each such
        worker's answer whole, its infos as columns)."""
        extras = list(answers.extras.values())
        if answers.rows is not None:
            extras.append((0, ROWS, pack_node_rows(*answers.rows)))
        for i in answers.infos:
            answer = answers.outcome(i, *slices[i]).value
            extras.append((workers[i], ANSWERED, encode_answer(answer)))
        return extras

    @locked
    def close_shared(self) -> None:
        """Close the shared step and its line (its workers go back to steps over their
        sockets)."""
        self.close_line()
        if self.shared is not None:
            self.shared.close()
        self.shared, self.shared_workers = None, []

    def _read(self, worker: int) -> bytes:
        sock, view = self.socks[worker], memoryview(self.bufs[worker])
        got = fill(sock, view, 0, ANSWER.size)
        _, *sizes = ANSWER.unpack_from(view)
        total = ANSWER.size + sum(sizes)
        if total > len(view):
            bigger = bytearray(total)
            bigger[:got] = view[:got]
            self.bufs[worker] = bigger
            view = memoryview(bigger)
        fill(sock, view, got, total)
        return bytes(view[:total])

    def _failed(self, worker: int, error: BaseException) -> RelayAnswer:
        self.disconnect(worker)
        if isinstance(error, TimeoutError):
            why = f"no answer within step_timeout={self.step_timeout} s (through its node's relay)"
            return worker, SILENT, why
        why = f"worker {worker}'s socket on its node failed: {type(error).__name__}: {error}"
        return worker, LOST, why

    def shutdown(self) -> None:
        self.close_shared()
        for worker in list(self.socks):
            self.disconnect(worker)
        for worker in list(self.forked):
            self.kill(worker)
        if self.zygote is not None:
            self.zygote.close()
            self.zygote = None
        shutil.rmtree(self.dir, ignore_errors=True)


@dataclass
class RelayCall:
    """One relay call in flight: the steps of some of its node's workers."""

    node: str
    ref: Any = None  # the ObjectRef of NodeRelay.step
    answers: dict[int, tuple[str, Any]] | None = None  # worker -> (ANSWERED..., bytes or why)
    failure: str | None = None  # the call itself failed (the relay or its node died)


@dataclass
class RelayHandle:
    """One worker's step, sent through its node's relay."""

    worker: int
    data: bytes
    kind: int  # REQUEST's flag byte: 0 or 1 (a step, timed), or CALL (a forked worker's)
    call: RelayCall
    outcome: Any = None


@dataclass
class Relays:
    """The driver's relays, one per node, and which workers each serves."""

    spin_us: float
    step_timeout: float | None
    accept_timeout: float
    by_node: dict[str, Any] = field(default_factory=dict)  # node id -> NodeRelay actor
    node_of: dict[int, str] = field(default_factory=dict)  # relayed worker -> node id
    pending: dict[str, list[RelayHandle]] = field(default_factory=dict)  # not sent yet
    lineless: set[str] = field(default_factory=set)  # nodes whose TCP line failed to open

    def relay(self, node: str) -> Any:
        """The relay of ``node``, started there if there is none yet."""
        if node not in self.by_node:
            import ray
            from ray.util.scheduling_strategies import NodeAffinitySchedulingStrategy

            actor_cls = ray.remote(NodeRelay).options(
                num_cpus=0,
                max_restarts=0,
                scheduling_strategy=NodeAffinitySchedulingStrategy(node, soft=False),
            )
            self.by_node[node] = actor_cls.remote(
                self.spin_us, self.step_timeout, self.accept_timeout
            )
        return self.by_node[node]

    def connect(self, workers: dict[int, tuple[Any, str]], timeout: float | None) -> list[int]:
        """Connect each worker (its actor, its node) to its node's relay; the ones connected."""
        import ray

        refs = {
            w: self.relay(node).connect.remote(w, actor) for w, (actor, node) in workers.items()
        }
        done = []
        for w, ref in refs.items():
            try:
                ok = ray.get(ref, timeout=timeout)
            except Exception:
                ok = False
            if ok:
                self.node_of[w] = workers[w][1]
                done.append(w)
        return done

    def forget(self, worker: int) -> None:
        """Worker ``worker`` is gone or replaced: its relay drops its socket."""
        node = self.node_of.pop(worker, None)
        if node is not None and node in self.by_node:
            with contextlib.suppress(Exception):
                self.by_node[node].disconnect.remote(worker)

    def submit(self, worker: int, data: bytes, kind: int) -> RelayHandle:
        """Queue a request of ``worker`` (``kind``: see :class:`RelayHandle`); it leaves with
        its node's others at :meth:`flush`."""
        node = self.node_of[worker]
        queued = self.pending.setdefault(node, [])
        call = queued[0].call if queued else RelayCall(node)
        handle = RelayHandle(worker, bytes(data), kind, call)
        queued.append(handle)
        return handle

    def flush(self) -> None:
        """Send every queued step: one call per node."""
        for node, handles in self.pending.items():
            requests = [(h.worker, h.data, h.kind) for h in handles]
            handles[0].call.ref = self.by_node[node].step.remote(requests)
        self.pending = {}

    def resolve(self, call: RelayCall, timeout: float | None) -> None:
        """Wait for ``call``'s answers (once); a failed call marks the relay dead."""
        if call.answers is not None or call.failure is not None:
            return
        import ray

        try:
            answers = ray.get(call.ref, timeout=timeout)
        except Exception as error:
            call.failure = f"the relay of node {call.node} failed: {type(error).__name__}: {error}"
            self.drop_node(call.node)
            return
        call.answers = {worker: (status, value) for worker, status, value in answers}

    def drop_node(self, node: str) -> None:
        """Forget a dead relay (and its node's workers: they are replaced)."""
        actor = self.by_node.pop(node, None)
        if actor is not None:
            import ray

            with contextlib.suppress(Exception):
                ray.kill(actor, no_restart=True)
        for worker in [w for w, n in self.node_of.items() if n == node]:
            del self.node_of[worker]

    def shutdown(self) -> None:
        import ray

        refs = [actor.shutdown.remote() for actor in self.by_node.values()]
        with contextlib.suppress(Exception):
            ray.get(refs, timeout=5.0)
        for actor in self.by_node.values():
            with contextlib.suppress(Exception):
                ray.kill(actor, no_restart=True)
        self.by_node, self.node_of, self.pending = {}, {}, {}
