"""The shared-memory barrier step across nodes: one Ray call per node, nothing per worker.

With every worker on the driver's node, a barrier step goes through one shared block
(:mod:`chronogym.vector.shared_step`). With workers on other nodes, each of those nodes'
relays (:mod:`chronogym.vector.relay`) holds such a block for its node's workers
(:meth:`~chronogym.vector.relay.NodeRelay.open_shared`). A step then costs the driver:

1. one frame per other node, carrying that node's action rows over a TCP line to its relay
   (:mod:`chronogym.vector.relay_channel`; a Ray call where no line could be opened), sent
   first, so every node steps while the driver waits;
2. the driver's own block for the workers on its node, if it has any;
3. one copy of each node's returned rows into the batch.

The driver does nothing per worker, except for a worker with more to say (restarts, an
env's error, a loss, infos other than numeric scalars), whose answer comes whole, as over
its socket. Numeric scalar infos come as each node's records of one schema
(:mod:`chronogym.vector.info_rows`), and the driver copies each node's into the batch. A relay
whose line or call fails (its node died) makes all of its workers lost.

A :class:`SpreadStep` serves one placement of the workers. The backend marks it
``stale`` when a worker is lost or replaced (the replacement may land on another node)
and opens a new one at the next barrier step.
"""

from __future__ import annotations

import contextlib
import socket
from collections.abc import Callable
from dataclasses import dataclass
from typing import Any

import numpy as np

from chronogym.vector.backend import Outcome
from chronogym.vector.info_rows import INFO_ROW, InfoSchema, RowReader, unpack_node_rows
from chronogym.vector.relay import LOST, Relays
from chronogym.vector.relay_channel import ROWS, DriverLine
from chronogym.vector.shared_step import SharedAnswers, SharedLayout, SharedStep

#: One node's infos as records of one schema: the node, the schema, and its records as a
#: ``(the node's envs, schema.used)`` uint8 array in the order of its block
NodeInfos = tuple["NodeRows", InfoSchema, np.ndarray]

#: the driver's node in :class:`NodeRows` (a relay's node is its Ray node id)
HERE = ""
#: seconds to reach a relay's TCP line before that node stays on Ray calls (a firewall)
DIAL_TIMEOUT_S = 10.0


@dataclass(frozen=True)
class NodeRows:
    """One node's workers, in the order of its block, and the batch rows of their envs."""

    node: str
    workers: list[int]
    slices: list[tuple[int, int]]  # each worker's rows in the node's block
    rows: np.ndarray  # the node's block row k is batch row rows[k]


def by_node(slices: list[tuple[int, int]], node_of: dict[int, str]) -> list[NodeRows]:
    """Group the workers by node (:data:`HERE` for those not in ``node_of``), in worker
    order within a node."""
    members: dict[str, list[int]] = {}
    for w in range(len(slices)):
        members.setdefault(node_of.get(w, HERE), []).append(w)
    groups = []
    for node, workers in members.items():
        local, at, rows = [], 0, []
        for w in workers:
            lo, hi = slices[w]
            local.append((at, at + hi - lo))
            at += hi - lo
            rows.append(np.arange(lo, hi))
        groups.append(NodeRows(node, workers, local, np.concatenate(rows)))
    return groups


@dataclass(frozen=True)
class SpreadHandlers:
    """The backend's answers to what a step meets: a lost worker of the driver's node, an
    answer sent on its socket, and a relayed worker's (kind, value) as a relay reports it."""

    lost: Callable[[int, BaseException], Outcome]
    read: Callable[[int, float | None], Outcome]
    relayed: Callable[[int, tuple[str, Any]], Outcome]
    relay_timeout: float | None  # how long to wait for a relay's call


class SpreadStep:
    """The driver's end of a barrier step over the shared blocks of several nodes."""

    def __init__(self, here: NodeRows | None, remote: list[NodeRows], obs_row: int) -> None:
        self.here, self.remote, self.obs_row = here, remote, obs_row
        self.local: SharedStep | None = None  # the driver's block, for the workers here
        self.lines: dict[str, DriverLine] = {}  # node -> its relay's TCP line (else Ray calls)
        self.stale = False  # a worker was lost or replaced: open a new one
        self.steps = 0
        self._schemas = RowReader()

    @classmethod
    def open(
        cls,
        groups: list[NodeRows],
        relays: Relays,
        socks: list[socket.socket | None],
        action_row: int,
        obs_row: int,
        options: dict[str, Any],
        drop: Callable[[int], None],
    ) -> SpreadStep | None:
        """Attach every worker to its node's block (the driver's own for its node); None if
        one could not (``drop(w)``: a worker of this node that could not, whose socket may
        be midway through a message). ``options``: ``directory`` (of the driver's block),
        ``spin_s``, ``tree`` (None: each node decides), ``timeout`` (to attach),
        ``step_timeout`` and ``lines`` (False: every node's step is a Ray call)."""
        import ray

        here = next((g for g in groups if g.node == HERE), None)
        remote = [g for g in groups if g.node != HERE]
        refs = [
            relays.by_node[g.node].open_shared.remote(
                g.workers, g.slices, action_row, obs_row, options["tree"]
            )
            for g in remote
        ]
        step = cls(here, remote, obs_row)
        try:
            if here is not None:
                layout = SharedLayout(tuple(here.slices), action_row, obs_row, info_row=INFO_ROW)
                step.local = SharedStep(
                    layout, options["directory"], options["spin_s"], options["tree"]
                )
                for i, w in enumerate(here.workers):
                    sock = socks[w]
                    if sock is None or not step.local.attach(i, sock, options["timeout"]):
                        drop(w)
                        raise OSError(f"worker {w} could not attach")
                    sock.settimeout(options["step_timeout"])
            if not all(ray.get(refs, timeout=options["timeout"])):
                raise OSError("a relay's workers could not attach")
        except Exception:
            step.close(relays)
            return None
        if options.get("lines", True):
            dial = DIAL_TIMEOUT_S if options["timeout"] is None else options["timeout"]
            step.open_lines(relays, min(dial, DIAL_TIMEOUT_S))
        return step

    def open_lines(self, relays: Relays, timeout: float | None) -> None:
        """Dial each relay's TCP line; a node whose line cannot be opened stays on Ray calls,
        and is not dialled again (``relays.lineless``: a firewall would cost each new spread
        step the dial's timeout again)."""
        import ray

        groups = [g for g in self.remote if g.node not in relays.lineless]
        refs = [relays.by_node[g.node].open_line.remote() for g in groups]
        for group, ref in zip(groups, refs, strict=True):
            try:
                offer = ray.get(ref, timeout=timeout)
            except Exception:
                offer = None
            line = None
            if offer is not None:
                (host, port), token = offer
                line = DriverLine.dial((host, port), token, len(group.rows), self.obs_row, timeout)
            if line is None:
                relays.lineless.add(group.node)
            else:
                self.lines[group.node] = line

    def step(
        self,
        actions: np.ndarray,
        socks: list[socket.socket | None],
        deadline: float | None,
        relays: Relays,
        handlers: SpreadHandlers,
    ) -> SharedAnswers:
        """One barrier step of every worker; the batch's rows, and the workers' extras as
        :class:`~chronogym.vector.shared_step.SharedAnswers` holds them."""
        import ray

        n = len(actions)
        flat = actions.reshape(n, -1)
        sent: list[Any] = []  # per remote node: its line, a Ray ref, or the send's error
        for g in self.remote:
            rows = np.ascontiguousarray(flat[g.rows])
            line = self.lines.get(g.node)
            if line is None:
                sent.append(relays.by_node[g.node].shared_step.remote(rows))
                continue
            try:
                line.send(rows, handlers.relay_timeout)
                sent.append(line)
            except OSError as error:
                sent.append(error)
        self.steps += 1
        obs = np.zeros((n, self.obs_row), np.uint8)
        rewards = np.zeros(n, np.float64)
        terminations, truncations = np.zeros(n, np.bool_), np.zeros(n, np.bool_)
        extras: dict[int, Outcome] = {}
        infos: dict[int, Any] = {}  # worker -> its infos as columns (a few workers only)
        nodes: list[NodeInfos] = []
        if self.here is not None and self.local is not None:
            here = self.here
            got = self.local.step(
                np.ascontiguousarray(flat[here.rows]),
                [socks[w] for w in here.workers],
                deadline,
                lambda i, error: handlers.lost(here.workers[i], error),
                lambda i, when: handlers.read(here.workers[i], when),
                split_infos=True,
            )
            obs[here.rows], rewards[here.rows] = got.obs, got.rewards
            terminations[here.rows], truncations[here.rows] = got.terminations, got.truncations
            extras.update({here.workers[i]: outcome for i, outcome in got.extras.items()})
            infos.update({here.workers[i]: part for i, part in got.infos.items()})
            if got.rows is not None:
                schema, records = got.rows
                block = records.view(np.uint8).reshape(len(records), INFO_ROW)
                nodes.append((here, schema, block[:, : schema.used]))
        for group, way in zip(self.remote, sent, strict=True):
            try:
                if isinstance(way, BaseException):
                    raise way
                rows = (
                    way.receive()
                    if isinstance(way, DriverLine)
                    else ray.get(way, timeout=handlers.relay_timeout)
                )
            except Exception as error:
                why = f"the relay of node {group.node} failed: {type(error).__name__}: {error}"
                line = self.lines.pop(group.node, None)
                if line is not None:
                    line.close()
                relays.drop_node(group.node)
                for w in group.workers:
                    extras[w] = handlers.relayed(w, (LOST, why))
                continue
            got_obs, got_rewards, got_terminations, got_truncations, more = rows
            obs[group.rows], rewards[group.rows] = got_obs, got_rewards
            terminations[group.rows], truncations[group.rows] = got_terminations, got_truncations
            for w, kind, value in more:
                if kind == ROWS:
                    nodes.append((group, *unpack_node_rows(self._schemas, value, len(group.rows))))
                else:
                    extras[w] = handlers.relayed(w, (kind, value))
        answers = SharedAnswers(obs, rewards, terminations, truncations, extras, infos)
        if nodes:
            _take_node_rows(nodes, answers, n)
        return answers

    def close(self, relays: Relays | None) -> None:
        """Close the driver's block and ask every relay to close its own."""
        if self.local is not None:
            self.local.close()
            self.local = None
        for line in self.lines.values():
            line.close()
        self.lines = {}
        for group in self.remote if relays is not None else []:
            actor = relays.by_node.get(group.node)  # type: ignore[union-attr]
            if actor is not None:
                with contextlib.suppress(Exception):
                    actor.close_shared.remote()


def _take_node_rows(nodes: list[NodeInfos], answers: SharedAnswers, num_envs: int) -> None:
    """The nodes' infos records into ``answers``: one batch of records when every env's came
    in one schema and no worker has more to say (each node's copied into the batch at its
    rows), else each worker's columns, as its tail slot would have held them."""
    schema = nodes[0][1]
    covered = sum(len(group.rows) for group, _, _ in nodes)
    one_schema = all(other.text == schema.text for _, other, _ in nodes)
    if covered == num_envs and one_schema and not answers.extras and not answers.infos:
        batch = np.empty((num_envs, schema.used), np.uint8)
        for group, _, block in nodes:
            batch[group.rows] = block
        answers.rows = (schema, batch.view(schema.packed).reshape(num_envs))
        return
    for group, node_schema, block in nodes:
        for i, w in enumerate(group.workers):
            if w in answers.extras:
                continue
            lo, hi = group.slices[i]
            records = np.ascontiguousarray(block[lo:hi]).view(node_schema.packed)
            answers.infos[w] = node_schema.columns(records.reshape(hi - lo))
