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

    The file's folder must exist: no folder is created (FileNotFoundError names it).
    """
    import optuna

    if not isinstance(url, str) or not url:
        raise ValueError(f"storage={url!r}: expected a URL such as {DEFAULT_STORAGE!r}")
    if url.startswith("journal:"):
        path = Path(url[len("journal:") :].removeprefix("//"))
        if not path.name:
            raise ValueError(f"storage={url!r}: expected 'journal:path/to/file.log'")
        _check_folder(url, path)
        backend = optuna.storages.journal.JournalFileBackend(str(path))
        return optuna.storages.JournalStorage(backend)
    if "://" not in url:
        raise ValueError(
            f"storage={url!r}: expected 'sqlite:///file.db', 'journal:file.log' or an RDB URL"
        )
    database = _sqlite_file(url)
    if database is not None:
        _check_folder(url, database)
    return optuna.storages.RDBStorage(url)


def _sqlite_file(url: str) -> Path | None:
    """The database file of a SQLite URL; None for another database, an in-memory one or a
    ``file:`` URI (SQLite reads those itself)."""
    if not url.startswith("sqlite"):
        return None
    from sqlalchemy.engine import make_url
    from sqlalchemy.exc import ArgumentError

    try:
        parsed = make_url(url)
    except ArgumentError:  # RDBStorage reports it
        return None
    database = parsed.database
    if parsed.get_backend_name() != "sqlite" or not database or database == ":memory:":
        return None
    if database.startswith("file:"):
        return None
    return Path(database)


def _check_folder(url: str, path: Path) -> None:
    """Raise FileNotFoundError when the folder that would hold ``path`` does not exist."""
    folder = path.parent
    if folder.is_dir():
        return
    if folder.exists():
        raise FileNotFoundError(
            f"storage={url!r}: {str(folder)!r} is not a folder; "
            "expected a file in an existing folder"
        )
    raise FileNotFoundError(
        f"storage={url!r}: the folder {str(folder)!r} does not exist; create it first "
        "(chronogym creates no folders)"
    )
