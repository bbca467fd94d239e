"""open_storage: real SQLite and journal files in tmp_path; no folder is ever created."""

from __future__ import annotations

import optuna
import pytest

from chronogym.cli import main
from chronogym.optim import open_storage


def test_sqlite_and_journal_files_in_an_existing_folder_hold_a_study(tmp_path):
    for url, path in (
        (f"sqlite:///{tmp_path}/study.db", tmp_path / "study.db"),
        (f"journal:{tmp_path}/study.log", tmp_path / "study.log"),
    ):
        study = optuna.create_study(storage=open_storage(url), study_name="s")
        study.optimize(lambda trial: trial.suggest_float("x", 0, 1), n_trials=2)
        assert path.is_file()
        assert len(optuna.load_study(study_name="s", storage=open_storage(url)).trials) == 2


@pytest.mark.parametrize("scheme", ["sqlite:///", "sqlite+pysqlite:///", "journal:"])
def test_a_missing_folder_is_named_and_not_created(tmp_path, scheme):
    folder = tmp_path / "missing" / "deeper"
    url = f"{scheme}{folder}/study.db"
    message = f"storage='{url}': the folder '{folder}' does not exist; create it first"
    with pytest.raises(FileNotFoundError, match=message.replace("+", r"\+")):
        open_storage(url)
    assert not (tmp_path / "missing").exists()


def test_a_relative_path_in_a_missing_folder_is_refused(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    with pytest.raises(FileNotFoundError, match="the folder 'runs' does not exist"):
        open_storage("sqlite:///runs/study.db")
    assert list(tmp_path.iterdir()) == []
    open_storage("sqlite:///study.db")  # the working directory itself exists
    assert (tmp_path / "study.db").is_file()


def test_a_file_where_the_folder_should_be_is_named(tmp_path):
    (tmp_path / "notes").write_text("")
    with pytest.raises(FileNotFoundError, match="'.*notes' is not a folder"):
        open_storage(f"sqlite:///{tmp_path}/notes/study.db")


def test_in_memory_sqlite_needs_no_folder():
    study = optuna.create_study(storage=open_storage("sqlite:///:memory:"))
    study.optimize(lambda trial: trial.suggest_float("x", 0, 1), n_trials=1)
    assert len(study.trials) == 1


def test_cli_optimize_names_the_missing_folder_and_creates_nothing(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("CHRONOGYM_DEBUG", raising=False)
    folder = tmp_path / "nonexistent-dir"
    with pytest.raises(SystemExit) as exit_info:
        main(["optimize", "lander", "--storage", f"sqlite:///{folder}/x.db", "--trials", "1"])
    assert f"the folder '{folder}' does not exist; create it first" in str(exit_info.value)
    assert list(tmp_path.iterdir()) == []
