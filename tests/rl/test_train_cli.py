"""`chronogym train quadruped` and `chronogym play quadruped`, end to end at tiny size."""

from __future__ import annotations

import csv
import os
import subprocess
import sys

import pytest

from chronogym.rl.checkpoint import read_checkpoint
from chronogym.tasks.quadruped.training import input_size
from chronogym.tasks.quadruped.walking import load_traces

pytest.importorskip("rsl_rl")

CLI = [sys.executable, "-m", "chronogym.cli"]


def run_cli(*args: str, timeout: float = 300) -> subprocess.CompletedProcess:
    env = {**os.environ, "RAY_ADDRESS": ""}
    return subprocess.run([*CLI, *args], capture_output=True, text=True, timeout=timeout, env=env)


def actor_inputs(path) -> int | None:
    return input_size(read_checkpoint(path, "path"), "actor_state_dict")


def iterations(out) -> list[int]:
    with open(out / "progress.csv", newline="") as handle:
        return [int(row["iteration"]) for row in csv.DictReader(handle)]


def test_the_papers_observation_on_request(tmp_path):
    out = tmp_path / "run"
    trained = run_cli(
        "train", "quadruped", "--num-envs", "2", "--backend", "serial", "--iterations", "1",
        "--eval-episodes", "0", "--no-observe-base-lin-vel", "--out", str(out),
    )  # fmt: skip
    assert trained.returncode == 0, trained.stderr[-3000:]
    assert actor_inputs(out / "latest.pt") == 45
    played = run_cli("play", "quadruped", str(out / "latest.pt"), "--steps", "5")
    assert played.returncode == 0, played.stderr[-3000:]  # play makes the 45-value env


def test_train_resume_and_play_on_the_serial_backend(tmp_path):
    out = tmp_path / "run"
    first = run_cli(
        "train", "quadruped", "--num-envs", "2", "--backend", "serial",
        "--iterations", "2", "--out", str(out),
    )  # fmt: skip
    assert first.returncode == 0, first.stderr[-3000:]
    assert "iterations 2, env steps" in first.stdout
    assert iterations(out) == [0, 1]
    assert (out / "latest.pt").is_file() and (out / "model_1.pt").is_file()
    # the last checkpoint was scored on the walking criterion: it is the best so far
    assert f"best checkpoint {out / 'best.pt'} = model_1.pt (iteration 1" in first.stdout
    assert "/7 pass (v2)" in first.stdout
    assert (out / "best.pt").read_bytes() == (out / "model_1.pt").read_bytes()
    # the policy reads the 45 observations and the base's velocity (the training default)
    assert actor_inputs(out / "latest.pt") == 48

    resumed = run_cli(
        "train", "quadruped", "--num-envs", "2", "--backend", "serial", "--iterations", "1",
        "--out", str(out), "--resume", str(out / "latest.pt"), "--finetune",
    )  # fmt: skip
    assert resumed.returncode == 0, resumed.stderr[-3000:]
    assert iterations(out) == [0, 1, 2]  # the count carries on, rows are appended
    assert (out / "model_2.pt").is_file()

    played = run_cli(
        "play", "quadruped", str(out / "latest.pt"), "--steps", "15",
        "--command", "0.5", "0", "0", "--command", "0", "0.2", "0",
    )  # fmt: skip
    assert played.returncode == 0, played.stderr[-3000:]
    lines = played.stdout.strip().splitlines()
    assert "x_mse" in lines[0]
    assert lines[1].split()[0:3] == ["(+0.50,", "+0.00,", "+0.00)"]
    assert lines[2].split()[0:3] == ["(+0.00,", "+0.20,", "+0.00)"]
    assert lines[0].split()[-2:] == ["v1", "v2"]

    traced = run_cli(
        "play", "quadruped", str(out / "latest.pt"), "--steps", "15", "--command", "0.5", "0",
        "0", "--episodes", "2", "--traces", str(tmp_path / "t.npz"),
        "--step-response", str(tmp_path / "s.png"),
    )  # fmt: skip
    assert traced.returncode == 0, traced.stderr[-3000:]
    assert f"traces: {tmp_path / 't.npz'}" in traced.stdout
    traces = load_traces(tmp_path / "t.npz")
    expected = [((0.5, 0.0, 0.0), seed, 15) for seed in (0, 1)]
    assert [(t.command, t.seed, len(t.vx)) for t in traces] == expected
    assert (tmp_path / "s.png").read_bytes()[:4] == b"\x89PNG"

    checked = run_cli("play", "quadruped", str(out / "latest.pt"), "--check-walking")
    assert checked.returncode == 0, checked.stderr[-3000:]
    table = checked.stdout.strip().splitlines()
    assert len(table) >= 1 + 7 + 2  # header, 6 commands and the switch, the verdicts
    assert table[7].split()[0] == "switch" and table[7].split()[-2:] == ["-", "FAIL"]
    assert "walks by criterion v2: no, because" in table
    assert table[-1] == "walks by criterion v1 (whole-episode MSE): no"

    shaken = run_cli(
        "play", "quadruped", str(out / "best.pt"), "--steps", "15", "--command", "0.5", "0", "0",
        "--push", "--push-interval", "0.1", "--friction", "0.4", "0.8",
    )  # fmt: skip
    assert shaken.returncode == 0, shaken.stderr[-3000:]
    shaken_lines = shaken.stdout.strip().splitlines()
    assert shaken_lines[0] == (
        "randomization: pushes up to 1 m/s per axis every 0.1 s; friction uniform in [0.4, 0.8]"
    )
    calm = run_cli(
        "play", "quadruped", str(out / "best.pt"), "--steps", "15", "--command", "0.5", "0", "0"
    )
    assert calm.returncode == 0, calm.stderr[-3000:]
    assert shaken_lines[-1] != calm.stdout.strip().splitlines()[-1]  # the kicks moved the base


def can_render() -> bool:
    from chronogym.tasks.quadruped.play import check_can_render

    try:
        check_can_render()
    except RuntimeError:
        return False
    return True


def test_play_writes_a_video(tmp_path):
    if not can_render():
        pytest.skip("no OpenGL backend for offscreen rendering (README: Rendering)")
    out = tmp_path / "run"
    trained = run_cli(
        "train", "quadruped", "--num-envs", "1", "--backend", "serial", "--iterations", "1",
        "--out", str(out),
    )  # fmt: skip
    assert trained.returncode == 0, trained.stderr[-3000:]
    for name in ("rollout.mp4", "rollout.gif", "rollout.png"):
        video = tmp_path / name
        played = run_cli(
            "play", "quadruped", str(out / "latest.pt"), "--steps", "6", "--command", "0.5", "0",
            "0", "--video", str(video),
        )  # fmt: skip
        assert played.returncode == 0, played.stderr[-3000:]
        assert f"video: {video}" in played.stdout
        assert video.stat().st_size > 1000
    import imageio.v2 as imageio

    frames = imageio.mimread(tmp_path / "rollout.gif")
    assert len(frames) == 4  # steps 0, 2, 4, 6: 25 frames/s of the 50 Hz control
    assert frames[0].shape[2] in (3, 4) and frames[0].std() > 1  # an image, not a blank
    strip = imageio.imread(tmp_path / "rollout.png")
    height, width = frames[0].shape[:2]
    assert strip.shape[:2] == (height, 4 * width)  # the 4 frames side by side


def test_train_defaults_to_ray_workers_with_synchronous_updates(tmp_path):
    result = run_cli(
        "train", "quadruped", "--num-envs", "2", "--iterations", "3", "--out", str(tmp_path),
    )  # fmt: skip
    assert result.returncode == 0, result.stderr[-3000:]
    assert iterations(tmp_path) == [0, 1, 2]
    assert "on the ray backend" in result.stdout
    with (tmp_path / "progress.csv").open() as handle:
        lags = [int(row["policy_lag"]) for row in csv.DictReader(handle)]
    assert lags == [0, 0, 0]  # the default: synchronous PPO (the overlap is --policy-lag 1)


@pytest.mark.parametrize(
    ("args", "message"),
    [
        (["--iterations", "0"], "--iterations=0: expected an integer >= 1"),
        ([], "give --iterations I, --minutes M, or both"),
        (["--minutes", "1", "--num-envs", "0"], "--num-envs=0: expected an integer >= 1"),
        (["--minutes", "1", "--resume", "missing.pt"], "--resume=missing.pt: no such checkpoint"),
        (["--minutes", "1", "--policy-lag", "-1"], "--policy-lag=-1: expected 0 (synchronous"),
        (["--minutes", "1", "--backend", "bogus"], "argument --backend: invalid choice: 'bogus'"),
        (["--minutes", "1", "--update-threads", "0"], "--update-threads=0: expected an integer"),
        (
            ["--minutes", "1", "--policy-lag", "1", "--update-threads", "2"],
            "--update-threads=2 with --policy-lag 1",
        ),
    ],
)
def test_train_rejects_bad_input(args, message, tmp_path):
    result = run_cli("train", "quadruped", "--out", str(tmp_path), *args, timeout=60)
    assert result.returncode != 0
    assert message in result.stderr


def test_play_rejects_a_missing_checkpoint(tmp_path):
    result = run_cli("play", "quadruped", str(tmp_path / "nope.pt"), timeout=60)
    assert result.returncode != 0
    assert "no such file" in result.stderr


def test_play_rejects_a_video_format_it_cannot_write(tmp_path):
    checkpoint = tmp_path / "any.pt"
    checkpoint.write_bytes(b"")
    result = run_cli("play", "quadruped", str(checkpoint), "--video", "out.avi", timeout=60)
    assert result.returncode != 0
    assert "--video=out.avi: expected a .mp4, .gif or .png path" in result.stderr


def test_finetune_a_rigid_checkpoint_on_soil_and_play_it_there(tmp_path):
    rigid, soil = tmp_path / "rigid", tmp_path / "soil"
    first = run_cli(
        "train", "quadruped", "--num-envs", "2", "--backend", "serial",
        "--iterations", "1", "--out", str(rigid),
    )  # fmt: skip
    assert first.returncode == 0, first.stderr[-3000:]
    tuned = run_cli(
        "train", "quadruped", "--terrain", "soil", "--num-envs", "2", "--backend", "serial",
        "--iterations", "1", "--out", str(soil), "--resume", str(rigid / "latest.pt"),
        "--finetune",
    )  # fmt: skip
    assert tuned.returncode == 0, tuned.stderr[-3000:]
    assert "soil terrain" in tuned.stdout
    assert iterations(soil) == [1]  # carries on from the rigid run's count
    played = run_cli(
        "play", "quadruped", str(soil / "latest.pt"), "--terrain", "soil", "--steps", "10",
        "--command", "0.5", "0", "0",
    )  # fmt: skip
    assert played.returncode == 0, played.stderr[-3000:]
    assert played.stdout.strip().splitlines()[1].split()[0] == "(+0.50,"
