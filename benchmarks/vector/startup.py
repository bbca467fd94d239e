"""Wall time of a RayVectorEnv's start and close: from ``RayVectorEnv(...)`` to the first
``reset()`` returning, and from ``close()`` to its return, cold (Ray not yet initialised in
the process: the env starts a local cluster) and warm (Ray already up), for W = 1, 2, 4
workers of chronogym/CartPole-v0 (one env per worker). Each W runs in a fresh child process:
one cold start, then ``--warm`` warm starts; the child also times ``import chronogym`` plus
Ray and the final ``ray.shutdown()``. Prints a table and writes JSON.

    python -m benchmarks.vector.startup [--workers 1 2 4] [--warm 3] [--out PATH]
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import textwrap
from pathlib import Path

from benchmarks.common import RESULTS, Column, child_env, header, settings, table, write_json

DEFAULT_OUT = RESULTS / "startup.json"
ENV_ID = "chronogym/CartPole-v0"

#: The child: prints one JSON line of phase times (seconds).
CHILD = textwrap.dedent(
    """
    import json, sys, time
    t = time.perf_counter()
    from chronogym import RayVectorEnv
    import ray
    imports = time.perf_counter() - t
    env_id, workers, warm = sys.argv[1], int(sys.argv[2]), int(sys.argv[3])

    def once():
        t0 = time.perf_counter()
        env = RayVectorEnv(env_id, workers, envs_per_worker=1)
        t1 = time.perf_counter()
        env.reset(seed=0)
        t2 = time.perf_counter()
        env.step(env.action_space.sample())
        t3 = time.perf_counter()
        env.close()
        t4 = time.perf_counter()
        return {"start": t2 - t0, "construct": t1 - t0, "close": t4 - t3}

    assert not ray.is_initialized()
    cold = once()
    warm_runs = [once() for _ in range(warm)]
    t = time.perf_counter()
    ray.shutdown()
    print(json.dumps({"imports": imports, "cold": cold, "warm": warm_runs,
                      "shutdown": time.perf_counter() - t}))
    """
)

COLUMNS = (
    Column("W", 3, key="workers"),
    Column("import s", 9, "{:.2f}", key="imports"),
    Column("cold start s", 13, "{:.2f}", key="cold_start"),
    Column("cold close s", 13, "{:.3f}", key="cold_close"),
    Column("warm start s", 13, "{:.2f}", key="warm_start"),
    Column("warm close s", 13, "{:.3f}", key="warm_close"),
    Column("ray.shutdown s", 15, "{:.2f}", key="shutdown"),
)


def measure(workers: int, warm: int) -> dict:
    """One child process for ``workers``: its phase times, warm ones as medians."""
    run = subprocess.run(
        [sys.executable, "-c", CHILD, ENV_ID, str(workers), str(warm)],
        capture_output=True,
        text=True,
        env=child_env(),
        check=True,
    )
    got = json.loads(run.stdout.strip().splitlines()[-1])
    return {
        "workers": workers,
        "imports": got["imports"],
        "cold_start": got["cold"]["start"],
        "cold_construct": got["cold"]["construct"],
        "cold_close": got["cold"]["close"],
        "warm_start": statistics.median(r["start"] for r in got["warm"]),
        "warm_close": statistics.median(r["close"] for r in got["warm"]),
        "warm_runs": got["warm"],
        "shutdown": got["shutdown"],
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument("--warm", type=int, default=3, help="warm starts per W (median shown)")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    record = header("vector/startup")
    record["settings"] = settings(args)
    record["env_id"] = ENV_ID
    rows = []
    for workers in args.workers:
        rows.append(measure(workers, args.warm))
        print(table(COLUMNS, rows[-1:]).splitlines()[-1] if len(rows) > 1 else table(COLUMNS, rows))
    record["rows"] = rows
    write_json(args.out, record)


if __name__ == "__main__":
    main()
