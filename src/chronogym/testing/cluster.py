"""A real multi-node Ray cluster on this machine, for tests and benchmarks.

:class:`LocalCluster` starts a head and ``workers`` worker nodes with
``ray start --block`` (one subprocess per node, all on loopback), waits until
every node is alive and stops exactly the processes it started: it never runs
``ray stop``, which would stop every Ray on the host. Each cluster gets its own
temporary directory (one sub-directory per node: nodes
started at once in one directory race for the same socket names), its own
ports and its own authentication token (passed to
the nodes and to the driver as ``RAY_AUTH_TOKEN`` with ``RAY_AUTH_MODE=token``),
so it can run beside another Ray on the same machine.

Each node carries a custom resource named after it (``{"node_0": 1}`` for the
head, ``node_1``, ``node_2`` ... for the workers).

This is a test and benchmark utility, not a way to run production clusters.
Nothing here imports Ray until a cluster is started.
"""

from __future__ import annotations

import contextlib
import json
import os
import secrets
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from chronogym.ray_runtime import WORKER_NICENESS, worker_niceness_env
from chronogym.validation import check_int

#: Ports each node needs besides the head's GCS port; all are picked free on loopback.
NODE_PORT_FLAGS = (
    "--node-manager-port",
    "--object-manager-port",
    "--dashboard-agent-listen-port",
    "--dashboard-agent-grpc-port",
    "--runtime-env-agent-port",
    "--metrics-export-port",
)


#: How often :meth:`LocalCluster.start` retries with fresh ports after a port clash.
PORT_RETRIES = 2
#: What ``ray start`` logs when a port it was given is taken.
PORT_CLASH_SIGNS = ("used by other components", "Address already in use", "Failed to bind")


class NodeStartError(RuntimeError):
    """A node's ``ray start`` exited during start-up; ``port_clash`` says whether a port
    it was given was taken (worth a retry with fresh ports)."""

    def __init__(self, message: str, port_clash: bool = False) -> None:
        super().__init__(message)
        self.port_clash = port_clash


def free_port() -> int:
    """A TCP port that nothing listens on right now (loopback)."""
    return free_ports(1)[0]


def free_ports(count: int, exclude: set[int] | frozenset[int] = frozenset()) -> list[int]:
    """``count`` distinct loopback ports that nothing listens on now, none in ``exclude``.

    The probe sockets stay bound until all are picked, so the kernel cannot hand the same
    port out twice (two separate :func:`free_port` calls can, and Ray then refuses to start
    with "port ... is used by other components").
    """
    check_int("count", count, 0)
    held: list[socket.socket] = []
    ports: list[int] = []
    try:
        while len(ports) < count:
            sock = socket.socket(socket.AF_INET, socket.SOCK_STREAM)
            held.append(sock)
            sock.bind(("127.0.0.1", 0))
            port = int(sock.getsockname()[1])
            if port not in exclude:
                ports.append(port)
    finally:
        for sock in held:
            sock.close()
    return ports


def ray_executable() -> str:
    """The ``ray`` CLI of this Python environment; FileNotFoundError when absent."""
    candidate = Path(sys.executable).with_name("ray")
    if candidate.is_file():
        return str(candidate)
    found = shutil.which("ray")
    if found is None:
        raise FileNotFoundError(
            f"no `ray` executable beside {sys.executable} or on PATH; expected Ray's CLI "
            "(pip install ray)"
        )
    return found


def _children_map() -> dict[int, list[int]]:
    """Parent pid -> child pids of every process, from /proc."""
    children: dict[int, list[int]] = {}
    for entry in os.scandir("/proc"):
        if not entry.name.isdigit():
            continue
        try:
            stat = Path(entry.path, "stat").read_text()
        except OSError:  # exited meanwhile
            continue
        ppid = int(stat.rsplit(")", 1)[1].split()[1])
        children.setdefault(ppid, []).append(int(entry.name))
    return children


def descendants(pid: int) -> list[int]:
    """``pid`` and every process below it (children, grandchildren, ...)."""
    children = _children_map()
    found, queue = [], [pid]
    while queue:
        current = queue.pop()
        found.append(current)
        queue.extend(children.get(current, []))
    return found


def _alive(pid: int) -> bool:
    try:
        os.kill(pid, 0)
    except ProcessLookupError:
        return False
    except PermissionError:
        return True
    return True


def refresh_ray_auth() -> None:
    """Make an imported Ray re-read ``RAY_AUTH_MODE`` / ``RAY_AUTH_TOKEN``.

    Ray caches both per process (the token loader keeps the first token it
    found, e.g. ``~/.ray/auth_token`` of an earlier local ``ray.init``); this
    does what Ray itself does when it turns token auth on.
    """
    if "ray" not in sys.modules:
        return
    from ray._raylet import AuthenticationTokenLoader, Config

    Config.initialize("")
    AuthenticationTokenLoader.instance().reset_cache()


def _set_env(values: dict[str, str | None]) -> None:
    for key, value in values.items():
        if value is None:
            os.environ.pop(key, None)
        else:
            os.environ[key] = value
    refresh_ray_auth()


@dataclass
class NodeProcess:
    """One node: the ``ray start --block`` process that owns its Ray daemons."""

    name: str
    process: subprocess.Popen
    log_path: Path
    node_id: str | None = None

    def pids(self) -> list[int]:
        """The node's processes now: ``ray start``, its daemons and their workers."""
        if self.process.poll() is not None:
            return []
        return descendants(self.process.pid)


@dataclass
class LocalCluster:
    """A head plus ``workers`` worker nodes started with ``ray start`` on loopback.

    Use it as a context manager::

        with LocalCluster(workers=2) as cluster:
            cluster.connect()                      # ray.init(address=cluster.address)
            vec = RayVectorEnv(..., address=cluster.address, scheduling="spread")

    Args:
        workers: worker nodes besides the head (>= 0).
        num_cpus: CPUs each node advertises (the head included).
        head_cpus: CPUs of the head (default ``num_cpus``); 0 keeps work off it.
        object_store_mb: object store of each node, MiB (Ray's minimum is 75).
        start_timeout: seconds to wait for all nodes to be alive.
    """

    workers: int = 2
    num_cpus: int = 1
    head_cpus: int | None = None
    object_store_mb: int = 100
    start_timeout: float = 60.0
    nodes: list[NodeProcess] = field(default_factory=list, init=False)
    temp_dir: Path | None = field(default=None, init=False)
    port: int | None = field(default=None, init=False)
    token: str = field(default_factory=lambda: secrets.token_hex(32), init=False, repr=False)
    _saved_env: dict[str, str | None] = field(default_factory=dict, init=False, repr=False)
    _ports_used: set[int] = field(default_factory=set, init=False, repr=False)

    def __post_init__(self) -> None:
        for name in ("workers", "num_cpus", "object_store_mb"):
            check_int(name, getattr(self, name), 0)
        if self.head_cpus is not None:
            check_int("head_cpus", self.head_cpus, 0, expected="None or an integer >= 0")
        if self.object_store_mb < 75:
            raise ValueError(
                f"object_store_mb={self.object_store_mb}: expected >= 75 (Ray's minimum)"
            )

    # -- addresses and environment ------------------------------------------------------
    @property
    def address(self) -> str:
        """``127.0.0.1:<port>``: what ``ray.init(address=...)`` and ``--address`` take."""
        if self.port is None:
            raise RuntimeError("the cluster is not started; call start() first")
        return f"127.0.0.1:{self.port}"

    def env(self) -> dict[str, str]:
        """Environment variables a process needs to join: the auth mode and this cluster's
        token (no ``RAY_ADDRESS``: pass the address explicitly)."""
        return {"RAY_AUTH_MODE": "token", "RAY_AUTH_TOKEN": self.token}

    def node_names(self) -> list[str]:
        """``node_0`` (the head), ``node_1``, ...: also each node's custom resource."""
        return [node.name for node in self.nodes]

    # -- life cycle -------------------------------------------------------------------
    def start(self) -> LocalCluster:
        """Start the head, then the worker nodes; return once every node is alive.

        A node that exits because a port picked for it was taken meanwhile (another
        process can bind it between the pick and ``ray start``) is retried with fresh
        ports, up to ``PORT_RETRIES`` times; any other failure raises at once.
        """
        if self.nodes:
            raise RuntimeError("the cluster is already started")
        for attempt in range(PORT_RETRIES + 1):
            try:
                return self._start_once()
            except NodeStartError as error:
                if not error.port_clash or attempt == PORT_RETRIES:
                    raise
        raise AssertionError("unreachable")

    def _start_once(self) -> LocalCluster:
        self.temp_dir = Path(tempfile.mkdtemp(prefix="cgray-", dir="/tmp"))
        self._ports_used = set()
        self.port = self._fresh_ports(1)[0]
        try:
            head_cpus = self.num_cpus if self.head_cpus is None else self.head_cpus
            self._launch("node_0", head_cpus, head=True)
            self._wait_gcs()  # worker nodes can join as soon as the GCS answers
            for k in range(1, self.workers + 1):
                self._launch(f"node_{k}", self.num_cpus, head=False)
            self._wait_alive(1 + self.workers)
        except NodeStartError as error:
            self.stop(keep_logs=not error.port_clash)
            raise
        except BaseException:
            self.stop(keep_logs=True)
            raise
        return self

    def _launch(self, name: str, num_cpus: int, head: bool) -> None:
        assert self.temp_dir is not None
        args = [
            ray_executable(),
            "start",
            "--block",
            "--node-ip-address=127.0.0.1",
            f"--num-cpus={num_cpus}",
            "--num-gpus=0",
            f"--resources={json.dumps({name: 1})}",
            f"--object-store-memory={self.object_store_mb * 1024 * 1024}",
            f"--temp-dir={self.temp_dir / name}",
            "--min-worker-port=0",
            "--max-worker-port=0",
            "--disable-usage-stats",
        ]
        ports = self._fresh_ports(len(NODE_PORT_FLAGS) + 1)
        args += [f"{flag}={port}" for flag, port in zip(NODE_PORT_FLAGS, ports, strict=False)]
        if head:
            args += [
                "--head",
                f"--port={self.port}",
                "--include-dashboard=false",
                f"--ray-client-server-port={ports[-1]}",
            ]
        else:
            args += [f"--address={self.address}", "--include-log-monitor=false"]
        log_path = self.temp_dir / f"{name}.log"
        env = {**os.environ, **self.env(), **worker_niceness_env(WORKER_NICENESS)}
        env.pop("RAY_ADDRESS", None)
        with log_path.open("wb") as log:
            process = subprocess.Popen(
                args, stdout=log, stderr=subprocess.STDOUT, env=env, start_new_session=True
            )
        self.nodes.append(NodeProcess(name, process, log_path))

    def _fresh_ports(self, count: int) -> list[int]:
        """``count`` free ports that no node of this cluster was given before."""
        ports = free_ports(count, exclude=self._ports_used)
        self._ports_used.update(ports)
        return ports

    def _wait_gcs(self) -> None:
        """Wait until the head's GCS port accepts connections."""
        deadline = time.monotonic() + self.start_timeout
        while True:
            self._check_running()
            try:
                with socket.create_connection(("127.0.0.1", self.port), timeout=1.0):
                    return
            except OSError:
                if time.monotonic() > deadline:
                    raise TimeoutError(
                        f"the head's GCS at {self.address} did not answer within "
                        f"{self.start_timeout} s; logs under {self.temp_dir}"
                    ) from None
                time.sleep(0.1)

    def _check_running(self) -> None:
        """Raise with the log tail when a node's ``ray start`` has exited."""
        for node in self.nodes:
            if node.process.poll() is not None:
                log = node.log_path.read_text()
                raise NodeStartError(
                    f"`ray start` for {node.name} exited with code "
                    f"{node.process.returncode}; log {node.log_path}:\n{log[-3000:]}",
                    port_clash=any(sign in log for sign in PORT_CLASH_SIGNS),
                )

    def _wait_alive(self, count: int) -> None:
        """Wait until ``count`` nodes are registered alive with the head's GCS."""
        deadline = time.monotonic() + self.start_timeout
        while True:
            self._check_running()
            alive = self._alive_nodes()
            if len(alive) >= count:
                for node in self.nodes:
                    node.node_id = alive.get(node.name, node.node_id)
                return
            if time.monotonic() > deadline:
                raise TimeoutError(
                    f"{len(alive)} of {count} Ray nodes alive after {self.start_timeout} s; "
                    f"logs under {self.temp_dir}"
                )
            time.sleep(0.25)

    def _alive_nodes(self) -> dict[str, str]:
        """Alive nodes as {custom resource name: node id}, asked from the GCS directly."""
        try:
            with self.driver_env():
                from ray._private.state import GlobalState
                from ray._raylet import GcsClientOptions

                state = GlobalState()
                options = GcsClientOptions.create(self.address, None, True, False)
                state._initialize_global_state(options)
                nodes = state.node_table()
                state.disconnect()
        except Exception:  # the GCS is not up yet
            return {}
        return {
            name: node["NodeID"]
            for node in nodes
            if node.get("Alive")
            for name in node.get("Resources", {})
            if name.startswith("node_")
        }

    @contextlib.contextmanager
    def driver_env(self) -> Iterator[None]:
        """Set this cluster's auth variables in ``os.environ`` for the block's duration."""
        saved = {key: os.environ.get(key) for key in self.env()}
        _set_env(dict(self.env()))
        try:
            yield
        finally:
            _set_env(saved)

    def connect(self, **init_kwargs: Any) -> Any:
        """``ray.init`` this process to the cluster (auth variables set); return ``ray``."""
        import ray

        for key in self.env():
            self._saved_env.setdefault(key, os.environ.get(key))
        _set_env(dict(self.env()))
        init_kwargs.setdefault("log_to_driver", False)
        ray.init(address=self.address, **init_kwargs)
        return ray

    def disconnect(self) -> None:
        """``ray.shutdown`` this process's connection and restore its environment."""
        import ray

        ray.shutdown()
        _set_env(self._saved_env)
        self._saved_env.clear()

    def node_of_pid(self, pid: int) -> str | None:
        """Name of the node whose processes include ``pid`` (e.g. a Ray actor's), or None."""
        for node in self.nodes:
            if pid in node.pids():
                return node.name
        return None

    def kill_node(self, name: str) -> list[int]:
        """SIGKILL every process of worker node ``name`` (its raylet, agents, actors).

        The head cannot be killed this way: without it there is no cluster.
        Returns the pids killed.
        """
        node = self._node(name)
        if node is self.nodes[0]:
            raise ValueError(f"name={name!r} is the head; expected a worker node name")
        pids = node.pids()
        for pid in reversed(pids):
            with contextlib.suppress(ProcessLookupError):
                os.kill(pid, signal.SIGKILL)
        node.process.wait(timeout=10)
        return pids

    def _node(self, name: str) -> NodeProcess:
        for node in self.nodes:
            if node.name == name:
                return node
        raise ValueError(f"name={name!r}: expected one of {self.node_names()}")

    def stop(self, timeout: float = 15.0, keep_logs: bool = False) -> None:
        """Stop the nodes (workers first, then the head) and remove the temp dir
        (unless ``keep_logs``: a failed start keeps it for its logs).

        Only processes started by this cluster are signalled: SIGTERM to each
        ``ray start --block``, which stops its daemons; whatever is left of them
        after ``timeout`` s gets SIGKILL.
        """
        if self._saved_env:
            with contextlib.suppress(Exception):
                self.disconnect()
        for node in reversed(self.nodes):
            self._stop_node(node, timeout)
        self.nodes = []
        if self.temp_dir is not None and not keep_logs:
            shutil.rmtree(self.temp_dir, ignore_errors=True)
            self.temp_dir = None

    @staticmethod
    def _stop_node(node: NodeProcess, timeout: float) -> None:
        pids = node.pids()
        if node.process.poll() is None:
            node.process.send_signal(signal.SIGTERM)
            with contextlib.suppress(subprocess.TimeoutExpired):
                node.process.wait(timeout=timeout)
        for pid in pids:
            if _alive(pid):
                with contextlib.suppress(ProcessLookupError):
                    os.kill(pid, signal.SIGKILL)
        with contextlib.suppress(subprocess.TimeoutExpired):
            node.process.wait(timeout=5)

    def __enter__(self) -> LocalCluster:
        return self.start()

    def __exit__(self, *exc: object) -> None:
        self.stop()


def ray_start_available() -> str | None:
    """None when ``ray start`` can be used here, else the reason it cannot."""
    if not sys.platform.startswith("linux"):
        return f"LocalCluster needs Linux (/proc); this is {sys.platform}"
    try:
        ray_executable()
    except FileNotFoundError as error:
        return str(error)
    return None
