"""An env's own Python exception is raised in the driver (``env_errors="raise"``, the default),
by the first call that meets it, with no worker replaced; ``"restart"`` rebuilds the env, and a
crash loop ends at its first repetition. Real Ray workers and real MuJoCo envs."""

from __future__ import annotations

import os
import subprocess
import sys
import textwrap
from functools import partial
from pathlib import Path

import numpy as np
import pytest
from faulty_tasks import BuggyEnv, UserBug
from gymnasium.error import ResetNeeded

from chronogym import (
    RayVectorEnv,
    RemoteTraceback,
    SerialVectorEnv,
    WorkerCrashLoopError,
    WorkerEnvError,
    make_vec,
)

BACKENDS = {
    "serial": lambda fns, **kw: SerialVectorEnv(fns, envs_per_worker=1, **kw),
    "socket": lambda fns, **kw: RayVectorEnv(fns, envs_per_worker=1, transport="socket", **kw),
    "actor": lambda fns, **kw: RayVectorEnv(fns, envs_per_worker=1, transport="actor", **kw),
    "fork": lambda fns, **kw: RayVectorEnv(fns, envs_per_worker=1, transport="fork", **kw),
    "driver_worker": lambda fns, **kw: RayVectorEnv(
        fns, envs_per_worker=1, driver_worker=True, **kw
    ),
}
ACTIONS = np.zeros((3, 1), dtype=np.float32)


def buggy_fns(bug: str, at: int = 3, env: int = 1) -> list:
    """Three envs; env ``env`` has the bug."""
    return [partial(BuggyEnv, bug, at, bug_env=i == env) for i in range(3)]


def remote_text(error: BaseException) -> str:
    assert isinstance(error.__cause__, RemoteTraceback)
    return str(error.__cause__)


@pytest.mark.parametrize("backend", list(BACKENDS))
def test_a_step_error_is_raised_in_the_driver_with_its_own_class(ray_cluster, backend):
    vec = BACKENDS[backend](buggy_fns("step", at=3))
    try:
        pids = vec.worker_pids()
        vec.reset(seed=0)
        vec.step(ACTIONS)
        vec.step(ACTIONS)
        with pytest.raises(UserBug, match="the controller diverged at step 3") as raised:
            vec.step(ACTIONS)  # the first call that meets the bug raises it
        text = remote_text(raised.value)
        assert "env 1 (BuggyEnv) in step(), worker 1" in text
        assert "faulty_tasks.py" in text and "apply_action" in text  # the worker's traceback
        assert vec.worker_pids() == pids and not vec.restarts  # no restart in between
        with pytest.raises(ResetNeeded, match=r"step\(\) after env 1 raised in step\(\)"):
            vec.step(ACTIONS)
        vec.reset(seed=1)  # usable again after a reset
        vec.step(ACTIONS)
    finally:
        vec.close()


@pytest.mark.parametrize("backend", ["serial", "socket", "fork"])
def test_a_wrong_observation_shape_later_in_an_episode_names_the_env(ray_cluster, backend):
    vec = BACKENDS[backend](buggy_fns("shape", at=4, env=2))
    try:
        vec.reset(seed=0)
        for _ in range(3):
            vec.step(ACTIONS)
        with pytest.raises(ValueError, match=r"shape \(2,\); expected \(4,\)") as raised:
            vec.step(ACTIONS)
        assert "env 2 (BuggyEnv) in step()" in remote_text(raised.value)
        assert not vec.restarts
    finally:
        vec.close()


def test_a_construction_error_is_raised_from_the_constructor(ray_cluster):
    with pytest.raises(UserBug, match="cannot load the model 'nowhere.xml'") as raised:
        RayVectorEnv(buggy_fns("init", env=2), envs_per_worker=1)
    assert "env 2 (BuggyEnv) in make(), worker 2" in remote_text(raised.value)


def test_an_unpicklable_exception_arrives_as_worker_env_error(ray_cluster):
    vec = RayVectorEnv(buggy_fns("unpicklable", at=1, env=0), envs_per_worker=3)
    try:
        vec.reset(seed=0)
        pattern = r"UnpicklableError: unpicklable failure at step 1 \(raised by env 0 \(BuggyEnv\)"
        with pytest.raises(WorkerEnvError, match=pattern) as raised:
            vec.step(ACTIONS)
        assert raised.value.type_name == "faulty_tasks.UnpicklableError"
        assert "env 0 (BuggyEnv) in step()" in remote_text(raised.value)
    finally:
        vec.close()


@pytest.mark.parametrize("backend", ["serial", "actor", "fork"])
def test_call_and_reset_errors_are_raised_and_a_call_needs_no_reset(ray_cluster, backend):
    vec = BACKENDS[backend](buggy_fns("none"))
    try:
        vec.reset(seed=0)
        with pytest.raises(UserBug, match=r"boom\(\) was called") as raised:
            vec.call("boom")
        assert "env 0 (BuggyEnv) in boom()" in remote_text(raised.value)
        vec.step(ACTIONS)  # a failed call() changes no env: stepping goes on
    finally:
        vec.close()
    vec = BACKENDS[backend](buggy_fns("reset", env=1))
    try:
        with pytest.raises(UserBug, match="the reset pose is out of range") as raised:
            vec.reset(seed=0)
        assert "env 1 (BuggyEnv) in reset()" in remote_text(raised.value)
        with pytest.raises(ResetNeeded):
            vec.reset(seed=0, options={"reset_mask": np.array([True, False, False])})
    finally:
        vec.close()


def test_recv_raises_an_env_error_from_send(ray_cluster):
    vec = RayVectorEnv(buggy_fns("step", at=1, env=2), envs_per_worker=1)
    try:
        vec.reset(seed=0)
        vec.send(ACTIONS)
        with pytest.raises(UserBug, match="diverged at step 1"):
            vec.recv()
        with pytest.raises(ResetNeeded):
            vec.send(ACTIONS)
        assert len(vec.envs_in_flight) == 0
    finally:
        vec.close()


def test_restart_mode_rebuilds_the_env_and_reports_it_truncated(ray_cluster):
    vec = make_vec(buggy_fns("step", at=2), backend="ray", envs_per_worker=1, env_errors="restart")
    try:
        vec.reset(seed=0)
        vec.step(ACTIONS)
        _, _, _, truncated, info = vec.step(ACTIONS)
        assert truncated.tolist() == [False, True, False]
        assert "the controller diverged at step 2" in info["worker_error"][1]
        assert [i for i, _ in vec.restarts] == [1]
    finally:
        vec.close()


@pytest.mark.parametrize("backend", ["serial", "socket", "fork"])
def test_a_reset_crash_loop_ends_at_its_first_repetition_in_restart_mode(ray_cluster, backend):
    vec = BACKENDS[backend](buggy_fns("reset", env=0), env_errors="restart", max_restarts=50)
    try:
        with pytest.raises(WorkerCrashLoopError) as raised:
            vec.reset(seed=0)
        message = str(raised.value)
        assert "env 0 (BuggyEnv) in reset(), worker 0 failed again right after it was rebuilt" in (
            message
        )
        assert "UserBug: the reset pose is out of range" in message
        assert len(message.splitlines()) <= 10
        assert "Traceback" in raised.value.traceback  # the whole text is kept
    finally:
        vec.close()


def test_a_worker_lost_again_in_reset_is_a_crash_loop(ray_cluster):
    fns = buggy_fns("exit_in_reset", env=1)
    vec = RayVectorEnv(fns, envs_per_worker=1, max_restarts=50)
    try:
        with pytest.raises(WorkerCrashLoopError, match=r"worker 1 \(envs 1..1\) was lost again"):
            vec.reset(seed=0)
        assert len(vec.restarts) == 1  # replaced once, then given up
    finally:
        vec.close()


def test_bad_env_errors_value_is_rejected_by_name():
    with pytest.raises(ValueError, match=r"env_errors='ignore': expected 'raise'"):
        SerialVectorEnv(buggy_fns("none"), env_errors="ignore")


REPO = Path(__file__).resolve().parents[2]
SCRIPT = """
import sys
from functools import partial
sys.path.insert(0, {tests!r})
from faulty_tasks import BuggyEnv
import chronogym

fns = [partial(BuggyEnv, "reset") for _ in range(4)]
try:
    chronogym.RayVectorEnv(fns, envs_per_worker=1, num_cpus=0.25).reset(seed=0)
except Exception as error:
    print("raised", type(error).__name__)
"""


def test_a_reset_error_in_every_worker_prints_one_short_error():
    """A real run (Ray's worker logs reach the driver): one error, and nothing else."""
    script = SCRIPT.format(tests=str(REPO / "tests"))
    env = {**os.environ, "PYTHONPATH": str(REPO / "tests")}
    env.pop("RAY_ADDRESS", None)
    done = subprocess.run(
        [sys.executable, "-c", textwrap.dedent(script)],
        capture_output=True,
        text=True,
        timeout=180,
        env=env,
    )
    assert done.stdout.strip() == "raised UserBug", done.stdout + done.stderr
    lines = [line for line in done.stderr.splitlines() if line.strip()]
    assert len(lines) <= 3, done.stderr  # no traceback per worker, no replacement warnings
