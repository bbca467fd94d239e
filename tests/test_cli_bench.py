"""`chronogym bench ID`: a tiny budget on the cart-pole prints the fit, the efficiency table
and a recommendation; bad arguments are rejected by name. The cost model on its own."""

from __future__ import annotations

import os
import re
import subprocess
import sys

import numpy as np
import pytest

from chronogym.sizing import (
    SWEEP_ENVS_PER_WORKER,
    SWEEP_WORKERS,
    BenchReport,
    EnvProfile,
    StepModel,
    Timed,
    VectorRun,
    bench_workers,
    cores_shared,
    fit_overhead,
    fit_overhead_nonnegative,
    info_sizes,
    largest_workers,
    measure_env,
    recommend,
)

CLI = [sys.executable, "-m", "chronogym.cli", "bench"]
NUMBER = r"(\d+(?:\.\d+)?)"


def run_bench(*args: str) -> subprocess.CompletedProcess:
    env = {**os.environ, "RAY_ADDRESS": ""}
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=240, env=env)


def test_bench_on_the_cart_pole_prints_table_and_recommendation():
    result = run_bench(
        "chronogym/CartPole-v0",
        "--seconds",
        "0.2",
        "--max-workers",
        "2",
        "--env-kwargs",
        '{"k": 2}',
    )
    assert result.returncode == 0, result.stderr[-3000:]
    out = result.stdout
    step = re.search(rf"env chronogym/CartPole-v0: step {NUMBER} ms", out)
    assert step and float(step.group(1)) > 0
    rows = re.findall(rf"^\s+([12])\s+{NUMBER}\s+{NUMBER}\s+{NUMBER}$", out, re.M)
    assert [r[0] for r in rows] == ["1", "2"], out
    assert all(float(x) > 0 for row in rows for x in row[1:])
    fit = re.search(rf"a = {NUMBER} us \(fixed\), b = {NUMBER} us \(per worker\)", out)
    assert fit, out
    assert "workers shared" not in out  # --max-workers 2: W <= the CPUs (2 here or more)
    assert re.search(rf"check on the env itself, 2 workers: step {NUMBER} ms measured", out)
    table = re.findall(r"^  (\d+) +((?:\s+\d\.\d\d){5})$", out, re.M)
    assert [int(w) for w, _ in table] == list(SWEEP_WORKERS), out
    cells = [float(x) for _, row in table for x in row.split()]
    assert all(0 < x <= 1 for x in cells[:5])  # W = 1: positive efficiencies
    pick = re.search(
        r"recommendation for (\d+) cores: num_workers=(\d+), envs_per_worker=(\d+)", out
    )
    assert pick and int(pick.group(2)) >= 1 and int(pick.group(3)) in SWEEP_ENVS_PER_WORKER
    assert re.search(r"predicted efficiency 0\.\d\d", out)


def test_bench_times_forked_workers():
    result = run_bench(
        "chronogym/CartPole-v0", "--seconds", "0.2", "--max-workers", "2", "--transport", "fork"
    )
    assert result.returncode == 0, result.stderr[-3000:]
    out = result.stdout
    assert "measured (RayVectorEnv, transport='fork'" in out and "this machine has" in out
    rows = re.findall(rf"^\s+([12])\s+{NUMBER}\s+{NUMBER}\s+{NUMBER}$", out, re.M)
    assert [r[0] for r in rows] == ["1", "2"], out
    assert re.search(rf"check on the env itself, 2 workers: step {NUMBER} ms measured", out)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--seconds", "0"], "--seconds=0.0: expected a number > 0"),
        (["--max-workers", "0"], "--max-workers=0: expected an integer >= 1"),
        (["--target", "1.5"], "--target=1.5: expected an efficiency in (0, 1]"),
        (["--env-kwargs", "{k: 1}"], "--env-kwargs={k: 1}: not JSON"),
        (["--env-kwargs", "[1]"], "--env-kwargs=[1]: expected a JSON object"),
    ],
)
def test_bad_arguments_are_rejected_by_name(args, message):
    result = run_bench("chronogym/CartPole-v0", *args)
    assert result.returncode != 0
    assert message in result.stderr


def test_unknown_id_is_rejected():
    result = run_bench("chronogym/NoSuchEnv-v0", "--seconds", "0.1")
    assert result.returncode == 1
    assert "chronogym/NoSuchEnv-v0" in result.stderr and "chronogym envs" in result.stderr


def test_fit_recovers_a_and_b_and_the_model_predicts():
    model = StepModel(step_s=0.01, a=0.0005, b=0.00007)
    workers = [1, 2, 4, 16]
    a, b = fit_overhead(workers, [model.t_step(w) for w in workers], 0.01)
    assert (a, b) == (pytest.approx(0.0005), pytest.approx(0.00007))
    assert model.efficiency(1) == pytest.approx(0.01 / 0.01057)
    assert model.relative_efficiency(64) == pytest.approx(0.01057 / (0.0105 + 0.00448))
    assert model.env_steps_per_s(4, 2) == pytest.approx(8 / (0.02 + 0.0005 + 0.00028))
    assert fit_overhead_nonnegative([1, 2], [0.011, 0.0125], 0.0105) == (0.0, pytest.approx(0.0009))
    assert fit_overhead_nonnegative([1, 2], [0.012, 0.0115], 0.0105) == (pytest.approx(0.00125), 0)
    assert largest_workers(model, 1, 0.8) == 16  # E(16) = 0.86, E(32) = 0.78
    assert largest_workers(model, 1, 0.99) is None


def test_recommendation_is_one_worker_per_core_with_the_fewest_envs():
    model = StepModel(step_s=0.0001, a=0.0001, b=0.00001)
    pick = recommend(model, cores=16, target=0.8)
    assert pick.workers == 16 and pick.reached
    assert pick.envs_per_worker == 16 and pick.efficiency >= 0.8  # 8 envs: E = 0.75
    cheap = recommend(StepModel(0.01, 0.0001, 0.00001), cores=8)
    assert (cheap.workers, cheap.envs_per_worker) == (8, 1)
    slow = recommend(StepModel(0.00001, 0.001, 0.001), cores=8)
    assert not slow.reached and slow.workers == 1
    assert bench_workers(cpus=2, max_workers=16) == [1, 2, 4]
    assert bench_workers(cpus=32, max_workers=8) == [1, 2, 4, 8]
    assert bench_workers(cpus=6, max_workers=3) == [1, 2, 3]


def crowd_report(cpus: int, cores: int, workers: list[int]) -> BenchReport:
    report = BenchReport(EnvProfile("my/Env-v0", 1e-4, 4, 100), 1e-4, cpus, cores, 0.8)
    timed = Timed(100, 0.05, 0.02, 0.02)
    report.runs = [VectorRun("synthetic", w, 1, 1e-4, 0.1, timed) for w in workers]
    return report


def test_a_fit_with_more_workers_than_cpus_says_so():
    """On 2 CPUs the fit times 4 workers: b then holds their wait for a core, and a plan for
    more cores made from it is pessimistic; with a core per worker, no word."""
    crowded = cores_shared(crowd_report(2, 16, [1, 2, 4]))
    assert crowded is not None and "W = 4 workers shared the cluster's 2 CPUs" in crowded
    assert "the plan for 16 cores is pessimistic" in crowded
    same = cores_shared(crowd_report(3, 3, [1, 2, 3, 4]))
    assert same is not None and "W = 4 workers shared" in same and "pessimistic" not in same
    assert cores_shared(crowd_report(8, 64, [1, 2, 4, 8])) is None
    assert cores_shared(crowd_report(2, 16, [1, 2])) is None


def test_the_synthetic_env_copies_the_envs_info_sizes():
    assert info_sizes({"a": 1.0, "b": np.float32(2), "c": True, "d": np.zeros((2, 3))}) == (3, 6)
    assert info_sizes({"text": "x", "obj": object()}) == (0, 0)
    ant = measure_env("Ant-v5", {}, seconds=0.05)
    assert (ant.obs_floats, ant.info_scalars, ant.info_floats) == (105, 9, 0)
    assert ant.synthetic_kwargs["info_scalars"] == 9
