"""When a Go1 policy walks: velocity traces of its episodes, and the criteria that judge them.

An evaluation episode leaves a :class:`VelocityTrace`: the base's body-frame velocity (vx, vy,
yaw rate) after every control step, and the command in force at each step. Two criteria judge
traces:

* :class:`WalkingCriterion` (v2, the default): per command, survival, a rise time (t90), the
  steady-state x/y velocity MSE after the first second, the yaw-rate MSE, and a command switch.
* :class:`WalkingCriterionV1`: survival and the whole-episode x/y MSE (the paper's metric). It
  averages the start from rest into the error, which makes it a rise-time requirement that
  grows with speed², so it is kept only to compare with results scored before v2.

Both return a :class:`WalkingVerdict`: one :class:`CommandCheck` per group of episodes (a
command, or the switch), each naming the clauses it failed. Everything here is NumPy on
recorded traces; the rollouts are in :mod:`.evaluation`.
"""

from __future__ import annotations

import dataclasses
import json
import math
from collections.abc import Sequence
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from chronogym.validation import check_int, check_positive

Command = tuple[float, float, float]

#: Commands (vx m/s, vy m/s, yaw rate rad/s) every policy is judged on, in order.
DEFAULT_COMMANDS: tuple[Command, ...] = (
    (0.5, 0.0, 0.0),
    (1.0, 0.0, 0.0),
    (0.0, 0.3, 0.0),
    (-0.3, 0.0, 0.0),
    (0.5, 0.0, 0.5),
    (0.0, 0.0, 0.0),
)

_AXES = ("vx", "vy", "yaw rate")


def as_command(value: Any, name: str = "command") -> Command:
    """``value`` as a (vx, vy, yaw rate) tuple of 3 finite floats, or ValueError naming it."""
    try:
        command = tuple(float(c) for c in value)
    except (TypeError, ValueError):
        command = ()
    if len(command) != 3 or not all(math.isfinite(c) for c in command):
        raise ValueError(f"{name}={value!r}: expected 3 finite floats (vx, vy, yaw_rate)")
    return command  # type: ignore[return-value]


def command_label(command: Sequence[float]) -> str:
    """``"(+0.50, +0.00, +0.00)"``."""
    return "(" + ", ".join(f"{c:+.2f}" for c in command) + ")"


@dataclass(frozen=True)
class CommandSwitch:
    """An episode that starts at ``before`` and steps to ``after`` at ``at_s`` seconds."""

    before: Command = (0.5, 0.0, 0.0)
    after: Command = (1.0, 0.0, 0.0)
    at_s: float = 10.0

    def __post_init__(self) -> None:
        object.__setattr__(self, "before", as_command(self.before, "switch.before"))
        object.__setattr__(self, "after", as_command(self.after, "switch.after"))
        check_positive("switch.at_s", self.at_s, expected="a time > 0 s into the episode")

    def episode(self, seed: int) -> EpisodeSpec:
        """The episode of this switch with ``seed``."""
        return EpisodeSpec(self.before, seed, ((self.at_s, self.after),))

    @property
    def label(self) -> str:
        """``"switch (+0.50, ...) -> (+1.00, ...) at 10 s"``."""
        return (
            f"switch {command_label(self.before)} -> {command_label(self.after)} at {self.at_s:g} s"
        )


@dataclass(frozen=True)
class EpisodeSpec:
    """One evaluation episode: its first command, its seed, and the command changes after
    the start (``schedule``: ``(time_s, command)`` pairs, see the task's
    ``reset(options={"command_schedule": ...})``)."""

    command: Command
    seed: int
    schedule: tuple[tuple[float, Command], ...] = ()

    @classmethod
    def of(cls, job: Any) -> EpisodeSpec:
        """``job`` as a spec: an :class:`EpisodeSpec`, or a ``(command, seed)`` pair."""
        if isinstance(job, EpisodeSpec):
            return job
        command, seed = job
        return cls(as_command(command), int(seed))

    def options(self) -> dict[str, Any]:
        """The ``reset`` options that run this episode."""
        options: dict[str, Any] = {"command": self.command}
        if self.schedule:
            options["command_schedule"] = self.schedule
        return options


@dataclass
class VelocityTrace:
    """One episode: the base's body-frame velocity after each control step (``dt`` apart;
    sample ``i`` is at ``(i + 1) * dt`` s) and the command in force at each step."""

    command: Command
    seed: int
    dt: float
    vx: np.ndarray
    vy: np.ndarray
    wz: np.ndarray
    commands: np.ndarray
    survived: bool
    schedule: tuple[tuple[float, Command], ...] = ()
    episode_return: float = 0.0

    @property
    def time(self) -> np.ndarray:
        """Sample times (s)."""
        return (np.arange(len(self.vx)) + 1) * self.dt

    @property
    def length_s(self) -> float:
        return len(self.vx) * self.dt

    def axis(self, index: int) -> np.ndarray:
        """vx, vy or the yaw rate (index 0, 1, 2)."""
        return (self.vx, self.vy, self.wz)[index]

    def mse(self, index: int, from_s: float = 0.0) -> float:
        """Mean squared error of axis ``index`` against its command over samples at
        ``from_s`` s and later (nan if there are none)."""
        keep = self.time >= from_s - 1e-9
        if not keep.any():
            return math.nan
        error = self.axis(index)[keep] - self.commands[keep, index]
        return float(np.mean(error**2))

    def rise_time(
        self, index: int, target: float, start_s: float = 0.0, window_s: float = 0.2,
        fraction: float = 0.9,
    ) -> float:  # fmt: skip
        """t90: seconds after ``start_s`` until the trailing ``window_s`` moving average of
        axis ``index`` first reaches ``fraction`` of ``target`` (inf if it never does)."""
        window = max(1, round(window_s / self.dt))
        values = self.axis(index)
        if len(values) < window or target == 0:
            return math.inf if target else 0.0
        average = np.convolve(values, np.ones(window) / window, mode="valid")
        times = self.time[window - 1 :]
        reached = (average * math.copysign(1.0, target) >= fraction * abs(target) - 1e-12) & (
            times >= start_s - 1e-9
        )
        hits = np.flatnonzero(reached)
        return float(times[hits[0]] - start_s) if len(hits) else math.inf


@dataclass(frozen=True)
class CommandCheck:
    """How one group of episodes (a command, or the switch) did against a criterion.

    ``rise_s``: the slowest episode's t90 (None: no linear part); ``x_mse``/``y_mse``: the
    steady-state MSEs that the criterion bounds, averaged over the episodes; ``yaw_mse``:
    likewise (None: not judged); ``episode_x_mse``/``episode_y_mse``: whole-episode MSEs
    (the paper's metric, v1's clause); ``ratio``: the worst judged value over its bound
    (<= 1 on every clause passes; a fall counts as 1 plus the share of episodes that fell);
    ``failures``: what failed, in words."""

    label: str
    command: Command
    episodes: int
    survived: int
    rise_s: float | None
    x_mse: float
    y_mse: float
    yaw_mse: float | None
    episode_x_mse: float
    episode_y_mse: float
    ratio: float
    failures: tuple[str, ...] = ()

    @property
    def passed(self) -> bool:
        return not self.failures


@dataclass(frozen=True)
class WalkingVerdict:
    """A criterion's judgement of a policy: one check per group, in the criterion's order
    (a group not evaluated, after an early stop, is missing), and the traces judged."""

    checks: tuple[CommandCheck, ...]
    groups: int
    version: str = "v2"
    traces: tuple[VelocityTrace, ...] = field(default=(), repr=False, compare=False)

    @property
    def walks(self) -> bool:
        return len(self.checks) == self.groups and all(c.passed for c in self.checks)

    @property
    def commands_passed(self) -> int:
        """Groups passed in order before the first that failed."""
        passed = 0
        for check in self.checks:
            if not check.passed:
                break
            passed += 1
        return passed

    @property
    def worst_ratio(self) -> float:
        """The worst judged value over its bound, over the groups evaluated."""
        return max((c.ratio for c in self.checks), default=math.inf)

    @property
    def failures(self) -> list[str]:
        return [f"{c.label}: {f}" for c in self.checks for f in c.failures]

    # the Score protocol of chronogym.rl.best (best.pt)
    def key(self) -> tuple[float, float]:
        """Ranking key, larger is better: groups passed in order, then a smaller worst ratio."""
        return (self.commands_passed, -self.worst_ratio)

    def describe(self) -> str:
        """E.g. ``"5/7 pass (v2); first failure: (+1.00, ...): t90 1.56 s > 1 s (seed 2)"``."""
        text = f"{self.commands_passed}/{self.groups} pass ({self.version})"
        failures = self.failures
        return text + (f"; first failure: {failures[0]}" if failures else "")

    def columns(self) -> dict[str, float]:
        """Its ``progress.csv`` values (:attr:`~.evaluation.WalkingEvaluator.columns`)."""
        return {"eval_commands_passed": self.commands_passed, "eval_worst_ratio": self.worst_ratio}

    def as_dict(self) -> dict[str, Any]:
        """JSON-ready: the verdict and every check."""
        return {
            "version": self.version,
            "walks": self.walks,
            "passed": self.commands_passed,
            "groups": self.groups,
            "worst_ratio": _finite(self.worst_ratio),
            "failures": self.failures,
            "checks": [{k: _finite(v) for k, v in c.__dict__.items()} for c in self.checks],
        }


def _finite(value: Any) -> Any:
    """JSON has no inf/nan: write them as None."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    return value


def _mean(values: Sequence[float]) -> float:
    finite = [v for v in values if not math.isnan(v)]
    return float(np.mean(finite)) if finite else math.inf


@dataclass(frozen=True)
class _Group:
    label: str
    specs: tuple[EpisodeSpec, ...]


@dataclass(frozen=True)
class WalkingCriterion:
    """Walking criterion v2. A policy walks iff, for every command of ``commands`` (``episodes``
    episodes from rest, seeds ``seed``, ``seed + 1``, ...) and for the ``switch`` episodes
    (one per seed):

    * **survival**: every episode reaches the time limit without termination;
    * **rise time**: for each non-zero linear component (vx, vy) of the command, t90 <=
      ``max_rise_s`` in every episode: the first time the trailing ``rise_window_s`` moving
      average of that component reaches ``rise_fraction`` of its command;
    * **steady state**: over [``settle_s``, end], the x- and y-velocity MSEs averaged over the
      episodes are <= ``max_x_mse`` / ``max_y_mse`` (m/s)²;
    * **yaw**: for a command with a yaw rate, the yaw-rate MSE over the same window, averaged
      over the episodes, is <= ``max_yaw_mse`` (rad/s)²;
    * **switch**: the command steps from ``switch.before`` to ``switch.after`` at
      ``switch.at_s``; t90 after the switch <= ``max_rise_s``, and the steady state over
      [``switch.at_s + settle_s``, end] meets the same bounds (None: no switch episodes).

    The whole-episode x/y MSEs (the paper's metric) are reported beside the verdict.
    """

    commands: tuple[Command, ...] = DEFAULT_COMMANDS
    episodes: int = 5
    seed: int = 0
    max_rise_s: float = 1.0
    rise_fraction: float = 0.9
    rise_window_s: float = 0.2
    settle_s: float = 1.0
    max_x_mse: float = 0.01
    max_y_mse: float = 0.01
    max_yaw_mse: float = 0.04
    switch: CommandSwitch | None = field(default_factory=CommandSwitch)

    version = "v2"

    def __post_init__(self) -> None:
        for name in ("max_x_mse", "max_y_mse"):
            check_positive(name, getattr(self, name), expected="a threshold > 0 in (m/s)^2")
        check_positive("max_yaw_mse", self.max_yaw_mse, expected="a threshold > 0 in (rad/s)^2")
        check_positive("max_rise_s", self.max_rise_s, expected="a time > 0 s")
        check_positive("rise_window_s", self.rise_window_s, expected="a window > 0 s")
        if not 0 < self.rise_fraction <= 1:
            raise ValueError(f"rise_fraction={self.rise_fraction!r}: expected a fraction in (0, 1]")
        if not (isinstance(self.settle_s, int | float) and 0 <= self.settle_s < math.inf):
            raise ValueError(f"settle_s={self.settle_s!r}: expected a time >= 0 s")
        _check_common(self)
        if self.switch is not None and not isinstance(self.switch, CommandSwitch):
            raise TypeError(f"switch={self.switch!r}: expected a CommandSwitch or None")

    def groups(self) -> list[_Group]:
        """The episodes to run, grouped as they are judged, in order."""
        groups = _command_groups(self)
        if self.switch is not None:
            seeds = range(self.seed, self.seed + self.episodes)
            groups.append(_Group(self.switch.label, tuple(self.switch.episode(s) for s in seeds)))
        return groups

    def check_group(self, label: str, traces: Sequence[VelocityTrace]) -> CommandCheck:
        """Judge one group's traces."""
        first = traces[0]
        switch_s = first.schedule[0][0] if first.schedule else 0.0
        command = first.schedule[-1][1] if first.schedule else first.command
        start = switch_s + self.settle_s
        failures = _survival_failures(traces)
        ratios = []
        rise = None
        linear = [i for i in (0, 1) if command[i] != 0]
        if linear:
            rises = [
                (t.rise_time(i, command[i], switch_s, self.rise_window_s, self.rise_fraction),
                 _AXES[i], t.seed)
                for t in traces for i in linear
            ]  # fmt: skip
            rise, axis, seed = max(rises, key=lambda r: r[0])
            # never reaching 90 % ranks as reaching it at the episode's end
            ratios.append(min(rise, first.length_s - switch_s) / self.max_rise_s)
            if rise > self.max_rise_s:
                after = "after the switch " if first.schedule else ""
                shown = "never" if math.isinf(rise) else f"{rise:.2f} s"
                failures.append(
                    f"rise time: {axis} t90 {after}{shown} > {self.max_rise_s:g} s (seed {seed})"
                )
        x_mse = _mean([t.mse(0, start) for t in traces])
        y_mse = _mean([t.mse(1, start) for t in traces])
        for name, value, bound in (("x", x_mse, self.max_x_mse), ("y", y_mse, self.max_y_mse)):
            ratios.append(value / bound)
            if value > bound:
                failures.append(
                    f"steady state: {name}-velocity MSE over [{start:g} s, end] "
                    f"{value:.4f} > {bound:g} (m/s)²"
                )
        yaw_mse = None
        if command[2] != 0:
            yaw_mse = _mean([t.mse(2, start) for t in traces])
            ratios.append(yaw_mse / self.max_yaw_mse)
            if yaw_mse > self.max_yaw_mse:
                failures.append(
                    f"yaw: yaw-rate MSE over [{start:g} s, end] {yaw_mse:.4f} > "
                    f"{self.max_yaw_mse:g} (rad/s)²"
                )
        return _check(label, command, traces, rise, x_mse, y_mse, yaw_mse, ratios, failures)

    def judge(self, traces: Sequence[VelocityTrace]) -> WalkingVerdict:
        """The verdict on traces of this criterion's episodes (see :func:`judge`)."""
        return judge(self, traces)


@dataclass(frozen=True)
class WalkingCriterionV1:
    """Walking criterion v1 (before 2026-11-27), kept to compare with results scored by it:
    for every command, ``episodes`` episodes all survive and the whole-episode x- and
    y-velocity MSEs averaged over them are <= ``max_x_mse`` / ``max_y_mse`` (m/s)²."""

    commands: tuple[Command, ...] = DEFAULT_COMMANDS
    episodes: int = 5
    seed: int = 0
    max_x_mse: float = 0.01
    max_y_mse: float = 0.01

    version = "v1"

    def __post_init__(self) -> None:
        for name in ("max_x_mse", "max_y_mse"):
            check_positive(name, getattr(self, name), expected="a threshold > 0 in (m/s)^2")
        _check_common(self)

    def groups(self) -> list[_Group]:
        return _command_groups(self)

    def check_group(self, label: str, traces: Sequence[VelocityTrace]) -> CommandCheck:
        command = traces[0].command
        failures = _survival_failures(traces)
        x_mse = _mean([t.mse(0) for t in traces])
        y_mse = _mean([t.mse(1) for t in traces])
        ratios = [x_mse / self.max_x_mse, y_mse / self.max_y_mse]
        for name, value, bound in (("x", x_mse, self.max_x_mse), ("y", y_mse, self.max_y_mse)):
            if value > bound:
                failures.append(f"whole-episode {name}-velocity MSE {value:.4f} > {bound:g}")
        return _check(label, command, traces, None, x_mse, y_mse, None, ratios, failures)

    def judge(self, traces: Sequence[VelocityTrace]) -> WalkingVerdict:
        return judge(self, traces)


def criterion_for_episode(criterion: WalkingCriterion, length_s: float) -> WalkingCriterion:
    """``criterion`` for episodes of ``length_s`` s (training on short episodes): in an
    episode shorter than twice the switch time the switch comes half-way through, and in one
    shorter than 4 x ``settle_s`` the steady state starts after a quarter of the episode."""
    changes: dict[str, Any] = {}
    switch = criterion.switch
    if switch is not None and length_s < 2 * switch.at_s:
        changes["switch"] = dataclasses.replace(switch, at_s=round(length_s / 2, 6))
    if length_s < 4 * criterion.settle_s:
        changes["settle_s"] = round(length_s / 4, 6)
    return dataclasses.replace(criterion, **changes) if changes else criterion


def _command_groups(criterion: Any) -> list[_Group]:
    """One group per command of ``criterion``: its episodes from rest, seeds ``seed``, ..."""
    seeds = range(criterion.seed, criterion.seed + criterion.episodes)
    return [
        _Group(command_label(c), tuple(EpisodeSpec(c, s) for s in seeds))
        for c in criterion.commands
    ]


def _check_common(criterion: Any) -> None:
    check_int("episodes", criterion.episodes, low=1)
    check_int("seed", criterion.seed, low=0)
    if not criterion.commands:
        raise ValueError("commands=(): expected at least one (vx, vy, wz) command")
    commands = tuple(as_command(c, "commands[]") for c in criterion.commands)
    object.__setattr__(criterion, "commands", commands)


def _survival_failures(traces: Sequence[VelocityTrace]) -> list[str]:
    fell = [t.seed for t in traces if not t.survived]
    if not fell:
        return []
    return [f"survival: {len(fell)}/{len(traces)} episodes ended early (seeds {fell})"]


def _survival_ratio(traces: Sequence[VelocityTrace]) -> float:
    """Survival's place among the ratios: 0 if every episode survived, else 1 plus the share
    that fell (a group with a fall never ranks as passing)."""
    fell = sum(not t.survived for t in traces)
    return 1.0 + fell / len(traces) if fell else 0.0


def _check(
    label: str, command: Command, traces: Sequence[VelocityTrace], rise: float | None,
    x_mse: float, y_mse: float, yaw_mse: float | None, ratios: list[float], failures: list[str],
) -> CommandCheck:  # fmt: skip
    return CommandCheck(
        label=label,
        command=command,
        episodes=len(traces),
        survived=sum(t.survived for t in traces),
        rise_s=rise,
        x_mse=x_mse,
        y_mse=y_mse,
        yaw_mse=yaw_mse,
        episode_x_mse=_mean([t.mse(0) for t in traces]),
        episode_y_mse=_mean([t.mse(1) for t in traces]),
        ratio=max([*ratios, _survival_ratio(traces)]),
        failures=tuple(failures),
    )


def judge(
    criterion: WalkingCriterion | WalkingCriterionV1, traces: Sequence[VelocityTrace]
) -> WalkingVerdict:
    """``criterion``'s verdict on ``traces``: each of its groups whose episodes (matched by
    command, seed and schedule) are all in ``traces`` is checked, in order."""
    found = {(t.command, t.seed, t.schedule): t for t in traces}
    checks = []
    groups = criterion.groups()
    for group in groups:
        mine = [found.get((s.command, s.seed, s.schedule)) for s in group.specs]
        if any(t is None for t in mine):
            continue
        checks.append(criterion.check_group(group.label, mine))  # type: ignore[arg-type]
    return WalkingVerdict(tuple(checks), len(groups), criterion.version, tuple(traces))


# --- traces on disk ----------------------------------------------------------------------


def save_traces(path: str | Path, traces: Sequence[VelocityTrace]) -> Path:
    """Write ``traces`` to one ``.npz`` (:func:`load_traces` reads it back)."""
    path = Path(path)
    if path.suffix != ".npz":
        raise ValueError(f"traces path {str(path)!r}: expected a file name ending in .npz")
    path.parent.mkdir(parents=True, exist_ok=True)
    meta = [
        {"command": t.command, "seed": t.seed, "dt": t.dt, "survived": t.survived,
         "schedule": [[s, list(c)] for s, c in t.schedule], "return": t.episode_return}
        for t in traces
    ]  # fmt: skip
    arrays = {
        "lengths": np.array([len(t.vx) for t in traces], dtype=np.int64),
        "velocity": np.concatenate(
            [np.stack([t.vx, t.vy, t.wz], axis=1) for t in traces] or [np.zeros((0, 3))]
        ),
        "commands": np.concatenate([t.commands for t in traces] or [np.zeros((0, 3))]),
        "meta": np.array(json.dumps(meta)),
    }
    np.savez_compressed(path, **arrays)
    return path


def load_traces(path: str | Path) -> list[VelocityTrace]:
    """The traces :func:`save_traces` wrote to ``path``."""
    with np.load(Path(path), allow_pickle=False) as data:
        meta = json.loads(str(data["meta"]))
        ends = np.cumsum(data["lengths"])
        velocity = np.split(data["velocity"], ends[:-1])
        commands = np.split(data["commands"], ends[:-1])
    return [
        VelocityTrace(
            command=tuple(m["command"]),  # type: ignore[arg-type]
            seed=int(m["seed"]),
            dt=float(m["dt"]),
            vx=v[:, 0].copy(),
            vy=v[:, 1].copy(),
            wz=v[:, 2].copy(),
            commands=c,
            survived=bool(m["survived"]),
            schedule=tuple((float(s), tuple(c)) for s, c in m["schedule"]),  # type: ignore[misc]
            episode_return=float(m["return"]),
        )
        for m, v, c in zip(meta, velocity, commands, strict=True)
    ]
