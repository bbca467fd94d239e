"""Griffe extension for the API reference: Sphinx roles in docstrings become Markdown code.

chronogym's docstrings cross-reference with Sphinx roles (``:class:`~chronogym.SimEnv```),
which Markdown would print as written. ``:role:`~a.b.C``` becomes ```C``` and
``:role:`a.b.C``` becomes ```a.b.C```; ``:role:`text <target>``` keeps the text.
"""

from __future__ import annotations

import re
from typing import Any

import griffe

_ROLE = re.compile(r":(?:class|func|meth|mod|data|attr|exc|obj):`(?P<target>[^`]+)`")


def plain_roles(text: str) -> str:
    """``text`` with every Sphinx role replaced by a Markdown code span."""

    def code(match: re.Match[str]) -> str:
        target = match.group("target")
        if "<" in target and target.endswith(">"):
            return f"`{target.split('<', 1)[0].strip()}`"
        if target.startswith("~"):
            target = target[1:].rsplit(".", 1)[-1]
        return f"`{target.lstrip('.')}`"

    return _ROLE.sub(code, text)


class SphinxRoles(griffe.Extension):
    """Rewrites the Sphinx roles of every docstring griffe loads."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None:
            obj.docstring.value = plain_roles(obj.docstring.value)
