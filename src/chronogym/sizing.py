"""Sizing a parallel run: the cost model of a vector step, its fit, and ``chronogym bench``.

**The model.** A vector step of W workers, each stepping ``envs_per_worker`` envs of step
cost ``s`` one after another, takes

    t_step(W) = S + a + b * W,        S = envs_per_worker * s

where ``a`` is the fixed cost of a vector step (the driver's work, one round trip, the
wake-ups) and ``b`` the cost per worker (the driver writes and reads each worker's request
and answer, and the barrier waits for the slowest). The parallel efficiency is the
measured throughput over the ideal one (every worker computing all the time):

    E(W) = S / t_step(W),    E(W) / E(1) = (S + a + b) / (S + a + b * W).

**How ``chronogym bench ID`` measures it** (:func:`run_bench`):

1. ``s``: the env's own step, timed serially in this process (``gymnasium.make``, random
   actions, resets when an episode ends; no Ray).
2. ``a`` and ``b``: ``RayVectorEnv`` with W = 1, 2, 4 and the cluster's CPU count workers
   (capped by ``--max-workers``), one env each, stepping :class:`SyntheticEnv` whose step
   *sleeps* ``s`` and whose observation and info have the env's sizes (its info's numeric
   scalars as float64 scalars, its other numeric values as one float array: infos cost the
   driver and the workers Python per step, Gymnasium's MuJoCo tasks nine scalars each). A
   sleeping step releases its core, where the real env at W > cores would measure the
   cores' contention; but each worker's own CPU per step (its serving loop and the step's
   wake-up, ~0.1 ms on a small VM) does not sleep, so where the W workers outnumber the
   CPUs (W = 4 on 2 or 3) ``b`` holds their wait for a core, and the report says so
   (:func:`cores_shared`): a plan for more cores made there is pessimistic. What this leaves out
   is what the workers' real compute does to each other on real cores (memory bandwidth,
   turbo, hyper-threads), so a last run checks the model on the real env at W = the CPUs
   (``--max-workers`` capped), where the cores can still run every worker at once.
3. The least-squares fit of ``t_step - S`` on W gives ``a`` and ``b``; the table is
   ``E(W)`` for W up to 256 and 1 to 16 envs per worker, and the recommendation is the
   smallest ``envs_per_worker`` at which one worker per core (``--cores``, default the
   cluster's CPUs) keeps ``E >= --target``.

Nothing heavy is imported at module level: Ray, Gymnasium and the env load when a
measurement runs.
"""

from __future__ import annotations

import itertools
import time
from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any

#: Workers and envs per worker of the printed table.
SWEEP_WORKERS = (1, 2, 4, 8, 16, 32, 64, 128, 256)
SWEEP_ENVS_PER_WORKER = (1, 2, 4, 8, 16)
#: Efficiency the recommendation asks for.
DEFAULT_TARGET = 0.8


# -- the model ----------------------------------------------------------------------------


@dataclass(frozen=True)
class StepModel:
    """``t_step(W) = envs_per_worker * step_s + a + b * W`` (seconds)."""

    step_s: float
    a: float
    b: float

    def t_step(self, workers: float, envs_per_worker: int = 1) -> float:
        return envs_per_worker * self.step_s + self.a + self.b * workers

    def efficiency(self, workers: float, envs_per_worker: int = 1) -> float:
        """``E(W)``: the ideal step time over the modelled one."""
        busy = envs_per_worker * self.step_s
        return busy / self.t_step(workers, envs_per_worker) if busy > 0 else 0.0

    def relative_efficiency(self, workers: float, envs_per_worker: int = 1) -> float:
        """``E(W) / E(1)``."""
        return self.t_step(1, envs_per_worker) / self.t_step(workers, envs_per_worker)

    def env_steps_per_s(self, workers: float, envs_per_worker: int = 1) -> float:
        return workers * envs_per_worker / self.t_step(workers, envs_per_worker)


def fit_line(xs: Sequence[float], ys: Sequence[float]) -> tuple[float, float]:
    """Least-squares ``(intercept, slope)`` of ``ys`` on ``xs`` (slope 0 for one distinct x)."""
    if len(xs) != len(ys) or not xs:
        raise ValueError(
            f"fit_line: expected as many xs as ys, at least one; got {len(xs)}, {len(ys)}"
        )
    n = len(xs)
    mean_x, mean_y = sum(xs) / n, sum(ys) / n
    spread = sum((x - mean_x) ** 2 for x in xs)
    if spread == 0:
        return mean_y, 0.0
    slope = sum((x - mean_x) * (y - mean_y) for x, y in zip(xs, ys, strict=True)) / spread
    return mean_y - slope * mean_x, slope


def fit_overhead(
    workers: Sequence[float], t_step: Sequence[float], busy_s: Sequence[float] | float
) -> tuple[float, float]:
    """``(a, b)`` of ``t_step = busy + a + b * W`` by least squares (``busy``: S per point,
    or one S for all)."""
    busy = [busy_s] * len(workers) if isinstance(busy_s, (int, float)) else list(busy_s)
    return fit_line(list(workers), [t - s for t, s in zip(t_step, busy, strict=True)])


def fit_overhead_nonnegative(
    workers: Sequence[float], t_step: Sequence[float], busy_s: Sequence[float] | float
) -> tuple[float, float]:
    """:func:`fit_overhead` with ``a, b >= 0``: a negative one is set to 0 and the other
    refitted alone (noise at few points can tilt the line past the origin)."""
    a, b = fit_overhead(workers, t_step, busy_s)
    if a >= 0 and b >= 0:
        return a, b
    busy = [busy_s] * len(workers) if isinstance(busy_s, (int, float)) else list(busy_s)
    ys = [t - s for t, s in zip(t_step, busy, strict=True)]
    if a < 0:  # through the origin: b = sum(W y) / sum(W^2)
        b = sum(w * y for w, y in zip(workers, ys, strict=True)) / sum(w * w for w in workers)
        return 0.0, max(b, 0.0)
    return max(sum(ys) / len(ys), 0.0), 0.0


def largest_workers(
    model: StepModel, envs_per_worker: int, target: float, sweep: Sequence[int] = SWEEP_WORKERS
) -> int | None:
    """The largest W of ``sweep`` whose efficiency is ``>= target`` (None: not even W=1)."""
    fits = [w for w in sweep if model.efficiency(w, envs_per_worker) >= target]
    return max(fits) if fits else None


@dataclass(frozen=True)
class Recommendation:
    """Workers and envs per worker for ``cores`` cores, and their predicted efficiency."""

    workers: int
    envs_per_worker: int
    efficiency: float
    reached: bool  # whether ``efficiency >= target``


def recommend(
    model: StepModel,
    cores: int,
    target: float = DEFAULT_TARGET,
    envs_per_worker: Sequence[int] = SWEEP_ENVS_PER_WORKER,
) -> Recommendation:
    """One worker per core with the smallest ``envs_per_worker`` that keeps ``E >= target``;
    if none does, the largest one, with as many workers (<= cores) as keep the target."""
    for epw in sorted(envs_per_worker):
        if model.efficiency(cores, epw) >= target:
            return Recommendation(cores, epw, model.efficiency(cores, epw), True)
    epw = max(envs_per_worker)
    fits = [w for w in range(1, cores + 1) if model.efficiency(w, epw) >= target]
    workers = max(fits) if fits else 1
    efficiency = model.efficiency(workers, epw)
    return Recommendation(workers, epw, efficiency, efficiency >= target)


# -- measurements (chronogym bench) -------------------------------------------------------


@dataclass
class Timed:
    """Steps timed in one setting: count, wall and driver CPU seconds (``cpu_s``: the whole
    process, every thread; ``thread_cpu_s``: the thread that made the calls)."""

    steps: int
    wall_s: float
    cpu_s: float
    thread_cpu_s: float

    @property
    def wall_per_step(self) -> float:
        return self.wall_s / self.steps

    @property
    def cpu_per_step(self) -> float:
        return self.cpu_s / self.steps


def timed_loop(step: Any, seconds: float, min_steps: int = 5, warmup: int = 3) -> Timed:
    """``warmup`` untimed calls of ``step()``, then calls until ``seconds`` have passed and
    ``min_steps`` were made: wall, this process's CPU time and the calling thread's."""
    for _ in range(warmup):
        step()
    steps, cpu, own = 0, time.process_time(), time.thread_time()
    start = time.perf_counter()
    while True:
        step()
        steps += 1
        wall = time.perf_counter() - start
        if wall >= seconds and steps >= min_steps:
            return Timed(steps, wall, time.process_time() - cpu, time.thread_time() - own)


def flat_size(space: Any) -> int:
    """Floats in a flattened sample of ``space`` (at least 1)."""
    import gymnasium as gym

    return max(1, int(gym.spaces.flatdim(space)))


@dataclass
class EnvProfile:
    """The user's env: its step cost (s) and the sizes the synthetic env copies: the
    observation's floats, and its step's info as numeric scalars and other floats."""

    env_id: str
    step_s: float
    obs_floats: int
    steps: int
    info_scalars: int = 0
    info_floats: int = 0

    @property
    def synthetic_kwargs(self) -> dict[str, Any]:
        """``SyntheticEnv`` keyword arguments of this env's sizes and step (``step_ms``)."""
        return {
            "step_ms": self.step_s * 1000,
            "obs_dim": self.obs_floats,
            "info_scalars": self.info_scalars,
            "info_floats": self.info_floats,
        }


def info_sizes(info: dict[str, Any]) -> tuple[int, int]:
    """(numeric scalars, floats in every other numeric value) of one step's info; values of
    other kinds (strings, objects) count as nothing."""
    import numpy as np

    scalars, floats = 0, 0
    for value in info.values():
        if isinstance(value, (bool, int, float, np.number, np.bool_)):
            scalars += 1
        elif isinstance(value, np.ndarray) and value.dtype.kind in "biuf":
            floats += value.size
    return scalars, floats


def measure_env(
    env_id: str, env_kwargs: dict[str, Any], seconds: float, seed: int = 0
) -> EnvProfile:
    """Time the env's own step serially in this process (random actions, resets at the end
    of an episode, not counted)."""
    import gymnasium as gym

    env = gym.make(env_id, **env_kwargs)
    try:
        env.reset(seed=seed)
        env.action_space.seed(seed)
        sample, step = env.action_space.sample, env.step
        for _ in range(3):  # warm-up: first calls compile, allocate, check
            env.step(sample())
        steps, busy, start, info = 0, 0.0, time.perf_counter(), {}
        while time.perf_counter() - start < seconds or steps < 5:
            action = sample()
            t0 = time.perf_counter()
            _, _, terminated, truncated, info = step(action)
            busy += time.perf_counter() - t0
            steps += 1
            if terminated or truncated:
                env.reset()
        obs_floats = flat_size(env.observation_space)
        return EnvProfile(env_id, busy / steps, obs_floats, steps, *info_sizes(info))
    finally:
        env.close()


@dataclass
class VectorRun:
    """One timed RayVectorEnv setting."""

    kind: str  # "synthetic" or "real"
    workers: int
    envs_per_worker: int
    step_s: float
    start_s: float
    timed: Timed


def time_vector_env(
    env_id: str,
    workers: int,
    env_kwargs: dict[str, Any],
    seconds: float,
    address: str | None,
    envs_per_worker: int = 1,
    transport: str | None = None,
) -> tuple[float, Timed]:
    """Build ``RayVectorEnv(env_id, workers * envs_per_worker)``, reset, step for ``seconds``:
    (seconds to the first reset, the timed steps)."""
    from chronogym.vector.ray_vector_env import RayVectorEnv

    start = time.perf_counter()
    vec = RayVectorEnv(
        env_id,
        workers * envs_per_worker,
        envs_per_worker=envs_per_worker,
        address=address,
        env_kwargs=env_kwargs,
        transport=transport,
    )
    try:
        vec.reset(seed=0)
        start_s = time.perf_counter() - start
        vec.action_space.seed(0)
        actions = itertools.cycle([vec.action_space.sample() for _ in range(8)])
        return start_s, timed_loop(lambda: vec.step(next(actions)), seconds)
    finally:
        vec.close()


def synthetic_step_s(step_s: float, seconds: float) -> float:
    """What one :class:`SyntheticEnv` step of ``step_s`` takes here, in this process (the
    sleep's own overshoot, which is not the vector env's cost)."""
    from chronogym.testing.synthetic import SyntheticEnv

    env = SyntheticEnv(step_ms=step_s * 1000)
    env.reset(seed=0)
    action = env.action_space.sample()
    return timed_loop(lambda: env.step(action), seconds).wall_per_step


def bench_workers(cpus: int, max_workers: int) -> list[int]:
    """W of the fit: 1, 2, 4 and ``cpus``, none above ``max_workers`` (which replaces
    ``cpus`` when ``cpus`` is larger)."""
    return sorted({w for w in (1, 2, 4, min(cpus, max_workers)) if w <= max_workers})


@dataclass
class BenchReport:
    """What ``chronogym bench`` measured and predicts."""

    env: EnvProfile
    synthetic_s: float
    cpus: int
    cores: int
    target: float
    runs: list[VectorRun] = field(default_factory=list)
    model: StepModel | None = None
    check: VectorRun | None = None
    transport: str = "socket"  # RayVectorEnv's transport, as measured
    where: str = "the cluster"  # whose CPUs: "this machine" for forked workers without Ray


def run_bench(
    env_id: str,
    env_kwargs: dict[str, Any] | None = None,
    seconds: float = 3.0,
    max_workers: int = 16,
    address: str | None = None,
    cores: int | None = None,
    target: float = DEFAULT_TARGET,
    check: bool = True,
    log: Any = print,
    transport: str | None = None,
) -> BenchReport:
    """Measure ``s``, ``a`` and ``b`` for ``env_id`` (module doc) with RayVectorEnv's
    ``transport`` (None: its default); ``log`` gets progress."""
    from chronogym.ray_runtime import cluster_cpus, ensure_ray
    from chronogym.validation import check_bool, check_int, check_number, check_positive
    from chronogym.vector.fork_placement import forks_here_only
    from chronogym.vector.ray_vector_env import check_transport
    from chronogym.vector.shared_step import usable_cpus

    transport = check_transport(transport)
    env_kwargs = dict(env_kwargs or {})
    seconds = check_positive("seconds", seconds)
    check_int("max_workers", max_workers, low=1)
    if cores is not None:
        check_int("cores", cores, low=1, expected="None or an integer >= 1")
    target = check_number("target", target, low=0.01, high=1.0)
    check_bool("check", check)
    log(f"timing {env_id} serially for {seconds:g} s ...")
    profile = measure_env(env_id, env_kwargs, seconds)
    log(
        f"  step: {profile.step_s * 1e3:.3f} ms ({profile.steps} steps); info: "
        f"{profile.info_scalars} scalars, {profile.info_floats} other floats"
    )
    here_only = transport == "fork" and forks_here_only(address)  # forked here, without Ray
    if here_only:
        cpus = usable_cpus()
    else:
        ensure_ray(address)
        cpus = max(1, int(cluster_cpus()))
    synthetic = profile.synthetic_kwargs
    report = BenchReport(
        profile, synthetic_step_s(profile.step_s, min(seconds, 1.0)), cpus, cores or cpus, target
    )
    report.transport = transport
    report.where = "this machine" if here_only else "the cluster"
    for workers in bench_workers(cpus, max_workers):
        log(f"timing RayVectorEnv, {workers} synthetic worker(s), for {seconds:g} s ...")
        start_s, timed = time_vector_env(
            "chronogym/Synthetic-v0", workers, synthetic, seconds, address, transport=transport
        )
        report.runs.append(VectorRun("synthetic", workers, 1, profile.step_s, start_s, timed))
    a, b = fit_overhead_nonnegative(
        [r.workers for r in report.runs],
        [r.timed.wall_per_step for r in report.runs],
        report.synthetic_s,
    )
    report.model = StepModel(profile.step_s, a, b)
    if check:
        workers = min(cpus, max_workers)
        log(f"checking the model on {env_id} itself, {workers} worker(s) ...")
        start_s, timed = time_vector_env(
            env_id, workers, env_kwargs, seconds, address, transport=transport
        )
        report.check = VectorRun("real", workers, 1, profile.step_s, start_s, timed)
    return report


# -- report ---------------------------------------------------------------------------------


def cores_shared(report: BenchReport) -> str | None:
    """A warning when the fit's largest W had more workers than CPUs: each worker's own CPU
    per step (its serving loop, the step's wake-up) then queues for the cores, and ``b``
    holds that queueing, which more cores would not have (None: a core per worker; at W =
    the CPUs only the driver, which mostly waits, shares one)."""
    most = max(run.workers for run in report.runs)
    if most <= report.cpus:
        return None
    text = (
        f"  W = {most} workers shared {report.where}'s {report.cpus} CPUs: b holds their wait "
        "for a core"
    )
    if report.cores > report.cpus:
        text += (
            f", so the plan for {report.cores} cores is pessimistic; run chronogym bench "
            "where the run will be (--address for a cluster)"
        )
    return text


def format_report(report: BenchReport) -> str:
    """The measurements, the efficiency table and the recommendation, as text."""
    model = report.model
    assert model is not None
    ms = 1e3
    lines = [
        f"env {report.env.env_id}: step {report.env.step_s * ms:.3f} ms, "
        f"observation {report.env.obs_floats} floats, info {report.env.info_scalars} scalars"
        f" and {report.env.info_floats} other floats; "
        f"{report.where} has {report.cpus} CPUs",
        "",
        f"measured (RayVectorEnv, transport={report.transport!r}, synthetic env sleeping the "
        "env's step, 1 env per worker):",
        "  workers  start s  step ms  driver CPU ms/step",
    ]
    for run in report.runs:
        lines.append(
            f"  {run.workers:7d}  {run.start_s:7.2f}  {run.timed.wall_per_step * ms:7.3f}  "
            f"{run.timed.cpu_per_step * ms:18.3f}"
        )
    lines += [
        f"fit: t_step = S + a + b*W with a = {model.a * 1e6:.1f} us (fixed), "
        f"b = {model.b * 1e6:.1f} us (per worker); S = envs_per_worker x "
        f"{model.step_s * ms:.3f} ms",
    ]
    if (crowded := cores_shared(report)) is not None:
        lines.append(crowded)
    if report.check is not None:
        run = report.check
        predicted = model.t_step(run.workers)
        lines.append(
            f"check on the env itself, {run.workers} workers: step "
            f"{run.timed.wall_per_step * ms:.3f} ms measured, {predicted * ms:.3f} ms predicted"
        )
        if run.timed.wall_per_step > 1.25 * predicted:
            lines.append(
                "  the model is optimistic here: the workers' compute (and the driver's) "
                "compete for these cores, which sleeping synthetic steps do not; with a core "
                "per worker besides the driver's, the prediction holds better"
            )
    lines += [
        "",
        "predicted efficiency E(W) = S / t_step (rows: workers W; columns: envs per worker)",
    ]
    header = "  W     " + "".join(f"{epw:>8d}" for epw in SWEEP_ENVS_PER_WORKER)
    lines.append(header)
    for workers in SWEEP_WORKERS:
        cells = "".join(f"{model.efficiency(workers, e):8.2f}" for e in SWEEP_ENVS_PER_WORKER)
        lines.append(f"  {workers:<6d}{cells}")
    lines.append("")
    for epw in SWEEP_ENVS_PER_WORKER:
        most = largest_workers(model, epw, report.target)
        text = f"W = {most}" if most is not None else "none"
        lines.append(f"largest W with E >= {report.target:g} at envs_per_worker={epw}: {text}")
    pick = recommend(model, report.cores, report.target)
    verdict = "" if pick.reached else f" (below the target {report.target:g})"
    lines += [
        "",
        f"recommendation for {report.cores} cores: num_workers={pick.workers}, "
        f"envs_per_worker={pick.envs_per_worker} (num_envs={pick.workers * pick.envs_per_worker}), "
        f"predicted efficiency {pick.efficiency:.2f}{verdict}, "
        f"{model.env_steps_per_s(pick.workers, pick.envs_per_worker):,.0f} env-steps/s",
    ]
    return "\n".join(lines)
