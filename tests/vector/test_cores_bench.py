"""benchmarks/vector/cores.py (real workloads on real cores, beside the synthetic model) and
benchmarks/offline_kit.py (EnvPool trimmed for a machine with no network): short real runs."""

from __future__ import annotations

import json
from pathlib import Path

import pytest

from benchmarks.offline_kit import trim_envpool
from benchmarks.vector import cores
from benchmarks.vector.scaling import parse_args as scaling_args
from benchmarks.vector.scaling import ray_paths_of

MODEL = Path(__file__).parents[2] / "benchmarks" / "results" / "scaling_fork" / "run3.json"


def test_cores_runs_forked_and_async_workers_against_serial(tmp_path):
    out = tmp_path / "cores.json"
    argv = ["--workloads", "chronogym/CartPole-v0", "--workers", "1", "2"]
    argv += ["--envs-per-worker", "1", "--paths", "fork", "async", "envpool"]
    argv += ["--envpool-threads", "--seconds", "0.05", "--min-steps", "3", "--warmup", "1"]
    assert cores.main([*argv, "--model", str(MODEL), "--out", str(out)]) == 0
    record = json.loads(out.read_text())
    rows = {(r["path"], r["workers"]): r for r in record["runs"]}
    assert set(rows) == {("serial", 1), ("fork", 1), ("fork", 2), ("async", 1), ("async", 2)}
    assert all(r["env_steps_per_s"] > 0 and r["efficiency"] > 0 for r in rows.values())
    assert rows["fork", 1]["rel_e"] == pytest.approx(1.0)
    assert rows["fork", 2]["num_envs"] == 2
    # the synthetic model of the same path and envs per worker, at W = 2: at most 1
    assert 0 < rows["fork", 2]["predicted_rel_e"] <= 1.0
    assert rows["fork", 2]["model_b_cpu_us"] is not None
    assert rows["fork", 2]["model"] == str(MODEL) and record["info_scalars"] == {
        "chronogym/CartPole-v0": 0
    }
    assert {f["path"] for f in record["fits"]} == {"fork", "async"}
    assert any(
        s["path"] == "envpool" and "envpool" in s["reason"].lower() for s in record["skipped"]
    )
    assert out.with_suffix(".png").stat().st_size > 0


def test_cores_refuses_a_model_file_that_is_not_there(tmp_path, capsys):
    with pytest.raises(SystemExit):
        cores.parse_args(["--model", str(tmp_path / "missing.json")])
    assert "missing.json: no such file" in capsys.readouterr().err


def test_default_workers_leave_the_driver_a_core():
    assert cores.default_workers(16) == [1, 2, 4, 8, 15]
    assert cores.default_workers(2) == [1]
    assert cores.default_workers(1) == [1]


def test_scaling_needs_ray_only_for_the_paths_of_ray_workers():
    quiet = scaling_args(["--paths", "fork", "async", "--straggler-paths", "fork"])
    assert ray_paths_of(quiet) == []
    mixed = scaling_args(["--paths", "fork", "socket", "--no-stragglers", "--multinode"])
    assert ray_paths_of(mixed) == ["socket", *mixed.multinode_paths]
    assert ray_paths_of(mixed, multinode=False) == ["socket"]


def test_offline_kit_keeps_only_the_named_envpool_suites(tmp_path):
    site = tmp_path / "site"
    package = site / "envpool"
    for folder, library in (("atari", "atari_envpool"), ("mujoco", "mujoco_gym_envpool")):
        (package / folder).mkdir(parents=True)
        (package / folder / f"{library}.so").write_bytes(b"\0")
    (package / "atari" / "__init__.py").write_text("from .atari_envpool import _Atari\n")
    (package / "mujoco" / "gym").mkdir()
    (package / "mujoco" / "gym" / "__init__.py").write_text(
        "from envpool.mujoco.mujoco_gym_envpool import _GymAnt\n"
    )
    (package / "entry.py").write_text(
        '"""Entry."""\n\nimport envpool.atari.registration  # noqa: F401\n'
        "import envpool.mujoco.gym.registration  # noqa: F401\n"
    )
    for folder in ("mujoco/assets_gym", "mujoco/assets_dmc", "atari/roms"):
        (site / "envpool_assets" / folder).mkdir(parents=True)
        (site / "envpool_assets" / folder / "x.xml").write_text("<x/>")
    removed = trim_envpool(site, ["mujoco_gym"])
    assert "envpool/atari/atari_envpool.so" in removed
    assert (package / "mujoco" / "mujoco_gym_envpool.so").exists()
    entry = (package / "entry.py").read_text()
    assert "envpool.mujoco.gym.registration" in entry and "atari" not in entry
    assert (site / "envpool_assets" / "mujoco" / "assets_gym" / "x.xml").exists()
    assert not (site / "envpool_assets" / "mujoco" / "assets_dmc").exists()
    assert not (site / "envpool_assets" / "atari").exists()


def test_efficiency_is_against_serial_and_the_same_paths_first_worker_in_any_order():
    rows = [
        {
            "workload": "w",
            "path": "fork",
            "workers": 2,
            "envs_per_worker": 1,
            "env_steps_per_s": 300.0,
        },
        {
            "workload": "w",
            "path": "fork",
            "workers": 1,
            "envs_per_worker": 1,
            "env_steps_per_s": 200.0,
        },
        {
            "workload": "w",
            "path": "serial",
            "workers": 1,
            "envs_per_worker": 1,
            "env_steps_per_s": 250.0,
        },
    ]
    cores.add_efficiency(rows)
    assert [r["efficiency"] for r in rows] == pytest.approx([0.6, 0.8, 1.0])
    assert [r["rel_e"] for r in rows] == pytest.approx([0.75, 1.0, 1.0])


def test_each_workload_takes_the_model_nearest_its_infos():
    models = {"plain": {"settings": {}}, "ant-like": {"settings": {"info_scalars": 9}}}
    assert cores.models_by_nearness(models, 9) == ["ant-like", "plain"]
    assert cores.models_by_nearness(models, 0) == ["plain", "ant-like"]
