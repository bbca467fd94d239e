"""Optuna ask/tell with trials evaluated concurrently by Ray workers.

The driver owns the study: it asks for a trial, samples its parameters
(``suggest(trial)``), hands them to a free worker and tells the result back
when the worker answers. Each worker builds its evaluator once
(``evaluator_factory()``) and keeps it between trials, so heavy set-up is paid
once per worker.

The workers run on the vector envs' machinery: a :class:`TrialWorker` is a
worker of an :class:`~chronogym.vector.actor_transport.ActorBackend` (one Ray
actor each) or, with ``backend="serial"``, of a
:class:`~chronogym.vector.serial.LocalBackend` (this process), and the trials
in flight wait in an :class:`~chronogym.vector.in_flight.InFlight`, as a
vector env's ``send`` / ``recv`` do.

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

import math
import os
import time
import traceback
from collections import deque
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

from tqdm import tqdm

from chronogym.ray_runtime import actor_scheduling, ensure_ray, resolve_worker_cpus
from chronogym.validation import check_int, check_positive
from chronogym.vector.actor_transport import ActorBackend
from chronogym.vector.backend import Backend, Outcome
from chronogym.vector.in_flight import CallKind, InFlight
from chronogym.vector.serial import LocalBackend

Evaluator = Callable[[dict[str, Any]], tuple[float, dict[str, Any]]]
FINISHED_STATES = ("COMPLETE", "FAIL", "PRUNED")
BACKENDS = ("ray", "serial")


class TrialFailure(Exception):
    """An evaluation that ended without a valid objective value (e.g. a diverged simulation)."""


class TrialWorker:
    """Runs in a worker: builds the evaluator once, then evaluates trial after trial."""

    def __init__(self, evaluator_factory: Callable[[], Evaluator]) -> None:
        self.evaluate_fn = evaluator_factory()

    def ready(self) -> bool:
        return True

    def pid(self) -> int:
        return os.getpid()

    def evaluate(self, params: dict[str, Any]) -> tuple[str, Any, Any]:
        """("ok", value, user_attrs) or ("fail", reason, None); exceptions are caught here."""
        try:
            value, attrs = self.evaluate_fn(params)
        except TrialFailure as failure:
            return "fail", f"{type(failure).__name__}: {failure}", None
        except Exception:
            return "fail", traceback.format_exc(limit=8), None
        if not isinstance(value, (int, float)) or not math.isfinite(value):
            return "fail", f"objective value {value!r} is not a finite number", None
        return "ok", float(value), attrs


class TrialActors(ActorBackend):
    """W Ray actors, each a :class:`TrialWorker` (``ray::TrialWorker`` processes)."""

    worker_cls = TrialWorker
    builds = "its evaluator"


class LocalTrials(LocalBackend):
    """One :class:`TrialWorker` in this process (debugging, W=1 without Ray)."""

    worker_cls = TrialWorker


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


@dataclass
class TrialJob:
    """A trial handed to a worker: the Optuna trial, its parameters, and its retries so far."""

    trial: Any
    params: dict[str, Any]
    worker: int
    attempt: int = 0


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
        pool_hook: called with the worker pool (its vector backend) once started
            (fault-injection tests).
    """
    _check_arguments(n_trials, workers, backend, max_retries, trial_timeout, scheduling)
    report = StudyReport(study.study_name)
    report.recovered = recover_stale_trials(study)
    remaining = max(n_trials - finished_trials(study), 0)
    start = time.perf_counter()
    pool = _start_workers(
        backend, evaluator_factory, workers, num_cpus, address, scheduling, trial_timeout
    )
    report.startup = time.perf_counter() - start
    if pool_hook is not None:
        pool_hook(pool)
    bar = tqdm(
        total=n_trials,
        initial=n_trials - remaining,
        desc="trials",
        disable=not progress,
        dynamic_ncols=True,
    )
    run = StudyRun(
        study,
        suggest,
        pool,
        {"evaluator_factory": evaluator_factory},
        report,
        bar,
        workers=workers,
        max_retries=max_retries,
        trial_timeout=trial_timeout,
    )
    try:
        run.run(remaining)
    finally:
        bar.close()
        run.fail_unfinished()  # interrupted: never leave trials RUNNING
        pool.shutdown()
    report.elapsed = time.perf_counter() - run.start
    _fill_best(study, report)
    return report


def _check_arguments(
    n_trials: int,
    workers: int,
    backend: str,
    max_retries: int,
    trial_timeout: float | None,
    scheduling: str,
) -> None:
    """Every argument check of run_parallel_study, before anything starts."""
    check_int("n_trials", n_trials, low=1)
    check_int("workers", workers, low=1)
    if backend not in BACKENDS:
        raise ValueError(f"backend={backend!r}: expected 'ray' or 'serial'")
    if backend == "serial" and workers != 1:
        raise ValueError(f"workers={workers} with backend='serial'; expected workers=1")
    check_int("max_retries", max_retries, low=0)
    if trial_timeout is not None:
        check_positive("trial_timeout", trial_timeout, expected="None or seconds > 0")
    actor_scheduling(scheduling)  # validates it


def _start_workers(
    backend: str,
    evaluator_factory: Callable[[], Evaluator],
    workers: int,
    num_cpus: float | None,
    address: str | None,
    scheduling: str,
    trial_timeout: float | None,
) -> Backend:
    """``workers`` TrialWorkers, started and ready: in this process, or Ray actors."""
    kwargs = [{"evaluator_factory": evaluator_factory}] * workers
    pool: Backend
    if backend == "serial":
        pool = LocalTrials()
    else:
        ensure_ray(address)
        cpus = resolve_worker_cpus(num_cpus, workers)
        # start_timeout None: building an evaluator may take long; trial_timeout bounds a trial
        pool = TrialActors(cpus, 0, None, trial_timeout, scheduling=scheduling)
    pool.start(kwargs)
    return pool


class StudyRun:
    """One run of the ask/tell loop: trials to free workers, results told as they come."""

    def __init__(
        self,
        study: Any,
        suggest: Callable[[Any], dict[str, Any]],
        pool: Backend,
        worker_kwargs: dict[str, Any],
        report: StudyReport,
        bar: Any,
        *,
        workers: int,
        max_retries: int,
        trial_timeout: float | None,
    ) -> None:
        self.study = study
        self.suggest = suggest
        self.pool = pool
        self.worker_kwargs = worker_kwargs  # a replacement worker is built from them
        self.report = report
        self.bar = bar
        self.max_retries = max_retries
        overdue = None
        if trial_timeout is not None:
            overdue = f"no result within trial_timeout={trial_timeout} s"
        slices = [(w, w + 1) for w in range(workers)]  # one trial per worker
        self.in_flight = InFlight(pool, slices, overdue_message=overdue)
        self.jobs: dict[int, TrialJob] = {}  # worker -> the trial it evaluates
        self.free = deque(range(workers))
        self.start = time.perf_counter()  # history and elapsed count from the first trial on

    def run(self, to_ask: int) -> None:
        """Ask ``to_ask`` trials, keeping every worker busy, until all are told."""
        while to_ask > 0 or self.jobs:
            while self.free and to_ask > 0:
                trial = self.study.ask()
                params = self.suggest(trial)
                self._submit(TrialJob(trial, params, self.free.popleft()))
                to_ask -= 1
            for worker, (_, outcome) in self.in_flight.collect(1, None).items():
                self._answer(self.jobs.pop(worker), outcome)

    def _submit(self, job: TrialJob) -> None:
        self.jobs[job.worker] = job
        self.in_flight.submit(CallKind.TRIAL, "evaluate", [job.worker], [(job.params,)])

    def _answer(self, job: TrialJob, outcome: Outcome) -> None:
        """A worker's answer; a lost (dead or hung) worker's trial is recovered."""
        if outcome.ok:
            self._record(job, *outcome.value)
        else:
            self._recover(job, outcome.error)

    def _record(self, job: TrialJob, status: str, payload: Any, attrs: Any) -> None:
        """Tell the study a trial's final state and free its worker."""
        if status == "ok":
            for key, value in (attrs or {}).items():
                job.trial.set_user_attr(key, value)
            self.study.tell(job.trial, payload)
            self.report.completed += 1
        else:
            _tell_fail(self.study, job.trial, payload)
            self.report.failed += 1
        self.free.append(job.worker)
        best = _best_value(self.study)
        value = payload if status == "ok" else None
        elapsed = time.perf_counter() - self.start
        self.report.history.append((elapsed, job.trial.number, value, best))
        self.bar.update(1)
        if best is not None:
            self.bar.set_postfix_str(f"best J {best:.4g}")

    def _recover(self, job: TrialJob, reason: str) -> None:
        """Replace a lost worker; retry its trial there, or record it failed."""
        self.pool.replace(job.worker, self.worker_kwargs)
        if job.attempt < self.max_retries:
            self.report.retried += 1
            job.attempt += 1
            self._submit(job)
        else:
            self._record(job, "fail", f"worker lost {job.attempt + 1} times: {reason}", None)

    def fail_unfinished(self) -> None:
        """Tell FAIL for every trial still in flight (the run was interrupted)."""
        for job in self.jobs.values():
            _tell_fail(self.study, job.trial, "the run was interrupted before this trial finished")
        self.jobs.clear()
        self.in_flight.clear()


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
