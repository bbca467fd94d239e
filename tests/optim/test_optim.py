"""Parallel Bayesian optimization: real Optuna storage, real Ray workers, real lander."""

from __future__ import annotations

import math
import signal
import subprocess
import sys
import time

import optuna
import pytest
import sqlalchemy
from faulty_objectives import Quadratic, suggest_x

from chronogym.optim import open_storage, run_parallel_study
from chronogym.optim.lander import LanderEvaluator, LanderObjective, suggest_lander_design

optuna.logging.set_verbosity(optuna.logging.WARNING)


def new_study(tmp_path, name="s", url=None):
    storage = open_storage(url or f"sqlite:///{tmp_path}/study.db")
    sampler = optuna.samplers.TPESampler(seed=0, constant_liar=True, n_startup_trials=4)
    return optuna.create_study(
        storage=storage, study_name=name, sampler=sampler, load_if_exists=True
    )


def states(study):
    return [t.state.name for t in study.get_trials(deepcopy=False)]


def test_lander_study_beats_the_prior_on_ray(ray_cluster, tmp_path):
    study = new_study(tmp_path)
    report = run_parallel_study(
        study, suggest_lander_design, LanderObjective(), 16, workers=2, progress=False
    )
    assert report.completed == 16 and report.failed == 0
    values = [t.value for t in study.trials]
    prior_median = sorted(values[:4])[2]  # the 4 random start-up trials
    assert report.best_value < prior_median
    assert set(report.best_params) == {"f_y", "beta", "alpha2"}
    assert {"a_max", "E_abs", "E_init", "max_stroke"} <= set(report.best_attrs)
    assert len(report.history) == 16


def test_failing_evaluations_are_recorded_and_the_study_continues(tmp_path):
    study = new_study(tmp_path)
    study.enqueue_trial({"x": 0.9})
    report = run_parallel_study(
        study, suggest_x, Quadratic(fail_above=0.8), 10, backend="serial", progress=False
    )
    failed = [t for t in study.trials if t.state.name == "FAIL"]
    assert report.failed == len(failed) >= 1
    assert "in the failing region" in failed[0].user_attrs["fail_reason"]
    assert report.completed + report.failed == 10 and "RUNNING" not in states(study)


def test_killed_worker_is_replaced_and_its_trial_retried(ray_cluster, tmp_path):
    marker = tmp_path / "died"
    study = new_study(tmp_path)
    study.enqueue_trial({"x": 0.95})
    report = run_parallel_study(
        study, suggest_x, Quadratic(die_at=0.9, marker=str(marker)), 6, workers=2, progress=False
    )
    assert marker.exists()  # the worker really died once
    assert report.retried == 1 and report.completed == 6
    first = study.trials[0]
    assert first.state.name == "COMPLETE" and first.params["x"] == 0.95
    assert "RUNNING" not in states(study)


def test_trial_is_failed_when_retries_run_out(ray_cluster, tmp_path):
    study = new_study(tmp_path)
    study.enqueue_trial({"x": 0.95})
    objective = Quadratic(die_at=0.9, always_die=True)
    report = run_parallel_study(
        study, suggest_x, objective, 4, workers=2, max_retries=1, progress=False
    )
    first = study.trials[0]
    assert first.state.name == "FAIL"
    assert "worker lost 2 times" in first.user_attrs["fail_reason"]
    assert report.retried == 1 and report.failed >= 1
    assert len(study.trials) >= 4 and "RUNNING" not in states(study)


def test_resume_fails_stale_running_trials_and_requeues_them(tmp_path):
    study = new_study(tmp_path)
    run_parallel_study(study, suggest_x, Quadratic(), 3, backend="serial", progress=False)
    orphan = study.ask({"x": optuna.distributions.FloatDistribution(0.0, 1.0)})  # driver "dies"
    resumed = new_study(tmp_path)  # same storage and name, as a new process would open it
    report = run_parallel_study(
        resumed, suggest_x, Quadratic(), 6, backend="serial", progress=False
    )
    trials = resumed.get_trials(deepcopy=False)
    assert report.recovered == 1
    assert trials[orphan.number].state.name == "FAIL"
    assert "driver stopped" in trials[orphan.number].user_attrs["fail_reason"]
    retry = [t for t in trials if t.user_attrs.get("retry_of") == orphan.number]
    assert retry and retry[0].params == trials[orphan.number].params
    assert sum(t.state.name == "COMPLETE" for t in trials) == 6 - 1 + 0  # 3 kept + 3 new - orphan
    assert "RUNNING" not in states(resumed)


def test_killing_the_cli_driver_then_rerunning_resumes(tmp_path):
    db = tmp_path / "cli.db"
    url = f"sqlite:///{db}"
    cmd = [
        sys.executable,
        "-m",
        "chronogym.cli",
        "optimize",
        "lander",
        "--workers",
        "1",
        "--trials",
        "30",
        "--storage",
        url,
        "--study",
        "resume",
        "--backend",
        "serial",
    ]
    # Create the schema first: the CLI and this test's polling would otherwise both run the
    # first-use migration of the SQLite file at once (UNIQUE constraint on alembic_version).
    optuna.storages.RDBStorage(url)
    first = subprocess.Popen(cmd, stdout=subprocess.DEVNULL, stderr=subprocess.DEVNULL)
    deadline = time.time() + 120
    completed_before = 0
    while time.time() < deadline and first.poll() is None:
        time.sleep(0.2)
        if db.exists():
            try:
                study = optuna.load_study(study_name="resume", storage=url)
            except (KeyError, sqlalchemy.exc.SQLAlchemyError):  # not created yet / locked
                continue
            completed_before = sum(t.state.name == "COMPLETE" for t in study.trials)
            if completed_before >= 3:
                break
    assert first.poll() is None, "the first run finished before it could be killed"
    first.send_signal(signal.SIGKILL)
    first.wait()
    kept = {
        t.number: t.value
        for t in optuna.load_study(study_name="resume", storage=url).trials
        if t.state.name == "COMPLETE"
    }
    assert len(kept) >= 3
    second = subprocess.run(cmd, capture_output=True, text=True, timeout=240)
    assert second.returncode == 0, second.stderr[-2000:]
    study = optuna.load_study(study_name="resume", storage=url)
    finished = [t for t in study.trials if t.state.name in ("COMPLETE", "FAIL")]
    assert len(finished) == 30 and "RUNNING" not in states(study)
    for number, value in kept.items():  # every completed trial of the killed run is kept
        assert study.trials[number].value == value
    assert "best trial" in second.stdout


def test_journal_storage_and_bad_storage_urls(tmp_path):
    study = new_study(tmp_path, url=f"journal:{tmp_path}/journal.log")
    run_parallel_study(study, suggest_x, Quadratic(), 3, backend="serial", progress=False)
    assert (tmp_path / "journal.log").exists() and len(study.trials) == 3
    with pytest.raises(ValueError, match="storage='lander.db'"):
        open_storage("lander.db")


def test_bad_arguments_and_designs():
    with pytest.raises(ValueError, match="n_trials=0"):
        run_parallel_study(None, suggest_x, Quadratic(), 0)
    with pytest.raises(ValueError, match="workers=2 with backend='serial'"):
        run_parallel_study(None, suggest_x, Quadratic(), 3, workers=2, backend="serial")
    with pytest.raises(ValueError, match="terrain='lava'"):
        LanderObjective(terrain="lava")
    evaluator = LanderEvaluator("rigid", 0)
    with pytest.raises(ValueError, match="f_y=50.0 N is outside the allowed range"):
        evaluator({"f_y": 50.0, "beta": 1.0, "alpha2": 0.5})


def test_lander_evaluator_reuses_its_simulation():
    evaluator = LanderEvaluator("rigid", 0)
    value, attrs = evaluator({"f_y": 4000.0, "beta": 1.0, "alpha2": 0.5})
    sim = evaluator.sim
    again, _ = evaluator({"f_y": 4000.0, "beta": 1.0, "alpha2": 0.5})
    assert evaluator.sim is sim and value == again and math.isfinite(value)
    assert attrs["E_init"] > 0 and 0 < attrs["max_stroke"] < 0.35


def test_hung_worker_is_replaced_after_trial_timeout(ray_cluster, tmp_path):
    study = new_study(tmp_path)
    study.enqueue_trial({"x": 0.95})
    report = run_parallel_study(
        study,
        suggest_x,
        Quadratic(hang_above=0.9),
        4,
        workers=2,
        max_retries=0,
        trial_timeout=3.0,
        progress=False,
    )
    first = study.trials[0]
    assert first.state.name == "FAIL"
    assert "trial_timeout=3.0" in first.user_attrs["fail_reason"]
    assert report.failed >= 1 and len(report.history) == report.completed + report.failed
    assert "RUNNING" not in states(study)
