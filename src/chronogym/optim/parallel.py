"""Optuna ask/tell with trials evaluated concurrently by Ray workers.

The driver owns the study: it asks for a trial, samples its parameters
(``suggest(trial)``), hands them to a free worker and tells the result back
when the worker answers (``ray.wait`` for the first finished of W in flight).
Each worker builds its evaluator once (``evaluator_factory()``) and keeps it
between trials, so heavy set-up is paid once per worker.

Nothing is lost:

* an evaluation that raises (or raises :class:`TrialFailure`, e.g. a diverged
  simulation) is told FAIL with the reason in the user attribute ``fail_reason``;
* a worker that dies or exceeds ``trial_timeout`` is replaced, and its trial is
  retried on the new worker up to ``max_retries`` times, then told FAIL;
* trials left RUNNING by a driver that was killed are told FAIL when the study
  is resumed and their parameters are queued again, so the same command resumes
  the study with every finished trial kept.

Only one driver should run a given study at a time.
"""

from __future__ import annotations

import time
import traceback
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any, Protocol

Evaluator = Callable[[dict[str, Any]], tuple[float, dict[str, Any]]]
FINISHED_STATES = ("COMPLETE", "FAIL", "PRUNED")


class TrialFailure(Exception):
    """An evaluation that ended without a valid objective value (e.g. a diverged simulation)."""


class TrialWorker:
    """Runs in a worker: builds the evaluator once, then evaluates trial after trial."""

    def __init__(self, evaluator_factory: Callable[[], Evaluator]) -> None:
        self.evaluate_fn = evaluator_factory()

    def ready(self) -> bool:
        return True

    def pid(self) -> int:
        import os

        return os.getpid()

    def evaluate(self, params: dict[str, Any]) -> tuple[str, Any, Any]:
        """("ok", value, user_attrs) or ("fail", reason, None); exceptions are caught here."""
        try:
            value, attrs = self.evaluate_fn(params)
        except TrialFailure as failure:
            return "fail", f"{type(failure).__name__}: {failure}", None
        except Exception:
            return "fail", traceback.format_exc(limit=8), None
        if (
            not isinstance(value, (int, float))
            or value != value
            or value
            in (
                float("inf"),
                float("-inf"),
            )
        ):
            return "fail", f"objective value {value!r} is not a finite number", None
        return "ok", float(value), attrs


@dataclass
class StudyReport:
    """What a run added to the study, and the study's best trial."""

    study_name: str
    completed: int = 0
    failed: int = 0
    retried: int = 0
    recovered: int = 0
    elapsed: float = 0.0
    """Seconds from the first trial to the last (worker start-up excluded)."""
    startup: float = 0.0
    """Seconds to start the workers (and build their evaluators)."""
    best_value: float | None = None
    best_params: dict[str, Any] = field(default_factory=dict)
    best_attrs: dict[str, Any] = field(default_factory=dict)
    best_number: int | None = None
    history: list[tuple[float, int, float | None, float | None]] = field(default_factory=list)
    """(seconds since start, trial number, value or None if failed, best so far)."""


class _Pool(Protocol):
    def submit(self, worker: int, params: dict[str, Any]) -> Any: ...
    def wait_one(self, timeout: float | None) -> list[Any]: ...
    def result(self, handle: Any) -> tuple[str, Any, Any]: ...
    def replace(self, worker: int) -> None: ...
    def shutdown(self) -> None: ...


class _SerialPool:
    """Evaluates in this process, one trial at a time (debugging, W=1 without Ray)."""

    def __init__(self, evaluator_factory: Callable[[], Evaluator]) -> None:
        self.factory = evaluator_factory
        self.worker = TrialWorker(evaluator_factory)
        self.done: deque[Any] = deque()

    def submit(self, worker: int, params: dict[str, Any]) -> Any:
        handle = object()
        self.done.append((handle, self.worker.evaluate(params)))
        return handle

    def wait_one(self, timeout: float | None) -> list[Any]:
        return [self.done[0][0]] if self.done else []

    def result(self, handle: Any) -> tuple[str, Any, Any]:
        _, outcome = self.done.popleft()
        return outcome

    def replace(self, worker: int) -> None:
        self.worker = TrialWorker(self.factory)

    def shutdown(self) -> None:
        self.done.clear()


class WorkerLost(Exception):
    """The worker process died or stopped answering."""


class _RayPool:
    """W Ray actors, each a TrialWorker."""

    def __init__(
        self,
        evaluator_factory: Callable[[], Evaluator],
        workers: int,
        num_cpus: float | None,
        address: str | None,
        scheduling: str = "default",
    ) -> None:
        import ray

        from chronogym.ray_runtime import (
            actor_scheduling,
            ensure_ray,
            resolve_worker_cpus,
        )

        placement = actor_scheduling(scheduling)
        ensure_ray(address)
        self.ray = ray
        cpus = resolve_worker_cpus(num_cpus, workers)
        self.actor_cls = ray.remote(TrialWorker).options(
            num_cpus=cpus, max_restarts=0, max_task_retries=0, **placement
        )
        self.factory = evaluator_factory
        self.actors = [self.actor_cls.remote(evaluator_factory) for _ in range(workers)]
        ray.get([actor.ready.remote() for actor in self.actors])
        self.inflight: dict[Any, int] = {}

    def submit(self, worker: int, params: dict[str, Any]) -> Any:
        ref = self.actors[worker].evaluate.remote(params)
        self.inflight[ref] = worker
        return ref

    def wait_one(self, timeout: float | None) -> list[Any]:
        ready, _ = self.ray.wait(list(self.inflight), num_returns=1, timeout=timeout)
        return ready

    def result(self, handle: Any) -> tuple[str, Any, Any]:
        self.inflight.pop(handle, None)
        try:
            return self.ray.get(handle)
        except self.ray.exceptions.RayError as error:
            raise WorkerLost(f"{type(error).__name__}: {error}") from None

    def forget(self, handle: Any) -> None:
        self.inflight.pop(handle, None)

    def replace(self, worker: int) -> None:
        import contextlib

        from chronogym.ray_runtime import start_with_retries

        with contextlib.suppress(Exception):
            self.ray.kill(self.actors[worker], no_restart=True)
        self.actors[worker] = start_with_retries(
            lambda: self.actor_cls.remote(self.factory),
            lambda actor: self.ray.get(actor.ready.remote()),
            (self.ray.exceptions.RayActorError,),
        )

    def pid(self, worker: int) -> int:
        return self.ray.get(self.actors[worker].pid.remote())

    def shutdown(self) -> None:
        for actor in self.actors:
            self.ray.kill(actor, no_restart=True)
        self.actors = []


@dataclass
class _Inflight:
    trial: Any
    params: dict[str, Any]
    worker: int
    attempt: int
    started: float


def recover_stale_trials(study: Any) -> int:
    """Tell FAIL for trials a killed driver left RUNNING and queue their parameters again."""
    import optuna

    stale = study.get_trials(deepcopy=False, states=(optuna.trial.TrialState.RUNNING,))
    for frozen in stale:
        trial = optuna.trial.Trial(study, frozen._trial_id)
        trial.set_user_attr("fail_reason", "the driver stopped before this trial finished")
        study.tell(trial, state=optuna.trial.TrialState.FAIL)
        if frozen.params:
            study.enqueue_trial(frozen.params, user_attrs={"retry_of": frozen.number})
    return len(stale)


def finished_trials(study: Any) -> int:
    """Trials that reached a final state (complete, failed or pruned)."""
    return sum(t.state.name in FINISHED_STATES for t in study.get_trials(deepcopy=False))


def run_parallel_study(
    study: Any,
    suggest: Callable[[Any], dict[str, Any]],
    evaluator_factory: Callable[[], Evaluator],
    n_trials: int,
    *,
    workers: int = 1,
    backend: str = "ray",
    num_cpus: float | None = None,
    address: str | None = None,
    scheduling: str = "default",
    max_retries: int = 1,
    trial_timeout: float | None = None,
    progress: bool = True,
    pool_hook: Callable[[Any], None] | None = None,
) -> StudyReport:
    """Run ``study`` until it holds ``n_trials`` finished trials, W at a time.

    Args:
        study: an Optuna study (its sampler decides; use TPE with constant_liar
            for parallel trials).
        suggest: ``suggest(trial) -> params``, run in the driver.
        evaluator_factory: builds, in each worker, ``evaluate(params) ->
            (value, user_attrs)``; must be picklable.
        n_trials: total finished trials wanted in the study (resuming counts the
            ones already there).
        workers: trials evaluated at once. backend: ``"ray"`` or ``"serial"``.
        scheduling: ``"default"`` or ``"spread"`` (Ray workers over as many
            nodes as possible; see :class:`~chronogym.vector.RayVectorEnv`).
        max_retries: re-runs of a trial whose worker died. trial_timeout: seconds
            before a worker is considered hung.
        pool_hook: called with the worker pool once started (fault-injection tests).
    """
    from tqdm import tqdm

    _check_positive_int("n_trials", n_trials)
    _check_positive_int("workers", workers)
    if backend not in ("ray", "serial"):
        raise ValueError(f"backend={backend!r}: expected 'ray' or 'serial'")
    if backend == "serial" and workers != 1:
        raise ValueError(f"workers={workers} with backend='serial'; expected workers=1")
    if not isinstance(max_retries, int) or max_retries < 0:
        raise ValueError(f"max_retries={max_retries!r}: expected an integer >= 0")
    if trial_timeout is not None and not trial_timeout > 0:
        raise ValueError(f"trial_timeout={trial_timeout!r}: expected None or seconds > 0")
    from chronogym.ray_runtime import actor_scheduling

    actor_scheduling(scheduling)  # validates it

    report = StudyReport(study.study_name)
    report.recovered = recover_stale_trials(study)
    remaining = n_trials - finished_trials(study)
    start = time.perf_counter()
    pool: _Pool = (
        _SerialPool(evaluator_factory)
        if backend == "serial"
        else _RayPool(evaluator_factory, workers, num_cpus, address, scheduling)
    )
    report.startup = time.perf_counter() - start
    start = time.perf_counter()  # history and elapsed count from the first trial on
    if pool_hook is not None:
        pool_hook(pool)
    bar = tqdm(
        total=n_trials,
        initial=n_trials - max(remaining, 0),
        desc="trials",
        disable=not progress,
        dynamic_ncols=True,
    )
    inflight: dict[Any, _Inflight] = {}
    free = deque(range(workers))
    to_ask = max(remaining, 0)

    def record(job: _Inflight, status: str, payload: Any, attrs: Any) -> None:
        """Tell the study a trial's final state and free its worker."""
        if status == "ok":
            for key, value in (attrs or {}).items():
                job.trial.set_user_attr(key, value)
            study.tell(job.trial, payload)
            report.completed += 1
        else:
            _tell_fail(study, job.trial, payload)
            report.failed += 1
        free.append(job.worker)
        best = _best_value(study)
        value = payload if status == "ok" else None
        report.history.append((time.perf_counter() - start, job.trial.number, value, best))
        bar.update(1)
        if best is not None:
            bar.set_postfix_str(f"best J {best:.4g}")

    def recover(job: _Inflight, reason: str) -> None:
        """Replace a lost worker; retry its trial there, or record it failed."""
        pool.replace(job.worker)
        if job.attempt < max_retries:
            report.retried += 1
            job.attempt += 1
            job.started = time.perf_counter()
            inflight[pool.submit(job.worker, job.params)] = job
        else:
            record(job, "fail", f"worker lost {job.attempt + 1} times: {reason}", None)

    try:
        while to_ask > 0 or inflight:
            while free and to_ask > 0:
                trial = study.ask()
                params = suggest(trial)
                worker = free.popleft()
                handle = pool.submit(worker, params)
                inflight[handle] = _Inflight(trial, params, worker, 0, time.perf_counter())
                to_ask -= 1
            ready = pool.wait_one(_next_timeout(inflight, trial_timeout))
            if not ready:  # a trial ran past trial_timeout: its worker is hung
                for handle, job in _overdue(inflight, trial_timeout):
                    del inflight[handle]
                    if hasattr(pool, "forget"):
                        pool.forget(handle)
                    recover(job, f"no result within trial_timeout={trial_timeout} s")
                continue
            for handle in ready:
                job = inflight.pop(handle)
                try:
                    outcome = pool.result(handle)
                except WorkerLost as lost:
                    recover(job, str(lost))
                else:
                    record(job, *outcome)
    finally:
        bar.close()
        for job in inflight.values():  # interrupted: never leave trials RUNNING
            _tell_fail(study, job.trial, "the run was interrupted before this trial finished")
        pool.shutdown()
    report.elapsed = time.perf_counter() - start
    _fill_best(study, report)
    return report


def _check_positive_int(name: str, value: Any) -> None:
    if isinstance(value, bool) or not isinstance(value, int) or value < 1:
        raise ValueError(f"{name}={value!r}: expected an integer >= 1")


def _tell_fail(study: Any, trial: Any, reason: str) -> None:
    import optuna

    trial.set_user_attr("fail_reason", str(reason)[-2000:])
    study.tell(trial, state=optuna.trial.TrialState.FAIL)


def _best_value(study: Any) -> float | None:
    try:
        return float(study.best_value)
    except ValueError:  # no complete trial yet
        return None


def _fill_best(study: Any, report: StudyReport) -> None:
    try:
        best = study.best_trial
    except ValueError:
        return
    report.best_value = float(best.value)
    report.best_params = dict(best.params)
    report.best_attrs = dict(best.user_attrs)
    report.best_number = best.number


def _next_timeout(inflight: dict[Any, _Inflight], trial_timeout: float | None) -> float | None:
    if trial_timeout is None or not inflight:
        return None
    oldest = min(job.started for job in inflight.values())
    return max(0.0, oldest + trial_timeout - time.perf_counter())


def _overdue(
    inflight: dict[Any, _Inflight], trial_timeout: float | None
) -> list[tuple[Any, _Inflight]]:
    """The in-flight trials that have run longer than ``trial_timeout``."""
    if trial_timeout is None:
        return []
    now = time.perf_counter()
    return [(h, job) for h, job in inflight.items() if now - job.started >= trial_timeout]
