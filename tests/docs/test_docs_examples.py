"""The ```python blocks of README.md and docs/ run as written, each in a fresh namespace.

Directives above a block (``<!-- skip: ... -->``, ``<!-- slow: ... -->``, ``<!-- requires: ...
-->``) are described in ``docs_codeblocks``. Slow blocks run with ``CHRONOGYM_DOCS_SLOW=1``.
"""

from __future__ import annotations

import importlib.util
import os
from pathlib import Path

import pytest
from docs_codeblocks import CodeBlock, all_code_blocks, code_blocks

RUN_SLOW = os.environ.get("CHRONOGYM_DOCS_SLOW") == "1"


def _param(block: CodeBlock) -> object:
    marks = [pytest.mark.slow] if "slow" in block.directives else []
    return pytest.param(block, id=block.id, marks=marks)


BLOCKS = all_code_blocks()


@pytest.mark.parametrize("block", [_param(b) for b in BLOCKS])
def test_docs_example_runs(
    block: CodeBlock, tmp_path: Path, monkeypatch: pytest.MonkeyPatch, request
) -> None:
    if "skip" in block.directives:
        pytest.skip(f"{block.id}: {block.directives['skip']}")
    if "slow" in block.directives and not RUN_SLOW:
        pytest.skip(f"{block.id}: slow ({block.directives['slow']}); CHRONOGYM_DOCS_SLOW=1 runs it")
    missing = [m for m in block.required_modules if importlib.util.find_spec(m) is None]
    if missing:
        pytest.skip(f"{block.id}: needs {', '.join(missing)}")
    if "ray" in block.code.lower():
        request.getfixturevalue("ray_cluster")  # one shared local cluster, as the other tests
    monkeypatch.chdir(tmp_path)  # files an example writes land in a fresh directory
    namespace = {"__name__": "__docs_example__"}
    exec(compile(block.code, block.id, "exec"), namespace)


def test_docs_have_runnable_examples() -> None:
    runnable = [b for b in BLOCKS if not b.directives]
    assert len(runnable) >= 5, [b.id for b in runnable]


def test_directives_are_read(tmp_path: Path) -> None:
    page = tmp_path / "page.md"
    page.write_text(
        "text\n<!-- requires: pychrono, numpy -->\n<!-- slow: minutes -->\n```python\n"
        "x = 1\n```\n\n```python\ny = 2\n```\n",
        encoding="utf-8",
    )
    first, second = code_blocks(page)
    assert first.directives == {"requires": "pychrono, numpy", "slow": "minutes"}
    assert first.required_modules == ["pychrono", "numpy"]
    assert first.code == "x = 1\n" and first.line == 4
    assert second.directives == {} and second.code == "y = 2\n"


def test_unknown_directive_is_an_error(tmp_path: Path) -> None:
    page = tmp_path / "page.md"
    page.write_text("<!-- skipp: typo -->\n```python\nx = 1\n```\n", encoding="utf-8")
    with pytest.raises(ValueError, match="'skipp'"):
        code_blocks(page)
