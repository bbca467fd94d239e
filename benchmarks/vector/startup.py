"""Wall time of a vector env's start and close, per transport: from ``RayVectorEnv(...)`` to
the first ``reset()`` returning, and from ``close()`` to its return, cold (first in the
process: Ray not yet initialised, so the env starts a local cluster; for ``fork``, the
zygote's first start) and warm (``--warm`` more, median), for W workers of
chronogym/CartPole-v0 (``--env``: another id) with one env per worker. Each transport and W
runs in a fresh child process, which also times ``import chronogym`` plus Ray and the final
``ray.shutdown()``.

Transports: ``socket`` (the default; Ray actors), ``actor``, ``fork`` (workers forked from a
warm zygote, no Ray), and ``ray_bare``: W Ray actors of an empty class to their first call,
nothing of chronogym's -- the floor under any transport whose workers are Ray actors. The
machine's CPU seconds per worker (``/proc/stat``, every process) over each warm start say
what a start costs where the workers outnumber the cores.

    python -m benchmarks.vector.startup [--workers 1 2 4] [--transports socket fork]
        [--warm 3] [--out PATH]
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
TRANSPORTS = ("socket", "actor", "fork", "ray_bare")

#: The child: prints one JSON line of phase times (seconds).
CHILD = textwrap.dedent(
    """
    import json, os, sys, time
    t = time.perf_counter()
    from chronogym import RayVectorEnv
    import ray
    imports = time.perf_counter() - t
    env_id, workers, warm, transport = sys.argv[1], int(sys.argv[2]), int(sys.argv[3]), sys.argv[4]

    def busy():
        with open("/proc/stat") as f:
            v = list(map(int, f.readline().split()[1:]))
        return (sum(v) - v[3] - v[4]) / os.sysconf("SC_CLK_TCK")

    class Bare:
        def ready(self):
            return True

    def bare():
        from chronogym.ray_runtime import ensure_ray
        ensure_ray()
        cls = ray.remote(Bare).options(num_cpus=0)
        actors = [cls.remote() for _ in range(workers)]
        ray.get([a.ready.remote() for a in actors])
        return actors

    def once():
        c0, t0 = busy(), time.perf_counter()
        if transport == "ray_bare":
            actors = bare()
            t1 = t2 = t3 = time.perf_counter()
            c1 = busy()
            for actor in actors:
                ray.kill(actor)
        else:
            env = RayVectorEnv(env_id, workers, envs_per_worker=1, transport=transport)
            t1 = time.perf_counter()
            env.reset(seed=0)
            t2, c1 = time.perf_counter(), busy()
            env.step(env.action_space.sample())
            t3 = time.perf_counter()
            env.close()
        t4 = time.perf_counter()
        return {"start": t2 - t0, "construct": t1 - t0, "close": t4 - t3,
                "cpu_per_worker": (c1 - c0) / workers}

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
    Column("transport", 10, align="<", key="transport"),
    Column("W", 3, key="workers"),
    Column("import s", 9, "{:.2f}", key="imports"),
    Column("cold start s", 13, "{:.2f}", key="cold_start"),
    Column("cold close s", 13, "{:.3f}", key="cold_close"),
    Column("warm start s", 13, "{:.2f}", key="warm_start"),
    Column("CPU s/worker", 13, "{:.3f}", key="warm_cpu_per_worker"),
    Column("warm close s", 13, "{:.3f}", key="warm_close"),
    Column("ray.shutdown s", 15, "{:.2f}", key="shutdown"),
)


def measure(transport: str, workers: int, warm: int, env_id: str = ENV_ID) -> dict:
    """One child process for ``transport`` and ``workers`` of ``env_id``: its phase times,
    warm ones as medians."""
    run = subprocess.run(
        [sys.executable, "-c", CHILD, env_id, str(workers), str(warm), transport],
        capture_output=True,
        text=True,
        env=child_env(),
        check=True,
    )
    got = json.loads(run.stdout.strip().splitlines()[-1])
    warm_runs = got["warm"] or [got["cold"]]
    return {
        "transport": transport,
        "workers": workers,
        "imports": got["imports"],
        "cold_start": got["cold"]["start"],
        "cold_construct": got["cold"]["construct"],
        "cold_close": got["cold"]["close"],
        "warm_start": statistics.median(r["start"] for r in warm_runs),
        "warm_cpu_per_worker": statistics.median(r["cpu_per_worker"] for r in warm_runs),
        "warm_close": statistics.median(r["close"] for r in warm_runs),
        "warm_runs": got["warm"],
        "shutdown": got["shutdown"],
    }


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--workers", type=int, nargs="+", default=[1, 2, 4])
    parser.add_argument("--transports", nargs="+", choices=TRANSPORTS, default=["socket", "fork"])
    parser.add_argument("--warm", type=int, default=3, help="warm starts per W (median shown)")
    parser.add_argument("--env", default=ENV_ID, help=f"the env id (default {ENV_ID})")
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args(argv)
    import gymnasium as gym

    import chronogym  # noqa: F401  (registers chronogym's ids)

    try:  # in this process, not first in a child's traceback
        gym.spec(args.env)
    except gym.error.Error as error:
        parser.error(f"--env {args.env!r}: not a registered env id ({error})")
    record = header("vector/startup")
    record["settings"] = settings(args)
    record["env_id"] = args.env
    rows = []
    for workers in args.workers:
        for transport in args.transports:
            rows.append(measure(transport, workers, args.warm, args.env))
            shown = table(COLUMNS, rows[-1:])
            print(shown.splitlines()[-1] if len(rows) > 1 else shown, flush=True)
    record["rows"] = rows
    write_json(args.out, record)


if __name__ == "__main__":
    main()
