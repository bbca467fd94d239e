"""The Python code blocks of the Markdown docs, with the directives written above them.

A block is a fenced ```` ```python ```` block. HTML comments on the lines right above its fence
direct the test that runs it:

- ``<!-- skip: reason -->``: never run (e.g. it needs a file the reader brings);
- ``<!-- slow: reason -->``: run only when ``CHRONOGYM_DOCS_SLOW=1``;
- ``<!-- requires: module, ... -->``: run only where these modules import (e.g. ``pychrono``).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

REPO = Path(__file__).resolve().parents[2]
DIRECTIVES = ("skip", "slow", "requires")

_FENCE = re.compile(r"^(?P<indent>\s*)```python\s*$")
_DIRECTIVE = re.compile(r"^\s*<!--\s*(?P<name>[a-z]+)\s*:\s*(?P<value>.*?)\s*-->\s*$")


@dataclass(frozen=True)
class CodeBlock:
    """One Python block: where it is, its code, and its directives (name -> value)."""

    path: Path
    line: int
    code: str
    directives: dict[str, str] = field(default_factory=dict)

    @property
    def id(self) -> str:
        return f"{self.path.relative_to(REPO)}:{self.line}"

    @property
    def required_modules(self) -> list[str]:
        return [m.strip() for m in self.directives.get("requires", "").split(",") if m.strip()]


def markdown_files() -> list[Path]:
    """README.md and every page under docs/, in a fixed order."""
    return [REPO / "README.md", *sorted((REPO / "docs").rglob("*.md"))]


def code_blocks(path: Path) -> list[CodeBlock]:
    """The Python blocks of one Markdown file, in order."""
    lines = path.read_text(encoding="utf-8").splitlines()
    blocks = []
    i = 0
    while i < len(lines):
        fence = _FENCE.match(lines[i])
        if fence is None:
            i += 1
            continue
        indent = fence.group("indent")
        end = i + 1
        while end < len(lines) and lines[end].strip() != "```":
            end += 1
        if end == len(lines):
            raise ValueError(f"{path}:{i + 1}: the ```python block is never closed")
        code = "\n".join(line.removeprefix(indent) for line in lines[i + 1 : end])
        blocks.append(CodeBlock(path, i + 1, code + "\n", _directives_above(path, lines, i)))
        i = end + 1
    return blocks


def _directives_above(path: Path, lines: list[str], fence: int) -> dict[str, str]:
    directives: dict[str, str] = {}
    j = fence - 1
    while j >= 0 and (match := _DIRECTIVE.match(lines[j])):
        name = match.group("name")
        if name not in DIRECTIVES:
            raise ValueError(
                f"{path}:{j + 1}: directive {name!r}: expected one of {', '.join(DIRECTIVES)}"
            )
        directives[name] = match.group("value")
        j -= 1
    return directives


def all_code_blocks() -> list[CodeBlock]:
    """Every Python block of the docs; a block repeated verbatim (README and docs) once."""
    seen: set[str] = set()
    blocks = []
    for path in markdown_files():
        for block in code_blocks(path):
            if block.code not in seen:
                seen.add(block.code)
                blocks.append(block)
    return blocks
