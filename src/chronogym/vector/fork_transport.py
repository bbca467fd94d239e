"""The ``transport="fork"`` backend: workers forked from a warm process, on this machine.

Each worker is an EnvGroup in a process forked by the zygote
(:mod:`chronogym.vector.fork_zygote`), not a Ray actor: it starts in ~15 ms of CPU where a
Ray worker takes ~0.7 s, and it carries none of Ray's threads while it steps. It serves one
Unix socket in the driver's private directory exactly as a socket-transport worker does
(packed steps, the shared-memory barrier step), and every other call (reset, ``call``,
``render``...) travels over the same socket as a pickled ``(method, args)``
(:data:`~chronogym.vector.wire_format.CALL`). Everything the driver does with the answers
is the socket transport's, so the numbers are the same.

Workers live on the driver's machine only, and no Ray cluster is started. A worker that
dies is seen as the end of its socket, and the zygote, its parent, names its signal or exit
code; a worker that stops answering for ``step_timeout`` is killed. Either is replaced and
its envs reported truncated, as with Ray's workers.
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

from chronogym.ray_runtime import WORKER_NICENESS
from chronogym.vector.actor_transport import ActorGroup
from chronogym.vector.backend import Outcome
from chronogym.vector.fork_zygote import Zygote
from chronogym.vector.socket_transport import (
    ACCEPT_TIMEOUT_S,
    DEATH_PROBE_S,
    STEP_METHOD,
    SocketBackend,
    SockHandle,
    _poller,
    _serve,
)
from chronogym.vector.wire_format import CALL, CALL_ANSWER, REQUEST, fill

ENTRY = re.compile(r"^[A-Za-z_][\w.]*:[A-Za-z_][\w.]*$")  # "module:attr", as an entry point
DIAL_PAUSE_S = 1e-3  # between tries to connect to a worker that is still starting
START_TIMEOUT_S = 120.0  # start_timeout=None: still give up on a worker that never listens


def check_fork_arguments(**given: Any) -> None:
    """Reject the Ray arguments that mean nothing to forked workers, by name."""
    meaningless = {
        "num_cpus": None,
        "num_gpus": 0,
        "address": None,
        "worker_niceness": WORKER_NICENESS,
        "scheduling": "default",
    }
    for name, value in given.items():
        if value != meaningless[name]:
            raise ValueError(
                f"{name}={value!r} with transport='fork': forked workers run on this machine, "
                "outside Ray, at the driver's priority; expected "
                f"{name}={meaningless[name]!r} (or a Ray transport, 'socket' or 'actor')"
            )


def serve_forked(payload: bytes, path: str, spin_s: float) -> None:
    """In a forked worker: listen at ``path``, build the EnvGroup pickled in ``payload``
    (an env that fails to build is reported by the first call), and serve the driver
    until it hangs up."""
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    listener.bind(path)  # first, so that the driver can connect while the envs build
    listener.listen(1)
    listener.settimeout(ACCEPT_TIMEOUT_S)
    group = ActorGroup(**pickle.loads(payload))  # trusted: own driver (its zygote's line)
    _serve(group, listener, path, spin_s)


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


def _running(pid: int) -> bool:
    """Is process ``pid`` alive (a zombie, ended but not yet reaped, is not)?"""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:  # gone (or no /proc: then assume alive, the milder message)
        return not os.path.isdir("/proc") or os.path.exists(f"/proc/{pid}")


@dataclass
class CallHandle(SockHandle):
    """A call other than the packed step, sent over a forked worker's socket."""


class ForkBackend(SocketBackend):
    """Workers forked by a zygote on this machine; every call over their sockets."""

    def __init__(
        self,
        start_timeout: float | None,
        step_timeout: float | None,
        *,
        spin_us: float | None = None,
        shared_memory: bool = True,
        modules: list[str] | None = None,
    ) -> None:
        self.start_timeout = start_timeout
        self.step_timeout = step_timeout
        self.actors: list[Any] = []  # no Ray actors: the inherited actor paths see none
        self._init_sockets(spin_us, shared_memory, relay_tcp=False)
        self._modules = list(modules or [])
        self._zygote: Zygote | None = None
        self._pids: list[int | None] = []
        self._paths: list[str] = []

    # -- processes ------------------------------------------------------------------------
    def start(self, group_kwargs: list[dict[str, Any]]) -> None:
        self._open_directory(len(group_kwargs))
        self._zygote = Zygote(self._modules, self.start_timeout)
        self._pids = [None] * len(group_kwargs)
        self._paths = [""] * len(group_kwargs)
        try:
            for w, kwargs in enumerate(group_kwargs):
                self._fork(w, kwargs)
            self._connect(list(range(len(group_kwargs))))
        except BaseException:
            self.shutdown()
            raise

    def _fork(self, w: int, kwargs: dict[str, Any]) -> None:
        import cloudpickle  # as Ray sends an actor's arguments (lambdas, closures)

        assert self._zygote is not None and self._dir is not None
        self._opened += 1
        self._paths[w] = os.path.join(self._dir, f"w{w}-{self._opened}.sock")
        payload = cloudpickle.dumps(kwargs)
        try:
            self._pids[w] = self._zygote.fork(payload, self._paths[w], self.spin_us * 1e-6)
        except (OSError, EOFError):  # the zygote died (its workers live on): a new one
            self._zygote.close()
            self._zygote = Zygote(self._modules, self.start_timeout)
            self._pids[w] = self._zygote.fork(payload, self._paths[w], self.spin_us * 1e-6)

    def _replace_process(self, worker: int, kwargs: dict[str, Any]) -> None:
        self._kill(worker)
        self._fork(worker, kwargs)

    def _kill(self, w: int) -> None:
        pid = self._pids[w]
        if pid is not None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)

    def pid(self, worker: int) -> int:
        return self._pids[worker]  # type: ignore[return-value]

    def shutdown(self) -> None:
        super().shutdown()  # closes every socket: the workers see their driver leave
        for w in range(len(self._pids)):
            self._kill(w)
        self._pids = []
        if self._zygote is not None:
            self._zygote.close()
            self._zygote = None

    # -- connections ----------------------------------------------------------------------
    def _connect(self, workers: list[int]) -> None:
        """Connect to ``workers`` as they listen, then wait until each has built its envs."""
        for w in workers:
            sock = self._socks[w] = self._dial(w)
            self._pollers[w] = _poller(sock)
        self._all_here = None not in self._socks
        saved, self.step_timeout = self.step_timeout, self.start_timeout
        try:  # building the envs may take longer than a step
            outcomes = [self._resolve(self.submit(w, "ready")) for w in workers]
        finally:
            self.step_timeout = saved
        for w, outcome in zip(workers, outcomes, strict=True):
            if not outcome.ok:
                raise RuntimeError(
                    f"forked worker {w} failed while building its envs "
                    f"(start_timeout={self.start_timeout} s):\n{outcome.error}"
                )
        for w in workers:
            self._socks[w].settimeout(self.step_timeout)  # type: ignore[union-attr]

    def _dial(self, w: int) -> socket.socket:  # type: ignore[override]
        """A connection to worker ``w``'s socket, once it listens."""
        assert self._zygote is not None
        timeout = self.start_timeout or START_TIMEOUT_S
        deadline = time.monotonic() + timeout
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        while True:
            try:
                sock.connect(self._paths[w])
                break
            except (FileNotFoundError, ConnectionRefusedError):
                ended = self._zygote.ending(self._pids[w])  # type: ignore[arg-type]
                if ended is not None or time.monotonic() > deadline:
                    sock.close()
                    why = ended or f"did not listen within start_timeout={timeout} s"
                    raise RuntimeError(
                        f"forked worker {w} (pid {self._pids[w]}) {why} while starting; "
                        "its error, if any, is above on stderr"
                    ) from None
                time.sleep(DIAL_PAUSE_S)
        with contextlib.suppress(OSError):  # the worker unlinks it too, once it accepted
            os.unlink(self._paths[w])
        return sock

    def _death_cause(self, w: int) -> str:
        """How worker ``w``'s process ended, as its parent, the zygote, saw it."""
        pid = self._pids[w]
        ended = None
        if self._zygote is not None and pid is not None:
            with contextlib.suppress(OSError, EOFError):
                ended = self._zygote.ending(pid, DEATH_PROBE_S)
        if ended is not None:
            return f"the worker process (pid {pid}) {ended}"
        if pid is not None and not _running(pid):
            return f"the worker process (pid {pid}) ended; its parent, an earlier zygote, is gone"
        return f"the worker process (pid {pid}) is alive but closed its socket"

    # -- calls ----------------------------------------------------------------------------
    def submit(self, worker: int, method: str, *args: Any) -> Any:
        """The packed step as the socket transport sends it; anything else as a call."""
        sock = self._socks[worker]
        if method == STEP_METHOD and sock is not None:
            return super().submit(worker, method, *args)
        deadline = None if self.step_timeout is None else time.monotonic() + self.step_timeout
        handle = CallHandle(worker, deadline)
        if sock is None:
            handle.outcome = Outcome(False, None, f"worker {worker} is not connected", lost=True)
            return handle
        import cloudpickle

        request = cloudpickle.dumps((method, args))
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

    def _read_call(self, w: int, deadline: float | None) -> Outcome:
        """One call's answer from worker ``w``'s socket: the Outcome it pickled."""
        sock = self._socks[w]
        if sock is None:
            raise EOFError(f"worker {w}'s socket was closed before its answer came")
        if deadline is not None:
            sock.settimeout(max(deadline - time.monotonic(), 1e-3))
        head = memoryview(bytearray(CALL_ANSWER.size))
        fill(sock, head, 0, CALL_ANSWER.size)
        (size,) = CALL_ANSWER.unpack(head)
        body = memoryview(bytearray(size))
        fill(sock, body, 0, size)
        return pickle.loads(body)  # trusted: own worker (a private socket)
