"""Workers of a Ray cluster that chronogym starts run at the driver's priority (nice 0).

Each case starts its own real local cluster in a fresh subprocess (the session's shared
cluster was started by the tests, not by chronogym) and reads the workers' nice values.
"""

from __future__ import annotations

import json
import os
import subprocess
import sys

import pytest

from chronogym import RayVectorEnv

PROBE = r"""
import json, os, sys
import ray
from chronogym import RayVectorEnv
kwargs = json.loads(sys.argv[1])
vec = RayVectorEnv("chronogym/CartPole-v0", 2, envs_per_worker=1, **kwargs)
nice = [os.getpriority(os.PRIO_PROCESS, pid) for pid in vec.worker_pids()]
vec.close()
ray.shutdown()
print(json.dumps({"nice": nice, "env_left": "RAY_worker_niceness" in os.environ}))
"""


def clean_env() -> dict[str, str]:
    """This environment without a Ray address or a worker niceness of its own."""
    drop = ("RAY_ADDRESS", "RAY_worker_niceness")
    return {k: v for k, v in os.environ.items() if k not in drop}


def worker_nice(env: dict[str, str] | None = None, **kwargs) -> dict:
    run = subprocess.run(
        [sys.executable, "-c", PROBE, json.dumps(kwargs)],
        capture_output=True,
        text=True,
        timeout=240,
        env={**clean_env(), **(env or {})},
    )
    assert run.returncode == 0, run.stderr[-3000:]
    return json.loads(run.stdout.strip().splitlines()[-1])


@pytest.mark.skipif(not hasattr(os, "getpriority"), reason="reads nice values (POSIX)")
def test_started_cluster_runs_workers_at_driver_priority_unless_told_otherwise():
    default = worker_nice()
    assert default["nice"] == [os.getpriority(os.PRIO_PROCESS, 0)] * 2
    assert not default["env_left"]  # the setting does not leak into the driver's environment
    assert worker_nice(worker_niceness=None)["nice"] == [15, 15]  # Ray's own default
    assert worker_nice(worker_niceness=7)["nice"] == [7, 7]
    assert worker_nice({"RAY_worker_niceness": "12"})["nice"] == [12, 12]  # the user's wins


@pytest.mark.parametrize("bad", [20, -21, 1.5, True, "0"])
def test_bad_worker_niceness_names_the_value(bad):
    with pytest.raises(ValueError, match=rf"worker_niceness={bad!r}: expected an integer"):
        RayVectorEnv("chronogym/CartPole-v0", 2, worker_niceness=bad, address="127.0.0.1:1")
