"""Instructions per vector step, counted by Valgrind: a regression check that noise cannot hide.

On the 2-core VMs here, single samples of one unchanged shape's env-steps/s swing by ±25 %
(``archive/compare_revisions.py``), so a wall-clock A/B cannot resolve the 3 % that a
refactor of ``vector/`` may cost. The instructions a step executes do not swing. This
script runs a shape under Valgrind's ``callgrind`` (every process: the driver, the zygote,
the forked workers), steps it ``--warmup`` times, then has every process dump its counts
(``callgrind_control``), steps ``--steps`` more times and dumps again: the second dump holds
exactly those steps (plus the one that wakes the workers for their dumps). Per shape and
revision: the driver's and the workers' (summed) instructions per vector step, and over
``--repeats`` runs their spread.

What it does not see: time in the kernel (system calls, wake-ups), cache misses and
waiting. It counts user-space instructions, which is what a change of Python code moves.
Forked workers only (``transport="fork"``, no Ray: Ray's own threads would count too); they
run the shared-step code of Ray workers on the driver's node.

    python -m benchmarks.vector.instructions --base 5031ffb [--head HEAD] [--shapes go1 ant]

Needs ``valgrind`` and ``callgrind_control`` on the PATH. Each run takes a minute or two
(Valgrind runs Python ~50x slower). Output: a table and JSON (default
``benchmarks/results/instructions.json``).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path
from typing import Any

from benchmarks.common import (
    RESULTS,
    Column,
    checkout,
    header,
    positive_int,
    remove_checkout,
    revision,
    table,
    write_json,
)

DEFAULT_OUT = RESULTS / "instructions.json"
#: name: (env id, env kwargs, workers, envs per worker)
SHAPES: dict[str, tuple[str, dict[str, Any], int, int]] = {
    "cartpole": ("chronogym/CartPole-v0", {"k": 1}, 2, 8),
    "go1": ("chronogym/Go1Velocity-v0", {}, 2, 8),
    "ant": ("Ant-v5", {}, 4, 1),  # nine scalar infos per step: the info rows
    # the synthetic env with Ant-v5's nine infos at 1, 2 and 8 workers: the driver's
    # instructions per further worker, free of the physics (1 to 2 adds what only runs with
    # more than one worker)
    "synthetic1": ("chronogym/Synthetic-v0", {"step_ms": 0.0, "info_scalars": 9}, 1, 1),
    "synthetic2": ("chronogym/Synthetic-v0", {"step_ms": 0.0, "info_scalars": 9}, 2, 1),
    "synthetic8": ("chronogym/Synthetic-v0", {"step_ms": 0.0, "info_scalars": 9}, 8, 1),
}

# Runs under Valgrind, in the checkout's src: warm up, dump, step, dump (every process).
MEASURE = r"""
import glob, json, os, sys, time
import chronogym
env_id, env_kwargs, workers, epw, warmup, steps, out = json.loads(sys.argv[1])
vec = chronogym.make_vec(env_id, workers * epw, backend="ray", envs_per_worker=epw,
                         transport="fork", spin_us=0, env_kwargs=env_kwargs)
vec.reset(seed=0)
space = vec.action_space
space.seed(0)
actions = [space.sample() for _ in range(64)]
driver, pids = os.getpid(), vec.worker_pids()

def dumped(pid, k):
    return len(glob.glob(f"{out}/callgrind.out.{pid}.*")) >= k

def request(pid, k):  # posix_spawn: little Python in the driver's own counts
    quiet = [(os.POSIX_SPAWN_OPEN, 1, os.devnull, os.O_WRONLY, 0)]
    argv = ["callgrind_control", f"--dump=phase{k}", str(pid)]
    os.waitpid(os.posix_spawnp(argv[0], argv, os.environ, file_actions=quiet), 0)

def dump_driver(k):  # it dumps while it polls for its file
    request(driver, k)
    while not dumped(driver, k):
        time.sleep(0.01)

def dump(k):
    # each worker dumps when the next step wakes it, so its two dumps cut the same point of
    # a step; the workers are asked outside the driver's counted phase (before its first
    # dump, after its second), so that phase holds the same work at any W
    if k == 2:
        dump_driver(k)
    for pid in pids:
        request(pid, k)
    if k == 1:
        dump_driver(k)
    vec.step(actions[0])
    while not all(dumped(pid, k) for pid in pids):
        time.sleep(0.01)

for t in range(warmup):
    vec.step(actions[t % 64])
dump(1)
for t in range(steps):
    vec.step(actions[t % 64])
dump(2)
print(json.dumps({"driver": driver, "workers": pids, "module": chronogym.__file__}), flush=True)
vec.close()
"""


def parse_args(argv: list[str] | None = None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--base", help="a revision to compare against (default: none)")
    parser.add_argument("--head", default="HEAD", help="the revision under test")
    parser.add_argument("--shapes", choices=tuple(SHAPES), nargs="+", default=["go1", "ant"])
    parser.add_argument("--warmup", type=positive_int, default=20, help="steps before counting")
    parser.add_argument("--steps", type=positive_int, default=200, help="vector steps counted")
    parser.add_argument("--repeats", type=positive_int, default=2, help="runs per shape")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    if len(set(args.shapes)) != len(args.shapes):
        parser.error(f"--shapes {' '.join(args.shapes)}: each shape once")
    for option in ("base", "head"):
        if (rev := getattr(args, option)) is not None:
            try:
                revision(rev)
            except ValueError as error:
                parser.error(f"--{option} {error}")
    return args


def require_valgrind() -> None:
    """Fail early, by name, where Valgrind's tools are missing."""
    missing = [tool for tool in ("valgrind", "callgrind_control") if shutil.which(tool) is None]
    if missing:
        raise SystemExit(
            f"instructions.py needs {' and '.join(missing)} on the PATH (Valgrind); "
            "install it (e.g. apt install valgrind) and run again"
        )


def dump_total(path: Path) -> int:
    """The instructions a callgrind dump holds (its ``summary:`` line)."""
    for line in path.read_text().splitlines():
        if line.startswith("summary:"):
            return int(line.split()[1])
    raise ValueError(f"{path}: no 'summary:' line; expected a callgrind dump")


def run_once(src: Path, shape: str, warmup: int, steps: int) -> dict[str, float]:
    """One run of ``shape`` under callgrind: instructions per vector step, driver and workers."""
    env_id, env_kwargs, workers, epw = SHAPES[shape]
    with tempfile.TemporaryDirectory(prefix="chronogym-callgrind-") as out:
        arg = json.dumps([env_id, env_kwargs, workers, epw, warmup, steps, out])
        command = [
            "valgrind", "--tool=callgrind", "--trace-children=yes",
            "--trace-children-skip=*callgrind_control*,*perl*",
            f"--callgrind-out-file={out}/callgrind.out.%p",
            sys.executable, "-c", MEASURE, arg,
        ]  # fmt: skip
        env = {**os.environ, "PYTHONPATH": str(src), "PYTHONHASHSEED": "0"}
        done = subprocess.run(command, env=env, capture_output=True, text=True, check=True)
        got = json.loads(done.stdout.strip().splitlines()[-1])
        if not got["module"].startswith(str(src)):
            raise RuntimeError(f"measured {got['module']}, not the checkout at {src}")
        per_step = steps + 1  # the step that wakes the workers for the first dump
        phase = {
            pid: Path(out) / f"callgrind.out.{pid}.2" for pid in [got["driver"], *got["workers"]]
        }
        driver = dump_total(phase.pop(got["driver"])) / per_step
        workers = sum(dump_total(path) for path in phase.values()) / per_step
    return {"driver": driver, "workers": workers}


def measure(revisions: dict[str, Path], args: argparse.Namespace) -> list[dict[str, Any]]:
    """Every shape, every revision, ``--repeats`` times (revisions alternating)."""
    rows = []
    for shape in args.shapes:
        runs: dict[str, list[dict[str, float]]] = {name: [] for name in revisions}
        for r in range(args.repeats):
            order = list(revisions) if r % 2 == 0 else list(reversed(revisions))
            for name in order:
                runs[name].append(run_once(revisions[name], shape, args.warmup, args.steps))
                print(f"  {shape} {name} run {r + 1}/{args.repeats}: driver "
                      f"{runs[name][-1]['driver']:,.0f}, workers {runs[name][-1]['workers']:,.0f} "
                      "instructions per step", flush=True)  # fmt: skip
        for name, got in runs.items():
            row: dict[str, Any] = {"shape": shape, "revision": name, "runs": got}
            for part in ("driver", "workers"):
                values = [run[part] for run in got]
                row[part] = statistics.median(values)
                row[f"{part}_spread"] = (max(values) - min(values)) / row[part]
            rows.append(row)
    if "base" in revisions:
        base = {row["shape"]: row for row in rows if row["revision"] == "base"}
        for row in rows:
            for part in ("driver", "workers"):
                row[f"{part}_over_base"] = row[part] / base[row["shape"]][part]
    return rows


def main(argv: list[str] | None = None) -> int:
    args = parse_args(argv)
    require_valgrind()
    wanted = {"head": args.head} if args.base is None else {"base": args.base, "head": args.head}
    commits = {name: revision(rev) for name, rev in wanted.items()}
    revs = ", ".join(f"{name} {commit[:9]}" for name, commit in commits.items())
    print(f"instructions: {revs}; shapes {' '.join(args.shapes)}; {args.steps} steps counted, "
          f"{args.repeats} runs each")  # fmt: skip
    with tempfile.TemporaryDirectory(prefix="chronogym-revs-") as tmp:
        srcs = {name: checkout(rev, Path(tmp) / name) for name, rev in commits.items()}
        try:
            rows = measure(srcs, args)
        finally:
            for name in srcs:
                remove_checkout(Path(tmp) / name)
    print(table([
        Column("shape", 10, align="<"), Column("revision", 9, align="<"),
        Column("driver / step", 14, "{:,.0f}"), Column("spread", 7, "{:.2%}"),
        Column("/ base", 7, "{:.4f}"), Column("workers / step", 15, "{:,.0f}"),
        Column("spread", 7, "{:.2%}"), Column("/ base", 7, "{:.4f}"),
    ], [
        (r["shape"], r["revision"], r["driver"], r["driver_spread"], r.get("driver_over_base"),
         r["workers"], r["workers_spread"], r.get("workers_over_base"))
        for r in rows
    ], rule=True))  # fmt: skip
    record = {**header("instructions"), "revisions": commits, "settings": {
        "shapes": {s: SHAPES[s] for s in args.shapes}, "warmup": args.warmup,
        "steps": args.steps, "repeats": args.repeats}, "rows": rows}  # fmt: skip
    write_json(args.out, record, note=" (instructions per vector step, callgrind)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
