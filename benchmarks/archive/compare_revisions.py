"""Vector-env throughput of two git revisions of chronogym, side by side in one run.

Each revision's ``src/`` is checked out into a temporary folder (``git worktree``)
and measured in its own subprocess (``PYTHONPATH`` = that ``src``, its own local
Ray), the revisions alternating round by round so that machine noise falls on
both. A regression check for refactors of ``vector/``:

    python -m benchmarks.archive.compare_revisions --base 305a016 [--head HEAD] [--rounds 3]

Prints a table (median env-steps/s per shape, head / base ratio, and the driver process's
CPU per vector step, µs) and writes JSON.
"""

from __future__ import annotations

import argparse
import json
import statistics
import subprocess
import sys
import tempfile
from pathlib import Path

from benchmarks.common import RESULTS, checkout, header, remove_checkout, revision, write_json

OUT = RESULTS / "compare_revisions.json"

#: (label, env id, env kwargs, num_envs, backend, vector kwargs)
SHAPES = [
    ("cartpole serial 16", "chronogym/CartPole-v0", {"k": 1}, 16, "serial", {}),
    ("cartpole ray-sock 2x8", "chronogym/CartPole-v0", {"k": 1}, 16, "ray", {"envs_per_worker": 8}),
    ("cartpole ray-actor 2x8", "chronogym/CartPole-v0", {"k": 1}, 16, "ray",
     {"envs_per_worker": 8, "transport": "actor"}),
    ("go1 serial 16", "chronogym/Go1Velocity-v0", {}, 16, "serial", {}),
    ("go1 ray-sock 2x8", "chronogym/Go1Velocity-v0", {}, 16, "ray", {"envs_per_worker": 8}),
]  # fmt: skip
#: Tasks that report infos at every step (Ant-v5: nine scalars), one env per worker as on a
#: machine with a core per worker, forked workers and Ray's.
INFO_SHAPES = [
    ("ant fork 1x1", "Ant-v5", {}, 1, "ray", {"envs_per_worker": 1, "transport": "fork"}),
    ("ant fork 4x1", "Ant-v5", {}, 4, "ray", {"envs_per_worker": 1, "transport": "fork"}),
    ("ant fork 8x1", "Ant-v5", {}, 8, "ray", {"envs_per_worker": 1, "transport": "fork"}),
    ("ant ray-sock 4x1", "Ant-v5", {}, 4, "ray", {"envs_per_worker": 1}),
    ("ant fork 2x8", "Ant-v5", {}, 16, "ray", {"envs_per_worker": 8, "transport": "fork"}),
    ("go1 fork 4x1", "chronogym/Go1Velocity-v0", {}, 4, "ray",
     {"envs_per_worker": 1, "transport": "fork"}),
]  # fmt: skip
#: The synthetic env with Ant-v5's nine scalar infos and 1 ms steps: the driver's CPU per
#: vector step at 1, 8 and 32 forked workers gives its cost per worker with infos.
SYNTHETIC_INFOS = {"step_ms": 1.0, "info_scalars": 9}
SYNTHETIC_INFO_SHAPES = [
    (f"synthetic+9 infos fork {w}x1", "chronogym/Synthetic-v0", SYNTHETIC_INFOS, w, "ray",
     {"envs_per_worker": 1, "transport": "fork"})
    for w in (1, 8, 32)
] + [
    ("synthetic+9 infos ray-sock 8x1", "chronogym/Synthetic-v0", SYNTHETIC_INFOS, 8, "ray",
     {"envs_per_worker": 1}),
]  # fmt: skip
SHAPE_SETS = {"default": SHAPES, "infos": INFO_SHAPES, "synthetic_infos": SYNTHETIC_INFO_SHAPES}

# Runs inside the subprocess: step one shape with random actions, print env-steps/s as JSON.
MEASURE = r"""
import json, sys, time
import numpy as np
import chronogym
env_id, env_kwargs, n, backend, vec_kwargs, seconds = json.loads(sys.argv[1])
if backend == "ray":
    import ray
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)
vec = chronogym.make_vec(env_id, n, backend=backend, env_kwargs=env_kwargs, **vec_kwargs)
vec.reset(seed=0)
space = vec.action_space
space.seed(0)
actions = [space.sample() for _ in range(64)]
for a in actions[:20]:
    vec.step(a)
steps, start, cpu = 0, time.perf_counter(), time.process_time()
while time.perf_counter() - start < seconds:
    vec.step(actions[steps % 64])
    steps += 1
rate = steps * n / (time.perf_counter() - start)
cpu_us = 1e6 * (time.process_time() - cpu) / steps
vec.close()
print(json.dumps({"rate": rate, "cpu_us": cpu_us, "module": chronogym.__file__}))
"""


def measure(src: Path, shape: tuple, seconds: float) -> dict:
    _, env_id, env_kwargs, n, backend, vec_kwargs = shape
    arg = json.dumps([env_id, env_kwargs, n, backend, vec_kwargs, seconds])
    done = subprocess.run(
        [sys.executable, "-c", MEASURE, arg],
        env={"PYTHONPATH": str(src), "PATH": "/usr/bin:/bin", "HOME": str(Path.home())},
        capture_output=True,
        text=True,
        check=True,
    )
    result = json.loads(done.stdout.strip().splitlines()[-1])
    if not result["module"].startswith(str(src)):
        raise RuntimeError(f"measured {result['module']}, not the checkout at {src}")
    return result


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--base", required=True, help="the revision to compare against")
    parser.add_argument("--head", default="HEAD", help="the revision under test")
    parser.add_argument("--rounds", type=int, default=3)
    parser.add_argument("--seconds", type=float, default=4.0, help="stepping time per sample")
    parser.add_argument(
        "--shapes", choices=tuple(SHAPE_SETS), default="default", help="which set of shapes"
    )
    parser.add_argument("--out", type=Path, default=OUT)
    args = parser.parse_args(argv)
    shapes = SHAPE_SETS[args.shapes]
    if args.rounds < 1 or args.seconds <= 0:
        parser.error(f"--rounds={args.rounds} / --seconds={args.seconds}: expected >= 1 / > 0")
    try:
        commits = {name: revision(rev) for name, rev in (("base", args.base), ("head", args.head))}
    except ValueError as error:
        parser.error(str(error))
    rates: dict[str, dict[str, list[float]]] = {s[0]: {"base": [], "head": []} for s in shapes}
    cpus: dict[str, dict[str, list[float]]] = {s[0]: {"base": [], "head": []} for s in shapes}
    with tempfile.TemporaryDirectory(prefix="chronogym-revs-") as tmp:
        srcs = {name: checkout(commit, Path(tmp) / name) for name, commit in commits.items()}
        try:
            for r in range(args.rounds):
                for shape in shapes:
                    order = ("base", "head") if r % 2 == 0 else ("head", "base")
                    for name in order:
                        got = measure(srcs[name], shape, args.seconds)
                        rates[shape[0]][name].append(got["rate"])
                        cpus[shape[0]][name].append(got["cpu_us"])
                    print(f"round {r + 1}/{args.rounds} {shape[0]}: "
                          f"base {rates[shape[0]]['base'][-1]:,.0f} "
                          f"head {rates[shape[0]]['head'][-1]:,.0f}", flush=True)  # fmt: skip
        finally:
            for name in srcs:
                remove_checkout(Path(tmp) / name)
    rows = []
    print(f"\n{'shape':<32}{'base':>10}{'head':>10}{'head/base':>10}"
          f"{'cpu base':>10}{'cpu head':>10}")  # fmt: skip
    for label, per in rates.items():
        base, head = statistics.median(per["base"]), statistics.median(per["head"])
        cpu = {name: statistics.median(values) for name, values in cpus[label].items()}
        rows.append(
            {
                "shape": label,
                "base": base,
                "head": head,
                "ratio": head / base,
                **per,
                "driver_cpu_us": cpu,
                "driver_cpu_us_rounds": cpus[label],
            }
        )
        print(f"{label:<32}{base:>10,.0f}{head:>10,.0f}{head / base:>10.2f}"
              f"{cpu['base']:>10,.0f}{cpu['head']:>10,.0f}")  # fmt: skip
    record = {
        **header("compare_revisions"),
        "revisions": commits,
        "rounds": args.rounds,
        "seconds": args.seconds,
        "shapes": args.shapes,
        "rows": rows,
    }
    note = f" (env-steps/s and the driver's CPU µs per step, medians of {args.rounds} rounds)"
    write_json(args.out, record, note=note)


if __name__ == "__main__":
    main()
