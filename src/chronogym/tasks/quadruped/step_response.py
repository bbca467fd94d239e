"""The step response of a Go1 policy as a picture: vx, vy and the yaw rate against time.

One column per command (and one for the command switch), one row per axis; each episode is a
thin line, the command a dashed line, 90 % of it a dotted one, and the criterion's rise-time
bound a grey band, so a policy's start, steady state and switch show at a glance.
matplotlib (the ``rl`` extra) is imported when a picture is drawn.
"""

from __future__ import annotations

import textwrap
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from chronogym.tasks.quadruped.walking import (
    CommandCheck,
    VelocityTrace,
    WalkingCriterion,
    WalkingVerdict,
    command_label,
)

_ROWS = (("vx (m/s)", 0), ("vy (m/s)", 1), ("yaw rate (rad/s)", 2))


def _groups(traces: Sequence[VelocityTrace]) -> dict[str, list[VelocityTrace]]:
    groups: dict[str, list[VelocityTrace]] = {}
    for trace in traces:
        if trace.schedule:
            label = f"{command_label(trace.command)} -> {command_label(trace.schedule[-1][1])}"
        else:
            label = command_label(trace.command)
        groups.setdefault(label, []).append(trace)
    return groups


def plot_step_response(
    traces: Sequence[VelocityTrace],
    path: str | Path,
    criterion: WalkingCriterion | None = None,
    verdict: WalkingVerdict | None = None,
    title: str = "Go1 step response",
) -> Path:
    """Draw ``traces`` (one column per command or switch) into the PNG ``path``. With
    ``criterion``, shade its rise-time bound after each start and switch; with ``verdict``,
    title each column with its check's result."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    if not traces:
        raise ValueError("plot_step_response: no traces to draw")
    groups = _groups(traces)
    checks = {c.label: c for c in verdict.checks} if verdict is not None else {}
    fig, axes = plt.subplots(
        3, len(groups), figsize=(3.2 * len(groups) + 1, 7.5), sharex="col", squeeze=False
    )
    for column, (label, mine) in enumerate(groups.items()):
        starts = [0.0, *(t for t, _ in mine[0].schedule)]
        for (name, index), axis in zip(_ROWS, axes[:, column], strict=True):
            for trace in mine:
                axis.plot(trace.time, trace.axis(index), lw=0.7, alpha=0.8)
            longest = max(mine, key=lambda t: len(t.vx))
            command = longest.commands[:, index]
            axis.plot(longest.time, command, color="k", ls="--", lw=1.0)
            if np.any(command != 0):
                axis.plot(longest.time, 0.9 * command, color="k", ls=":", lw=0.8)
            if criterion is not None:
                for start in starts:
                    axis.axvspan(start, start + criterion.max_rise_s, color="0.85", zorder=0)
            axis.grid(alpha=0.3)
            if column == 0:
                axis.set_ylabel(name)
        axes[-1, column].set_xlabel("time (s)")
        heading = label
        check = _check_for(checks, mine[0])
        if check is not None:
            result = "pass" if check.passed else "FAIL: " + check.failures[0]
            heading += "\n" + "\n".join(textwrap.wrap(result, 44))
        axes[0, column].set_title(heading, fontsize=8)
    fig.suptitle(title + " (dashed: command; dotted: 90 % of it; grey: rise-time bound)")
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=90)
    plt.close(fig)
    return path


def _check_for(checks: dict[str, CommandCheck], trace: VelocityTrace) -> CommandCheck | None:
    """The verdict's check of ``trace``'s group (by its label), if there is one."""
    for label, check in checks.items():
        same_command = check.command == (trace.schedule[-1][1] if trace.schedule else trace.command)
        if same_command and label.startswith("switch") == bool(trace.schedule):
            return check
    return None
