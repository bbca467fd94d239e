"""Optional timing of vector steps: where one barrier ``step`` spends its time.

Off by default. ``vec.profile_steps()`` attaches a :class:`StepProfile`; every
following ``step`` adds its driver-side phases, and each worker (Box spaces,
packed path) reports its own compute and (de)serialization time with its result.
The step profiled is the one ``step`` takes: the shared-memory block of the driver's
node where it is on (each worker's times in the block), else one message per worker.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field

PHASES = ("prepare", "submit", "wait", "get", "join")


@dataclass
class StepProfile:
    """Seconds summed over ``steps`` profiled vector steps.

    Driver phases: ``prepare`` (check actions, split them into per-worker
    bytes), ``submit`` (issue every worker's call), ``wait`` (the barrier),
    ``get`` (fetch and deserialize the answers), ``join`` (unpack and join them).
    Worker phases (measured inside the workers, ``max`` over the workers of one
    step, i.e. the critical path): ``compute`` (time in the envs' step/reset)
    and ``serde`` (actions from bytes, results to bytes); ``compute_sum`` adds
    the workers' compute instead.
    """

    steps: int = 0
    driver: dict[str, float] = field(default_factory=lambda: dict.fromkeys(PHASES, 0.0))
    compute: float = 0.0
    serde: float = 0.0
    compute_sum: float = 0.0

    def add(self, marks: list[float], worker_times: list[tuple[float, float]]) -> None:
        """One step: ``marks`` = perf_counter at its 6 phase boundaries; (serde, compute) each."""
        for name, start, end in zip(PHASES, marks, marks[1:], strict=False):
            self.driver[name] += end - start
        if worker_times:
            self.serde += max(serde for serde, _ in worker_times)
            self.compute += max(compute for _, compute in worker_times)
            self.compute_sum += sum(compute for _, compute in worker_times)
        self.steps += 1

    def per_step_us(self) -> dict[str, float]:
        """Mean µs per vector step of every phase, plus the derived ``call`` and totals.

        ``call`` = wait - worker compute - worker serde: Ray's call and transfer
        (and any queueing behind other processes) not hidden behind the submit.
        ``driver`` = prepare + submit + get + join: the driver's own work.
        """
        n = max(self.steps, 1)
        out = {name: value / n * 1e6 for name, value in self.driver.items()}
        out["compute"] = self.compute / n * 1e6
        out["serde"] = self.serde / n * 1e6
        out["compute_sum"] = self.compute_sum / n * 1e6
        out["call"] = out["wait"] - out["compute"] - out["serde"]
        out["driver"] = sum(out[name] for name in PHASES if name != "wait")
        out["total"] = sum(out[name] for name in PHASES)
        return out


@dataclass
class StepTimer:
    """One profiled step under way: its phase boundaries so far (started when made) and
    each answering worker's (serde, compute) seconds."""

    marks: list[float] = field(default_factory=lambda: [now()])
    workers: list[tuple[float, float]] = field(default_factory=list)

    def mark(self) -> None:
        """The current phase ends now."""
        self.marks.append(now())


def now() -> float:
    """The clock every phase is measured with."""
    return time.perf_counter()
