"""Which TCP ports a chronogym-started Ray cluster listens on, on which addresses, and by whom.

Starts Ray the way chronogym does (``RayVectorEnv`` on the cart-pole with two workers, so the
driver, the head's services and two worker actors all run), then reads Linux's socket tables
(``/proc/net/tcp``, ``/proc/net/tcp6``) and maps every listening socket to its process through
``/proc/<pid>/fd``. Prints a table (process, address, port, exposure) and writes JSON. Also
records whether Ray's token authentication is on and whether a dashboard or metrics endpoint
is up. Linux only (it reads ``/proc``).

    python -m benchmarks.vector.ray_ports [--out benchmarks/results/ray_ports.json]
"""

from __future__ import annotations

import argparse
import os
import socket
import struct
import sys
from pathlib import Path

if not __package__:  # run by path, as tests/test_security.py does: `benchmarks` is 2 folders up
    sys.path.insert(0, str(Path(__file__).resolve().parents[2]))
import chronogym
from benchmarks.common import (
    RESULTS,
    Column,
    header,
    proc_cmdline,
    proc_stat,
    table,
    versions,
    write_json,
)

DEFAULT_OUT = RESULTS / "ray_ports.json"
LISTEN = "0A"  # TCP state LISTEN in /proc/net/tcp
DASHBOARD_PORT = 8265
COLUMNS = (
    Column("process", 28, align="<", key="process"),
    Column("address", 16, align="<", key="address"),
    Column("port", 7, key="port"),
    Column("exposure", 0, align="<", key="exposure"),
)


def _address(hex_address: str, family: int) -> str:
    """``/proc/net/tcp`` address field (little-endian hex words) to text."""
    raw = bytes.fromhex(hex_address)
    if family == socket.AF_INET:
        return socket.inet_ntop(family, raw[::-1])
    words = struct.unpack("<4I", raw)
    return socket.inet_ntop(family, struct.pack(">4I", *words))


def listening_sockets() -> dict[str, tuple[str, int]]:
    """Socket inode -> (address, port) of every listening TCP socket on this host."""
    found = {}
    for name, family in (("tcp", socket.AF_INET), ("tcp6", socket.AF_INET6)):
        path = Path("/proc/net") / name
        if not path.exists():
            continue
        for line in path.read_text().splitlines()[1:]:
            fields = line.split()
            if fields[3] != LISTEN:
                continue
            address, port = fields[1].split(":")
            found[fields[9]] = (_address(address, family), int(port, 16))
    return found


def process_name(pid: int) -> str:
    """A short name: Ray's process title (``ray::...``, ``raylet``, ``gcs_server``)."""
    parts = proc_cmdline(pid)
    if parts and parts[0].startswith("ray::"):
        return parts[0].split()[0]
    for part in parts:
        base = os.path.basename(part)
        if base in ("raylet", "gcs_server") or base.endswith(".py"):
            return base
    return os.path.basename(parts[0]) if parts else "?"


def sockets_by_process(pids: set[int]) -> list[dict]:
    """Listening sockets owned by ``pids``: one row each."""
    listening = listening_sockets()
    rows = []
    for pid in sorted(pids):
        try:
            fds = os.listdir(f"/proc/{pid}/fd")
        except OSError:
            continue
        for fd in fds:
            try:
                target = os.readlink(f"/proc/{pid}/fd/{fd}")
            except OSError:
                continue
            inode = target[len("socket:[") : -1] if target.startswith("socket:[") else None
            if inode in listening:
                address, port = listening[inode]
                exposure = "loopback" if address in ("127.0.0.1", "::1") else "all interfaces"
                if address not in ("0.0.0.0", "::", "127.0.0.1", "::1"):
                    exposure = "node IP"
                rows.append(
                    {
                        "pid": pid,
                        "process": process_name(pid),
                        "address": address,
                        "port": port,
                        "exposure": exposure,
                    }
                )
    return rows


def descendants(root: int) -> set[int]:
    """``root`` and every process below it (Ray's head services are the driver's children,
    its workers the raylet's): this cluster only, not other Ray sessions on the host."""
    children: dict[int, list[int]] = {}
    for entry in os.listdir("/proc"):
        if not entry.isdigit():
            continue
        try:
            parent = int(proc_stat(entry)[1])
        except OSError:
            continue
        children.setdefault(parent, []).append(int(entry))
    found, todo = {root}, [root]
    while todo:
        for child in children.get(todo.pop(), []):
            if child not in found:
                found.add(child)
                todo.append(child)
    return found


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--out", type=Path, default=DEFAULT_OUT)
    args = parser.parse_args()
    if not Path("/proc/net/tcp").exists():
        parser.error("needs Linux's /proc/net/tcp")
    os.environ.pop("RAY_ADDRESS", None)  # a fresh local cluster, as chronogym starts it

    import ray

    vec = chronogym.RayVectorEnv("chronogym/CartPole-v0", 4, envs_per_worker=2)
    try:
        vec.reset(seed=0)
        rows = sockets_by_process(descendants(os.getpid()))
        auth_mode = os.environ.get("RAY_AUTH_MODE", "")
        context = ray.get_runtime_context()
        dashboard_up = any(row["port"] == DASHBOARD_PORT for row in rows)
        dashboard_url = getattr(context, "dashboard_url", None)
    finally:
        vec.close()
        ray.shutdown()
    print(table(COLUMNS, rows, sep=" "))
    print(f"RAY_AUTH_MODE={auth_mode!r}; dashboard on :{DASHBOARD_PORT}: {dashboard_up}")
    result = {
        **header("ray_ports"),
        **versions("ray"),  # also a top-level key, as in the committed JSON
        "auth_mode": auth_mode,
        "dashboard_listening": dashboard_up,
        "dashboard_url": dashboard_url,
        "sockets": rows,
    }
    write_json(args.out, result)


if __name__ == "__main__":
    main()
