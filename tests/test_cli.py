"""The `chronogym` command line, run as a user would (its own process, its own local Ray)."""

from __future__ import annotations

import os
import re
import subprocess
import sys

CLI = [sys.executable, "-m", "chronogym.cli"]


def run_cli(*args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "RAY_ADDRESS": ""}
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=240, env=env)


def test_demo_runs_on_ray_and_matches_serial():
    result = run_cli("demo", "--num-envs", "3", "--steps", "60")
    assert result.returncode == 0, result.stderr[-2000:]
    assert "bit-identical trajectories" in result.stdout
    assert re.search(r"\d+ Ray workers x \d+ envs each", result.stdout)


def test_envs_lists_registered_ids():
    result = run_cli("envs")
    assert result.returncode == 0
    assert "chronogym/CartPole-v0" in result.stdout.split()


def test_bad_steps_is_rejected():
    result = run_cli("demo", "--steps", "0")
    assert result.returncode != 0
    assert "--steps=0: expected an integer >= 1" in result.stderr


def test_optimize_summary_quotes_the_newest_failed_trials_reason():
    import optuna

    from chronogym.cli import last_fail_reason

    study = optuna.create_study(storage=optuna.storages.InMemoryStorage())
    assert last_fail_reason(study) == "none recorded"
    for reason in ("old", "Traceback (most recent call last):\n  File x\nZeroDivisionError: boom"):
        trial = study.ask()
        trial.set_user_attr("fail_reason", reason)
        study.tell(trial, state=optuna.trial.TrialState.FAIL)
    assert last_fail_reason(study, lines=2).split() == ["File", "x", "ZeroDivisionError:", "boom"]
