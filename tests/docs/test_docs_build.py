"""The docs site builds strictly, and the docs agree with the repository they describe."""

from __future__ import annotations

import importlib.util
import json
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from docs_codeblocks import REPO, markdown_files

SETUP_COMMANDS = (  # CI (.ci/run) runs the second one verbatim
    "python3 -m venv .venv && . .venv/bin/activate && pip install -e . && chronogym demo",
    'python3 -m venv .venv && . .venv/bin/activate && pip install -e ".[test]" && pytest',
)
_LINK = re.compile(r"\]\((?P<target>[^)\s]+)\)")
_RESULTS_ROW = re.compile(
    r"^\| `(?P<file>[^`]+\.json)` \| `(?P<script>benchmarks/[^`]+\.py)` \| (?P<date>[^|]+) \| "
    r"(?P<cpus>[^|]+) \|"
)
_REPO_PATH = re.compile(r"\b(?:benchmarks|tests|src/chronogym)/[\w/]+(?:\.py|/)")


def _missing(*modules: str) -> list[str]:
    return [m for m in modules if not _installed(m)]


def _installed(module: str) -> bool:
    """Whether ``module`` can be imported (a submodule of a missing package cannot)."""
    try:
        return importlib.util.find_spec(module) is not None
    except ModuleNotFoundError:
        return False


@pytest.mark.skipif(
    bool(_missing("mkdocs", "material", "mkdocstrings_handlers.python")),
    reason="mkdocs, mkdocs-material or mkdocstrings-python is not installed "
    '(pip install -e ".[docs]")',
)
def test_mkdocs_builds_strictly(tmp_path: Path) -> None:
    env = {**os.environ, "NO_MKDOCS_2_WARNING": "1"}
    run = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(tmp_path)],
        cwd=REPO,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stdout + run.stderr
    assert (tmp_path / "api" / "core" / "index.html").is_file()
    assert "chronogym.SimEnv" in (tmp_path / "api" / "core" / "index.html").read_text()


@pytest.mark.skipif(bool(_missing("griffe")), reason="griffe comes with the docs extra")
def test_sphinx_roles_become_markdown_code() -> None:
    spec = importlib.util.spec_from_file_location(
        "sphinx_roles", REPO / "docs" / "_ext" / "sphinx_roles.py"
    )
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    text = ":class:`~chronogym.rl.TrainResult`, :mod:`.mujoco`, :func:`chronogym.make_vec`"
    assert module.plain_roles(text) == "`TrainResult`, `mujoco`, `chronogym.make_vec`"
    assert module.plain_roles(":meth:`the step <chronogym.SimEnv.step>`") == "`the step`"


def test_readme_is_short_and_keeps_the_setup_commands() -> None:
    readme = (REPO / "README.md").read_text(encoding="utf-8").splitlines()
    assert len(readme) <= 250, f"README.md has {len(readme)} lines (at most 250)"
    for command in SETUP_COMMANDS:
        assert command in readme, f"README.md lost the set-up line: {command}"


def test_relative_links_point_to_files() -> None:
    pages = [*markdown_files(), REPO / "benchmarks" / "README.md", REPO / "CHANGELOG.md"]
    broken = []
    for page in pages:
        for match in _LINK.finditer(page.read_text(encoding="utf-8")):
            target = match.group("target").split("#", 1)[0]
            if not target or re.match(r"^[a-z]+:", target):
                continue  # an anchor on the same page, or a URL
            if not (page.parent / target).exists():
                broken.append(f"{page.relative_to(REPO)} -> {match.group('target')}")
    assert not broken, broken


def test_files_named_in_the_docs_exist() -> None:
    named = {
        path
        for page in [*markdown_files(), REPO / "benchmarks" / "README.md"]
        for path in _REPO_PATH.findall(page.read_text(encoding="utf-8"))
    }
    assert "benchmarks/vector/throughput.py" in named
    assert sorted(p for p in named if not (REPO / p).exists()) == []


def test_benchmark_index_lists_every_script() -> None:
    index = (REPO / "benchmarks" / "README.md").read_text(encoding="utf-8")
    scripts = sorted((REPO / "benchmarks").glob("*/*.py"))
    assert scripts
    unlisted = [s.relative_to(REPO / "benchmarks").as_posix() for s in scripts]
    unlisted = [s for s in unlisted if s.split("/", 1)[1] not in index]
    assert not unlisted, f"benchmarks/README.md does not list {unlisted}"


def test_results_table_matches_the_committed_json() -> None:
    page = (REPO / "docs" / "performance" / "index.md").read_text(encoding="utf-8")
    rows = {m.group("file"): m for line in page.splitlines() if (m := _RESULTS_ROW.match(line))}
    results = REPO / "benchmarks" / "results"
    committed = {p.relative_to(results).as_posix() for p in results.rglob("*.json")}
    assert sorted(committed - set(rows)) == [], "results files missing from the table"
    for name, row in rows.items():
        assert name in committed, f"the table names {name}, which is not in benchmarks/results"
        assert (REPO / row.group("script")).is_file(), row.group("script")
        data = json.loads((results / name).read_text(encoding="utf-8"))
        machine = data.get("machine", {})
        date = (machine.get("date") or data.get("date") or "")[:10]
        assert row.group("date").strip() == date, name
        assert row.group("cpus").strip() == str(machine.get("cpus", machine.get("cpu_count"))), name
