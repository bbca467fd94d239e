"""Optuna storage from a URL: SQLite by default, JournalStorage or any RDB URL."""

from __future__ import annotations

from pathlib import Path
from typing import Any

DEFAULT_STORAGE = "sqlite:///chronogym-optuna.db"


def open_storage(url: str) -> Any:
    """Return an Optuna storage for ``url``.

    * ``sqlite:///path.db`` (default) — one file, one driver process writing to it;
    * ``journal:path.log`` — Optuna's JournalStorage on a file, safe for several
      processes (e.g. drivers on a shared filesystem);
    * any other SQLAlchemy URL (``postgresql://…``, ``mysql://…``) — an RDB server for
      cluster use.
    """
    import optuna

    if not isinstance(url, str) or not url:
        raise ValueError(f"storage={url!r}: expected a URL such as {DEFAULT_STORAGE!r}")
    if url.startswith("journal:"):
        path = Path(url[len("journal:") :].removeprefix("//"))
        if not path.name:
            raise ValueError(f"storage={url!r}: expected 'journal:path/to/file.log'")
        path.parent.mkdir(parents=True, exist_ok=True)
        backend = optuna.storages.journal.JournalFileBackend(str(path))
        return optuna.storages.JournalStorage(backend)
    if "://" not in url:
        raise ValueError(
            f"storage={url!r}: expected 'sqlite:///file.db', 'journal:file.log' or an RDB URL"
        )
    if url.startswith("sqlite:///"):
        Path(url[len("sqlite:///") :]).parent.mkdir(parents=True, exist_ok=True)
    return optuna.storages.RDBStorage(url)
