"""The barrier step through shared memory: one wake-up for every worker on the driver's node.

Over sockets, a barrier step costs the driver one message out and one in per worker,
and each costs it a system call and the kernel's wake-up of the other end: ~35 µs of
the driver's CPU per worker per step on a 2-core VM, a serial cost that caps W workers
at 1 / (W * 35 µs) steps per second. Here the driver and its workers on this node share
one memory block (a ``memfd``, or an unlinked file in the sockets' private directory,
passed over each worker's socket with ``SCM_RIGHTS``: nothing has a name others can
open) holding every env's action row and answer row, so a step costs the driver:

1. one copy of the batched actions into the block, and the step's number (``gen``);
2. one byte written to a *go* pipe that every worker waits on (one system call; the
   kernel wakes the waiting workers, ~2 µs each, unless they were still spinning);
3. one wake-up when the last worker has answered: each worker writes its rows and its
   ``done`` word, then counts its answer under a lock on the block (``lockf``: the
   workers' system calls, not the driver's), and the last to count writes one byte to
   the *done* pipe; the driver checks that every ``done`` word holds ``gen``;
4. one copy of the obs, rewards and flags out of the block.

So the driver's CPU per worker is the kernel's wake-up of an idle worker and a few
bytes of copying: nothing per worker in Python. From :data:`TREE_MIN_WORKERS` workers on,
when each has a core (:func:`wants_tree`), even the wake-ups leave the driver
(:func:`wake_plan`): the go pipe wakes one *leader* per
group of :data:`FANOUT`, and each leader, before its own step, wakes its group through the
group's own pair of pipes (draining the byte of the step before, which every member is past).
A leader found dead has its group woken by the driver. The price is one more wake-up hop
for the members (tens of µs), small beside the steps that many workers are for.

Two go pipes alternate (step ``g`` uses pipe ``g % 2``) so a fast worker never sees the
step it just answered as a new one; the driver drains pipe ``g % 2`` once every worker has
answered step ``g``.
Memory order: every hand-over is a pipe system call (the kernel's locks order the
block's writes before it), so it holds on any CPU, not just x86.

A worker's answer that carries anything besides its rows (infos, restarts, an env's
error) is written whole, in :mod:`chronogym.vector.wire_format`'s answer format, to
the worker's *tail* slot in the block (status ``IN_TAIL``), or sent on its socket when
it does not fit (``ON_SOCKET``). A tail that adds only infos to the worker's rows (every
Gymnasium MuJoCo task reports infos at every step) keeps the step on the whole-batch path:
the driver takes the rows from the block and joins the infos alone, with no per-worker
answer to build (``split_infos``; with Ant-v5's nine infos, 34 µs less of the driver's CPU
per step with one worker and 48 µs with eight on a 2-core VM:
``benchmarks/archive/split_infos.py``). In the driver's own block the infos need not even be
pickled: a worker whose envs report the same numeric scalars writes them as records into its
envs' rows of the block's info area (status ``INFO_ROWS``, :mod:`chronogym.vector.info_rows`),
and when every worker did so with one schema the driver copies each key's column out of the
area, with nothing per worker. A step the driver marks as timed (``profile_steps()``) has
each worker write its serde and compute seconds into its slot of the block's ``timings``.
A worker that dies shows as a hung-up socket, one silent past ``step_timeout`` as lost:
both are replaced by the socket transport as before. The same
:class:`~chronogym.vector.group.EnvGroup` call (``step_packed``) makes the bytes either
way, so the numbers are the socket path's.
"""

from __future__ import annotations

import contextlib
import fcntl
import mmap
import os
import pickle
import select
import socket
import tempfile
import time
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from chronogym.vector.backend import Outcome, StepAnswer
from chronogym.vector.info_rows import INFO_ROW, InfoSchema, RowReader, RowWriter, records_in
from chronogym.vector.infos import to_columns
from chronogym.vector.profile import StepTimer
from chronogym.vector.wire_format import (
    ANSWER,
    OK,
    REQUEST,
    answer_extra,
    decode_answer,
    encode_answer,
)

ATTACH = 2  # REQUEST's flag byte: attach to a shared step (0 and 1: a step over the socket)
PLAIN, IN_TAIL, ON_SOCKET, INFO_ROWS = 0, 1, 2, 3  # a worker's status word after a shared
# step (INFO_ROWS: its infos in the info area, its schema's text in its tail slot)
DIRECT, LEADER, MEMBER = "direct", "leader", "member"  # how a worker is woken (see wake_plan)
FANOUT = 8  # with many workers: groups of this many, each woken by its first (the leader)
TREE_MIN_WORKERS = 16  # fewer workers: the driver wakes them all itself
TAIL_BYTES = 64 * 1024  # each worker's slot for an answer with infos (else: its socket)
CHECK_S = 0.2  # while blocked, look for hung-up workers (and deadlines) this often
ALIGN = 64


def _aligned(n: int) -> int:
    return -(-n // ALIGN) * ALIGN


@dataclass(frozen=True)
class SharedLayout:
    """Where each part of a shared step lies in the block (byte offsets)."""

    slices: tuple[tuple[int, int], ...]  # each worker's envs [lo, hi)
    action_row: int  # bytes of one env's action
    obs_row: int  # bytes of one env's observation
    tail_bytes: int = TAIL_BYTES
    info_row: int = 0  # bytes per env of the info area (0: none; infos go to the tail slot)
    offsets: dict[str, int] = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        n, w = self.slices[-1][1], len(self.slices)
        sizes = {
            "gen": 8,
            "count": 16,  # the step whose answers are counted, and how many came
            "timed": 8,  # 1: the driver profiles this step (profile_steps()); workers time it
            "actions": n * self.action_row,
            "obs": n * self.obs_row,
            "rewards": 8 * n,
            "terminations": n,
            "truncations": n,
            "done": 8 * w,
            "status": 8 * w,  # per worker: uint32 status, uint32 tail length
            "timings": 16 * w,  # per worker, of a timed step: seconds of serde, of compute
            "tails": w * self.tail_bytes,
            "info_rows": n * self.info_row,
        }
        at = 0
        for name, size in sizes.items():
            self.offsets[name] = at
            at += _aligned(size)
        self.offsets["end"] = at

    @property
    def num_envs(self) -> int:
        return self.slices[-1][1]

    @property
    def size(self) -> int:
        return self.offsets["end"]


class SharedViews:
    """NumPy views of a mapped block, as both ends read and write it."""

    def __init__(self, layout: SharedLayout, buf: mmap.mmap) -> None:
        n, w, o = layout.num_envs, len(layout.slices), layout.offsets
        self.buf = buf
        self.gen = np.frombuffer(buf, np.uint64, 1, o["gen"])
        self.count = np.frombuffer(buf, np.uint64, 2, o["count"])
        self.timed = np.frombuffer(buf, np.uint64, 1, o["timed"])
        self.actions = np.frombuffer(buf, np.uint8, n * layout.action_row, o["actions"])
        self.obs = np.frombuffer(buf, np.uint8, n * layout.obs_row, o["obs"])
        self.rewards = np.frombuffer(buf, np.float64, n, o["rewards"])
        self.terminations = np.frombuffer(buf, np.bool_, n, o["terminations"])
        self.truncations = np.frombuffer(buf, np.bool_, n, o["truncations"])
        self.done = np.frombuffer(buf, np.uint64, w, o["done"])
        self.status = np.frombuffer(buf, np.uint32, 2 * w, o["status"]).reshape(w, 2)
        self.timings = np.frombuffer(buf, np.float64, 2 * w, o["timings"]).reshape(w, 2)
        self.tails = np.frombuffer(buf, np.uint8, w * layout.tail_bytes, o["tails"])
        self.info_rows = np.frombuffer(buf, np.uint8, n * layout.info_row, o["info_rows"])

    def release(self) -> None:
        """Drop the views, so the block can be unmapped."""
        for name in list(vars(self)):
            if name != "buf":
                delattr(self, name)


def _new_block(size: int, directory: str | None) -> int:
    """A file descriptor of ``size`` zero bytes that no other process can open by name."""
    if hasattr(os, "memfd_create"):
        fd = os.memfd_create("chronogym-step", os.MFD_CLOEXEC)
    else:  # no memfd (macOS): a file in the private directory, unlinked at once
        fd, path = tempfile.mkstemp(prefix="step-", dir=directory)
        os.unlink(path)
    os.ftruncate(fd, size)
    return fd


def usable_cpus() -> int:
    """CPUs this process may run on (its affinity where the OS tells it)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def wants_tree(workers: int, cpus: int) -> bool:
    """Wake in groups? Only from :data:`TREE_MIN_WORKERS` workers on, and only when each has
    a core of its own: with more workers than cores a member waits for its leader to get a
    core (measured on 2 cores, mixed: docs/performance/vector.md#scaling)."""
    return TREE_MIN_WORKERS <= workers <= cpus


def wake_plan(workers: int, tree: bool) -> list[list[int]]:
    """Groups of workers woken together: one group (the driver wakes each worker) without
    ``tree``, else groups of :data:`FANOUT` whose first worker, woken by the driver, wakes
    the rest (the driver's kernel work per step: one wake-up per group)."""
    if not tree:
        return [list(range(workers))]
    return [list(range(lo, min(lo + FANOUT, workers))) for lo in range(0, workers, FANOUT)]


def _drain(fd: int) -> int:
    """Read whatever a non-blocking pipe holds; the byte count."""
    got = 0
    with contextlib.suppress(BlockingIOError):
        while chunk := os.read(fd, 65536):
            got += len(chunk)
            if len(chunk) < 65536:
                break
    return got


# -- driver side ------------------------------------------------------------------------------
@dataclass
class SharedAnswers:
    """One shared step's results: whole-batch arrays, plus the workers with more to say."""

    obs: np.ndarray  # uint8, one row of raw bytes per env (the caller views them as its space)
    rewards: np.ndarray
    terminations: np.ndarray
    truncations: np.ndarray
    extras: dict[int, Any]  # worker -> its full answer (infos, restarts, error, loss): an
    # Outcome on the driver, a RelayAnswer in a relay
    infos: dict[int, Any] = field(default_factory=dict)  # worker -> its infos, where they
    # were all it had to add to its rows (``split_infos``)
    rows: tuple[InfoSchema, np.ndarray] | None = None  # every env's infos as records of one
    # schema, where every worker wrote them so (:mod:`chronogym.vector.info_rows`; a view of
    # the block: read it before the next step)

    def outcome(self, w: int, lo: int, hi: int) -> Outcome:
        """Worker ``w``'s answer as the socket path gives it (rows ``lo:hi``)."""
        if w in self.extras:
            return self.extras[w]
        answer = StepAnswer(
            self.obs[lo:hi].tobytes(),
            self.rewards[lo:hi].tobytes(),
            self.terminations[lo:hi].tobytes(),
            self.truncations[lo:hi].tobytes(),
            self.infos.get(w),
            None,
        )
        return Outcome(True, answer)


class SharedStep:
    """The driver's end: the block, the pipes, and the barrier step over them."""

    def __init__(
        self,
        layout: SharedLayout,
        directory: str | None,
        spin_s: float,
        tree: bool | None = False,
    ) -> None:
        """``tree``: wake the workers in groups (None: :func:`wants_tree` on this node)."""
        from chronogym.vector.socket_transport import AdaptiveSpin

        self.layout = layout
        self._fd = _new_block(layout.size, directory)
        self._map = mmap.mmap(self._fd, layout.size)
        self.views = SharedViews(layout, self._map)
        self._go = [os.pipe(), os.pipe()]
        self._done_r, self._done_w = os.pipe()
        if tree is None:
            tree = wants_tree(len(layout.slices), usable_cpus())
        self.groups = wake_plan(len(layout.slices), tree)
        self._group_of = {w: k for k, group in enumerate(self.groups) for w in group}
        tree = len(self.groups) > 1
        self._group_go = [[os.pipe(), os.pipe()] if tree else None for _ in self.groups]
        for fd in (self._go[0][0], self._go[1][0], self._done_r, *self._group_reads()):
            os.set_blocking(fd, False)
        self._done_poll = select.poll()
        self._done_poll.register(self._done_r, select.POLLIN)
        self._spinner = AdaptiveSpin(spin_s)
        self._schemas = RowReader()
        self.gen = 0
        self.attached: set[int] = set()

    def _group_reads(self) -> list[int]:
        return [pair[0] for pipes in self._group_go if pipes for pair in pipes]

    def role(self, w: int) -> str:
        """How worker ``w`` is woken: by the driver (direct, or a group's leader) or by its
        group's leader (member)."""
        k = self._group_of[w]
        if self._group_go[k] is None:
            return DIRECT
        return LEADER if self.groups[k][0] == w else MEMBER

    def _wake_fds(self, w: int) -> list[int]:
        """The pipes worker ``w`` waits on (two), then, for a leader, its group's (two read
        ends to drain, two write ends to wake the members with)."""
        role, pipes = self.role(w), self._group_go[self._group_of[w]]
        if role == DIRECT:
            return [self._go[0][0], self._go[1][0]]
        assert pipes is not None
        if role == MEMBER:
            return [pipes[0][0], pipes[1][0]]
        return [self._go[0][0], self._go[1][0], pipes[0][0], pipes[1][0], pipes[0][1], pipes[1][1]]

    def attach(self, w: int, sock: socket.socket, timeout: float | None) -> bool:
        """Hand worker ``w`` the block and the pipes over its socket; did it take them?"""
        payload = pickle.dumps((self.layout, w, self.gen, self.role(w)))
        fds = [self._fd, self._done_w, *self._wake_fds(w)]
        try:
            sock.sendall(REQUEST.pack(len(payload), ATTACH))
            socket.send_fds(sock, [payload], fds)
            sock.settimeout(timeout)
            ok = sock.recv(1) == b"\x01"
        except OSError:
            return False
        if ok:
            self.attached.add(w)
            self.views.done[w] = self.gen
        return ok

    def step(
        self,
        actions: np.ndarray,
        socks: list[socket.socket | None],
        deadline: float | None,
        lost: Any,
        read: Any,
        decode: Any = None,
        split_infos: bool = False,
        timer: StepTimer | None = None,
    ) -> SharedAnswers:
        """One barrier step of every worker. ``lost(w, error)`` gives a lost worker's Outcome;
        ``read(w, deadline)`` reads an answer sent on worker ``w``'s socket; ``decode(w,
        view)`` an answer found in worker ``w``'s tail slot (default: its Outcome; a relay
        keeps the raw bytes). ``split_infos``: a tail that adds only infos to the worker's
        rows (the common case: every Gymnasium MuJoCo task reports infos at every step) goes
        to ``infos``, not ``extras``, so the caller keeps the whole-batch rows. ``timer``
        (``profile_steps()``): the workers time their part (``timer.workers``), and the ends
        of the phases submit and wait are marked (the caller marks the rest)."""
        v = self.views
        g = self.gen = self.gen + 1
        v.actions[:] = np.frombuffer(actions, np.uint8)
        if timer is not None or v.timed[0]:
            v.timed[0] = timer is not None
            v.timings[:] = np.nan  # a worker that does not answer leaves no times
        v.gen[0] = g
        go = self._go[g % 2][1]
        os.write(go, b"\x01")
        if timer is not None:
            timer.mark()
        extras = self._wait(g, socks, deadline, lost)
        _drain(self._go[g % 2][0])
        if timer is not None:
            timer.mark()
            answered = v.timings[~np.isnan(v.timings[:, 1])]
            timer.workers = [(float(serde), float(compute)) for serde, compute in answered]
        obs = v.obs.reshape(self.layout.num_envs, self.layout.obs_row).copy()
        answers = SharedAnswers(
            obs, v.rewards.copy(), v.terminations.copy(), v.truncations.copy(), extras
        )
        status = v.status[:, 0]
        said = np.flatnonzero(status)
        if not len(said):
            return answers
        if len(said) == len(self.layout.slices) and (status == INFO_ROWS).all():
            self._take_rows(said.tolist(), answers)  # every worker wrote rows (Ant-v5's)
            return answers
        kinds, sizes = v.status.T.tolist()  # Python ints: no NumPy call per worker
        rows = []
        for w in said.tolist():
            if kinds[w] == INFO_ROWS:
                rows.append(w)
            elif w in extras:
                continue
            elif kinds[w] == IN_TAIL:
                at = w * self.layout.tail_bytes
                view = memoryview(v.tails[at : at + sizes[w]].tobytes())
                if decode is not None:
                    extras[w] = decode(w, view)
                    continue
                head, *parts = ANSWER.unpack_from(view)
                extra = answer_extra(parts, view) if split_infos and head == OK else None
                if extra is not None and len(extra) == 2 and extra[1] is None:
                    answers.infos[w] = extra[0]  # its rows are in the block already
                    continue
                extras[w] = decode_answer(head, parts, view, extra)
            else:
                try:
                    extras[w] = read(w, deadline)
                except (OSError, EOFError) as error:
                    extras[w] = lost(w, error)
        if rows:
            self._take_rows(rows, answers)
        return answers

    def _take_rows(self, rows: list[int], answers: SharedAnswers) -> None:
        """The infos that workers ``rows`` wrote to the info area: one vector info when every
        worker wrote rows of one schema (its text the same in every tail slot), else each
        worker's columns, as its tail slot would have held them."""
        v, lay = self.views, self.layout
        workers = len(lay.slices)
        if len(rows) == workers and not answers.extras:
            sizes = v.status[:, 1]
            size = int(sizes[0])
            texts = v.tails.reshape(workers, lay.tail_bytes)[:, :size]
            if workers == 1 or ((sizes == size).all() and (texts == texts[0]).all()):
                schema = self._schemas.schema(texts[0].tobytes())
                answers.rows = (schema, records_in(v.info_rows, schema, lay.num_envs))
                return
        for w in rows:
            if w in answers.extras:
                continue
            at, (lo, hi) = w * lay.tail_bytes, lay.slices[w]
            schema = self._schemas.schema(v.tails[at : at + int(v.status[w, 1])].tobytes())
            records = v.info_rows[lo * lay.info_row : hi * lay.info_row].view(schema.dtype)
            answers.infos[w] = schema.columns(records)

    def _wait(
        self, g: int, socks: list[socket.socket | None], deadline: float | None, lost: Any
    ) -> dict[int, Outcome]:
        """Until every worker's ``done`` word holds ``g``; the workers lost meanwhile.

        The done pipe is read only after ``poll`` found it readable (a byte left by a step
        that ended before its byte came only wakes the next step's wait once), and the done
        words are scanned for who is missing only when someone was lost or the wait is long.
        """
        lost_now: dict[int, Outcome] = {}
        done = self.views.done
        spinner, checked = self._spinner, time.monotonic()
        spinner.spin(self._done_poll)
        woken = False
        while True:
            if (done == g).all() or (
                lost_now and all(int(w) in lost_now for w in np.flatnonzero(done != g))
            ):
                if not woken:
                    _drain(self._done_r)
                spinner.arrived()
                return lost_now
            now = time.monotonic()
            wait_s = CHECK_S if deadline is None else min(CHECK_S, max(deadline - now, 0.0))
            woken = bool(self._done_poll.poll(max(1, int(wait_s * 1000))))
            if woken:
                _drain(self._done_r)
            if not woken or now - checked >= CHECK_S:
                checked = time.monotonic()
                for w in np.flatnonzero(done != g).tolist():
                    if w not in lost_now and (why := self._why_lost(w, socks[w], deadline)):
                        lost_now[w] = lost(w, why)
                        if self.role(w) == LEADER:  # wake its group, as it would have
                            pipes = self._group_go[self._group_of[w]]
                            os.write(pipes[g % 2][1], b"\x01")  # type: ignore[index]

    @staticmethod
    def _why_lost(w: int, sock: socket.socket | None, deadline: float | None) -> Any:
        """Why worker ``w`` will not answer (its socket closed, or past the deadline), or None
        (the text names no worker: a relay's block numbers them its own way; the caller's
        message names it)."""
        if sock is None:
            return EOFError("its socket was closed before its answer came")
        poller = select.poll()  # not select(): a driver may hold more than 1024 descriptors
        poller.register(sock, select.POLLIN)
        if poller.poll(0):
            with contextlib.suppress(BlockingIOError, OSError):
                if sock.recv(1, socket.MSG_PEEK | socket.MSG_DONTWAIT) == b"":
                    return EOFError("it hung up during a shared step")
        if deadline is not None and time.monotonic() >= deadline:
            return TimeoutError()
        return None

    def close(self) -> None:
        """Unmap the block and close the pipes (workers keep their own copies until EOF)."""
        self.views.release()
        with contextlib.suppress(BufferError, ValueError):
            self._map.close()
        group_fds = [fd for pipes in self._group_go if pipes for pair in pipes for fd in pair]
        for fd in (self._fd, *self._go[0], *self._go[1], self._done_r, self._done_w, *group_fds):
            with contextlib.suppress(OSError):
                os.close(fd)


# -- worker side ------------------------------------------------------------------------------
class SharedServer:
    """A worker's end: answers the shared steps of its envs (rows ``lo:hi``)."""

    def __init__(self, layout: SharedLayout, w: int, gen: int, role: str, fds: list[int]) -> None:
        self.layout, self.w = layout, w
        self.lo, self.hi = layout.slices[w]
        for fd in fds:  # received descriptors: not for the env's own child processes
            os.set_inheritable(fd, False)
        self._mem_fd, self._done_w, go0, go1, *self._fanout = fds
        if len(self._fanout) != (4 if role == LEADER else 0):
            raise ValueError(f"a {role} worker got {len(fds)} descriptors")
        self._map = mmap.mmap(self._mem_fd, layout.size)
        self._go = (go0, go1)
        self.views = SharedViews(layout, self._map)
        self._rows = RowWriter() if layout.info_row == INFO_ROW else None
        self.last = gen
        self.on_socket = b""  # an answer too long for the tail slot, to send on the socket

    @property
    def go_fds(self) -> tuple[int, int]:
        """Both go pipes (step ``g`` signals on ``go_fds[g % 2]``)."""
        return self._go

    @property
    def go_fd(self) -> int:
        """The pipe that signals the next step."""
        return self._go[(self.last + 1) % 2]

    def pending(self) -> bool:
        """Has the driver started a step this worker has not answered? (after the go pipe
        was seen readable: its read orders the driver's writes before ours)"""
        return int(self.views.gen[0]) > self.last

    def serve(self, step: Any) -> None:
        """Answer the current step: ``step(action_bytes, timed)`` gives a StepAnswer (its
        infos as the envs gave them: a list of dicts; with ``timed``, its timings, which go
        to this worker's slot of the block) or a StepFailure."""
        v, lo, hi, lay = self.views, self.lo, self.hi, self.layout
        g = int(v.gen[0])
        if self._fanout:  # a leader wakes its group first (its own step may be long)
            _drain(self._fanout[(g + 1) % 2])  # step g - 1's byte: every member is past it
            os.write(self._fanout[2 + g % 2], b"\x01")
        answer = step(v.actions[lo * lay.action_row : hi * lay.action_row], bool(v.timed[0]))
        status, size, message = PLAIN, 0, b""
        if isinstance(answer, StepAnswer):
            if answer.timings is not None:  # a timed step's: to the block, not the tail slot
                v.timings[self.w] = answer.timings
                answer.timings = None
            v.obs[lo * lay.obs_row : hi * lay.obs_row] = np.frombuffer(answer.obs, np.uint8)
            v.rewards[lo:hi] = np.frombuffer(answer.rewards, np.float64)
            v.terminations[lo:hi] = np.frombuffer(answer.terminations, np.bool_)
            v.truncations[lo:hi] = np.frombuffer(answer.truncations, np.bool_)
            if self._wrote_rows(answer):
                status, size = INFO_ROWS, len(self._rows.schema.text)  # type: ignore[union-attr]
                answer.infos = None
            elif isinstance(answer.infos, list):
                answer.infos = to_columns(answer.infos)
            extra = answer.infos is not None or answer.restarts
        else:
            extra = True
        if extra:
            message = encode_answer(answer)
            size = len(message)
            if size <= lay.tail_bytes:
                at = self.w * lay.tail_bytes
                v.tails[at : at + size] = np.frombuffer(message, np.uint8)
                status = IN_TAIL
            else:
                status = ON_SOCKET
        v.status[self.w] = (status, size)
        v.done[self.w] = g
        self.last = g
        if self._counted_last(g):
            os.write(self._done_w, b"\x01")
        self.on_socket = message if status == ON_SOCKET else b""

    def _wrote_rows(self, answer: StepAnswer) -> bool:
        """Did the answer's infos go to the info area as rows of one schema (whose text is
        then in this worker's tail slot)? Not with restarts: those need the tail slot."""
        if self._rows is None or answer.restarts:
            return False
        if not isinstance(answer.infos, list):
            return False
        if (records := self._rows.records(answer.infos)) is None:
            return False
        v, lay, text = self.views, self.layout, self._rows.schema.text  # type: ignore[union-attr]
        if len(text) > lay.tail_bytes:
            return False
        v.info_rows[self.lo * INFO_ROW : self.hi * INFO_ROW] = np.frombuffer(records, np.uint8)
        at = self.w * lay.tail_bytes
        v.tails[at : at + len(text)] = np.frombuffer(text, np.uint8)
        return True

    def _counted_last(self, g: int) -> bool:
        """Count this answer to step ``g`` (under a lock on the block: the workers are
        separate processes); is it the last one, which wakes the driver? A block's only
        worker is the last without counting (no lock: two system calls less per step)."""
        if len(self.layout.slices) == 1:
            return True
        count = self.views.count
        fcntl.lockf(self._mem_fd, fcntl.LOCK_EX, 1)
        try:
            if int(count[0]) != g:
                count[0], count[1] = g, 0
            count[1] += 1
            return int(count[1]) >= len(self.layout.slices)
        finally:
            fcntl.lockf(self._mem_fd, fcntl.LOCK_UN, 1)

    def close(self) -> None:
        self.views.release()
        with contextlib.suppress(BufferError, ValueError):
            self._map.close()
        for fd in (*self._go, self._done_w, self._mem_fd, *self._fanout):
            with contextlib.suppress(OSError):
                os.close(fd)
