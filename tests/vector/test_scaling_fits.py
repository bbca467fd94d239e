"""benchmarks/vector/scaling.py's driver-CPU measures and fits (no timing of chronogym)."""

from __future__ import annotations

import threading
import time

import pytest

from benchmarks.vector import scaling
from chronogym.sizing import timed_loop


def test_timed_loop_separates_the_calling_thread_from_the_others():
    stop = threading.Event()

    def busy() -> None:  # another thread's CPU: the process's, not the caller's
        while not stop.is_set():
            sum(range(1000))

    spinner = threading.Thread(target=busy, daemon=True)
    spinner.start()
    try:
        timed = timed_loop(lambda: time.sleep(0.01), seconds=0.3, min_steps=10, warmup=1)
    finally:
        stop.set()
        spinner.join()
    assert timed.steps >= 10
    assert timed.cpu_s > 0.05  # the spinning thread
    assert 0 <= timed.thread_cpu_s < 0.5 * timed.cpu_s


def test_fits_give_the_stepping_threads_slope_and_its_prediction():
    def run(workers: int) -> dict:
        return {
            "path": "socket",
            "workers": workers,
            "envs_per_worker": 1,
            "step_ms": 10.0,
            "wall_ms_per_step": 10.5 + 0.4 * workers,  # 2 cores: the wall grows with W
            "driver_cpu_ms_per_step": 0.3 + 0.006 * workers,
            "driver_thread_cpu_ms_per_step": 0.28 + 0.003 * workers,
        }

    (entry,) = scaling.fits([run(w) for w in (1, 4, 16, 64)])
    assert entry["b_cpu_us"] == pytest.approx(6.0)
    assert (entry["a_thread_us"], entry["b_thread_us"]) == (pytest.approx(280), pytest.approx(3))
    t1 = 10.9
    assert entry["predicted_rel_e_256_cores_thread"] == pytest.approx(t1 / (t1 + 0.003 * 255))
    assert entry["predicted_rel_e_256_cores"] == pytest.approx(t1 / (t1 + 0.006 * 255))


def test_fits_of_runs_without_the_thread_measure_have_no_thread_keys():
    rows = [
        {
            "path": "actor",
            "workers": w,
            "envs_per_worker": 1,
            "step_ms": 1.0,
            "wall_ms_per_step": 1.5 + w,
            "driver_cpu_ms_per_step": 0.1 * w,
        }
        for w in (1, 2)
    ]
    (entry,) = scaling.fits(rows)
    assert "b_thread_us" not in entry and "predicted_rel_e_64_cores_thread" not in entry
    assert entry["b_cpu_us"] == pytest.approx(100)
