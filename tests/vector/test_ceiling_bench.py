"""benchmarks/vector/ceiling.py: bare processes stepping their own synthetic envs, and the
ratios it derives (real processes, a short run)."""

from __future__ import annotations

import pytest

from benchmarks.vector.ceiling import relate, run_bare


def test_bare_processes_step_near_their_ideal_rate():
    got = run_bare(workers=2, epw=2, step_ms=2.0, seconds=0.4)
    ideal = 2 * 2 / (2 * 2e-3)  # 2 processes of 2 envs, each env step 2 ms: 1,000 /s
    assert 0.6 * ideal < got["env_steps_per_s"] <= 1.02 * ideal
    assert 0 < got["worker_cpu_us_per_env_step"] < 2000


def test_each_path_is_related_to_its_first_worker_and_to_bare():
    rows = [
        {"path": "bare", "workers": 1, "step_ms": 10, "efficiency": 1.0, "env_steps_per_s": 100},
        {"path": "bare", "workers": 4, "step_ms": 10, "efficiency": 0.9, "env_steps_per_s": 360},
        {"path": "fork", "workers": 1, "step_ms": 10, "efficiency": 0.8, "env_steps_per_s": 80},
        {"path": "fork", "workers": 4, "step_ms": 10, "efficiency": 0.6, "env_steps_per_s": 240},
    ]
    relate(rows)
    assert [r["efficiency_rel_w1"] for r in rows] == pytest.approx([1.0, 0.9, 1.0, 0.75])
    assert [r["x_ceiling"] for r in rows] == pytest.approx([1.0, 1.0, 0.8, 240 / 360])
