"""The zygote of ``transport="fork"``: one warm process that forks every worker.

A Ray worker process spends ~0.7 s of CPU before it builds anything (the interpreter,
``import ray``, its core worker: ``benchmarks/vector/startup.py``, ``ray_bare``), so on a
2-core machine 64 of them take over 30 s to start. The zygote is one fresh interpreter that the
driver starts: it imports once what every worker needs (NumPy, Gymnasium, chronogym and the
envs' modules), then forks each worker on request, ~15 ms of CPU each. It runs one thread,
so a fork copies no half-held lock of another thread. It reaps its children and tells the
driver how one ended (its signal or exit code). When the driver closes its line (the
driver's exit included) it kills the workers still running and exits.

The line is a socketpair; each message is a length-prefixed pickle, one request then one
answer: ``("init", sys_path, modules)``, ``("fork", payload, path, spin_s)`` (answer: the
child's pid) and ``("status", pid, wait_s)`` (answer: how it ended, or None while it runs).
"""

from __future__ import annotations

import contextlib
import importlib
import os
import pickle
import signal
import socket
import struct
import subprocess
import sys
import time
import traceback
from typing import Any

LENGTH = struct.Struct("<Q")
#: What every worker imports: its serving code, and cloudpickle, which reads its arguments
#: and writes its answers (the one Gymnasium depends on: Ray's own would import all of Ray).
BASE_MODULES = ("chronogym.vector.fork_transport", "cloudpickle")
CLOSE_GRACE_S = 2.0  # how long the driver waits for the zygote to exit before killing it
DIAL_PAUSE_S = 1e-3  # between tries to connect to a worker that is still starting


def send(line: socket.socket, message: Any) -> None:
    data = pickle.dumps(message)
    line.sendall(LENGTH.pack(len(data)) + data)


def receive(line: socket.socket) -> Any:
    """One message; EOFError when the other end closed the line."""
    (size,) = LENGTH.unpack(_exactly(line, LENGTH.size))
    return pickle.loads(_exactly(line, size))  # trusted: own driver, or its zygote


def _exactly(line: socket.socket, size: int) -> bytes:
    data = bytearray()
    while len(data) < size:
        chunk = line.recv(size - len(data))
        if not chunk:
            raise EOFError("the line to the zygote closed")
        data += chunk
    return bytes(data)


def ending(status: int) -> str:
    """How a process ended, from its ``waitpid`` status."""
    if os.WIFSIGNALED(status):
        number = os.WTERMSIG(status)
        try:
            name = signal.Signals(number).name
        except ValueError:
            name = f"signal {number}"
        return f"was killed by {name}"
    return f"exited with code {os.waitstatus_to_exitcode(status)}"


# -- driver side ------------------------------------------------------------------------------
class Zygote:
    """The driver's handle on its zygote process."""

    def __init__(self, modules: list[str], timeout: float | None) -> None:
        ours, theirs = socket.socketpair()
        command = [sys.executable, "-m", "chronogym.vector.fork_zygote", str(theirs.fileno())]
        self._process = subprocess.Popen(  # its own session: a Ctrl-C reaches the driver only
            command, pass_fds=(theirs.fileno(),), stdin=subprocess.DEVNULL, start_new_session=True
        )
        theirs.close()
        self._line = ours
        ours.settimeout(timeout)
        try:
            self.pid = self._ask(("init", list(sys.path), modules))
        except (OSError, EOFError) as error:
            self.close()
            raise RuntimeError(
                f"the process that forks transport='fork' workers did not start ({error}); "
                "its error, if any, is above on stderr"
            ) from None

    def _ask(self, request: tuple[Any, ...]) -> Any:
        send(self._line, request)
        return receive(self._line)

    def fork(self, payload: bytes, path: str, spin_s: float) -> int:
        """A new worker serving ``path``, built from the pickled EnvGroup ``payload``: its pid."""
        return self._ask(("fork", payload, path, spin_s))

    def ending(self, pid: int, wait_s: float = 0.0) -> str | None:
        """How worker ``pid`` ended (None: still running after ``wait_s``)."""
        return self._ask(("status", pid, wait_s))

    def connect(self, pid: int, path: str, timeout: float) -> socket.socket:
        """A connection to worker ``pid``'s socket ``path``, once it listens; a RuntimeError
        saying why if it ended first or did not listen within ``timeout`` s."""
        deadline = time.monotonic() + timeout
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        while True:
            try:
                sock.connect(path)
                break
            except (FileNotFoundError, ConnectionRefusedError):
                ended = self.ending(pid)
                if ended is not None or time.monotonic() > deadline:
                    sock.close()
                    why = ended or f"did not listen within start_timeout={timeout} s"
                    raise RuntimeError(f"(pid {pid}) {why} while starting") from None
                time.sleep(DIAL_PAUSE_S)
        with contextlib.suppress(OSError):  # the worker unlinks it too, once it accepted
            os.unlink(path)
        return sock

    def close(self) -> None:
        """Close the line: the zygote kills its workers still running and exits."""
        with contextlib.suppress(OSError):
            self._line.close()
        try:
            self._process.wait(CLOSE_GRACE_S)
        except subprocess.TimeoutExpired:
            self._process.kill()
            self._process.wait()


def fork_worker(
    zygote: Zygote | None,
    modules: list[str],
    timeout: float | None,
    request: tuple[bytes, str, float],
) -> tuple[Zygote, int]:
    """Fork a worker (``request``: its payload, socket path and spin) from ``zygote``, or
    from a new one when there is none or it died (the workers it forked live on): the
    zygote used, and the worker's pid."""
    if zygote is not None:
        try:
            return zygote, zygote.fork(*request)
        except (OSError, EOFError):
            zygote.close()
    zygote = Zygote(modules, timeout)
    return zygote, zygote.fork(*request)


def running(pid: int) -> bool:
    """Is process ``pid`` alive (a zombie, ended but not yet reaped, is not)?"""
    try:
        with open(f"/proc/{pid}/stat") as stat:
            return stat.read().rsplit(")", 1)[1].split()[0] != "Z"
    except OSError:  # gone (or no /proc: then assume alive, the milder message)
        return not os.path.isdir("/proc") or os.path.exists(f"/proc/{pid}")


def how_ended(zygote: Zygote | None, pid: int, wait_s: float) -> str | None:
    """How worker ``pid`` ended, as ``zygote`` (its parent) saw it within ``wait_s``; for
    an orphan of an earlier zygote, only that it ended; None while it runs."""
    ended = None
    if zygote is not None:
        with contextlib.suppress(OSError, EOFError):
            ended = zygote.ending(pid, wait_s)
    if ended is None and not running(pid):
        return "ended; its parent, an earlier zygote, is gone"
    return ended


# -- zygote side ------------------------------------------------------------------------------
def main(fd: int) -> None:
    """Serve the driver's requests on line ``fd`` until it closes it."""
    line = socket.socket(fileno=fd)
    ended: dict[int, str | None] = {}  # every child forked: how it ended (None: running)
    try:
        while True:
            try:
                request = receive(line)
            except (EOFError, OSError):
                break
            _reap(ended)
            kind = request[0]
            if kind == "init":
                _init(*request[1:])
                send(line, os.getpid())
            elif kind == "fork":
                pid = os.fork()
                if pid == 0:
                    _child(line, *request[1:])
                ended[pid] = None
                send(line, pid)
            elif kind == "status":
                send(line, _wait_for(ended, *request[1:]))
    finally:
        _end(ended)


def _init(path: list[str], modules: list[str]) -> None:
    """The driver's import path, and the modules every worker needs, imported once."""
    sys.path[:] = path
    for name in [*BASE_MODULES, *modules]:
        with contextlib.suppress(Exception):  # a worker that needs it reports the error
            importlib.import_module(name)


def _child(line: socket.socket, payload: bytes, path: str, spin_s: float) -> None:
    """In the forked worker: serve the driver, then exit (never returns)."""
    code = 0
    try:
        line.close()
        from chronogym.vector.fork_transport import serve_forked

        serve_forked(payload, path, spin_s)
    except BaseException:
        traceback.print_exc()
        code = 1
    finally:
        with contextlib.suppress(Exception):
            sys.stdout.flush()
            sys.stderr.flush()
        os._exit(code)


def _reap(ended: dict[int, str | None]) -> None:
    """Record how every child that has exited ended."""
    while True:
        try:
            pid, status = os.waitpid(-1, os.WNOHANG)
        except ChildProcessError:
            return
        if pid == 0:
            return
        ended[pid] = ending(status)


def _wait_for(ended: dict[int, str | None], pid: int, wait_s: float) -> str | None:
    if pid not in ended:  # not a child of this zygote (an earlier one forked it)
        return None
    deadline = time.monotonic() + wait_s
    while ended.get(pid) is None and time.monotonic() < deadline:
        time.sleep(0.005)
        _reap(ended)
    return ended.get(pid)


def _end(ended: dict[int, str | None]) -> None:
    """Kill the children still running, and reap them."""
    for pid, how in ended.items():
        if how is None:
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
    for pid, how in ended.items():
        if how is None:
            with contextlib.suppress(ChildProcessError):
                os.waitpid(pid, 0)


if __name__ == "__main__":
    main(int(sys.argv[1]))
    sys.stdout.flush()
    sys.stderr.flush()
    os._exit(0)  # nothing to tear down: its workers are gone (an interpreter's exit: ~0.1 s)
