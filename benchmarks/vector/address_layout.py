"""Why Gymnasium's AsyncVectorEnv workers cost less CPU per step than Ray's on a node with more
workers than cores: the address layout of the worker processes.

Every path below runs the same worker loop on the same env and measures, per vector step, the
workers' CPU time (user + system from ``/proc``, per worker), the driver's CPU time and the
throughput, after ``--settle`` idle seconds (Ray's daemons finish starting) and ``--warmup``
steps. Each (path, setting) runs in a fresh driver process of its own, the repeats
interleaved; the table shows medians. One env per worker, zero actions:

- ``forked``: W workers forked from the driver: chronogym's socket worker loop
  (``_serve_conn``), stepped through the shared-memory barrier step
  (:class:`chronogym.vector.shared_step.SharedStep`), as ``RayVectorEnv`` steps its
  workers, without Ray. Forked processes share their parent's address layout.
- ``exec``: the same loop in W fresh interpreters (``python -m
  benchmarks.vector.address_layout --serve ...``): each has its own randomized layout (ASLR),
  as each Ray worker, which Ray's raylet starts by exec, has.
- ``exec_same``: the same, started by ``setarch <machine> -R`` (ASLR off): W fresh
  interpreters that run the same script lie at the same addresses.
- ``ray``: ``RayVectorEnv`` (defaults: socket transport, shared-memory step).
- ``ray_same``: the same in a driver started by ``setarch <machine> -R``: Ray's daemons and so
  its workers inherit ASLR off.
- ``async``: Gymnasium's ``AsyncVectorEnv`` (workers forked from the driver).

``exec_same`` and ``ray_same`` are skipped with a note where ``setarch`` is missing.

    python -m benchmarks.vector.address_layout            # ~6 min on 2 cores
    python -m benchmarks.vector.address_layout --quick    # smoke run

Writes ``results/address_layout.json``.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import shutil
import socket
import statistics
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from typing import Any

import numpy as np

from benchmarks.common import (
    RESULTS,
    Column,
    header,
    positive_int,
    proc_cpu_s,
    settings,
    table,
    write_json,
)

PATHS = ("forked", "exec", "exec_same", "ray", "ray_same", "async")
SYNTHETIC = "chronogym/Synthetic-v0"
#: (env id, step ms for the synthetic env or None, workers): the default grid.
SETTINGS = ((SYNTHETIC, 0.1, 2), (SYNTHETIC, 0.1, 8), ("Ant-v5", None, 2), ("Ant-v5", None, 8))


def same_layout_prefix() -> list[str] | None:
    """The command prefix that starts a program with ASLR off, or None without setarch."""
    tool = shutil.which("setarch")
    return [tool, platform.machine(), "-R"] if tool else None


def env_kwargs(step_ms: float | None) -> dict[str, Any]:
    return {} if step_ms is None else {"step_ms": step_ms}


# -- the worker side of forked / exec -------------------------------------------------------


def build_group(env_id: str, worker: int, step_ms: float | None) -> Any:
    from gymnasium.vector import AutoresetMode

    from chronogym.vector.group import EnvGroup

    kwargs = env_kwargs(step_ms)
    group = EnvGroup([env_id], [worker], AutoresetMode.NEXT_STEP, [worker], env_kwargs=kwargs)
    group.reset([worker], None)
    return group


def serve(path: str, env_id: str, worker: int, step_ms: float | None, spin_s: float) -> None:
    """A fresh interpreter's worker: listen on ``path``, then serve the driver that connects."""
    from chronogym.vector.socket_transport import serve_listener

    group = build_group(env_id, worker, step_ms)
    listener = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
    listener.bind(path)
    listener.listen(1)
    Path(path + ".ready").touch()
    serve_listener(group, listener, path, spin_s)


def start_processes(
    path: str, env_id: str, workers: int, step_ms: float | None, spin_s: float
) -> tuple[list[int], list[socket.socket], Any]:
    """The workers of ``forked`` / ``exec`` / ``exec_same``: (pids, driver's sockets, stop)."""
    if path == "forked":
        from chronogym.vector.socket_transport import _serve_conn

        pids, socks = [], []
        for w in range(workers):
            ours, theirs = socket.socketpair(socket.AF_UNIX, socket.SOCK_STREAM)
            pid = os.fork()
            if pid == 0:  # the worker
                try:
                    ours.close()
                    _serve_conn(build_group(env_id, w, step_ms), theirs, spin_s)
                except BaseException:
                    import traceback

                    traceback.print_exc()
                finally:
                    os._exit(0)
            theirs.close()
            pids.append(pid)
            socks.append(ours)
        return pids, socks, lambda: [os.waitpid(p, 0) for p in pids]
    prefix = same_layout_prefix() if path == "exec_same" else []
    folder = tempfile.mkdtemp(prefix="chronogym-layout-")
    names = [os.path.join(folder, f"w{w}") for w in range(workers)]
    procs = []
    for w, name in enumerate(names):
        command = [sys.executable, "-m", "benchmarks.vector.address_layout", "--serve", name]
        command += ["--env", env_id, "--worker", str(w), "--spin-us", str(spin_s * 1e6)]
        if step_ms is not None:
            command += ["--step-ms", str(step_ms)]
        procs.append(subprocess.Popen([*(prefix or []), *command]))
    deadline = time.monotonic() + 120
    while not all(os.path.exists(n + ".ready") for n in names):
        if time.monotonic() > deadline or any(p.poll() is not None for p in procs):
            raise RuntimeError(f"{path}: the workers did not start")
        time.sleep(0.02)
    socks = []
    for name in names:
        sock = socket.socket(socket.AF_UNIX, socket.SOCK_STREAM)
        sock.connect(name)
        socks.append(sock)
    return [p.pid for p in procs], socks, lambda: [p.wait(30) for p in procs]


# -- one measurement, in a fresh driver -----------------------------------------------------


def measure(args: argparse.Namespace) -> dict[str, Any]:
    """Build ``args.run``'s vector env, step it, and return the per-step costs."""
    import gymnasium as gym

    import chronogym  # noqa: F401  (registers the chronogym/ ids)

    probe = gym.make(args.env, **env_kwargs(args.step_ms))
    action = np.zeros(probe.action_space.shape, probe.action_space.dtype)
    obs_bytes = probe.observation_space.sample().nbytes
    probe.close()
    actions = np.stack([action] * args.workers)
    if args.run in ("forked", "exec", "exec_same"):
        from chronogym.vector.shared_step import SharedLayout, SharedStep

        spin_s = args.spin_us * 1e-6
        layout = SharedLayout(
            tuple((w, w + 1) for w in range(args.workers)), action.nbytes, obs_bytes
        )
        shared = SharedStep(layout, None, spin_s)
        pids, socks, wait = start_processes(args.run, args.env, args.workers, args.step_ms, spin_s)
        for w, sock in enumerate(socks):
            if not shared.attach(w, sock, 30.0):
                raise RuntimeError(f"{args.run}: worker {w} did not take the shared step")

        def lost(w: int, error: BaseException) -> Any:
            raise RuntimeError(f"{args.run}: worker {w} lost: {error}")

        def step() -> None:
            shared.step(actions, socks, None, lost, None)

        def close() -> None:
            shared.close()
            for sock in socks:
                sock.close()
            wait()

    else:
        if args.run == "async":
            vec = gym.make_vec(
                args.env, args.workers, vectorization_mode="async", **env_kwargs(args.step_ms)
            )
            pids = [p.pid for p in vec.processes]
        else:
            from benchmarks.vector.throughput_timing import start_ray
            from chronogym import RayVectorEnv

            start_ray()  # workers at chronogym's nice value, as RayVectorEnv's own Ray has
            vec = RayVectorEnv(
                args.env, args.workers, envs_per_worker=1, env_kwargs=env_kwargs(args.step_ms)
            )
            pids = vec.worker_pids()
        vec.reset(seed=0)

        def step() -> None:
            vec.step(actions)

        close = vec.close
    personality = sorted({Path(f"/proc/{p}/personality").read_text().strip() for p in pids})
    time.sleep(args.settle)  # let Ray's daemons finish starting before the timing
    for _ in range(args.warmup):
        step()
    cpu0, wall0, drv0 = sum(proc_cpu_s(p) for p in pids), time.perf_counter(), time.process_time()
    for _ in range(args.steps):
        step()
    cpu1, wall1, drv1 = sum(proc_cpu_s(p) for p in pids), time.perf_counter(), time.process_time()
    close()
    return {
        "path": args.run,
        "env": args.env,
        "step_ms": args.step_ms,
        "workers": args.workers,
        "worker_cpu_us": (cpu1 - cpu0) / args.steps / args.workers * 1e6,
        "driver_cpu_us": (drv1 - drv0) / args.steps * 1e6,
        "env_steps_per_s": args.steps * args.workers / (wall1 - wall0),
        "aslr_off": personality != ["00000000"],
    }


def run_one(path: str, env_id: str, step_ms: float | None, workers: int, args: Any) -> dict:
    """``measure`` in a fresh driver (under setarch for ``ray_same``)."""
    prefix = same_layout_prefix() if path == "ray_same" else []
    command = [sys.executable, "-m", "benchmarks.vector.address_layout", "--run", path]
    command += ["--env", env_id, "--workers", str(workers), "--steps", str(args.steps)]
    command += ["--warmup", str(args.warmup), "--spin-us", str(args.spin_us)]
    command += ["--settle", str(args.settle)]
    if step_ms is not None:
        command += ["--step-ms", str(step_ms)]
    done = subprocess.run([*(prefix or []), *command], capture_output=True, text=True, timeout=600)
    lines = [line for line in done.stdout.splitlines() if line.startswith("{")]
    if done.returncode != 0 or not lines:
        raise RuntimeError(f"{path} {env_id} W={workers} failed:\n{done.stderr[-2000:]}")
    return json.loads(lines[-1])


# -- the sweep ------------------------------------------------------------------------------


COLUMNS = (
    Column("env", 24, align="<", key="env"),
    Column("step ms", 7, "{:.1f}", key="step_ms"),
    Column("W", 3, key="workers"),
    Column("path", 9, align="<", key="path"),
    Column("worker CPU us/step", 18, "{:.0f}", key="worker_cpu_us"),
    Column("driver CPU us/step", 18, "{:.0f}", key="driver_cpu_us"),
    Column("env-steps/s", 11, "{:.0f}", key="env_steps_per_s"),
    Column("x ray", 5, "{:.2f}", key="vs_ray"),
)


def summarize(runs: list[dict]) -> list[dict]:
    """Median over repeats per (setting, path), with throughput relative to ``ray``."""
    rows: dict[tuple, dict] = {}
    for run in runs:
        key = (run["env"], run["step_ms"], run["workers"], run["path"])
        rows.setdefault(key, {**run, "repeats": []})["repeats"].append(run)
    out = []
    for row in rows.values():
        for field in ("worker_cpu_us", "driver_cpu_us", "env_steps_per_s"):
            row[field] = statistics.median(r[field] for r in row["repeats"])
        out.append(row)
    for row in out:
        ray_row = rows.get((*tuple(row[k] for k in ("env", "step_ms", "workers")), "ray"))
        row["vs_ray"] = row["env_steps_per_s"] / ray_row["env_steps_per_s"] if ray_row else None
    return out


def main(argv: list[str] | None = None) -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--paths", nargs="+", choices=PATHS, default=list(PATHS))
    parser.add_argument("--repeats", type=positive_int, default=2)
    parser.add_argument("--steps", type=positive_int, default=2000)
    parser.add_argument("--warmup", type=positive_int, default=50)
    parser.add_argument("--spin-us", type=float, default=250.0, help="the workers' spin")
    parser.add_argument(
        "--settle", type=float, default=3.0, help="seconds idle between start-up and timing"
    )
    parser.add_argument("--quick", action="store_true", help="synthetic W=2 only, 300 steps")
    parser.add_argument("--out", type=Path, default=RESULTS / "address_layout.json")
    # internal: one measurement (--run), or one fresh interpreter's worker (--serve)
    parser.add_argument("--run", choices=PATHS, help=argparse.SUPPRESS)
    parser.add_argument("--serve", help=argparse.SUPPRESS)
    parser.add_argument("--env", default=SYNTHETIC, help=argparse.SUPPRESS)
    parser.add_argument("--step-ms", type=float, default=None, help=argparse.SUPPRESS)
    parser.add_argument("--workers", type=positive_int, default=2, help=argparse.SUPPRESS)
    parser.add_argument("--worker", type=int, default=0, help=argparse.SUPPRESS)
    args = parser.parse_args(argv)
    for name in ("spin_us", "settle"):
        if not getattr(args, name) >= 0:
            parser.error(f"--{name.replace('_', '-')}={getattr(args, name)!r}: expected >= 0")
    if args.serve:
        serve(args.serve, args.env, args.worker, args.step_ms, args.spin_us * 1e-6)
        return
    if args.run:
        print(json.dumps(measure(args)), flush=True)
        return
    grid = SETTINGS[:1] if args.quick else SETTINGS
    if args.quick:
        args.steps, args.repeats = min(args.steps, 300), 1
    paths = list(args.paths)
    skipped = {}
    if same_layout_prefix() is None:
        for path in ("exec_same", "ray_same"):
            if path in paths:
                paths.remove(path)
                skipped[path] = "setarch not found"
    runs = []
    for repeat in range(args.repeats):
        for env_id, step_ms, workers in grid:
            for path in paths:
                run = run_one(path, env_id, step_ms, workers, args)
                runs.append({**run, "repeat": repeat})
                print(f"  {path:9s} {env_id} W={workers}: {run['env_steps_per_s']:.0f} env-steps/s")
    rows = summarize(runs)
    print(table(COLUMNS, rows, rule=True))
    record = {**header("address_layout", "ray", "gymnasium", "mujoco"), "settings": settings(args)}
    write_json(args.out, {**record, "skipped": skipped, "rows": rows})


if __name__ == "__main__":
    main()
