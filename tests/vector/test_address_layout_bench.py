"""benchmarks/vector/address_layout.py: one real measurement and the summary (no timing)."""

from __future__ import annotations

import argparse
import sys

import pytest

from benchmarks.vector import address_layout as bench

pytestmark = pytest.mark.skipif(not sys.platform.startswith("linux"), reason="/proc, fork")


def test_forked_workers_step_the_shared_barrier():
    args = argparse.Namespace(
        run="forked",
        env=bench.SYNTHETIC,
        workers=2,
        step_ms=0.1,
        steps=20,
        warmup=2,
        spin_us=0.0,
        settle=0.0,
    )
    row = bench.measure(args)
    assert (row["path"], row["workers"]) == ("forked", 2)
    assert row["env_steps_per_s"] > 0 and row["worker_cpu_us"] >= 0
    assert row["aslr_off"] is False  # forked from this process, whose layout is randomized


def test_summary_takes_medians_and_compares_with_ray():
    def run(path: str, rate: float) -> dict:
        return {
            "path": path,
            "env": "e",
            "step_ms": 0.1,
            "workers": 2,
            "worker_cpu_us": rate / 100,
            "driver_cpu_us": 1.0,
            "env_steps_per_s": rate,
        }

    runs = [run("ray", 100), run("ray", 300), run("ray", 200), run("forked", 300)]
    rows = {row["path"]: row for row in bench.summarize(runs)}
    assert rows["ray"]["env_steps_per_s"] == 200 and len(rows["ray"]["repeats"]) == 3
    assert rows["forked"]["vs_ray"] == pytest.approx(1.5)
    assert rows["ray"]["vs_ray"] == pytest.approx(1.0)
