"""How well a Go1 policy tracks its commands: rollouts, the summary table, and when it walks.

``chronogym play quadruped`` runs :func:`evaluate` and prints :func:`format_summary`; the
training keeps ``best.pt`` by :class:`WalkingEvaluator`'s verdict, which runs the episodes of
a :class:`~.walking.WalkingCriterion` group by group, each group's episodes in step
(:func:`run_episodes_together`). Both kinds of rollout note each step in an
:class:`EpisodeTrace`, so a batched episode reports exactly what a single one does, and both
return the episode's :class:`~.walking.VelocityTrace` for the criteria of :mod:`.walking`.
"""

from __future__ import annotations

import math
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np
from tqdm import tqdm

from chronogym.rl.checkpoint import load_policy
from chronogym.tasks.quadruped.walking import (
    DEFAULT_COMMANDS,
    CommandCheck,
    CommandSwitch,
    EpisodeSpec,
    VelocityTrace,
    WalkingCriterion,
    WalkingCriterionV1,
    WalkingVerdict,
    as_command,
    command_label,
)
from chronogym.validation import check_int, check_positive
from chronogym.video import VideoRecorder

Policy = Callable[[np.ndarray], np.ndarray]
Criterion = WalkingCriterion | WalkingCriterionV1

__all__ = [
    "DEFAULT_COMMANDS",
    "EpisodeResult",
    "EpisodeTrace",
    "Policy",
    "WalkingCriterion",
    "WalkingCriterionV1",
    "WalkingEvaluator",
    "check_walking",
    "check_walking_by",
    "evaluate",
    "format_summary",
    "run_episode",
    "run_episodes_together",
    "summarize",
]


@dataclass(frozen=True)
class EpisodeResult:
    """One evaluation episode: its command and how well it was tracked."""

    command: tuple[float, float, float]
    seed: int
    survived: bool
    length_s: float
    x_vel_mse: float
    y_vel_mse: float
    mean_vx: float
    mean_vy: float
    episode_return: float
    trace: VelocityTrace = field(compare=False, repr=False)


@dataclass
class EpisodeTrace:
    """What the steps of one episode leave behind: its return, the base's velocity (body
    frame: vx, vy, yaw rate) after each step and the command then, turned into an
    :class:`EpisodeResult` when it ends."""

    spec: EpisodeSpec
    total: float = 0.0
    samples: list[tuple[float, float, float, float, float, float]] = field(default_factory=list)

    @property
    def command(self) -> Sequence[float]:
        return self.spec.command

    @property
    def seed(self) -> int:
        return self.spec.seed

    def record(self, task: Any, reward: float) -> None:
        """Note one step: its reward and the velocity of ``task`` (a Go1 task) after it."""
        self.total += float(reward)
        v, c = task.base_lin_vel, task.command
        self.samples.append(
            (float(v[0]), float(v[1]), task.base_yaw_rate, float(c[0]), float(c[1]), float(c[2]))
        )

    def result(
        self, task: Any, terminated: bool, truncated: bool, info: dict[str, Any]
    ) -> EpisodeResult:
        """The :class:`EpisodeResult` of the episode, ended by the step that returned
        ``terminated``, ``truncated`` and ``info``."""
        # The task logs its episode metrics when its own horizon ends the episode; a shorter
        # TimeLimit (``gym.make(..., max_episode_steps=N)``) ends it first: same errors from here.
        log = info.get("log", {})
        samples = np.asarray(self.samples, dtype=np.float64).reshape(-1, 6)
        trace = VelocityTrace(
            command=self.spec.command, seed=self.spec.seed, dt=float(task.control_dt),
            vx=samples[:, 0], vy=samples[:, 1], wz=samples[:, 2], commands=samples[:, 3:],
            survived=bool(truncated and not terminated), schedule=self.spec.schedule,
            episode_return=self.total,
        )  # fmt: skip
        command, vx, vy = self.command, trace.vx, trace.vy
        x_mse = trace.mse(0)
        y_mse = trace.mse(1)
        return EpisodeResult(
            command=tuple(float(c) for c in command),  # type: ignore[arg-type]
            seed=self.seed,
            survived=bool(truncated and not terminated),
            length_s=float(log.get("/metrics/episode_length_s", len(vx) * task.control_dt)),
            x_vel_mse=float(log.get("/metrics/x_vel_mse", x_mse)),
            y_vel_mse=float(log.get("/metrics/y_vel_mse", y_mse)),
            mean_vx=float(np.mean(vx)),
            mean_vy=float(np.mean(vy)),
            episode_return=self.total,
            trace=trace,
        )


def run_episode(
    env: Any,
    policy: Policy,
    command: Sequence[float] | EpisodeSpec,
    seed: int | None = None,
    recorder: VideoRecorder | None = None,
    record_steps: int = 0,
) -> EpisodeResult:
    """Run one full episode of ``env`` (a SimEnv of a Go1VelocityTask) with a fixed command
    and ``seed``, or as an :class:`~.walking.EpisodeSpec` says (``seed`` then unused); with
    ``recorder``, render its first ``record_steps`` steps into it."""
    spec = command if isinstance(command, EpisodeSpec) else EpisodeSpec.of((command, seed))
    obs, _ = env.reset(seed=spec.seed, options=spec.options())
    task = env.unwrapped.task
    trace = EpisodeTrace(spec)
    step = 0
    if recorder is not None:
        recorder.add(env.render, step)
    while True:
        action = np.asarray(policy(obs), dtype=np.float32)
        obs, reward, terminated, truncated, info = env.step(action)
        trace.record(task, reward)
        step += 1
        if recorder is not None and step <= record_steps:
            recorder.add(env.render, step)
        if terminated or truncated:
            return trace.result(task, terminated, truncated, info)


def run_episodes_together(
    envs: Sequence[Any], policy: Policy, jobs: Sequence[Any]
) -> list[EpisodeResult]:
    """Run one episode per job (a ``(command, seed)`` pair or an :class:`~.walking.EpisodeSpec`),
    each in its own env of ``envs`` (at least as many as jobs), all in step so that the
    policy sees one batch of observations per step: :func:`run_episode`'s results at a
    fraction of its cost per episode."""
    if len(envs) < len(jobs):
        raise ValueError(f"run_episodes_together: {len(jobs)} jobs but only {len(envs)} envs")
    specs = [EpisodeSpec.of(job) for job in jobs]
    envs = list(envs)[: len(specs)]
    obs = np.stack(
        [
            env.reset(seed=spec.seed, options=spec.options())[0]
            for env, spec in zip(envs, specs, strict=True)
        ]
    )
    traces = [EpisodeTrace(spec) for spec in specs]
    results: list[EpisodeResult | None] = [None] * len(jobs)
    running = list(range(len(jobs)))
    while running:
        actions = np.asarray(policy(obs[running]), dtype=np.float32)
        for action, i in zip(actions, list(running), strict=True):
            env = envs[i]
            obs[i], reward, terminated, truncated, info = env.step(action)
            task = env.unwrapped.task
            traces[i].record(task, reward)
            if terminated or truncated:
                results[i] = traces[i].result(task, terminated, truncated, info)
                running.remove(i)
    return [r for r in results if r is not None]


def evaluate(
    env: Any,
    policy: Policy,
    commands: Sequence[Sequence[float]] = DEFAULT_COMMANDS,
    episodes: int = 1,
    seed: int = 0,
    video: str | Path | None = None,
    progress: bool = True,
    video_seconds: float = 5.0,
    switch: CommandSwitch | None = None,
) -> list[EpisodeResult]:
    """Run ``episodes`` episodes per command (seeds ``seed``, ``seed + 1``, ...), then as
    many of ``switch`` (a command step during the episode), if given; with ``video``, record
    the first ``video_seconds`` of the first episode of each command (see
    :class:`VideoRecorder`). Each result's ``trace`` holds the episode's velocity trace."""
    check_int("episodes", episodes, low=1)
    check_positive("video_seconds", video_seconds, expected="a number > 0")
    fps = float(env.unwrapped.metadata.get("render_fps", 50))
    recorder = VideoRecorder(video, fps) if video is not None else None
    record_steps = math.ceil(video_seconds * fps)
    results = []
    runs = [EpisodeSpec(as_command(c), seed + i) for c in commands for i in range(episodes)]
    if switch is not None:
        runs += [switch.episode(seed + i) for i in range(episodes)]
    iterator: Any = tqdm(runs, desc="episodes", unit="ep") if progress else runs
    try:
        for spec in iterator:
            record = recorder if spec.seed == seed and not spec.schedule else None
            results.append(run_episode(env, policy, spec, None, record, record_steps))
    finally:
        if recorder is not None:
            recorder.close()
    return results


def summarize(
    results: Sequence[EpisodeResult], criterion: WalkingCriterion | None = None
) -> list[dict[str, Any]]:
    """One row per command (and per command switch): survival rate, whole-episode tracking
    errors (v1's metric), and the values of ``criterion``'s clauses (default: v2's) on its
    episodes: the slowest t90, the steady-state x/y MSEs, the yaw-rate MSE, and whether the
    group passes v2 (``"v2"``, with ``"failures"``) and v1 (``"v1"``; None for a switch)."""
    criterion = criterion if criterion is not None else WalkingCriterion()
    v1 = WalkingCriterionV1(max_x_mse=criterion.max_x_mse, max_y_mse=criterion.max_y_mse)
    groups: dict[tuple[Any, ...], list[EpisodeResult]] = {}
    for result in results:
        groups.setdefault((result.command, result.trace.schedule), []).append(result)
    rows = []
    for (command, schedule), group in groups.items():
        traces = [r.trace for r in group]
        label = command_label(command)
        if schedule:
            label = CommandSwitch(command, schedule[-1][1], schedule[-1][0]).label
        check = criterion.check_group(label, traces)
        rows.append(
            {
                "label": label,
                "command": check.command,
                "episodes": len(group),
                "survival": float(np.mean([r.survived for r in group])),
                "x_vel_mse": float(np.mean([r.x_vel_mse for r in group])),
                "y_vel_mse": float(np.mean([r.y_vel_mse for r in group])),
                "mean_vx": float(np.mean([r.mean_vx for r in group])),
                "mean_vy": float(np.mean([r.mean_vy for r in group])),
                "rise_s": check.rise_s,
                "steady_x_mse": check.x_mse,
                "steady_y_mse": check.y_mse,
                "yaw_mse": check.yaw_mse,
                "v2": check.passed,
                "failures": list(check.failures),
                "v1": None if schedule else v1.check_group(label, traces).passed,
            }
        )
    return rows


def format_summary(rows: Sequence[dict[str, Any]]) -> str:
    """The summary as an aligned text table; ``x_mse``/``y_mse`` are whole-episode MSEs (the
    paper's metric), ``t90`` the slowest rise time, ``ss_x``/``ss_y``/``yaw`` the steady-state
    MSEs that the walking criterion v2 bounds."""

    def number(value: float | None, width: int, digits: int) -> str:
        if value is None:
            return f"{'-':>{width}}"
        return f"{'never':>{width}}" if math.isinf(value) else f"{value:{width}.{digits}f}"

    width = max([22, *(len(row.get("label", "")) for row in rows)])
    lines = [
        f"{'command (vx, vy, wz)':>{width}} {'eps':>4} {'survival':>8} {'x_mse':>7} {'y_mse':>7} "
        f"{'mean vx':>7} {'mean vy':>7} {'t90 s':>6} {'ss_x':>7} {'ss_y':>7} {'yaw':>7} "
        f"{'v1':>4} {'v2':>4}"
    ]
    for row in rows:
        label = row.get("label", command_label(row["command"]))
        marks = {True: "pass", False: "FAIL", None: "-"}
        lines.append(
            f"{label:>{width}} {row['episodes']:4d} {row['survival']:8.2f} {row['x_vel_mse']:7.4f} "
            f"{row['y_vel_mse']:7.4f} {row['mean_vx']:7.3f} {row['mean_vy']:7.3f} "
            f"{number(row.get('rise_s'), 6, 2)} {number(row.get('steady_x_mse'), 7, 4)} "
            f"{number(row.get('steady_y_mse'), 7, 4)} {number(row.get('yaw_mse'), 7, 4)} "
            f"{marks[row.get('v1')]:>4} {marks[row.get('v2')]:>4}"
        )
    return "\n".join(lines)


def check_walking(
    env: Any,
    policy: Policy,
    criterion: Criterion,
    *,
    envs: Sequence[Any] | None = None,
    also: Sequence[Criterion] = (),
) -> WalkingVerdict:
    """``criterion``'s verdict on ``policy``, its groups (commands, then the switch) run in
    order until the first that fails, so a policy that does not walk costs little; the
    verdict then holds the groups run so far, and the traces of every episode run. A group's
    episodes run in step in ``envs`` (as many as ``criterion.episodes``), or one after another
    in ``env``. ``also``: more criteria judged from the same episodes (see
    :func:`check_walking_by`)."""
    return check_walking_by(env, policy, [criterion, *also], envs=envs)[0]


def check_walking_by(
    env: Any, policy: Policy, criteria: Sequence[Criterion], *, envs: Sequence[Any] | None = None
) -> list[WalkingVerdict]:
    """One verdict per criterion of ``criteria`` (e.g. v2 and v1) from one set of episodes:
    the groups of all of them, in order, each run once, while a criterion that needs it has
    not yet failed a group."""
    plans = [list(c.groups()) for c in criteria]
    union = list({g.specs: g for plan in plans for g in plan}.values())
    checks: list[list[CommandCheck]] = [[] for _ in criteria]
    alive = [True] * len(criteria)
    traces: list[VelocityTrace] = []
    for group in union:
        needed = [
            i
            for i, plan in enumerate(plans)
            if alive[i] and any(g.specs == group.specs for g in plan)
        ]
        if not needed:
            continue
        if envs is not None:
            results = run_episodes_together(envs, policy, group.specs)
        else:
            results = [run_episode(env, policy, spec) for spec in group.specs]
        mine = [r.trace for r in results]
        traces += mine
        for i in needed:
            check = criteria[i].check_group(group.label, mine)
            checks[i].append(check)
            alive[i] = check.passed
        if not any(alive):
            break
    return [
        WalkingVerdict(tuple(found), len(plan), c.version, tuple(traces))
        for c, plan, found in zip(criteria, plans, checks, strict=True)
    ]


class WalkingEvaluator:
    """Judges checkpoints by ``criterion`` during training (``best.pt``): the criterion's
    groups in order until the first that fails, each group's episodes in step in envs made
    once by ``make_env``."""

    columns = ("eval_commands_passed", "eval_worst_ratio")

    def __init__(self, make_env: Callable[[], Any], criterion: Criterion) -> None:
        self.criterion = criterion
        self.envs = [make_env() for _ in range(criterion.episodes)]

    def __call__(self, checkpoint: str | Path) -> WalkingVerdict:
        """Judge the policy of ``checkpoint`` (loaded as ``chronogym play`` loads it)."""
        policy = load_policy(checkpoint, torch_threads=None)
        return check_walking(self.envs[0], policy, self.criterion, envs=self.envs)

    def close(self) -> None:
        for env in self.envs:
            env.close()
        self.envs = []
