"""progress.csv: a column for every ``/metrics/*`` key the env reports, whatever the task."""

from __future__ import annotations

import csv
import math

import gymnasium as gym
import numpy as np
import pytest

pytest.importorskip("rsl_rl")

from test_rsl_adapter import LogCartPole

import chronogym
from chronogym.rl import ppo_train_config, train
from chronogym.rl.progress import ProgressBar, ProgressLog, progress_columns

PROGRESS_METRICS = {"x_mse": "/metrics/x_vel_mse", "y_mse": "/metrics/y_vel_mse"}  # the Go1's
CSV_HEADER = progress_columns(PROGRESS_METRICS)

METRIC_ENV = "chronogym-test/MetricCartPole-v0"
HORIZON = 4
PINNED = {"x_mse": "/metrics/x_vel_mse"}
RUN = {
    "wall_time": 1.5,
    "iteration": 0,
    "env_steps": 8,
    "mean_reward": 2.0,
    "collect_s": 0.5,
    "learn_s": 0.25,
    "policy_lag": 0,
}


class MetricCartPole(LogCartPole):
    """The cart-pole that never falls, reporting one pinned metric, one of its own and a
    reward sum when its horizon ends an episode."""

    def info(self) -> dict:
        if self.steps < self.max_episode_steps:
            return {}
        log = {"/metrics/x_vel_mse": 0.75, "/metrics/episode_steps": float(self.steps)}
        return {"log": {**log, "/reward/alive": 1.0}}


chronogym.register_task(METRIC_ENV, MetricCartPole, max_episode_steps=HORIZON)


def read(path) -> tuple[list[str], list[dict[str, str]]]:
    with open(path, newline="") as handle:
        reader = csv.DictReader(handle)
        return list(reader.fieldnames or []), list(reader)


def row(iteration: int) -> dict[str, float]:
    return {**RUN, "iteration": iteration}


def test_train_writes_a_column_for_every_metric_the_env_reports(tmp_path):
    vec = chronogym.make_vec(
        METRIC_ENV, 2, backend="serial", autoreset_mode=gym.vector.AutoresetMode.SAME_STEP
    )
    small = {"hidden_dims": [8]}
    cfg = ppo_train_config(num_steps_per_env=HORIZON, actor=small, critic=small)
    try:
        result = train(
            vec, tmp_path, iterations=2, train_cfg=cfg, progress=False,
            progress_metrics=PROGRESS_METRICS,
        )  # fmt: skip
    finally:
        vec.close()
    header, rows = read(result.csv_path)
    assert tuple(header) == progress_columns([*PROGRESS_METRICS, "episode_steps"])
    assert [float(r["episode_steps"]) for r in rows] == [HORIZON, HORIZON]
    assert [float(r["x_mse"]) for r in rows] == [0.75, 0.75]
    assert all(math.isnan(float(r["y_mse"])) for r in rows)  # pinned, never reported
    assert result.last_row["episode_steps"] == HORIZON


def test_pinned_columns_come_first_even_before_any_episode_ends(tmp_path):
    log = ProgressLog(tmp_path / "progress.csv", PROGRESS_METRICS)
    written = log.write(row(0))
    header, rows = read(log.path)
    assert tuple(header) == CSV_HEADER == progress_columns(PROGRESS_METRICS)
    assert math.isnan(written["x_mse"]) and rows[0]["x_mse"] == "nan"


def test_a_metric_reported_later_widens_the_file_and_rows_hold_episode_means(tmp_path):
    log = ProgressLog(tmp_path / "progress.csv", PINNED)
    log.write(row(0))
    log.record({"/metrics/x_vel_mse": np.array([1.0, 3.0]), "/reward/alive": np.array([5.0])})
    log.record({"/metrics/slip": np.array([0.5]), "/metrics/x_vel_mse": np.array([2.0])})
    written = log.write(row(1))
    header, rows = read(log.path)
    assert tuple(header) == progress_columns(["x_mse", "slip"])  # no column for /reward/*
    assert [r["iteration"] for r in rows] == ["0", "1"]
    assert rows[0]["slip"] == "nan" and rows[0]["x_mse"] == "nan"
    assert float(rows[1]["x_mse"]) == pytest.approx(2.0) and float(rows[1]["slip"]) == 0.5
    assert written == {**row(1), "x_mse": pytest.approx(2.0), "slip": 0.5}
    log.write(row(2))  # the episodes are counted once
    assert read(log.path)[1][2]["slip"] == "nan"


def test_appending_keeps_the_columns_of_the_file(tmp_path):
    path = tmp_path / "progress.csv"
    first = ProgressLog(path, PINNED)
    first.record({"/metrics/slip": np.array([0.5])})
    first.write(row(0))
    again = ProgressLog(path, PINNED, append=True)
    again.record({"/metrics/slip": np.array([0.25])})
    again.write(row(1))
    header, rows = read(path)
    assert tuple(header) == progress_columns(["x_mse", "slip"])
    assert [r["slip"] for r in rows] == ["0.5", "0.25"]
    ProgressLog(path, PINNED)  # without append: a new file
    assert read(path)[1] == []


def test_a_metric_named_like_a_run_column_keeps_its_whole_key(tmp_path):
    log = ProgressLog(tmp_path / "progress.csv", PINNED)
    log.record({"/metrics/iteration": np.array([7.0])})
    written = log.write(row(0))
    assert written["/metrics/iteration"] == 7.0 and written["iteration"] == 0


def test_progress_bar_counts_iterations(capsys):
    bar = ProgressBar(True, 2, math.inf, print)
    bar.update(row(0))
    bar.update(row(1))
    bar.close()
    assert "2/2" in capsys.readouterr().err
    silent = ProgressBar(False, 2, math.inf, print)
    silent.update(row(0))
    silent.close()
    assert capsys.readouterr() == ("", "")
