"""WorkerVectorEnv: the driver side of chronogym's vector envs, shared by Ray and serial.

The driver splits the batched action into one slice per worker, issues every
worker's call, then waits once (one barrier per vector step) and joins the
results. Each worker is an :class:`~chronogym.vector.group.EnvGroup` holding
``envs_per_worker`` environments. A worker that dies (a fault: a signal, ``os._exit``,
a lost node, ``step_timeout``) is replaced: its environments are rebuilt, get fresh
deterministic seeds, and are reported as truncated with ``info["worker_restarted"] = True``.
An env's own Python exception is raised here, in the driver, or restarts the env, as
``env_errors`` says (:mod:`chronogym.vector.env_errors`). After an env raised in
``reset``, ``step`` or ``recv``, the results of that call are lost, so the vector env
asks for a full ``reset()`` before the next step (``gymnasium.error.ResetNeeded``).

Besides that barrier, ``send`` / ``recv`` step subsets of whole workers without
one (EnvPool-style), and ``step_async`` / ``step_wait`` split a full step the
way Gymnasium's ``AsyncVectorEnv`` does. They are methods of this class; the calls
they leave in flight, and the waiting for their answers, are
:class:`~chronogym.vector.in_flight.InFlight`'s.
``profile_steps()`` times the phases of each barrier step (off by default); see
:mod:`chronogym.vector.profile`.
"""

from __future__ import annotations

import logging
from collections import deque
from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from gymnasium import spaces
from gymnasium.error import NoAsyncCallError, ResetNeeded
from gymnasium.vector import AutoresetMode, VectorEnv
from gymnasium.vector.utils import batch_space

from chronogym.actions import check_invalid_action_mode, prepare_box_action
from chronogym.errors import (
    DisabledAutoresetError,
    EnvsInFlightError,
    VectorEnvClosedError,
    WorkerCallError,
    WorkerCrashLoopError,
)
from chronogym.seeding import restart_seed, vector_seeds
from chronogym.vector.backend import (
    Backend,
    EnvFactory,
    Outcome,
    ResetAnswer,
    Restart,
    StepAnswer,
)
from chronogym.vector.batching import join_obs, rows_of, split_actions
from chronogym.vector.checks import (
    check_env_ids,
    check_envs_per_worker,
    check_max_envs,
    check_max_restarts,
    check_min_envs,
    check_reset_mask,
    normalize_env_fns,
    workers_of,
)
from chronogym.vector.driver_registry import DriverRegistry
from chronogym.vector.env_errors import (
    CRASH_LOOP_TAIL,
    EnvErrorSeen,
    EnvRaised,
    check_env_errors,
    driver_error,
)
from chronogym.vector.group import resolve_env_id
from chronogym.vector.in_flight import CallKind, InFlight, PendingCall
from chronogym.vector.info_rows import join_rows
from chronogym.vector.infos import InfoColumns, batch_infos, join_infos
from chronogym.vector.last_obs import LastObs
from chronogym.vector.profile import StepProfile, StepTimer

logger = logging.getLogger("chronogym")

#: Spaces whose batch of actions is one NumPy array (others batch to tuples or dicts).
ARRAY_BATCHES = (spaces.Box, spaces.MultiDiscrete, spaces.MultiBinary)


@dataclass
class StepPart:
    """One worker's share of a step (or of an asynchronous reset), unpacked for joining."""

    obs: Any
    rewards: np.ndarray
    terminations: np.ndarray
    truncations: np.ndarray
    infos: InfoColumns | list[dict[str, Any]] | None  # None: every env's info is empty


class WorkerVectorEnv(VectorEnv):
    """A ``gymnasium.vector.VectorEnv`` whose environments live in EnvGroup workers."""

    def __init__(
        self,
        env_fns: str | EnvFactory | Sequence[str | EnvFactory],
        num_envs: int | None,
        *,
        backend: Backend,
        envs_per_worker: int,
        autoreset_mode: str | AutoresetMode = AutoresetMode.NEXT_STEP,
        max_restarts: int = 3,
        invalid_action: str = "raise",
        env_kwargs: dict[str, Any] | None = None,
        env_errors: str = "raise",
    ) -> None:
        fns = normalize_env_fns(env_fns, num_envs)
        self.num_envs = len(fns)
        self.envs_per_worker = check_envs_per_worker(envs_per_worker, self.num_envs)
        self.autoreset_mode = AutoresetMode(autoreset_mode)
        check_invalid_action_mode(invalid_action)
        self.max_restarts = check_max_restarts(max_restarts)
        self.invalid_action = invalid_action
        self.env_errors = check_env_errors(env_errors)
        self._reset_needed = ""  # why a full reset() must come before the next step
        self.closed = False
        self._backend = backend
        m = self.envs_per_worker
        self._slices = [(lo, min(lo + m, self.num_envs)) for lo in range(0, self.num_envs, m)]
        self.num_workers = len(self._slices)
        self._env_fns = [resolve_env_id(fn) if isinstance(fn, str) else fn for fn in fns]
        self._env_kwargs = env_kwargs
        self._registry = self._driver_registry(self._env_fns)
        self._seed_roots = [int(np.random.SeedSequence().generate_state(1)[0])] * self.num_envs
        self._restart_counts = [0] * self.num_envs
        self.restarts: deque[tuple[int, str]] = deque(maxlen=1000)  # (env index, error)
        self._started = False
        backend.start([self._group_kwargs(w) for w in range(self.num_workers)])
        self._started = True
        try:
            obs_space, act_space, metadata, render_mode = self._check_spaces()
        except BaseException:  # an env failed to build: stop the workers, raise its error
            self._started, self.closed = False, True
            backend.shutdown()
            raise
        self.single_observation_space = obs_space
        self.single_action_space = act_space
        self.observation_space = batch_space(obs_space, self.num_envs)
        self.action_space = batch_space(act_space, self.num_envs)
        self.metadata = {**metadata, "autoreset_mode": self.autoreset_mode}
        self.render_mode = render_mode
        self._last_parts = LastObs(self.num_workers)  # obs rows of each worker
        self._in_flight = InFlight(backend, self._slices)
        self._packed = isinstance(obs_space, spaces.Box) and isinstance(act_space, spaces.Box)
        #: bytes of one env's observation (the rows of a shared-memory step)
        self._obs_row = 0
        if self._packed:
            self._obs_row = obs_space.dtype.itemsize * int(np.prod(obs_space.shape))  # type: ignore[union-attr]
        self._action_batches = {self.num_envs: self.action_space}  # batch_space by env count
        self.profile: StepProfile | None = None  # see profile_steps()

    # -- workers -----------------------------------------------------------------------
    def _group_kwargs(self, w: int) -> dict[str, Any]:
        lo, hi = self._slices[w]
        return {
            "env_fns": self._env_fns[lo:hi],
            "indices": list(range(lo, hi)),
            "autoreset_mode": self.autoreset_mode,
            "seed_roots": self._seed_roots[lo:hi],
            "restart_counts": self._restart_counts[lo:hi],
            "env_kwargs": self._env_kwargs,
            "env_errors": self.env_errors,
            "registry": self._registry,
        }

    def _driver_registry(self, env_fns: list[Any]) -> DriverRegistry | None:
        """The ids the workers need from this process (none: workers share its registry)."""
        return None

    def _check_spaces(self) -> tuple[Any, Any, dict[str, Any], str | None]:
        """Spaces of worker 0, after checking that every worker reports the same."""
        workers = list(range(self.num_workers))
        outcomes = self._call_all(workers, "spaces", [()] * self.num_workers)
        seen = EnvErrorSeen()
        for w, outcome in enumerate(outcomes):
            if isinstance(outcome.value, EnvRaised):
                seen.keep(outcome.value, w)
        if (error := seen.to_raise()) is not None:
            raise error from error.__cause__
        for w, outcome in enumerate(outcomes):
            if not outcome.ok:
                raise WorkerCallError(f"worker {w} failed to report its spaces:\n{outcome.error}")
        first = outcomes[0].value
        for w, outcome in enumerate(outcomes[1:], start=1):
            if outcome.value[:2] != first[:2]:
                raise RuntimeError(
                    f"envs of worker {w} have spaces {outcome.value[:2]}; expected the same "
                    f"spaces as env 0: {first[:2]}"
                )
        return first

    def _call_one(self, w: int, method: str, *args: Any) -> Any:
        (outcome,) = self._backend.gather([w], [self._backend.submit(w, method, *args)])
        if isinstance(outcome.value, EnvRaised):
            if method in ("reset_restarted", "mark_restarted"):
                self._reset_needed = f"env {outcome.value.env_index} raised in reset()"
            error = driver_error(outcome.value, w)
            raise error from error.__cause__
        if not outcome.ok:
            raise WorkerCallError(f"worker {w} failed in {method}():\n{outcome.error}")
        return outcome.value

    def _call_all(self, workers: list[int], method: str, args: list[tuple[Any, ...]]) -> list:
        return self._backend.gather(workers, self._submit_all(workers, method, args))

    def _submit_all(self, workers: list[int], method: str, args: list[tuple[Any, ...]]) -> list:
        return [self._backend.submit(w, method, *a) for w, a in zip(workers, args, strict=True)]

    def _count_restart(self, env_index: int, error: str) -> None:
        self._restart_counts[env_index] += 1
        self.restarts.append((env_index, error))
        if self.max_restarts >= 0 and self._restart_counts[env_index] > self.max_restarts:
            raise WorkerCrashLoopError(
                f"env {env_index} failed {self._restart_counts[env_index]} times, more than "
                f"max_restarts={self.max_restarts}; last error:\n{error}"
            )

    def _note_restarts(self, restarts: list[Restart]) -> None:
        for restart in restarts:
            logger.warning(
                "chronogym: env %d raised and was rebuilt:\n%s", restart.env_index, restart.error
            )
            self._count_restart(restart.env_index, restart.error)

    def _replace_worker(self, w: int, error: str) -> list[int]:
        """Replace a failed worker; return the fresh seeds of its envs."""
        lo, hi = self._slices[w]
        head = "\n".join([line for line in error.splitlines() if line.strip()][:2])
        logger.warning(
            "chronogym: worker %d (envs %d..%d) replaced: %s\n(the whole text: "
            "info['worker_error'] of its envs, and the vector env's restarts)",
            w,
            lo,
            hi - 1,
            head,
        )
        for i in range(lo, hi):
            self._count_restart(i, error)
        self._backend.replace(w, self._group_kwargs(w))
        roots, counts = self._seed_roots, self._restart_counts
        return [restart_seed(roots[i], i, counts[i]) for i in range(lo, hi)]

    def worker_pids(self) -> list[int]:
        """Process id of each worker (for monitoring and fault-injection tests)."""
        return [self._backend.pid(w) for w in range(self.num_workers)]

    # -- reset -------------------------------------------------------------------------
    def reset(
        self,
        *,
        seed: int | list[int | None] | None = None,
        options: dict[str, Any] | None = None,
    ) -> tuple[Any, dict[str, Any]]:
        self._check_open()
        self._check_idle("reset")
        seeds, options, mask = self._prepare_reset(seed, options)
        if mask is not None:
            self._check_reset_needed("reset(options={'reset_mask': ...})")
        self._check_first_reset(mask)
        workers = [
            w for w, (lo, hi) in enumerate(self._slices) if mask is None or mask[lo:hi].any()
        ]
        infos_per_env: list[dict[str, Any]] = [{} for _ in range(self.num_envs)]
        pending, replaced, seen = workers, set(), EnvErrorSeen()
        while pending:
            args = [self._reset_args(w, seeds, options, mask) for w in pending]
            outcomes = self._call_all(pending, "reset", args)
            failed = []
            for w, outcome in zip(pending, outcomes, strict=True):
                if outcome.ok:
                    lo, hi = self._slices[w]
                    infos_per_env[lo:hi] = self._take_reset(w, outcome.value)
                elif isinstance(outcome.value, EnvRaised):
                    seen.keep(outcome.value, w)
                else:
                    if w in replaced:
                        self._raise_lost_again(w, "reset", outcome.error)
                    replaced.add(w)
                    self._replace_worker(w, outcome.error)
                    failed.append(w)
            pending = failed
        if (error := self._env_error(seen)) is not None:
            raise error from error.__cause__
        self._reset_needed = ""
        return self._join_obs(), self._join_infos(infos_per_env)

    def _env_error(self, seen: EnvErrorSeen) -> BaseException | None:
        """The env's exception to raise, if one came (raised by the public method itself, so
        the traceback stays short); the call's results are then lost, so the next step
        needs a full reset first."""
        if seen.error is not None:
            self._reset_needed = f"env {seen.error.env_index} raised in {seen.error.method}()"
        return seen.to_raise()

    def _check_reset_needed(self, what: str) -> None:
        if self._reset_needed:
            raise ResetNeeded(
                f"{what} after {self._reset_needed}: the envs' states after an env's error are "
                "not defined (the call's results were lost); expected reset() of every env "
                "(no reset_mask) first"
            )

    def _raise_lost_again(self, w: int, method: str, error: str) -> None:
        """A worker lost again right after its replacement, in the same call: a crash loop."""
        lo, hi = self._slices[w]
        tail = "\n".join(error.rstrip().splitlines()[-CRASH_LOOP_TAIL:])
        raise WorkerCrashLoopError(
            f"worker {w} (envs {lo}..{hi - 1}) was lost again in {method}() right after it was "
            f"replaced: a crash loop, so it is not replaced again. The last error:\n{tail}",
            error,
        )

    def _check_first_reset(self, mask: np.ndarray | None) -> None:
        """A masked reset needs every env it leaves alone to have been reset before."""
        if mask is None:
            return
        never = [
            i
            for w, (lo, hi) in enumerate(self._slices)
            if self._last_parts.never_reset(w)
            for i in range(lo, hi)
            if not mask[i]
        ]
        if never:
            raise ValueError(
                f"options['reset_mask'] leaves envs {never} unreset, but they were never reset "
                "and have no observation; expected a first reset() of every env (no mask)"
            )

    def _prepare_reset(
        self, seed: int | list[int | None] | None, options: dict[str, Any] | None
    ) -> tuple[list[int | None], dict[str, Any] | None, np.ndarray | None]:
        """Per-env seeds, options without ``reset_mask``, and the mask; record seed roots."""
        seeds = vector_seeds(seed, self.num_envs)
        mask = None
        if options is not None and "reset_mask" in options:
            options = dict(options)
            mask = check_reset_mask(options.pop("reset_mask"), self.num_envs)
        for i, s in enumerate(seeds):
            if s is not None and (mask is None or mask[i]):
                self._seed_roots[i] = s
        return seeds, options, mask

    def _take_reset(self, w: int, answer: ResetAnswer | tuple) -> list[dict[str, Any]]:
        """Keep worker ``w``'s reset observations; return its envs' infos."""
        answer = ResetAnswer.of(answer)
        self._note_restarts(answer.restarts)
        self._last_parts[w] = answer.obs
        return list(answer.infos)

    def _reset_args(self, w: int, seeds: list, options: Any, mask: np.ndarray | None) -> tuple:
        lo, hi = self._slices[w]
        return (seeds[lo:hi], options, None if mask is None else mask[lo:hi].tolist())

    # -- step --------------------------------------------------------------------------
    def step(self, actions: Any) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict]:
        """Step every env with one barrier (the synchronous path)."""
        self._check_open()
        self._check_idle("step")
        if self._last_parts.never_reset(0):
            raise RuntimeError("step() called before reset(); call reset() first")
        self._check_reset_needed("step()")
        if self.profile is not None:
            return self._step_profiled(actions, self.profile)
        if self._packed and (shared := self._shared_step(actions)) is not None:
            return shared
        workers = list(range(self.num_workers))
        args = self._step_args(workers, actions)
        outcomes = self._call_all(workers, self._step_method, args)
        parts, seen = self._step_parts(workers, outcomes)
        if (error := self._env_error(seen)) is not None:
            raise error from error.__cause__
        return self._join_results(workers, parts)

    def _shared_step(self, actions: Any, timer: StepTimer | None = None) -> tuple | None:
        """``step`` through the backend's shared memory, when it has it
        (:mod:`chronogym.vector.shared_step`): nothing per worker on the driver's side
        unless a worker has infos, restarts or an error to report. None: not available.
        ``timer``: the phases up to ``get`` are marked (``join`` is the caller's)."""
        shares_steps = getattr(self._backend, "shares_steps", None)
        if shares_steps is None or not shares_steps():
            return None
        space = self.single_action_space
        array = prepare_box_action(actions, space, self.num_envs, self.invalid_action)  # type: ignore[arg-type]
        array = np.ascontiguousarray(array)
        if timer is not None:
            timer.mark()
        answers = self._backend.shared_step(array, self._slices, self._obs_row, timer)  # type: ignore[attr-defined]
        if answers is None:
            return None
        if timer is not None:
            timer.mark()
        if answers.extras:  # infos, restarts, errors: each worker's answer, as over sockets
            workers = list(range(self.num_workers))
            outcomes = [answers.outcome(w, lo, hi) for w, (lo, hi) in enumerate(self._slices)]
            parts, seen = self._step_parts(workers, outcomes)
            if (error := self._env_error(seen)) is not None:
                raise error from error.__cause__
            return self._join_results(workers, parts)
        obs_space = self.single_observation_space
        kept = answers.obs.view(obs_space.dtype).reshape(self.num_envs, *obs_space.shape)  # type: ignore[misc]
        kept.flags.writeable = False
        self._last_parts.set_all(kept, self._slices)
        infos = join_rows(*answers.rows) if answers.rows is not None else {}
        if answers.infos:  # the workers' infos, as the socket path joins them
            parts = [answers.infos.get(w) for w in range(self.num_workers)]
            infos = join_infos(parts, [hi - lo for lo, hi in self._slices])
        return kept.copy(), answers.rewards, answers.terminations, answers.truncations, infos

    def _step_parts(
        self, workers: list[int], outcomes: list[Outcome]
    ) -> tuple[list[StepPart], EnvErrorSeen]:
        """Each worker's part of a step, and the first env exception (raised by the caller
        once every answer is read)."""
        seen = EnvErrorSeen()
        parts = []
        for w, outcome in zip(workers, outcomes, strict=True):
            if isinstance(outcome.value, EnvRaised):
                seen.keep(outcome.value, w)
            else:
                parts.append(self._step_result(w, outcome))
        return parts, seen

    def profile_steps(self, enabled: bool = True) -> StepProfile | None:
        """Time every following ``step`` phase by phase (``enabled=False``: stop), on the
        path ``step`` takes: the shared-memory block with every worker on the driver's node
        (each worker writes its times into it), else one message per worker (the times
        come with each answer; with workers on other nodes too, their profiled steps go
        this way).

        Returns the :class:`~chronogym.vector.profile.StepProfile` that collects
        the timings (``per_step_us()`` gives the means), or None when disabled.
        """
        self.profile = StepProfile() if enabled else None
        return self.profile

    def _step_profiled(self, actions: Any, profile: StepProfile) -> tuple:
        """``step`` with each phase timed into ``profile`` (same numbers as ``step``), on the
        path ``step`` takes: the shared-memory block where the backend has one for every
        worker on the driver's node, else one message per worker."""
        if self._packed:
            timer = StepTimer()
            if (shared := self._shared_step(actions, timer)) is not None:
                timer.mark()
                profile.add(timer.marks, timer.workers)
                return shared
        timer = StepTimer()
        workers = list(range(self.num_workers))
        args = self._step_args(workers, actions)
        timer.mark()
        handles = self._submit_all(workers, self._step_method, args)
        timer.mark()
        self._backend.wait(handles, len(handles), None)
        timer.mark()
        outcomes = self._backend.gather(workers, handles)
        timer.mark()
        parts, seen = self._step_parts(workers, outcomes)
        if (error := self._env_error(seen)) is not None:
            raise error from error.__cause__
        out = self._join_results(workers, parts)
        timer.mark()
        answers = [StepAnswer.of(o.value) for o in outcomes if o.ok]
        timer.workers = [a.timings for a in answers if a.timings is not None]
        profile.add(timer.marks, timer.workers)
        return out

    @property
    def _step_method(self) -> str:
        return "step_packed" if self._packed else "step"

    def _step_args(
        self, workers: list[int], actions: Any, order: np.ndarray | None = None
    ) -> list[tuple[Any, ...]]:
        """One argument tuple per worker: the actions of its envs, checked.

        ``actions`` is a batch with one row per env of ``workers``, in env order,
        or in the order whose ``argsort`` is ``order``.
        """
        scalar = isinstance(actions, (int, float, np.generic)) or (
            isinstance(actions, np.ndarray) and actions.ndim == 0
        )
        if scalar and isinstance(self.action_space, ARRAY_BATCHES):
            # Gymnasium's class and text for a scalar, then what was expected
            raise TypeError(
                f"Unable to iterate over the following elements: {actions}; expected a batch "
                f"with one action per env (an element of {self.action_space})"
            )
        offsets, count = [], 0
        for w in workers:
            lo, hi = self._slices[w]
            offsets.append((count, count + hi - lo))
            count += hi - lo
        if self._packed:
            space = self.single_action_space
            array = prepare_box_action(actions, space, count, self.invalid_action)  # type: ignore[arg-type]
            data = (array if order is None else array[order]).tobytes()
            row = len(data) // count
            if self.profile is not None:  # ask the workers for their timings too
                return [(data[a * row : b * row], True) for a, b in offsets]
            return [(data[a * row : b * row],) for a, b in offsets]
        rows = split_actions(self._action_batch(count), actions, count)
        if order is not None:
            rows = [rows[k] for k in order]
        return [(rows[a:b],) for a, b in offsets]

    def _action_batch(self, count: int) -> spaces.Space:
        """The action space of ``count`` envs (``batch_space``, made once per count)."""
        if count not in self._action_batches:
            self._action_batches[count] = batch_space(self.single_action_space, count)
        return self._action_batches[count]

    def _step_result(self, w: int, outcome: Outcome) -> StepPart:
        """Worker ``w``'s part of a step; a failed worker is replaced and reported truncated."""
        lo, hi = self._slices[w]
        count = hi - lo
        if outcome.ok:
            answer = StepAnswer.of(outcome.value)
            part, rew, term, trunc = self._arrays(answer, count)
            infos = answer.infos
            self._note_restarts(answer.restarts or [])
        else:
            if isinstance(outcome.value, DisabledAutoresetError):
                raise outcome.value
            part, infos = self._restart_during_step(w, outcome.error)
            rew = np.zeros(count, dtype=np.float64)
            term, trunc = np.zeros(count, dtype=np.bool_), np.ones(count, dtype=np.bool_)
        self._last_parts[w] = part
        return StepPart(part, rew, term, trunc, infos)

    def _arrays(self, answer: StepAnswer, count: int) -> tuple:
        """Obs, rewards, terminations and truncations of an answer (packed: from bytes)."""
        if not self._packed:
            return answer.obs, answer.rewards, answer.terminations, answer.truncations
        space = self.single_observation_space
        return (
            np.frombuffer(answer.obs, dtype=space.dtype).reshape(count, *space.shape),
            np.frombuffer(answer.rewards, dtype=np.float64),
            np.frombuffer(answer.terminations, dtype=np.bool_),
            np.frombuffer(answer.truncations, dtype=np.bool_),
        )

    def _restart_during_step(self, w: int, error: str) -> tuple[Any, list[dict[str, Any]]]:
        lo, hi = self._slices[w]
        last_part = self._last_parts[w]
        last_rows = rows_of(last_part)
        seeds = self._replace_worker(w, error)
        flags = {"worker_restarted": True, "worker_error": error}
        if self.autoreset_mode == AutoresetMode.SAME_STEP:
            answer = ResetAnswer.of(self._call_one(w, "reset_restarted", seeds, last_rows))
            self._note_restarts(answer.restarts)
            return answer.obs, [{**info, **flags} for info in answer.infos]
        self._call_one(w, "mark_restarted", seeds, last_rows)
        return last_part, [dict(flags) for _ in range(hi - lo)]

    def _check_idle(self, what: str) -> None:
        if self._in_flight:
            raise EnvsInFlightError(
                f"{what}() called while envs {self.envs_in_flight.tolist()} are in flight; "
                "expected no envs in flight: recv() them first",
                what,
            )

    # -- asynchronous stepping ---------------------------------------------------------
    @property
    def envs_in_flight(self) -> np.ndarray:
        """Ids of the envs sent and not yet received (ascending)."""
        return self._in_flight.env_ids()

    def send(self, actions: Any, env_ids: Any = None) -> None:
        """Start stepping the envs ``env_ids`` (default: all) with ``actions`` (one row each).

        ``actions`` rows follow ``env_ids`` order. Calls are per worker, so
        ``env_ids`` must hold every env of each worker it touches, and none of
        them may be in flight already. Results come back through :meth:`recv`.
        """
        self._check_open()
        self._check_reset_needed("send()")
        ids = check_env_ids(env_ids, self.num_envs)
        workers = workers_of(ids, self._slices, self.envs_per_worker)
        busy = [w for w in workers if w in self._in_flight]
        if busy:
            envs = [i for w in busy for i in range(*self._slices[w])]
            raise EnvsInFlightError(
                f"env_ids={ids.tolist()}: envs {envs} are already in flight (sent, not yet "
                "received); expected envs not in flight; call recv() first"
            )
        unreset = [
            i for w in workers if self._last_parts.never_reset(w) for i in range(*self._slices[w])
        ]
        if unreset:
            raise RuntimeError(f"send() to envs {unreset} before their first reset(); reset first")
        args = self._step_args(workers, actions, np.argsort(ids, kind="stable"))
        self._in_flight.submit(CallKind.STEP, self._step_method, workers, args)

    def step_async(self, actions: Any) -> None:
        """Start stepping every env (Gymnasium ``AsyncVectorEnv`` semantics); see step_wait."""
        self._check_open()
        self._check_idle("step_async")
        self.send(actions)

    def step_wait(
        self, timeout: float | None = None
    ) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any]]:
        """Wait for the step started by :meth:`step_async`; the same numbers as ``step``."""
        self._check_open()
        if len(self._in_flight.calls) != self.num_workers or self._in_flight.kinds() != {
            CallKind.STEP
        }:
            raise NoAsyncCallError(
                "step_wait() expects a step of every env in flight (from step_async()); envs "
                f"in flight: {self.envs_in_flight.tolist()}",
                "step",
            )
        return self.recv(min_envs=self.num_envs, timeout=timeout)[:5]

    def async_reset(
        self,
        *,
        seed: int | list[int | None] | None = None,
        options: dict[str, Any] | None = None,
    ) -> None:
        """Start resetting every env (seeds as in ``reset``); results come through recv()."""
        self._check_open()
        self._check_idle("async_reset")
        if options is not None and "reset_mask" in options:
            raise ValueError(
                "async_reset() resets every env; options['reset_mask'] is for reset(); "
                "expected options without 'reset_mask'"
            )
        seeds, options, _ = self._prepare_reset(seed, options)
        workers = list(range(self.num_workers))
        args = [self._reset_args(w, seeds, options, None) for w in workers]
        self._in_flight.submit(CallKind.RESET, "reset", workers, args)

    def recv(
        self,
        min_envs: int | None = None,
        timeout: float | None = None,
        max_envs: int | None = None,
    ) -> tuple[Any, np.ndarray, np.ndarray, np.ndarray, dict[str, Any], np.ndarray]:
        """Results of at least ``min_envs`` envs in flight (default: all of them, at most
        ``max_envs``).

        Returns as soon as the workers that answered hold ``min_envs`` envs,
        with every env whose worker has answered by then, up to ``max_envs``
        (None: no limit; a multiple of ``envs_per_worker``): the earliest sent
        first, and envs answered beyond it stay in flight, returned first by the
        next ``recv``. ``recv(min_envs=k, max_envs=k)`` is EnvPool's batch mode:
        exactly ``k`` envs, the first to be ready. Returns ``(obs, rewards,
        terminations, truncations, infos, env_ids)``, rows in ascending
        ``env_ids`` order, infos batched over those rows. A reset comes back
        with reward 0 and both flags False.
        """
        self._check_open()
        if not self._in_flight:
            raise NoAsyncCallError(
                "recv() called with no envs in flight; call send(), step_async() or "
                "async_reset() first",
                "step",
            )
        in_flight = len(self.envs_in_flight)
        limit = check_max_envs(max_envs, in_flight, self.envs_per_worker)
        if min_envs is None and limit is not None:
            min_envs = min(limit, in_flight)
        need = check_min_envs(min_envs, in_flight)
        if limit is not None and need > limit:
            raise ValueError(f"min_envs={need} > max_envs={limit}; expected min_envs <= max_envs")
        answers = self._in_flight.collect(need, timeout, limit)
        workers = sorted(answers)
        seen = EnvErrorSeen()
        results = []
        for w in workers:
            call, outcome = answers[w]
            if isinstance(outcome.value, EnvRaised):
                seen.keep(outcome.value, w)
            else:
                results.append(self._pending_result(w, call, outcome))
        if (error := self._env_error(seen)) is not None:
            raise error from error.__cause__
        env_ids = np.concatenate([np.arange(*self._slices[w], dtype=np.int64) for w in workers])
        return (*self._join_results(workers, results), env_ids)

    def _pending_result(self, w: int, call: PendingCall, outcome: Outcome) -> StepPart:
        """A step's or a reset's part; a failed reset is redone on a replacement worker."""
        if call.kind is CallKind.STEP:
            return self._step_result(w, outcome)
        replaced = False
        while not outcome.ok:
            if isinstance(outcome.value, EnvRaised):
                error = self._env_error(EnvErrorSeen(outcome.value, w))
                raise error from error.__cause__  # type: ignore[misc]
            if replaced:
                self._raise_lost_again(w, "async_reset", outcome.error)
            self._replace_worker(w, outcome.error)
            replaced = True
            (outcome,) = self._call_all([w], "reset", [call.args])
        infos = self._take_reset(w, outcome.value)
        count = len(infos)
        zeros = np.zeros(count, dtype=np.bool_)
        return StepPart(self._last_parts[w], np.zeros(count), zeros, zeros.copy(), infos)

    # -- joining -----------------------------------------------------------------------
    def _join_obs(self) -> Any:
        return join_obs(self.single_observation_space, list(self._last_parts))

    def _join_infos(self, infos_per_env: list[dict[str, Any]]) -> dict[str, Any]:
        return batch_infos(infos_per_env)

    def _join_results(self, workers: list[int], results: list[StepPart]) -> tuple:
        """(obs, rewards, terminations, truncations, infos) of ``workers``, in order."""
        space = self.single_observation_space
        return (
            join_obs(space, [r.obs for r in results]),
            np.concatenate([r.rewards for r in results]).astype(np.float64, copy=False),
            np.concatenate([r.terminations for r in results]).astype(np.bool_, copy=False),
            np.concatenate([r.truncations for r in results]).astype(np.bool_, copy=False),
            join_infos([r.infos for r in results], [len(r.rewards) for r in results]),
        )

    # -- generic access ----------------------------------------------------------------
    def call(self, name: str, *args: Any, **kwargs: Any) -> tuple[Any, ...]:
        """Call ``name`` on every env (or read it, if not callable); results in env order."""
        self._check_open()
        self._check_idle("call")
        workers = list(range(self.num_workers))
        outcomes = self._call_all(workers, "call", [(name, args, kwargs)] * self.num_workers)
        return tuple(item for w in workers for item in self._unwrap(w, outcomes[w], name))

    def get_attr(self, name: str) -> tuple[Any, ...]:
        """The attribute ``name`` of every env, in env order."""
        return self.call(name)

    def set_attr(self, name: str, values: list[Any] | tuple[Any, ...] | Any) -> None:
        """Set ``name`` on every env: one value for all, or a list with one per env."""
        self._check_open()
        self._check_idle("set_attr")
        if not isinstance(values, (list, tuple)):
            values = [values] * self.num_envs
        if len(values) != self.num_envs:
            raise ValueError(
                f"set_attr got {len(values)} values; expected one value or a list of "
                f"num_envs={self.num_envs} values"
            )
        workers = list(range(self.num_workers))
        args = [(name, list(values[lo:hi])) for lo, hi in self._slices]
        for w, outcome in zip(workers, self._call_all(workers, "set_attr", args), strict=True):
            self._unwrap(w, outcome, name)

    def _unwrap(self, w: int, outcome: Outcome, name: str) -> Any:
        if outcome.ok:
            return outcome.value
        if isinstance(outcome.value, EnvRaised):
            error = driver_error(outcome.value, w)
            raise error from error.__cause__
        if outcome.lost:
            self._replace_worker(w, outcome.error)
            lo, hi = self._slices[w]
            raise WorkerCallError(
                f"worker {w} (envs {lo}..{hi - 1}) was lost during {name!r}; it was replaced, "
                f"and its envs need reset():\n{outcome.error}"
            )
        raise outcome.value

    @property
    def np_random_seed(self) -> tuple[int, ...]:
        """Each env's ``np_random_seed``, in env order (as Gymnasium's vector envs)."""
        return self.get_attr("np_random_seed")

    @property
    def np_random(self) -> tuple[np.random.Generator, ...]:
        """Each env's ``np_random`` generator, in env order (a copy: workers own theirs)."""
        return self.get_attr("np_random")

    def render(self) -> tuple[Any, ...] | None:
        """Frames of every env (``render_mode='rgb_array'``)."""
        return self.call("render")

    # -- closing -----------------------------------------------------------------------
    def close_extras(self, **kwargs: Any) -> None:
        if not self._started:
            return
        self._in_flight.clear()  # calls in flight finish before close() reaches each worker
        try:
            workers = list(range(self.num_workers))
            self._call_all(workers, "close", [()] * self.num_workers)
        finally:
            self._backend.shutdown()

    def _check_open(self) -> None:
        if self.closed:
            raise VectorEnvClosedError(f"{type(self).__name__} is closed; create a new one")

    def __del__(self) -> None:
        try:
            if not getattr(self, "closed", True):
                self.close()
        except Exception:
            pass
