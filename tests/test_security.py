"""Security defaults: Ray as chronogym starts it (token auth on, no dashboard, which ports on
which addresses), and no code path that evaluates or unpickles what a user did not write."""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
WORKERS = {"ray::SocketWorker", "ray::ActorGroup"}  # socket transport (default), actor transport
RAY_PROCESSES = {"gcs_server", "raylet", "ray::RuntimeEnvAgent", *WORKERS, "ray_ports.py"}


@pytest.mark.skipif(not Path("/proc/net/tcp").exists(), reason="reads Linux's /proc/net/tcp")
def test_ray_started_by_chronogym_keeps_auth_and_opens_no_dashboard(tmp_path):
    out = tmp_path / "ports.json"
    env = {**os.environ, "RAY_ADDRESS": ""}
    run = subprocess.run(
        [sys.executable, str(ROOT / "benchmarks" / "vector" / "ray_ports.py"), "--out", str(out)],
        capture_output=True, text=True, timeout=300, env=env,
    )  # fmt: skip
    assert run.returncode == 0, run.stderr[-3000:]
    result = json.loads(out.read_text())
    assert result["auth_mode"] == "token"
    assert not result["dashboard_listening"]
    names = {row["process"] for row in result["sockets"]}
    assert {"gcs_server", "raylet"} <= names and names & WORKERS  # the cluster really ran
    assert names <= RAY_PROCESSES, names - RAY_PROCESSES  # no dashboard, no metrics endpoint
    assert sum(row["process"] in WORKERS for row in result["sockets"]) == 2


FORBIDDEN = re.compile(r"\b(eval|exec)\(|pickle\.loads?\(|yaml\.load\(|weights_only=False")


def test_no_code_path_evaluates_or_unpickles_input():
    hits = []
    for path in sorted((ROOT / "src" / "chronogym").rglob("*.py")):
        for number, line in enumerate(path.read_text().splitlines(), 1):
            code = line.split("#", 1)[0]
            if "# trusted: own worker" in line:  # bytes our own Ray worker pickled (Ray
                continue  # unpickles every worker result anyway: no new trust boundary)
            if "# trusted: own driver" in line:  # bytes the driver pickled for a process it
                continue  # started (transport="fork"): a socketpair or a socket in a 0700 dir
            if FORBIDDEN.search(code) and ".eval()" not in code:
                hits.append(f"{path.relative_to(ROOT)}:{number}: {line.strip()}")
    assert not hits, "\n".join(hits)
