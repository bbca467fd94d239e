"""time_to_walk.py's merge of result folders: a later folder's runs and settings win."""

from __future__ import annotations

import csv
import json
from pathlib import Path

from benchmarks.rl.time_to_walk import load_earlier


def folder(path: Path, runs: dict[tuple[str, int], int], settings: dict[str, dict]) -> Path:
    """A result folder holding ``runs`` ((config, seed) -> env steps checked) and settings."""
    path.mkdir()
    record = {
        "date": path.name,
        "machine": {"platform": path.name},
        "configs": {config: {} for config, _ in runs},
        "settings": settings,
        "runs": [{"config": c, "seed": s, "env_steps_to_walk": n} for (c, s), n in runs.items()],
    }
    (path / "time_to_walk.json").write_text(json.dumps(record))
    with (path / "time_to_walk.csv").open("w", newline="") as handle:
        writer = csv.DictWriter(handle, fieldnames=["config", "seed", "iteration", "env_steps"])
        writer.writeheader()
        for (config, seed), steps in runs.items():
            writer.writerow({"config": config, "seed": seed, "iteration": 1, "env_steps": steps})
    return path


def test_a_later_folder_replaces_runs_and_settings_and_keeps_the_other_seeds(tmp_path):
    old = folder(
        tmp_path / "old",
        {("c", 0): 100, ("c", 1): 200, ("d", 0): 300},
        {"c": {"minutes": 10, "seeds": [0, 1, 2]}, "d": {"minutes": 10, "seeds": [0]}},
    )
    new = folder(tmp_path / "new", {("c", 0): 999}, {"c": {"env_steps": 1.5e6, "seeds": [0]}})
    earlier = load_earlier([old, new], running=set())
    runs = {(r["config"], r["seed"]): r["env_steps_to_walk"] for r in earlier["runs"]}
    assert runs == {("c", 0): 999, ("c", 1): 200, ("d", 0): 300}
    assert earlier["settings"]["c"] == {"env_steps": 1.5e6, "seeds": [0, 1]}
    assert earlier["settings"]["d"] == {"minutes": 10, "seeds": [0]}
    assert earlier["machines"]["c"]["date"] == "new" and earlier["machines"]["d"]["date"] == "old"
    steps = sorted((r["config"], r["seed"], r["env_steps"]) for r in earlier["rows"])
    assert steps == [("c", 0, 999), ("c", 1, 200), ("d", 0, 300)]


def test_runs_being_run_again_are_left_out(tmp_path):
    old = folder(tmp_path / "old", {("c", 0): 100, ("c", 1): 200}, {"c": {"seeds": [0, 1]}})
    earlier = load_earlier([old], running={("c", 0)})
    assert [(r["config"], r["seed"]) for r in earlier["runs"]] == [("c", 1)]
    assert earlier["settings"]["c"]["seeds"] == [1]
