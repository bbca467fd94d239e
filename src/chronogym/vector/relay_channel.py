"""A direct TCP line from the driver to one node's relay, for the barrier step.

A Ray actor call costs the driver ~1.5 ms of CPU whatever it carries
(``docs/performance/vector.md#scaling-spread``): with one call per other node and step, that
fixed cost bounds a cluster run long before the per-worker work does. So when the driver
opens a spread step (:mod:`chronogym.vector.spread_step`), each relay also opens a TCP
listener on its node for exactly one connection (:class:`RelayLine`), and the driver dials
it (:class:`DriverLine`). A step is then one frame each way over that connection: the
node's action rows out, and back the node's rows (obs, rewards, terminations, truncations),
its workers' numeric scalar infos as records of one schema (:mod:`chronogym.vector.info_rows`)
and the few answers of workers with more to say. A send and a receive cost the driver tens
of µs.

Security: the listener accepts one connection, and only from a peer that sends the 32-byte
token the relay drew (:func:`secrets.token_bytes`) and handed to the driver through Ray's
own channel; any other peer is dropped. Once connected the listener closes. Nothing on the
line is unpickled: the answers carry bytes, reasons UTF-8 text and an info schema JSON.

Faults are those of a Ray call: a line that fails, closes or stays silent past the relay
timeout makes the node's relay dead and its workers lost. A line that cannot be opened
leaves that node on Ray calls.
"""

from __future__ import annotations

import contextlib
import hmac
import secrets
import socket
import struct
import threading
from collections.abc import Callable
from typing import Any

import numpy as np

from chronogym.vector.wire_format import fill

TOKEN_BYTES = 32
FRAME = struct.Struct("<I")  # action bytes that follow
REPLY = struct.Struct("<BI")  # status (OK: rows follow; FAILED: a reason follows), extra bytes
EXTRA = struct.Struct("<IBI")  # worker, kind (an index in KINDS), bytes that follow
OK, FAILED = 0, 1
READY = b"\x01"  # the relay's answer to a valid token
TOKEN_TIMEOUT_S = 2.0  # a peer's time to send its token once connected
#: What a relay says about a worker, in wire order (:mod:`chronogym.vector.relay` names them
#: ANSWERED, LOST, SILENT): answered carries the answer's bytes, the others a reason. ROWS
#: is about the whole node: every worker's infos as records of one schema
#: (:func:`~chronogym.vector.info_rows.pack_node_rows`; its worker field is 0).
KINDS = ANSWERED, LOST, SILENT, ROWS = ("answered", "lost", "silent", "rows")

#: What a relay returns per worker: (worker, ANSWERED, the answer's bytes), or (worker, LOST
#: or SILENT, why): its socket failed, or it did not answer within ``step_timeout``; and for
#: the node, (0, ROWS, its infos' records) where every worker wrote them as rows.
RelayAnswer = tuple[int, str, Any]
#: What a relay's shared step returns: its workers' obs rows (uint8), rewards, terminations
#: and truncations, in the order of its block, and the RelayAnswers of the workers with more
#: to say (infos, restarts, an env's error, a loss).
SharedRows = tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, list[RelayAnswer]]


def encode_extras(extras: list[RelayAnswer]) -> bytes:
    """The answers of workers with more to say, as bytes (no pickle)."""
    parts = []
    for worker, kind, value in extras:
        data = value.encode() if isinstance(value, str) else bytes(value)
        parts.append(EXTRA.pack(worker, KINDS.index(kind), len(data)) + data)
    return b"".join(parts)


def decode_extras(view: memoryview) -> list[RelayAnswer]:
    """:func:`encode_extras`'s answers back; reasons as text, answers as bytes."""
    extras, at = [], 0
    while at < len(view):
        worker, kind, size = EXTRA.unpack_from(view, at)
        at += EXTRA.size
        data = bytes(view[at : at + size])
        at += size
        name = KINDS[kind]
        extras.append((worker, name, data if name in (ANSWERED, ROWS) else data.decode()))
    return extras


class RelayLine:
    """The relay's end: listens once, checks the token, then serves steps in a thread."""

    def __init__(self, host: str, accept_timeout: float) -> None:
        self.token = secrets.token_bytes(TOKEN_BYTES)
        family = socket.AF_INET6 if ":" in host else socket.AF_INET
        self.listener = socket.socket(family, socket.SOCK_STREAM)
        self.listener.bind((host, 0))
        self.listener.listen(4)
        self.listener.settimeout(accept_timeout)
        self.address = (host, self.listener.getsockname()[1])
        self.conn: socket.socket | None = None
        self.thread: threading.Thread | None = None

    def serve(self, rows: int, action_row: int, step: Callable[[memoryview], SharedRows]) -> None:
        """Start serving: each frame (``rows`` times ``action_row`` action bytes) goes to
        ``step``, whose rows go back."""
        self.thread = threading.Thread(
            target=self._run, args=(rows * action_row, step), name="chronogym-relay-line",
            daemon=True,
        )  # fmt: skip
        self.thread.start()

    def _accept(self) -> socket.socket | None:
        """The first peer that sends the token (None: none before the timeout)."""
        try:
            while True:
                conn, _ = self.listener.accept()
                conn.settimeout(TOKEN_TIMEOUT_S)  # a silent peer holds the driver back no longer
                got = bytearray(TOKEN_BYTES)
                try:
                    fill(conn, memoryview(got), 0, TOKEN_BYTES)
                except (OSError, EOFError):
                    conn.close()
                    continue
                if hmac.compare_digest(bytes(got), self.token):
                    return conn
                conn.close()
        except OSError:
            return None
        finally:
            with contextlib.suppress(OSError):
                self.listener.close()

    def _run(self, action_bytes: int, step: Callable[[memoryview], SharedRows]) -> None:
        conn = self._accept()
        if conn is None:
            return
        self.conn = conn
        conn.settimeout(None)
        conn.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
        buf = memoryview(bytearray(FRAME.size + action_bytes))
        try:
            conn.sendall(READY)
            while True:
                got = fill(conn, buf, 0, FRAME.size)
                (size,) = FRAME.unpack_from(buf)
                if size != action_bytes:
                    raise ValueError(f"a frame of {size} action bytes, expected {action_bytes}")
                fill(conn, buf, got, FRAME.size + size)
                try:
                    obs, rewards, terminations, truncations, extras = step(buf[FRAME.size :])
                except Exception as error:
                    why = f"{type(error).__name__}: {error}".encode()
                    conn.sendall(REPLY.pack(FAILED, len(why)) + why)
                    continue
                tail = encode_extras(extras)
                conn.sendall(b"".join((
                    REPLY.pack(OK, len(tail)), obs.tobytes(), rewards.tobytes(),
                    terminations.tobytes(), truncations.tobytes(), tail,
                )))  # fmt: skip
        except (OSError, EOFError, ValueError):
            pass  # the driver closed the line (or broke the protocol): stop serving
        finally:
            self.close()

    def close(self) -> None:
        """Stop serving (the driver sees the line close)."""
        with contextlib.suppress(OSError):
            self.listener.close()
        conn, self.conn = self.conn, None
        if conn is not None:
            with contextlib.suppress(OSError):
                conn.shutdown(socket.SHUT_RDWR)
            with contextlib.suppress(OSError):
                conn.close()


class DriverLine:
    """The driver's end of one relay's line."""

    def __init__(self, sock: socket.socket, rows: int, obs_row: int) -> None:
        self.sock, self.rows, self.obs_row = sock, rows, obs_row
        self.row_bytes = rows * (obs_row + 8 + 1 + 1)  # obs, reward, two flags
        self.buf = memoryview(bytearray(REPLY.size + self.row_bytes))

    @classmethod
    def dial(
        cls, address: tuple[str, int], token: bytes, rows: int, obs_row: int, timeout: float | None
    ) -> DriverLine | None:
        """Connect and present ``token``; None if the relay does not take it in time."""
        try:
            sock = socket.create_connection(address, timeout=timeout)
        except OSError:
            return None
        try:
            sock.setsockopt(socket.IPPROTO_TCP, socket.TCP_NODELAY, 1)
            sock.sendall(token)
            if sock.recv(1) != READY:
                raise OSError("the relay refused the line")
        except OSError:
            sock.close()
            return None
        return cls(sock, rows, obs_row)

    def send(self, actions: np.ndarray, timeout: float | None) -> None:
        """Send one step's action rows (C-contiguous)."""
        self.sock.settimeout(timeout)
        self.sock.sendall(FRAME.pack(actions.nbytes) + actions.tobytes())

    def receive(self) -> SharedRows:
        """The node's rows for the step sent; OSError or EOFError if the line failed, or
        RuntimeError with the relay's reason if its step raised."""
        buf, n = self.buf, self.rows
        got = fill(self.sock, buf, 0, REPLY.size)
        status, size = REPLY.unpack_from(buf)
        if status != OK:
            why = bytearray(size)
            view = memoryview(why)
            view[: got - REPLY.size] = buf[REPLY.size : got]
            fill(self.sock, view, got - REPLY.size, size)
            raise RuntimeError(f"the relay's step failed: {why.decode(errors='replace')}")
        fill(self.sock, buf, got, REPLY.size + self.row_bytes)
        at = REPLY.size
        obs = np.frombuffer(buf, np.uint8, n * self.obs_row, at).reshape(n, self.obs_row)
        at += n * self.obs_row
        rewards = np.frombuffer(buf, np.float64, n, at)
        terminations = np.frombuffer(buf, np.bool_, n, at + 8 * n)
        truncations = np.frombuffer(buf, np.bool_, n, at + 9 * n)
        extras: list[RelayAnswer] = []
        if size:
            tail = bytearray(size)
            fill(self.sock, memoryview(tail), 0, size)
            extras = decode_extras(memoryview(tail))
        return obs, rewards, terminations, truncations, extras

    def close(self) -> None:
        with contextlib.suppress(OSError):
            self.sock.close()
