"""The ``transport="compiled"`` backend: the barrier step through a Ray Compiled Graph.

The graph feeds every worker's action bytes through shared-memory channels
(``InputNode`` -> ``EnvGroup.step_seq`` on each actor -> ``MultiOutputNode``)
and is compiled lazily at the first ``step``. Everything else (reset, send /
recv, call, a step of a non-Box env) uses plain actor calls, which still work
while the graph is compiled.

Faults: a dead actor breaks the graph. The step's answers are then asked for
again by plain ``step_seq`` calls with the same sequence number, so a worker
that already stepped returns its answer instead of stepping twice; the dead
one comes back as lost and is replaced as with the plain transport, and the
graph is torn down and compiled again (with the replacement) at the next step.

Cost: Ray's channel reads poll: compiled actors use CPU while they wait for
their next step, and the driver while it waits for the answers (measured in
``benchmarks/throughput.py --breakdown``).
"""

from __future__ import annotations

import contextlib
import pickle
import time
from dataclasses import dataclass
from typing import Any

from chronogym.vector.driver import Outcome
from chronogym.vector.group import DisabledAutoresetError, StepFailure
from chronogym.vector.ray_backend import RayBackend

STEP_METHOD = "step_packed"  # the driver's step method this backend compiles
RECENT = 5  # steps remembered to estimate the next one's duration
NAP_SHARE = 0.7  # the driver sleeps this share of the shortest recent step before reading
NAP_MIN_S = 200e-6  # shorter naps are not worth a sleep


@dataclass
class DagCall:
    """One barrier step: the graph's output refs (None if execute failed) and each call."""

    workers: list[int]
    calls: list[tuple[Any, ...]]
    refs: Any = None
    outcomes: list[Outcome] | None = None
    submitted: float = 0.0  # time.perf_counter() after execute


@dataclass
class DagHandle:
    """Worker ``index``'s share of a DagCall (what ``submit_all`` hands the driver)."""

    call: DagCall
    index: int


def failure_outcome(failure: StepFailure) -> Outcome:
    """A StepFailure as the Outcome the plain transport gives for the same error."""
    if isinstance(failure.error, DisabledAutoresetError):
        return Outcome(False, failure.error, str(failure.error))
    return Outcome(False, failure.error, failure.text)


def value_outcome(value: Any) -> Outcome:
    """An answer of ``step_seq`` as an Outcome (its infos unpickled)."""
    if isinstance(value, StepFailure):
        return failure_outcome(value)
    if isinstance(value[4], bytes):
        value = (*value[:4], pickle.loads(value[4]), *value[5:])  # trusted: own worker
    return Outcome(True, value)


class CompiledRayBackend(RayBackend):
    """RayBackend whose barrier step runs through one compiled graph over every worker."""

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        super().__init__(*args, **kwargs)
        self._dag: Any = None
        self._seq = 0
        self._recent: list[float] = []  # seconds from execute to answers, last few steps
        self._broken = False  # a read failed: tear the graph down before the next step

    def _compiled(self) -> Any:
        """The compiled graph over the current actors (compiled on first use)."""
        if self._dag is None:
            from ray.dag import InputNode, MultiOutputNode

            with InputNode() as inp:
                outputs = [actor.step_seq.bind(inp[k]) for k, actor in enumerate(self.actors)]
                dag = MultiOutputNode(outputs)
            self._dag = dag.experimental_compile()
        return self._dag

    def _drop_dag(self) -> None:
        dag, self._dag, self._broken = self._dag, None, False
        if dag is not None:
            with contextlib.suppress(Exception):  # already torn down by a dead actor
                dag.teardown()

    def submit_all(self, workers: list[int], method: str, args: list[tuple[Any, ...]]) -> list:
        """A barrier step of every worker goes through the graph; anything else, plain calls."""
        if method != STEP_METHOD or workers != list(range(len(self.actors))):
            return [self.submit(w, method, *a) for w, a in zip(workers, args, strict=True)]
        if self._broken:
            self._drop_dag()
        self._seq += 1
        call = DagCall(workers, [(self._seq, *a) for a in args])
        try:
            call.refs = self._compiled().execute(*call.calls)
            call.submitted = time.perf_counter()
        except Exception:  # a dead actor broke the graph: _resolve asks by plain calls
            self._drop_dag()
        return [DagHandle(call, k) for k in range(len(workers))]

    def _resolve(self, call: DagCall) -> list[Outcome]:
        """Every worker's answer to ``call``: from the graph, else by plain ``step_seq``."""
        if call.outcomes is None and call.refs is not None:
            timeout = -1 if self.step_timeout is None else self.step_timeout
            self._nap(call)
            try:
                values = self._ray.get(call.refs, timeout=timeout)
                call.outcomes = [value_outcome(value) for value in values]
                took = time.perf_counter() - call.submitted
                self._recent = [*self._recent[-(RECENT - 1) :], took]
            except Exception:  # a worker died or hung mid-step: tear down once it is replaced
                self._broken = True
        if call.outcomes is None:
            pairs = zip(call.workers, call.calls, strict=True)
            handles = [self.actors[w].step_seq.remote(c) for w, c in pairs]
            outcomes = super().gather(call.workers, handles)
            call.outcomes = [value_outcome(o.value) if o.ok else o for o in outcomes]
        return call.outcomes

    def _nap(self, call: DagCall) -> None:
        """Sleep through most of the expected step: Ray's channel read polls a core meanwhile."""
        if len(self._recent) == RECENT:
            rest = NAP_SHARE * min(self._recent) - (time.perf_counter() - call.submitted)
            if rest > NAP_MIN_S:
                time.sleep(rest)

    def gather(self, workers: list[int], handles: list[Any]) -> list[Outcome]:
        if handles and isinstance(handles[0], DagHandle):
            outcomes = self._resolve(handles[0].call)
            return [outcomes[h.index] for h in handles]
        return super().gather(workers, handles)

    def wait(self, handles: list[Any], num_returns: int, timeout: float | None) -> list[int]:
        if handles and isinstance(handles[0], DagHandle):
            self._resolve(handles[0].call)  # a graph's answers come all at once
            return list(range(len(handles)))
        return super().wait(handles, num_returns, timeout)

    def replace(self, worker: int, kwargs: dict[str, Any]) -> None:
        super().replace(worker, kwargs)  # kills the old actor first, so teardown is quick
        self._drop_dag()

    def shutdown(self) -> None:
        self._drop_dag()
        super().shutdown()
