"""benchmarks/rl/rl_scaling.py's comparison of configurations: reward milestones, their
wall-clock ratios, whether two runs share one reward curve against env steps, and the merge
of runs made apart."""

from __future__ import annotations

import csv
import json
import math

import pytest

from benchmarks.rl.rl_scaling import (
    compare_to_first,
    main,
    merge_results,
    reward_milestones,
    same_curve,
)


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


def write_part(folder, configs, per_row, **fields):
    """An ``rl_scaling.json`` with a CSV per configuration, as one invocation writes them."""
    folder.mkdir()
    for name in configs:
        with (folder / f"{name}.csv").open("w", newline="") as handle:
            writer = csv.DictWriter(handle, ["wall_time", "env_steps", "mean_reward"])
            writer.writeheader()
            writer.writerows(rows([4.0, 10.0, 15.0, 21.0], per_row[name]))
    record = {
        "benchmark": "rl_scaling", "date": f"date of {folder.name}",
        "machine": {"cpus": 2, "load_average": [1.0]}, "minutes_per_config": 40.0,
        "engine": "chrono", "start": "from scratch", "seed": 0, "save_interval": 100,
        "pychrono_commit": "abc", "task": {"observe_base_lin_vel": True},
        "configs": [
            {"config": name, "csv": f"{name}.csv", "minutes_to_walk_v2": walk,
             "minutes_to_walk_v1": None, "time_to_walk_ratio_v2": 1.0}
            for name, walk in configs.items()
        ],
        **fields,
    }  # fmt: skip
    (folder / "rl_scaling.json").write_text(json.dumps(record))
    return folder


def test_merge_joins_runs_made_apart_and_compares_to_the_first(tmp_path):
    ray = write_part(tmp_path / "ray", {"ray-16": 10.0}, {"ray-16": 30.0})
    serial = write_part(tmp_path / "serial", {"serial-16": 15.0}, {"serial-16": 45.0})
    merged = merge_results([ray, serial], tmp_path / "out")
    first, second = merged["configs"]
    assert [first["config"], second["config"]] == ["ray-16", "serial-16"]
    assert (tmp_path / "out" / "serial-16.csv").is_file()
    assert second["time_to_walk_ratio_v2"] == 1.5  # recomputed: its part alone said 1.0
    assert second["time_to_walk_ratio_v1"] is None
    assert [m["minutes_ratio"] for m in second["reward_milestones"]] == [1.5, 1.5, 1.5]
    assert second["same_reward_curve_as_first"] is True
    assert [p["date"] for p in merged["parts"]] == ["date of ray", "date of serial"]
    assert merged["minutes_per_config"] == 40.0 and merged["pychrono_commit"] == "abc"


def test_merge_refuses_parts_that_differ_or_repeat(tmp_path):
    ray = write_part(tmp_path / "ray", {"ray-16": 10.0}, {"ray-16": 30.0})
    other = write_part(tmp_path / "other", {"serial-16": 15.0}, {"serial-16": 45.0}, seed=1)
    again = write_part(tmp_path / "again", {"ray-16": 10.0}, {"ray-16": 30.0})
    with pytest.raises(ValueError, match=r"seed=1 vs 0"):
        merge_results([ray, other], tmp_path / "out")
    with pytest.raises(ValueError, match="configuration ray-16 twice"):
        merge_results([ray, again], tmp_path / "out")
    with pytest.raises(ValueError, match="no rl_scaling.json"):
        merge_results([ray, tmp_path], tmp_path / "out")


def test_iterations_below_one_is_a_usage_error(monkeypatch, capsys):
    monkeypatch.setattr("sys.argv", ["rl_scaling", "--iterations", "0"])
    with pytest.raises(SystemExit) as stopped:
        main()
    assert stopped.value.code == 2
    assert "--iterations=0: expected an integer >= 1" in capsys.readouterr().err
