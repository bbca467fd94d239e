"""The ``transport="actor"`` backend: one Ray actor per worker, one actor call per request.

Every worker is an :class:`~chronogym.vector.group.EnvGroup` (or a subclass a
transport adds methods to) living in its own Ray actor for its whole life. A
dead actor is never restarted by Ray (its state would be lost): the driver
replaces it and reports its envs truncated.
"""

from __future__ import annotations

import contextlib
import traceback
from typing import Any

from chronogym.ray_runtime import actor_scheduling, quiet_mujoco_warnings, start_with_retries
from chronogym.vector.backend import Outcome, error_outcome
from chronogym.vector.env_errors import EnvRaised
from chronogym.vector.group import EnvGroup
from chronogym.vector.worker_death import describe_death


class ActorGroup(EnvGroup):
    """An EnvGroup in a Ray actor: its answers leave as plain tuples.

    Ray sends tuples, lists and bytes as msgpack and pickles only the rest; the typed
    answer would be pickled whole. The driver reads them back with ``StepAnswer.of`` /
    ``ResetAnswer.of`` (:mod:`chronogym.vector.backend`).
    """

    def __init__(self, *args: Any, **kwargs: Any) -> None:
        quiet_mujoco_warnings()  # before the envs compile their models
        super().__init__(*args, **kwargs)

    def reset(self, *args: Any, **kwargs: Any) -> tuple[Any, ...]:  # type: ignore[override]
        return super().reset(*args, **kwargs).as_tuple()

    def reset_restarted(self, *args: Any) -> tuple[Any, ...]:  # type: ignore[override]
        return super().reset_restarted(*args).as_tuple()

    def step(self, *args: Any) -> tuple[Any, ...]:  # type: ignore[override]
        return super().step(*args).as_tuple()

    def step_packed(self, *args: Any) -> tuple[Any, ...]:  # type: ignore[override]
        return super().step_packed(*args).as_tuple()


class ActorBackend:
    """One Ray actor per worker, each owning an EnvGroup for its whole life."""

    worker_cls: type = ActorGroup  # what each actor holds (an EnvGroup, or optim's TrialWorker)
    builds = "its envs"  # what a worker builds as it starts (for the error when it fails)

    def __init__(
        self,
        num_cpus: float,
        num_gpus: float,
        start_timeout: float | None,
        step_timeout: float | None,
        scheduling: str = "default",
    ) -> None:
        import ray

        self._ray = ray
        self._actor_cls = ray.remote(self.worker_cls).options(
            num_cpus=num_cpus,
            num_gpus=num_gpus,
            max_restarts=0,
            max_task_retries=0,
            **actor_scheduling(scheduling),
        )
        self.start_timeout = start_timeout
        self.step_timeout = step_timeout
        self.actors: list[Any] = []
        self._pids: list[int | None] = []

    def _wait_ready(self, actors: list[Any]) -> None:
        ray = self._ray
        refs = [actor.ready.remote() for actor in actors]
        try:
            ray.get(refs, timeout=self.start_timeout)
        except ray.exceptions.GetTimeoutError:
            for actor in actors:
                ray.kill(actor)
            raise TimeoutError(
                f"Ray workers did not start within {self.start_timeout} s; the cluster may lack "
                "the CPUs/GPUs they request (see `ray status`)"
            ) from None
        except ray.exceptions.RayActorError as error:
            for actor in actors:
                ray.kill(actor)
            raise RuntimeError(
                f"a Ray worker failed while building {self.builds}:\n{error}"
            ) from None

    def start(self, group_kwargs: list[dict[str, Any]]) -> None:
        actors = [self._actor_cls.remote(**kwargs) for kwargs in group_kwargs]
        self._wait_ready(actors)
        self.actors = actors
        self._pids = [None] * len(actors)

    def replace(self, worker: int, kwargs: dict[str, Any]) -> None:
        with contextlib.suppress(Exception):  # already dead
            self._ray.kill(self.actors[worker], no_restart=True)
        actor = start_with_retries(
            lambda: self._actor_cls.remote(**kwargs), lambda new: self._wait_ready([new])
        )
        self.actors[worker] = actor
        self._pids[worker] = None

    def submit(self, worker: int, method: str, *args: Any) -> Any:
        return getattr(self.actors[worker], method).remote(*args)

    def gather(self, workers: list[int], handles: list[Any]) -> list[Outcome]:
        ray = self._ray
        try:
            return [Outcome(True, value) for value in ray.get(handles, timeout=self.step_timeout)]
        except Exception:
            pass
        outcomes = []
        for handle in handles:
            try:
                outcomes.append(Outcome(True, ray.get(handle, timeout=self.step_timeout)))
            except ray.exceptions.RayTaskError as error:
                if isinstance(error.cause, EnvRaised):  # an env's own exception: no Ray frames
                    outcomes.append(Outcome(False, error.cause, error.cause.text))
                else:
                    outcomes.append(error_outcome(error.as_instanceof_cause(), str(error)))
            except ray.exceptions.GetTimeoutError:
                message = f"no answer within step_timeout={self.step_timeout} s"
                outcomes.append(Outcome(False, None, message, lost=True))
            except ray.exceptions.RayError as error:
                text = describe_death(f"{type(error).__name__}: {error}")
                outcomes.append(Outcome(False, error, text, True))
            except Exception as error:
                outcomes.append(Outcome(False, error, traceback.format_exc(), lost=True))
        return outcomes

    def wait(self, handles: list[Any], num_returns: int, timeout: float | None) -> list[int]:
        """Indices of ``handles`` that have answered (``ray.wait``; a dead worker counts)."""
        ready, _ = self._ray.wait(handles, num_returns=num_returns, timeout=timeout)
        done = set(ready)
        return [k for k, handle in enumerate(handles) if handle in done]

    def pid(self, worker: int) -> int:
        if self._pids[worker] is None:
            self._pids[worker] = self._ray.get(self.actors[worker].pid.remote())
        return self._pids[worker]  # type: ignore[return-value]

    def shutdown(self) -> None:
        for actor in self.actors:
            with contextlib.suppress(Exception):
                self._ray.kill(actor, no_restart=True)
        self.actors = []
