"""benchmarks/vector/side_by_side.py: vector envs stepped round by round (real forked
workers and Gymnasium's vector envs, a short run)."""

from __future__ import annotations

import json

import pytest

from benchmarks.vector.side_by_side import main, parse_args


def test_kinds_are_stepped_round_by_round_and_related_to_the_first(tmp_path):
    out = tmp_path / "side.json"
    argv = ["--env", "chronogym/Synthetic-v0", "--env-kwargs", '{"step_ms": 1.5}', "--kinds",
            "fork", "sync", "--workers", "1", "2", "--rounds", "2", "--steps", "20", "--warmup",
            "2", "--out", str(out)]  # fmt: skip
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


def test_a_kind_named_twice_is_refused():
    with pytest.raises(SystemExit):
        parse_args(["--kinds", "fork", "fork"])


@pytest.mark.parametrize("text", ["{step_ms: 1}", "[1, 2]"])
def test_env_kwargs_that_are_no_json_object_are_refused_by_value(text, capsys):
    with pytest.raises(SystemExit):
        parse_args(["--env-kwargs", text])
    assert repr(text) in capsys.readouterr().err
