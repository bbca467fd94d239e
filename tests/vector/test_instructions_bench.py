"""benchmarks/vector/instructions.py: instructions per vector step under Valgrind (a real
run of forked cart-pole workers, a few steps)."""

from __future__ import annotations

import json
import shutil

import pytest

from benchmarks.vector.instructions import dump_total, main, parse_args


def test_a_dump_total_is_its_summary_line(tmp_path):
    dump = tmp_path / "callgrind.out.1.2"
    dump.write_text("version: 1\ndesc: Trigger: dump phase2\nevents: Ir\nsummary: 123456\n")
    assert dump_total(dump) == 123456
    dump.write_text("events: Ir\n")
    with pytest.raises(ValueError, match="no 'summary:' line"):
        dump_total(dump)


def test_a_shape_named_twice_is_refused(capsys):
    with pytest.raises(SystemExit):
        parse_args(["--shapes", "go1", "go1"])
    assert "each shape once" in capsys.readouterr().err


@pytest.mark.parametrize("option", ["--base", "--head"])
def test_a_revision_git_does_not_know_is_refused_by_name(option, capsys):
    with pytest.raises(SystemExit):
        parse_args([option, "no-such-rev"])
    assert f"{option} 'no-such-rev': not a commit of this repository" in capsys.readouterr().err


@pytest.mark.skipif(
    shutil.which("valgrind") is None or shutil.which("callgrind_control") is None,
    reason="needs Valgrind (valgrind, callgrind_control)",
)
def test_counts_the_instructions_of_the_counted_steps_only(tmp_path):
    out = tmp_path / "instructions.json"
    argv = ["--shapes", "cartpole", "--warmup", "2", "--steps", "4", "--repeats", "1",
            "--out", str(out)]  # fmt: skip
    assert main(argv) == 0
    (row,) = json.loads(out.read_text())["rows"]
    assert row["shape"] == "cartpole" and row["revision"] == "head"
    # a vector step of 16 cart-poles: the driver's share is Python's tens of thousands of
    # instructions, far below the whole process's start-up (about a billion), which the
    # dumps leave out; each worker steps 8 envs, so the workers execute more than the driver
    assert 10_000 < row["driver"] < 5_000_000
    assert row["driver"] < row["workers"] < 100_000_000
