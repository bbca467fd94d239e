"""Why a worker process died, as far as the machine recorded it: for ``info["worker_error"]``.

Ray reports every dead worker with the same words ("Worker unexpectedly exits with a
connection error code 2"), whether it was a segfault, SIGKILL or ``os._exit``. A worker that
dies of a signal Python can catch (SIGSEGV, SIGABRT, SIGBUS, SIGFPE, SIGILL) writes
``*** SIGSEGV received`` / ``Fatal Python error: ...`` into its Ray log first, so for a
worker on the driver's node that log names the signal. SIGKILL (the OOM killer, ``kill -9``)
and ``os._exit`` leave nothing: the note then says so. Ray's own text follows either way
(it names OOM kills by its memory monitor itself).
"""

from __future__ import annotations

import glob
import os
import re

SIGNAL_LINE = re.compile(r"\*\*\* (SIG[A-Z]+) received")
FATAL_LINE = re.compile(r"Fatal Python error: ([^\n]+)")
PID_FIELD = re.compile(r"\bpid: (\d+)")
#: Bytes read from the end of a dead worker's log.
LOG_TAIL = 16384


def worker_log_dir() -> str | None:
    """The Ray session's log folder on this node (None without a local Ray node)."""
    try:
        import ray

        return ray._private.worker.global_worker.node.get_logs_dir_path()
    except Exception:
        return None


def recorded_signal(pid: int, log_dir: str | None = None) -> str | None:
    """``SIGSEGV`` (or Python's fatal-error line) from worker ``pid``'s log, if it left one."""
    log_dir = log_dir or worker_log_dir()
    if log_dir is None:
        return None
    for path in glob.glob(os.path.join(log_dir, f"worker-*-{pid}.err")):
        try:
            with open(path, "rb") as log:
                log.seek(max(os.path.getsize(path) - LOG_TAIL, 0))
                tail = log.read().decode("utf-8", "replace")
        except OSError:
            continue
        found = SIGNAL_LINE.search(tail) or FATAL_LINE.search(tail)
        if found:
            return found.group(1).strip()
    return None


def describe_death(ray_text: str) -> str:
    """Ray's text of a dead worker, headed by the signal its log names, or by a line saying
    that none was recorded (and what leaves none)."""
    match = PID_FIELD.search(ray_text)
    if match is None:
        return ray_text
    pid = int(match.group(1))
    cause = recorded_signal(pid)
    if cause is not None:
        head = f"the worker process (pid {pid}) died of {cause}, as its Ray log records"
    else:
        head = (
            f"the worker process (pid {pid}) died without recording a signal in its Ray log "
            "(SIGKILL, the OOM killer and os._exit leave none; a worker on another node "
            "keeps its log there)"
        )
    return f"{head}.\n{ray_text}"
