"""What the benchmark scripts share: the JSON header and machine record, writing the JSON,
aligned text tables, PNG figures, reading ``/proc`` (CPU time, process tables), and the
argparse types of positive and non-negative numbers.

Not a script: the scripts are modules of the ``benchmarks`` package, run from the repository
root as ``python -m benchmarks.<folder>.<script>``, and import this as ``benchmarks.common``.

Every JSON result starts with :func:`header`::

    {"benchmark": <name>, "date": <UTC, ISO 8601>, "machine": {...}, <the script's keys>}

and the machine record (:func:`machine`) holds the CPU count (``cpus``; ``cpu_count`` too, the
name older ``throughput.py`` records used), the CPUs this process may use, the load average
when the run started, platform, processor, the Python version and the versions of chronogym,
NumPy, MuJoCo, Gymnasium and Ray (plus the packages a script names; ``None`` where one is not
installed), and the date again (older ``throughput.py``, ``chaos.py`` and ``multinode.py``
records had it there).
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import platform
import subprocess
import sys
import time
from collections.abc import Callable, Iterable, Mapping, Sequence
from dataclasses import dataclass
from importlib import metadata
from pathlib import Path
from typing import Any

#: Where the committed results live (``benchmarks/results``).
RESULTS = Path(__file__).resolve().parent / "results"
#: The repository root: the folder that holds the ``benchmarks`` package.
REPO = Path(__file__).resolve().parents[1]
#: Packages whose versions every machine record holds.
PACKAGES = ("chronogym", "numpy", "mujoco", "gymnasium", "ray")


def child_env(**extra: str) -> dict[str, str]:
    """``os.environ`` plus ``extra``, with :data:`REPO` first on ``PYTHONPATH``: a child Python
    process (``python -m benchmarks...`` or ``-c``) imports ``benchmarks`` from any folder."""
    paths = [str(REPO), *filter(None, os.environ.get("PYTHONPATH", "").split(os.pathsep))]
    return {**os.environ, **extra, "PYTHONPATH": os.pathsep.join(paths)}


# -- JSON header and machine record ---------------------------------------------------------


def utc_now() -> str:
    """The current UTC time, ISO 8601 to the second."""
    return datetime.datetime.now(datetime.timezone.utc).isoformat(timespec="seconds")


def version(name: str) -> str | None:
    """Installed version of package ``name``: its metadata, else the ``__version__`` of an
    already imported module of that name (a conda PyChrono has no metadata), else ``None``."""
    try:
        return metadata.version(name)
    except metadata.PackageNotFoundError:
        module = sys.modules.get(name)
        found = getattr(module, "__version__", None) if module is not None else None
        return str(found) if found is not None else None


def versions(*names: str) -> dict[str, str | None]:
    """``{name: version(name)}`` for each name."""
    return {name: version(name) for name in names}


def usable_cpus() -> int:
    """CPUs this process may use (the affinity mask where the OS has one)."""
    if hasattr(os, "sched_getaffinity"):
        return len(os.sched_getaffinity(0))
    return os.cpu_count() or 1


def machine(*packages: str, date: str | None = None) -> dict[str, Any]:
    """Where and when a benchmark ran: CPUs, load, platform, Python and package versions
    (:data:`PACKAGES` and ``packages``)."""
    cpus = os.cpu_count()
    load = [round(x, 2) for x in os.getloadavg()] if hasattr(os, "getloadavg") else None
    return {
        "cpus": cpus,
        "cpu_count": cpus,
        "usable_cpus": usable_cpus(),
        "load_average": load,  # 1, 5 and 15 min, when the record was made
        "platform": platform.platform(),
        "processor": platform.processor() or platform.machine(),
        "python": platform.python_version(),
        **versions(*dict.fromkeys((*PACKAGES, *packages))),
        "date": date or utc_now(),
    }


def header(benchmark: str, *packages: str) -> dict[str, Any]:
    """The first keys of every result: ``benchmark``, ``date`` and ``machine`` (with the
    versions of ``packages`` besides :data:`PACKAGES`)."""
    date = utc_now()
    return {"benchmark": benchmark, "date": date, "machine": machine(*packages, date=date)}


def settings(args: argparse.Namespace) -> dict[str, Any]:
    """The command-line options as JSON values (paths as text)."""
    return {k: (str(v) if isinstance(v, Path) else v) for k, v in vars(args).items()}


def write_json(path: Path, record: dict[str, Any], note: str = "") -> None:
    """Write ``record`` to ``path`` (folders created) and print ``wrote <path><note>``."""
    path.parent.mkdir(parents=True, exist_ok=True)
    path.write_text(json.dumps(record, indent=2, default=str) + "\n")
    print(f"wrote {path}{note}")


# -- tables ---------------------------------------------------------------------------------


@dataclass(frozen=True)
class Column:
    """One column of a text table: its header, width, cell format and alignment, and where a
    row that is not a list or tuple keeps the cell (``key``: a mapping's key or an attribute)."""

    name: str
    width: int
    fmt: str = "{}"
    align: str = ">"
    key: str | None = None

    def cell(self, value: Any, missing: str) -> str:
        return missing if value is None else self.fmt.format(value)


def _values(columns: Sequence[Column], row: Any) -> Sequence[Any]:
    """A row's cells: the row itself (list or tuple), else each column's key of it."""
    if isinstance(row, (list, tuple)):
        return row
    if isinstance(row, Mapping):
        return [row[c.key] for c in columns if c.key is not None]
    return [getattr(row, c.key) for c in columns if c.key is not None]


def table(
    columns: Sequence[Column],
    rows: Iterable[Any],
    sep: str = "  ",
    rule: bool = False,
    missing: str = "-",
) -> str:
    """Aligned text table: a header, a rule under it if ``rule``, one line per row.

    A row is a list or tuple of cells in column order, or a mapping or object whose cells
    the columns' ``key`` name; ``None`` cells print as ``missing``, and a ``None`` row is a
    blank line (between groups).
    """

    def line(cells: Iterable[str]) -> str:
        return sep.join(
            f"{cell:{c.align}{c.width}}" for c, cell in zip(columns, cells, strict=True)
        ).rstrip()

    head = line(c.name for c in columns)
    lines = [head, "-" * len(head)] if rule else [head]
    for row in rows:
        if row is None:
            lines.append("")
            continue
        values = _values(columns, row)
        lines.append(line(c.cell(v, missing) for c, v in zip(columns, values, strict=True)))
    return "\n".join(lines)


# -- figures --------------------------------------------------------------------------------


def pyplot() -> Any:
    """``matplotlib.pyplot`` on the Agg backend (files only; ImportError without matplotlib)."""
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    return plt


def save_figure(fig: Any, path: Path, dpi: int = 110) -> None:
    """Lay out, save as PNG and close ``fig``."""
    import matplotlib.pyplot as plt

    fig.tight_layout()
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=dpi)
    plt.close(fig)


def error_text(error: BaseException) -> str:
    """``Type: message`` of an exception, for a table's note or a failure record."""
    return f"{type(error).__name__}: {error}".strip()


def finish(
    path: Path, record: dict[str, Any], plot: Callable[[Path], None] | None, failures: list
) -> int:
    """The run's end: print its failures, write ``record`` (with its ``seconds_in_all``) and,
    if ``plot``, the PNG beside it (a figure that fails is a printed note, not the run's
    failure); the exit status, 1 if anything failed."""
    for failure in failures:
        print(f"FAILED {failure['setting']}: {failure['error']}")
    write_json(path, record, f" ({record['seconds_in_all']:.0f} s in all)")
    if plot is not None:
        try:
            plot(path.with_suffix(".png"))
        except Exception as error:
            print(f"no figure: {error_text(error)}")
    return 1 if failures else 0


# -- /proc (Linux) --------------------------------------------------------------------------


def proc_stat(pid: int | str) -> list[str]:
    """Fields of ``/proc/<pid>/stat`` after the command name: ``[state, ppid, ...]``."""
    return Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()


def proc_cmdline(pid: int) -> list[str]:
    """The command line of ``pid`` (Ray actors rename themselves ``ray::Class.method``);
    empty if the process is gone or unreadable."""
    try:
        raw = Path(f"/proc/{pid}/cmdline").read_bytes()
    except OSError:
        return []
    return [part.decode(errors="replace") for part in raw.split(b"\0") if part]


def proc_cpu_s(pid: int) -> float:
    """CPU seconds (user + system) process ``pid`` used so far."""
    fields = proc_stat(pid)
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


def proc_threads(pid: int) -> dict[str, tuple[int, int]]:
    """Per thread name of process ``pid`` (its first thread named ``"main"``, threads of one
    name summed): (context switches so far, voluntary and not, CPU ns so far). Each switch is
    a wake-up of the thread or a preemption. Empty if the process is gone."""
    threads: dict[str, tuple[int, int]] = {}
    try:
        tasks = list(Path(f"/proc/{pid}/task").iterdir())
    except FileNotFoundError:
        return threads
    for task in tasks:
        try:
            name = "main" if task.name == str(pid) else (task / "comm").read_text().strip()
            switches = sum(
                int(line.split(":")[1])
                for line in (task / "status").read_text().splitlines()
                if line.endswith("ctxt_switches", 0, line.find(":"))
            )
            cpu_ns = int((task / "schedstat").read_text().split()[0])
        except (FileNotFoundError, ProcessLookupError):
            continue  # a thread that ended meanwhile
        before = threads.get(name, (0, 0))
        threads[name] = (before[0] + switches, before[1] + cpu_ns)
    return threads


def cpu_percent(pids: list[int], run: Callable[[], Any]) -> dict[str, float]:
    """% of one core the ``pids`` (summed) and this process used while ``run()`` ran."""
    before = [proc_cpu_s(pid) for pid in pids]
    driver, start = time.process_time(), time.perf_counter()
    run()
    wall = time.perf_counter() - start
    used = sum(proc_cpu_s(pid) for pid in pids) - sum(before)
    return {
        "workers": 100 * used / wall,
        "driver": 100 * (time.process_time() - driver) / wall,
    }


# -- argparse types ---------------------------------------------------------------------------


def positive_int(text: str) -> int:
    """An argparse type: an integer >= 1."""
    value = int(text)
    if value < 1:
        raise argparse.ArgumentTypeError(f"{text!r}: expected an integer >= 1")
    return value


def non_negative_int(text: str) -> int:
    """An argparse type: an integer >= 0."""
    value = int(text)
    if value < 0:
        raise argparse.ArgumentTypeError(f"{text!r}: expected an integer >= 0")
    return value


def positive_float(text: str) -> float:
    """An argparse type: a number > 0."""
    value = float(text)
    if not value > 0:
        raise argparse.ArgumentTypeError(f"{text!r}: expected a number > 0")
    return value


def json_object(text: str) -> dict[str, Any]:
    """An argparse type: a JSON object (keyword arguments), e.g. ``'{"step_ms": 10}'``."""
    try:
        value = json.loads(text)
    except json.JSONDecodeError as error:
        raise argparse.ArgumentTypeError(f"{text!r}: not JSON ({error})") from error
    if not isinstance(value, dict):
        raise argparse.ArgumentTypeError(f"{text!r}: expected a JSON object, e.g. '{{}}'")
    return value


# -- git revisions ------------------------------------------------------------------------


def checkout(rev: str, into: Path) -> Path:
    """``rev``'s tree in ``into`` (a detached git worktree of this repository); its ``src``
    folder, for a subprocess's ``PYTHONPATH``."""
    subprocess.run(
        ["git", "-C", str(REPO), "worktree", "add", "--detach", str(into), rev],
        check=True,
        capture_output=True,
    )
    return into / "src"


def revision(rev: str) -> str:
    """The full commit of git revision ``rev`` of this repository; a ValueError names a
    revision git does not know."""
    done = subprocess.run(
        ["git", "-C", str(REPO), "rev-parse", "--verify", "--quiet", f"{rev}^{{commit}}"],
        capture_output=True,
        text=True,
    )
    if done.returncode != 0:
        raise ValueError(f"{rev!r}: not a commit of this repository (git rev-parse)")
    return done.stdout.strip()


def remove_checkout(into: Path) -> None:
    """Remove the worktree that :func:`checkout` made in ``into`` (quietly if it is gone)."""
    remove = ["git", "-C", str(REPO), "worktree", "remove", "--force", str(into)]
    subprocess.run(remove, capture_output=True)
