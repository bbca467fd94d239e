"""Ray workers' priority beside a busy process (archived probe; it set ``WORKER_NICENESS``).

Steps 16 Go1 envs (2 Ray workers x 8, random actions) with the workers at nice 0
(chronogym's default for a cluster it starts) and at Ray's own nice 15, and serially, each
quiet and beside one busy process of normal priority (a Python spin loop, as a compile job
or a second experiment would be). Every measurement runs in its own subprocess with its own
local Ray, so the niceness is set when that cluster starts; rounds alternate the order.
Prints a table and writes ``benchmarks/results/throughput_priority.json``.

    python -m benchmarks.archive.throughput_priority [--seconds 3] [--rounds 2]   # about 3 min

(Until issue 31 this was ``throughput.py --background-load``.)
"""

from __future__ import annotations

import argparse
import json
import os
import statistics
import subprocess
import sys
import time
from contextlib import contextmanager
from pathlib import Path
from typing import Any

from benchmarks.common import RESULTS, Column, header, table, write_json

DEFAULT_OUT = RESULTS / "throughput_priority.json"

#: (label, backend, worker_niceness) measured; None is Ray's default (15).
CONFIGS = (("serial", "serial", 0), ("ray nice 0", "ray", 0), ("ray nice 15", "ray", None))

MEASURE = r"""
import json, os, sys, time
import chronogym
backend, niceness, seconds = json.loads(sys.argv[1])
kwargs = {"envs_per_worker": 8, "worker_niceness": niceness} if backend == "ray" else {}
vec = chronogym.make_vec("chronogym/Go1Velocity-v0", 16, backend=backend, **kwargs)
nice = [os.getpriority(os.PRIO_PROCESS, p) for p in vec.worker_pids()] if backend == "ray" else []
vec.reset(seed=0)
vec.action_space.seed(0)
actions = [vec.action_space.sample() for _ in range(32)]
for a in actions[:10]:
    vec.step(a)
steps, start = 0, time.perf_counter()
while time.perf_counter() - start < seconds:
    vec.step(actions[steps % 32])
    steps += 1
rate = steps * 16 / (time.perf_counter() - start)
vec.close()
print(json.dumps({"rate": rate, "worker_nice": nice}))
"""


@contextmanager
def busy_process(enabled: bool):
    """One busy process at normal priority while the block runs (nothing if not enabled)."""
    if not enabled:
        yield
        return
    spin = subprocess.Popen([sys.executable, "-c", "while True: pass"])
    try:
        yield
    finally:
        spin.kill()
        spin.wait()


def measure(backend: str, niceness: int | None, seconds: float) -> dict[str, Any]:
    done = subprocess.run(
        [sys.executable, "-c", MEASURE, json.dumps([backend, niceness, seconds])],
        capture_output=True,
        text=True,
        check=True,
        env={**_environ(), "RAY_ADDRESS": ""},
    )
    return json.loads(done.stdout.strip().splitlines()[-1])


def _environ() -> dict[str, str]:
    return {k: v for k, v in os.environ.items() if k != "RAY_worker_niceness"}


def run_priority(seconds: float, rounds: int) -> list[dict[str, Any]]:
    """Env-steps/s of every config, quiet and loaded; medians over ``rounds``."""
    rates: dict[tuple[str, bool], list[float]] = {}
    nice: dict[str, list[int]] = {}
    for r in range(rounds):
        for loaded in (False, True):
            order = CONFIGS if r % 2 == 0 else tuple(reversed(CONFIGS))
            with busy_process(loaded):
                for label, backend, niceness in order:
                    result = measure(backend, niceness, seconds)
                    rates.setdefault((label, loaded), []).append(result["rate"])
                    nice[label] = result["worker_nice"]
                    print(f"round {r + 1}/{rounds} {'loaded' if loaded else 'quiet '} "
                          f"{label}: {result['rate']:,.0f} env-steps/s", flush=True)  # fmt: skip
    serial_loaded = statistics.median(rates[("serial", True)])
    rows = []
    for label, _, _ in CONFIGS:
        quiet = statistics.median(rates[(label, False)])
        loaded = statistics.median(rates[(label, True)])
        rows.append({
            "config": label, "worker_nice": nice[label], "quiet": quiet, "loaded": loaded,
            "loaded_vs_quiet": loaded / quiet, "loaded_vs_serial": loaded / serial_loaded,
            "samples": {"quiet": rates[(label, False)], "loaded": rates[(label, True)]},
        })  # fmt: skip
    return rows


def format_priority(rows: list[dict[str, Any]]) -> str:
    columns = [
        Column("16 Go1 envs", 12, align="<", key="config"),
        Column("quiet", 9, "{:,.0f}", key="quiet"),
        Column("+ busy proc", 11, "{:,.0f}", key="loaded"),
        Column("kept", 6, "{:.2f}", key="loaded_vs_quiet"),
        Column("x serial", 8, "{:.2f}", key="loaded_vs_serial"),
    ]
    return table(columns, rows, rule=True)


def main(argv: list[str] | None = None) -> int:
    """Measure every config quiet and loaded, print the table, write the JSON."""
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--seconds", type=float, default=3.0, help="timed wall time per config")
    parser.add_argument("--rounds", type=int, default=2, help="rounds, alternating the order")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT, help="JSON output")
    args = parser.parse_args(argv)
    wall = time.perf_counter()
    seconds = max(args.seconds, 3.0)
    rows = run_priority(seconds, args.rounds)
    print()
    print(format_priority(rows))
    record = {**header("throughput_priority"), "seconds": seconds, "rounds": args.rounds}
    write_json(args.out, {**record, "rows": rows}, f" ({time.perf_counter() - wall:.0f} s)")
    return 0


if __name__ == "__main__":
    sys.exit(main())
