"""benchmarks/rl/rl_scaling.py's comparison of configurations: reward milestones, their
wall-clock ratios, and whether two runs share one reward curve against env steps."""

from __future__ import annotations

import csv
import math

from benchmarks.rl.rl_scaling import compare_to_first, reward_milestones, same_curve


def rows(rewards: list[float], seconds_per_row: float, steps_per_row: int = 100) -> list[dict]:
    return [
        {"wall_time": (i + 1) * seconds_per_row, "env_steps": (i + 1) * steps_per_row,
         "mean_reward": r}
        for i, r in enumerate(rewards)
    ]  # fmt: skip


def test_milestones_time_the_first_crossing_and_say_never():
    got = reward_milestones(rows([1.0, 12.0, 9.0, 16.0], 60.0), levels=(10.0, 15.0, 20.0))
    assert got == [
        {"reward": 10.0, "minutes": 2.0, "env_steps": 200},
        {"reward": 15.0, "minutes": 4.0, "env_steps": 400},
        {"reward": 20.0, "minutes": None, "env_steps": None},
    ]


def test_same_curve_matches_on_shared_env_steps_only():
    fast = rows([math.nan, 5.0, 12.0, 16.0], 30.0)
    slow = rows([math.nan, 5.0, 12.0], 60.0)  # fewer steps in the same budget, same numbers
    assert same_curve(slow, fast) is True
    assert same_curve(rows([math.nan, 5.0, 11.0], 60.0), fast) is False
    assert same_curve(rows([1.0], 60.0, steps_per_row=7), fast) is None


def test_compare_to_first_gives_ratios_of_minutes(tmp_path):
    for name, per_row in (("ray-16", 30.0), ("serial-16", 45.0)):
        with (tmp_path / f"{name}.csv").open("w", newline="") as handle:
            writer = csv.DictWriter(handle, ["wall_time", "env_steps", "mean_reward"])
            writer.writeheader()
            writer.writerows(rows([4.0, 10.0, 15.0, 21.0], per_row))
    summaries = [{"config": c, "csv": f"{c}.csv"} for c in ("ray-16", "serial-16")]
    compare_to_first(summaries, tmp_path)
    ray, serial = summaries
    assert [m["minutes_ratio"] for m in ray["reward_milestones"]] == [1.0, 1.0, 1.0]
    assert [m["minutes_ratio"] for m in serial["reward_milestones"]] == [1.5, 1.5, 1.5]
    assert serial["reward_milestones"][2]["minutes"] == 3.0
    assert serial["same_reward_curve_as_first"] is True
