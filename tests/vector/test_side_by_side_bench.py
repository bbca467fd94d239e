"""benchmarks/vector/side_by_side.py: vector envs stepped round by round (real forked
workers and Gymnasium's vector envs, a short run)."""

from __future__ import annotations

import json
import subprocess
import sys
import time

import pytest

from benchmarks.vector.side_by_side import idle_threads, idle_wakeups, main, parse_args


def test_kinds_are_stepped_round_by_round_and_related_to_the_first(tmp_path):
    out = tmp_path / "side.json"
    argv = ["--env", "chronogym/Synthetic-v0", "--env-kwargs", '{"step_ms": 1.5}', "--kinds",
            "fork", "sync", "--workers", "1", "2", "--rounds", "2", "--steps", "20", "--warmup",
            "2", "--idle-s", "0.3", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    rows = json.loads(out.read_text())["rows"]
    assert [(r["kind"], r["workers"]) for r in rows] == [
        ("fork", 1),
        ("sync", 1),
        ("fork", 2),
        ("sync", 2),
    ]
    for row in rows:
        assert len(row["rounds"]) == 2 and row["wall_us"] > 1400  # each env step sleeps 1.5 ms
        low, high = row["wall_over_first_range"]
        assert low <= row["wall_over_first"] <= high
    assert all(r["wall_over_first"] == 1.0 for r in rows if r["kind"] == "fork")
    assert rows[0]["worker_cpu_us"] >= 0 and rows[1]["worker_cpu_us"] == 0  # sync: no workers
    assert rows[1]["idle_wakeups_per_s"] == 0 and rows[0]["idle_wakeups_per_s"] >= 0


def test_idle_wakeups_count_a_process_that_keeps_waking():
    sleeper = subprocess.Popen([sys.executable, "-c", "import time\nwhile True: time.sleep(0.005)"])
    try:
        time.sleep(0.3)
        rate = idle_wakeups({"sleeper": [sleeper.pid], "none": []}, 0.5)
    finally:
        sleeper.kill()
        sleeper.wait()
    assert 50 < rate["sleeper"] < 400 and rate["none"] == 0  # ~200 wake-ups per second


def test_idle_threads_name_the_thread_that_wakes():
    code = (
        "import threading, time\n"
        "def tick():\n"
        "    while True: time.sleep(0.005)\n"
        "threading.Thread(target=tick).start()\n"
        "time.sleep(60)"
    )
    sleeper = subprocess.Popen([sys.executable, "-c", code])
    try:
        time.sleep(0.3)
        threads = idle_threads({"sleeper": [sleeper.pid], "none": []}, 0.5)["sleeper"]
    finally:
        sleeper.kill()
        sleeper.wait()
    busiest, woken = next(iter(threads.items()))  # named as the OS knows it (comm)
    assert busiest != "main" and 50 < woken["wakeups_per_s"] < 400  # ~200 a second
    assert woken["cpu_us_per_s"] > 0 and threads["main"]["wakeups_per_s"] < 5


def test_held_ray_workers_stop_the_main_threads_wake_ups(ray_cluster, tmp_path):
    out = tmp_path / "held.json"
    argv = ["--env", "chronogym/Synthetic-v0", "--env-kwargs", '{"step_ms": 1.0}', "--kinds",
            "socket", "socket_held", "--rounds", "1", "--steps", "20", "--warmup", "2",
            "--idle-s", "0.5", "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    free, held = json.loads(out.read_text())["rows"]
    assert held["kind"] == "socket_held" and held["wall_us"] > 900
    # Ray's signal check wakes a free worker's main thread every 10 ms; the held one's only
    # wakes for its hold's flag check (twice a second)
    assert free["idle_threads"]["main"]["wakeups_per_s"] > 50
    assert held["idle_threads"].get("main", {"wakeups_per_s": 0})["wakeups_per_s"] < 10


@pytest.mark.parametrize("seconds", ["0", "-1", "61"])
def test_idle_seconds_out_of_range_are_refused(seconds, capsys):
    with pytest.raises(SystemExit):
        parse_args(["--idle-s", seconds])
    assert f"--idle-s {float(seconds)}" in capsys.readouterr().err


def test_a_kind_named_twice_is_refused():
    with pytest.raises(SystemExit):
        parse_args(["--kinds", "fork", "fork"])


@pytest.mark.parametrize("text", ["{step_ms: 1}", "[1, 2]"])
def test_env_kwargs_that_are_no_json_object_are_refused_by_value(text, capsys):
    with pytest.raises(SystemExit):
        parse_args(["--env-kwargs", text])
    assert repr(text) in capsys.readouterr().err
