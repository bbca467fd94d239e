"""The ``transport="socket"`` backend: the barrier step over Unix domain sockets.

Workers are Ray actors as with the actor transport, created and replaced the
same way; each holds a :class:`SocketWorker` (an EnvGroup that can serve a
socket). Once a worker is ready and runs on the driver's node, it serves a
Unix socket in a private directory (``mkdtemp``, mode 0700: only
this user can connect; nothing on the network) from a daemon thread. Every
step of Box spaces -- the barrier ``step`` and ``send`` / ``recv`` -- then
writes one message per worker (its action bytes) and reads the answer from
the socket. A worker on another node steps through its node's relay
(:mod:`chronogym.vector.relay`): one Ray call per node carries the steps of all its
workers, which the relay serves over Unix sockets on that node. The barrier step goes
through shared memory: on the driver's node one block for every worker
(:mod:`chronogym.vector.shared_step`), and, with workers on other nodes, a block per node,
each other node's held by its relay (:mod:`chronogym.vector.spread_step`). Everything else
(reset, call, non-Box spaces) uses plain actor calls.

Waiting: a blocked read costs a wake-up, ~40 us per direction on a virtual
machine whose idle core must be woken, more than a cheap step. So each end
may first *spin* (poll the socket, yielding its core to any other runnable
process with ``sched_yield`` between polls), then block. The spin adapts
(:class:`AdaptiveSpin`): each end spins for twice its last wait, at most
``spin_us``, and not at all once a wait took longer than ``spin_us`` -- so
cheap steps (and a driver that sends the next actions at once) are caught
spinning, while dear steps and a driver that thinks between steps (a policy's
forward pass) leave the cores to the workers. ``spin_us=0`` gives plain
blocking reads (no CPU at all while waiting).

Messages: the packed-step format of :mod:`chronogym.vector.wire_format`.

Faults: EOF, a reset connection or ``step_timeout`` without an answer mark the
worker lost; the driver replaces it as with the plain transport and the
replacement's socket is connected again.
"""

from __future__ import annotations

import contextlib
import functools
import logging
import math
import os
import pickle
import select
import shutil
import socket
import tempfile
import threading
import time
import traceback
from dataclasses import dataclass
from typing import Any

import numpy as np

from chronogym.validation import check_number
from chronogym.vector.actor_transport import ActorBackend, ActorGroup
from chronogym.vector.backend import Outcome, gather_split
from chronogym.vector.group import EnvGroup
from chronogym.vector.info_rows import INFO_ROW
from chronogym.vector.profile import StepTimer
from chronogym.vector.relay import ANSWERED, LOST, SILENT, RelayHandle, Relays
from chronogym.vector.shared_step import (
    ATTACH,
    SharedAnswers,
    SharedLayout,
    SharedServer,
    SharedStep,
)
from chronogym.vector.spread_step import SpreadHandlers, SpreadStep, by_node
from chronogym.vector.wire_format import (
    ANSWER,
    CALL,
    REQUEST,
    StepFailure,
    answer_call,
    decode_answer,
    encode_answer,
    fill,
)
from chronogym.vector.worker_death import describe_death

STEP_METHOD = "step_packed"  # the driver's step method this backend sends over sockets
ACCEPT_TIMEOUT_S = 30.0  # a worker stops listening if the driver never connects
DEATH_PROBE_S = 10.0  # how long to ask Ray why a worker whose socket broke died
#: Default cap on the spin before a blocking read, µs (see the module docstring);
#: chosen with benchmarks/archive/socket_spin.py (results/socket_spin.json).
DEFAULT_SPIN_US = 250.0
MIXED_POLL_S = 1e-3  # recv over socket and actor-call workers: how often to look at each
RELAY_MARGIN_S = 10.0  # a relay's call may take this much longer than step_timeout

logger = logging.getLogger("chronogym")


def check_spin_us(spin_us: float | None) -> float:
    """``spin_us`` validated (None: :data:`DEFAULT_SPIN_US`), in µs."""
    if spin_us is None:
        return DEFAULT_SPIN_US
    expected = (
        f"None (default {DEFAULT_SPIN_US:g}) or microseconds in [0, 1e6] to spin before a "
        "blocking socket read (0: never spin)"
    )
    return check_number("spin_us", spin_us, low=0, high=1e6, expected=expected)


class AdaptiveSpin:
    """How long one end spins before it blocks: twice its last wait, at most ``cap_s``.

    A wait longer than ``cap_s`` turns spinning off until a wait is short again.
    """

    def __init__(self, cap_s: float) -> None:
        self.cap_s = cap_s
        self.last_s = 0.5 * cap_s  # the first wait spins the whole cap
        self._start = 0.0

    def spin(self, poller: select.poll) -> None:
        """Spin until readable or out of budget; the wait is timed until :meth:`arrived`."""
        self._start = time.perf_counter()
        if self.last_s < self.cap_s:
            spin_until_readable(poller, min(self.cap_s, 2.0 * self.last_s))

    def arrived(self) -> None:
        """The message started arriving: remember how long this wait took."""
        self.last_s = time.perf_counter() - self._start


def spin_until_readable(poller: select.poll, spin_s: float) -> bool:
    """Poll (yielding the core between polls) for up to ``spin_s``; is the socket readable?"""
    if spin_s <= 0:
        return False
    end = time.perf_counter() + spin_s
    while not poller.poll(0):
        if time.perf_counter() >= end:
            return False
        os.sched_yield()
    return True


def poller_of(sock: socket.socket, *fds: int) -> select.poll:
    """A poll object over ``sock`` (and ``fds``) for reading."""
    poller = select.poll()
    for fd in (sock, *fds):
        poller.register(fd, select.POLLIN)
    return poller


# -- worker side ------------------------------------------------------------------------------
class SocketWorker(ActorGroup):
    """An actor's EnvGroup that can also serve its packed steps over a Unix socket."""

    def open_socket(self, path: str, driver_node: str, spin_us: float) -> bool:
        """On ``driver_node``: serve steps at Unix socket ``path`` (else False), spinning
        ``spin_us`` before each blocking read."""
        import ray

        if ray.get_runtime_context().get_node_id() != driver_node:
            return False
        serve_socket(self, path, spin_us)
        return True

    def node_id(self) -> str:
        """The Ray node this worker runs on."""
        import ray

        return ray.get_runtime_context().get_node_id()


def serve_socket(group: EnvGroup, path: str, spin_us: float = DEFAULT_SPIN_US) -> None:
    """Listen at ``path`` and answer ``group``'s steps from a daemon thread."""
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    listener.bind(path)
    listener.listen(1)
    listener.settimeout(ACCEPT_TIMEOUT_S)
    args = (group, listener, path, spin_us * 1e-6)
    threading.Thread(target=serve_listener, args=args, daemon=True).start()


def serve_listener(group: EnvGroup, listener: socket.socket, path: str, spin_s: float) -> None:
    """Accept the driver (once), then answer its step requests until it hangs up."""
    try:
        conn, _ = listener.accept()
    except OSError:
        return
    finally:
        listener.close()
        with contextlib.suppress(OSError):
            os.unlink(path)
    with conn:
        conn.settimeout(None)
        _serve_conn(group, conn, spin_s)


def _serve_conn(group: EnvGroup, conn: socket.socket, spin_s: float) -> None:
    """Answer step requests until the driver hangs up (EOF) or the connection fails: over
    the socket, and, once the driver attached one, through shared memory
    (:mod:`chronogym.vector.shared_step`)."""
    head = memoryview(bytearray(REQUEST.size))
    data = memoryview(bytearray(256))
    plain, spinner = poller_of(conn), AdaptiveSpin(spin_s)
    step_shared = functools.partial(_step_bytes, group, raw_infos=True)  # (bytes, timed)
    shared: SharedServer | None = None
    go_pollers: dict[int, select.poll] = {}
    try:
        while True:
            poller = plain if shared is None else go_pollers[shared.go_fd]
            spinner.spin(poller)  # while stepping, the next request comes soon
            ready = dict(poller.poll())
            spinner.arrived()
            if shared is not None and shared.go_fd in ready:
                if shared.pending():
                    shared.serve(step_shared)
                    if shared.on_socket:
                        conn.sendall(shared.on_socket)
                    continue
                if ready[shared.go_fd] & select.POLLHUP:  # the driver closed the shared step
                    shared.close()
                    shared = None
                    continue
            if conn.fileno() not in ready:
                continue
            fill(conn, head, 0, REQUEST.size)
            size, kind = REQUEST.unpack(head)
            if kind == ATTACH:
                if shared is not None:
                    shared.close()
                shared = _attach(conn, size)
                if shared is not None:
                    go_pollers = {fd: poller_of(conn, fd) for fd in shared.go_fds}
                continue
            if size > len(data):
                data = memoryview(bytearray(size))
            fill(conn, data, 0, size)
            if kind == CALL:  # a forked worker's other calls (transport="fork")
                conn.sendall(answer_call(group, data[:size]))
                continue
            conn.sendall(encode_answer(_step_bytes(group, data[:size], bool(kind))))
    except (OSError, EOFError):
        return
    finally:
        if shared is not None:
            shared.close()


def _attach(conn: socket.socket, size: int) -> SharedServer | None:
    """Take the shared step the driver hands over (its layout, then the block's and the
    pipes' file descriptors); reply one byte: 1 taken, 0 not (the driver then closes the
    socket and calls this worker through Ray)."""
    message, fds, _, _ = socket.recv_fds(conn, size, 8)
    while len(message) < size:
        more = conn.recv(size - len(message))
        if not more:
            raise EOFError("the driver closed its socket while attaching a shared step")
        message += more
    try:
        layout, w, gen, role = pickle.loads(message)  # trusted: own worker (its driver's socket)
        server = SharedServer(layout, w, gen, role, fds)
    except Exception:
        logger.warning("chronogym: no shared-memory step in this worker", exc_info=True)
        for fd in fds:
            with contextlib.suppress(OSError):
                os.close(fd)
        conn.sendall(b"\x00")
        return None
    conn.sendall(b"\x01")
    return server


def _step_bytes(
    group: EnvGroup, action_bytes: memoryview, timed: bool, raw_infos: bool = False
) -> Any:
    """``EnvGroup.step_packed`` (which holds the group's lock): the typed answer, not an
    actor's tuple form; an error as a StepFailure."""
    try:
        return EnvGroup.step_packed(group, action_bytes, timed, raw_infos)
    except Exception as error:
        return StepFailure(error, traceback.format_exc())


# -- driver side ------------------------------------------------------------------------------
@dataclass
class SockHandle:
    """One worker's step sent over its socket; ``outcome`` once read."""

    worker: int
    deadline: float | None
    outcome: Outcome | None = None


class SocketBackend(ActorBackend):
    """ActorBackend whose steps go over Unix sockets to workers on this node."""

    worker_cls = SocketWorker

    def __init__(
        self,
        *args: Any,
        spin_us: float | None = None,
        shared_memory: bool = True,
        relay_tcp: bool = True,
        **kwargs: Any,
    ) -> None:
        super().__init__(*args, **kwargs)
        self._init_sockets(spin_us, shared_memory, relay_tcp)

    def _init_sockets(self, spin_us: float | None, shared_memory: bool, relay_tcp: bool) -> None:
        """The socket side's state: nothing connected yet."""
        self.spin_us = check_spin_us(spin_us)
        self.shared_memory = shared_memory  # barrier steps through shared memory, if it can
        self.relay_tcp = relay_tcp  # other nodes' relays answer them over TCP, if they can
        #: Wake the workers in groups (None: when there are enough and each has a core,
        #: :func:`~chronogym.vector.shared_step.wants_tree`); read at the first step.
        self.wake_tree: bool | None = None
        self._shared: SharedStep | None = None  # every worker on this node: one block
        self._spread: SpreadStep | None = None  # some on other nodes: a block per node
        self._dir: str | None = None
        self._socks: list[socket.socket | None] = []
        self._all_here = False  # every worker connected over a socket (no None in _socks)
        self._pollers: list[select.poll | None] = []
        self._spinners: list[AdaptiveSpin] = []
        self._recv_spinner = AdaptiveSpin(0.0)
        self._bufs: list[bytearray] = []
        self._opened = 0  # sockets opened so far (unique file names)
        self._relays: Relays | None = None  # workers on other nodes: their node's relay

    # -- connections ----------------------------------------------------------------------
    def start(self, group_kwargs: list[dict[str, Any]]) -> None:
        super().start(group_kwargs)
        self._open_directory(len(self.actors))
        self._relays = Relays(self.spin_us, self.step_timeout, self.start_timeout or 120.0)
        self._connect(list(range(len(self.actors))))

    def _open_directory(self, workers: int) -> None:
        """The private socket directory, and room for ``workers`` unconnected workers."""
        self._dir = tempfile.mkdtemp(prefix="chronogym-")
        os.chmod(self._dir, 0o700)
        self._socks = [None] * workers
        self._pollers = [None] * workers
        self._spinners = [AdaptiveSpin(self.spin_us * 1e-6) for _ in range(workers)]
        self._recv_spinner = AdaptiveSpin(self.spin_us * 1e-6)
        self._bufs = [bytearray(4096) for _ in range(workers)]

    @property
    def socket_dir(self) -> str | None:
        """The private directory of the workers' sockets (None once shut down)."""
        return self._dir

    def connected(self) -> list[bool]:
        """Which workers step over a socket of this node (the others: relays or plain calls)."""
        return [s is not None for s in self._socks]

    def relayed(self) -> list[bool]:
        """Which workers step through their node's relay (:mod:`chronogym.vector.relay`)."""
        node_of = self._relays.node_of if self._relays is not None else {}
        return [w in node_of for w in range(len(self._socks))]

    def _connect(self, workers: list[int]) -> None:
        """Ask ``workers`` to listen (those on this node) and connect to them."""
        if self._dir is None:
            return
        node = self._ray.get_runtime_context().get_node_id()
        paths = {}
        for w in workers:
            self._opened += 1
            paths[w] = os.path.join(self._dir, f"w{w}-{self._opened}.sock")
        refs = {w: self.actors[w].open_socket.remote(paths[w], node, self.spin_us) for w in workers}
        elsewhere = []
        for w in workers:
            sock = self._socks[w] = self._dial(refs[w], paths[w])
            self._pollers[w] = None if sock is None else poller_of(sock)
            if sock is None:
                elsewhere.append(w)
        self._all_here = None not in self._socks
        if elsewhere:
            self._connect_relayed(elsewhere)

    def _connect_relayed(self, workers: list[int]) -> None:
        """Workers on other nodes step through their node's relay (plain calls if that fails)."""
        assert self._relays is not None
        nodes = {w: self.actors[w].node_id.remote() for w in workers}
        found = {}
        for w, ref in nodes.items():
            with contextlib.suppress(Exception):  # a dead worker is found by its next call
                found[w] = (self.actors[w], self._ray.get(ref, timeout=self.start_timeout))
        self._relays.connect(found, self.start_timeout)

    def _dial(self, listening: Any, path: str) -> socket.socket | None:
        """A connection to the socket a worker opened; None (plain calls) if it could not."""
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        try:
            if not self._ray.get(listening, timeout=self.start_timeout):
                sock.close()
                return None  # another node: plain actor calls
            sock.settimeout(self.start_timeout)
            sock.connect(path)
            with contextlib.suppress(OSError):  # the worker unlinks it too, once it accepted
                os.unlink(path)
        except Exception as error:  # a worker that died now is found by its next plain call
            logger.warning(
                "chronogym: no socket to worker at %s (%s); using actor calls", path, error
            )
            sock.close()
            return None
        sock.settimeout(self.step_timeout)
        return sock

    def _disconnect(self, w: int) -> None:
        if self._shared is not None:
            self._shared.attached.discard(w)
        if self._spread is not None:
            self._spread.stale = True
        if self._relays is not None:
            self._relays.forget(w)
        sock, self._socks[w], self._pollers[w] = self._socks[w], None, None
        self._all_here = False
        if sock is not None:
            with contextlib.suppress(OSError):
                sock.close()

    def replace(self, worker: int, kwargs: dict[str, Any]) -> None:
        self._disconnect(worker)
        self._replace_process(worker, kwargs)
        self._connect([worker])
        if self._shared is None:
            return
        if self._socks[worker] is None:  # it landed on another node: a spread step next
            self._close_shared()
        elif not self._attach(worker):
            self._close_shared(f"its replacement worker {worker} could not attach")

    def _replace_process(self, worker: int, kwargs: dict[str, Any]) -> None:
        """A new process for ``worker``, not yet connected (here: a new Ray actor)."""
        super().replace(worker, kwargs)

    def shutdown(self) -> None:
        for w in range(len(self._socks)):
            self._disconnect(w)
        self._close_shared()
        self._close_spread()
        if self._relays is not None:
            self._relays.shutdown()
            self._relays = None
        super().shutdown()
        if self._dir is not None:
            shutil.rmtree(self._dir, ignore_errors=True)
            self._dir = None

    # -- the shared-memory barrier step -------------------------------------------------------
    def shared_step(
        self,
        actions: np.ndarray,
        slices: list[tuple[int, int]],
        obs_row: int,
        timer: StepTimer | None = None,
    ) -> SharedAnswers | None:
        """A barrier step of every worker through shared memory
        (:mod:`chronogym.vector.shared_step`), for a caller whose :meth:`shares_steps` said
        yes; None when the block cannot be opened (then: one socket message per worker).
        ``timer`` (``profile_steps()``) times the driver's node's block; None with workers
        on other nodes (a profiled step then goes as messages)."""
        if not self._all_here:  # workers on other nodes: a block per node
            if timer is not None:
                return None
            return self._spread_step(actions, slices, obs_row)
        if self._spread is not None:  # every worker is on this node again
            self._close_spread()
        if self._shared is None and not self._open_shared(actions, slices, obs_row):
            return None
        assert self._shared is not None
        deadline = None if self.step_timeout is None else time.monotonic() + self.step_timeout
        return self._shared.step(
            actions, self._socks, deadline, self._lost, self._read, split_infos=True, timer=timer
        )

    def shares_steps(self) -> bool:
        """Can the barrier step go through shared memory (on, and every worker connected
        here or to its node's relay)? Cheap: asked before each step's actions are prepared."""
        if not self.shared_memory:
            return False
        if self._all_here or (self._spread is not None and not self._spread.stale):
            return True
        relayed = self._relays.node_of if self._relays is not None else {}
        return all(s is not None or w in relayed for w, s in enumerate(self._socks))

    def _spread_step(
        self, actions: np.ndarray, slices: list[tuple[int, int]], obs_row: int
    ) -> SharedAnswers | None:
        """The barrier step through every node's block (:mod:`chronogym.vector.spread_step`)."""
        assert self._relays is not None
        if self._spread is not None and self._spread.stale:
            self._close_spread()
        if self._spread is None:
            self._spread = self._open_spread(actions, slices, obs_row)
            if self._spread is None:
                return None
        deadline = None if self.step_timeout is None else time.monotonic() + self.step_timeout
        relay_timeout = None if self.step_timeout is None else self.step_timeout + RELAY_MARGIN_S
        handlers = SpreadHandlers(self._lost, self._read, self._relayed_outcome, relay_timeout)
        return self._spread.step(actions, self._socks, deadline, self._relays, handlers)

    def _open_spread(
        self, actions: np.ndarray, slices: list[tuple[int, int]], obs_row: int
    ) -> SpreadStep | None:
        """Attach every worker to its node's block; None (and off for good) if one fails."""
        assert self._relays is not None
        groups = by_node(slices, self._relays.node_of)
        options = {
            "directory": self._dir,
            "spin_s": self.spin_us * 1e-6,
            "tree": self.wake_tree,
            "timeout": self.start_timeout,
            "step_timeout": self.step_timeout,
            "lines": self.relay_tcp,
        }
        action_row = actions.nbytes // slices[-1][1]
        spread = SpreadStep.open(
            groups, self._relays, self._socks, action_row, obs_row, options, self._disconnect
        )
        if spread is None:
            self.shared_memory = False
            logger.warning("chronogym: no shared-memory step across nodes; using messages")
        return spread

    def _close_spread(self) -> None:
        if self._spread is not None:
            self._spread.close(self._relays)
            self._spread = None

    def _open_shared(
        self, actions: np.ndarray, slices: list[tuple[int, int]], obs_row: int
    ) -> bool:
        """Make the block and attach every worker; False (and off for good) if one fails."""
        action_row = actions.nbytes // slices[-1][1]
        layout = SharedLayout(tuple(slices), action_row, obs_row, info_row=INFO_ROW)
        try:
            self._shared = SharedStep(layout, self._dir, self.spin_us * 1e-6, self.wake_tree)
        except OSError as error:
            self.shared_memory = False
            logger.warning("chronogym: no shared-memory step (%s); using sockets", error)
            return False
        for w in range(len(self._socks)):
            if not self._attach(w):
                self._close_shared(f"worker {w} could not attach")
                return False
        return True

    def _attach(self, w: int) -> bool:
        """Hand worker ``w`` the shared step; on failure its socket is closed (calls)."""
        sock = self._socks[w]
        assert self._shared is not None
        if sock is None:
            return False
        attached = self._shared.attach(w, sock, self.start_timeout)
        if attached:
            sock.settimeout(self.step_timeout)
        else:
            self._disconnect(w)
        return attached

    def _close_shared(self, why: str = "") -> None:
        if why:
            logger.warning("chronogym: shared-memory step turned off: %s; using sockets", why)
            self.shared_memory = False
        if self._shared is not None:
            self._shared.close()
            self._shared = None

    # -- steps ----------------------------------------------------------------------------
    def submit(self, worker: int, method: str, *args: Any) -> Any:
        """A step of a connected worker goes over its socket; anything else, plain."""
        sock = self._socks[worker]
        if method == STEP_METHOD and sock is None and self._relayed(worker):
            timed = int(bool(args[1])) if len(args) > 1 else 0
            return self._relays.submit(worker, args[0], timed)  # type: ignore[union-attr]
        if method != STEP_METHOD or sock is None:
            return super().submit(worker, method, *args)
        deadline = None if self.step_timeout is None else time.monotonic() + self.step_timeout
        handle = SockHandle(worker, deadline)
        data, timed = args[0], bool(args[1]) if len(args) > 1 else False
        try:
            sock.sendall(REQUEST.pack(len(data), timed) + data)
        except OSError as error:
            handle.outcome = self._lost(worker, error)
        return handle

    def _lost(self, w: int, error: BaseException) -> Outcome:
        """Worker ``w``'s socket failed: the worker is lost (Ray's reason, when it has one)."""
        self._disconnect(w)
        if isinstance(error, TimeoutError):
            message = f"no answer within step_timeout={self.step_timeout} s"
        else:
            message = (
                f"{self._death_cause(w)}\n(worker {w}'s socket: {type(error).__name__}: {error})"
            )
        return Outcome(False, None, message, lost=True)

    def _death_cause(self, w: int) -> str:
        """Why Ray says worker ``w`` died (as the plain transport reports it)."""
        try:
            self._ray.get(self.actors[w].ready.remote(), timeout=DEATH_PROBE_S)
        except Exception as error:
            return describe_death(f"{type(error).__name__}: {error}")
        return "the worker's process is alive but its socket thread stopped"

    def _resolve(self, handle: SockHandle) -> Outcome:
        """Read ``handle``'s answer (once)."""
        if handle.outcome is None:
            w = handle.worker
            try:
                handle.outcome = self._read(w, handle.deadline)
            except (OSError, EOFError) as error:
                handle.outcome = self._lost(w, error)
        return handle.outcome

    def _read(self, w: int, deadline: float | None) -> Outcome:
        """One answer from worker ``w``'s socket: spin, then blocking ``recv_into``."""
        sock, poller = self._socks[w], self._pollers[w]
        if sock is None or poller is None:
            raise EOFError(f"worker {w}'s socket was closed before its answer came")
        spinner = self._spinners[w]
        spinner.spin(poller)
        if deadline is not None:
            sock.settimeout(max(deadline - time.monotonic(), 1e-3))
        view = memoryview(self._bufs[w])
        got = fill(sock, view, 0, ANSWER.size)
        spinner.arrived()
        status, *sizes = ANSWER.unpack_from(view)
        total = ANSWER.size + sum(sizes)
        if total > len(view):  # grow the buffer, keeping what was read
            bigger = bytearray(total)
            bigger[:got] = view[:got]
            self._bufs[w] = bigger
            view = memoryview(bigger)
        fill(sock, view, got, total)
        return decode_answer(status, sizes, view)

    def _answered(self, handle: SockHandle) -> bool:
        """Has ``handle``'s worker answered (or hung up)? Reads the answer if so."""
        if handle.outcome is None:
            poller = self._pollers[handle.worker]
            if poller is not None and not poller.poll(0):
                return False
            self._resolve(handle)
        return True

    def gather(self, workers: list[int], handles: list[Any]) -> list[Outcome]:
        self._flush()
        return gather_split(
            workers, handles, (SockHandle, RelayHandle), self._resolve_any, super().gather
        )

    def _resolve_any(self, handle: SockHandle | RelayHandle) -> Outcome:
        if isinstance(handle, SockHandle):
            return self._resolve(handle)
        return self._resolve_relayed(handle)

    def _relayed(self, worker: int) -> bool:
        return self._relays is not None and worker in self._relays.node_of

    def _flush(self) -> None:
        """Send the steps queued for relays: one call per node."""
        if self._relays is not None and self._relays.pending:
            self._relays.flush()

    def _resolve_relayed(self, handle: RelayHandle) -> Outcome:
        """A relayed worker's answer, decoded as if read from its socket here (once)."""
        if handle.outcome is None:
            assert self._relays is not None
            timeout = None if self.step_timeout is None else self.step_timeout + RELAY_MARGIN_S
            self._relays.resolve(handle.call, timeout)
            answers = handle.call.answers or {}
            if handle.call.failure is not None:
                relayed: tuple[str, Any] = (LOST, handle.call.failure)
            else:
                relayed = answers.get(handle.worker, (LOST, "no answer from the relay"))
            handle.outcome = self._relayed_outcome(handle.worker, relayed, handle.kind)
        return handle.outcome

    def _relayed_outcome(self, w: int, relayed: tuple[str, Any], kind: int = 0) -> Outcome:
        """Worker ``w``'s (status, value) from its relay, as if read from its socket here
        (``kind``: the request's; a step's here)."""
        relay_status, value = relayed
        if relay_status == ANSWERED:
            status, *sizes = ANSWER.unpack_from(value)
            return decode_answer(status, sizes, memoryview(value))
        return self._lost_relayed(w, value, silent=relay_status == SILENT)

    def _lost_relayed(self, w: int, why: str, silent: bool) -> Outcome:
        """A relayed worker's step failed: the worker is lost (with Ray's reason, unless it is
        silent: a hung worker would not answer Ray's probe either)."""
        self._disconnect(w)
        if silent:
            return Outcome(False, None, why, lost=True)
        return Outcome(False, None, f"{self._death_cause(w)}\n({why})", lost=True)

    def wait(self, handles: list[Any], num_returns: int, timeout: float | None) -> list[int]:
        """Indices of ``handles`` that have answered: sockets by ``poll``, calls (and relays'
        calls) by ``ray.wait``."""
        self._flush()
        socks = {k: h for k, h in enumerate(handles) if isinstance(h, SockHandle)}
        refs = {
            k: h.call.ref if isinstance(h, RelayHandle) else h
            for k, h in enumerate(handles)
            if k not in socks
        }
        if not socks:
            return sorted(self._ready(refs, num_returns, timeout))
        if num_returns == len(handles) and timeout is None:  # a barrier: read every answer
            for h in socks.values():
                self._resolve(h)
            if refs:
                self._ready(refs, len(refs), None)
            return list(range(len(handles)))
        deadline = None if timeout is None else time.monotonic() + timeout
        done: set[int] = set()
        spinner: AdaptiveSpin | None = self._recv_spinner
        while True:
            done |= {k for k, h in socks.items() if k not in done and self._answered(h)}
            if refs:
                done |= self._ready(refs, len(refs), 0)
            if len(done) >= num_returns or (deadline is not None and time.monotonic() >= deadline):
                return sorted(done)
            budget = None if deadline is None else max(0.0, deadline - time.monotonic())
            if refs:
                budget = MIXED_POLL_S if budget is None else min(budget, MIXED_POLL_S)
            self._poll([h.worker for k, h in socks.items() if k not in done], spinner, budget)
            spinner = None  # spin once per wait

    def _ready(self, refs: dict[int, Any], num_returns: int, timeout: float | None) -> set[int]:
        """Keys of ``refs`` whose call has answered; several keys may share one relay call."""
        unique = list(dict.fromkeys(refs.values()))
        ready = ActorBackend.wait(self, unique, min(num_returns, len(unique)), timeout)
        answered = {id(unique[i]) for i in ready}
        return {k for k, ref in refs.items() if id(ref) in answered}

    def _poll(
        self, workers: list[int], spinner: AdaptiveSpin | None, timeout: float | None
    ) -> None:
        """Until one of ``workers``' sockets is readable or ``timeout``: spin, then block."""
        poller = select.poll()
        for w in workers:
            sock = self._socks[w]
            if sock is not None:
                poller.register(sock, select.POLLIN)
        if spinner is not None:
            spinner.spin(poller)
        ready = poller.poll(None if timeout is None else math.ceil(timeout * 1000))
        if spinner is not None and ready:
            spinner.arrived()
