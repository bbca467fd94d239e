"""The API reference on the built site: the vector envs' methods, and every public name.

One strict ``mkdocs build`` for this module (as ``test_docs_build.py`` runs it); the checks
read its HTML: each public method of ``RayVectorEnv`` and ``SerialVectorEnv``, inherited
ones included, has a heading and a signature under its class, and each name of
``chronogym.__all__`` is on some API page.
"""

from __future__ import annotations

import html
import importlib.util
import inspect
import os
import re
import subprocess
import sys
from pathlib import Path

import pytest
from docs_codeblocks import REPO

import chronogym

pytestmark = pytest.mark.skipif(
    any(
        importlib.util.find_spec(m) is None for m in ("mkdocs", "material", "mkdocstrings_handlers")
    ),
    reason="mkdocs, mkdocs-material or mkdocstrings-python is not installed "
    '(pip install -e ".[docs]")',
)

VECTOR_ENVS = ("RayVectorEnv", "SerialVectorEnv")
# The methods the issue names; the test also takes every public method of the classes.
NAMED = ("step", "reset", "send", "recv", "step_async", "step_wait", "async_reset")
NAMED += ("worker_pids", "profile_steps", "call", "get_attr", "set_attr", "close", "render")


@pytest.fixture(scope="module")
def site(tmp_path_factory: pytest.TempPathFactory) -> Path:
    """The site, built once, strictly."""
    out = tmp_path_factory.mktemp("site")
    run = subprocess.run(
        [sys.executable, "-m", "mkdocs", "build", "--strict", "--site-dir", str(out)],
        cwd=REPO,
        env={**os.environ, "NO_MKDOCS_2_WARNING": "1"},
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stdout + run.stderr
    return out


def public_methods(cls: type) -> list[str]:
    """Every public method of ``cls``, inherited ones included (properties are not methods)."""
    return sorted(
        name
        for name, value in inspect.getmembers(cls)
        if not name.startswith("_") and inspect.isfunction(value)
    )


def sections(page: str, owner: str) -> dict[str, str]:
    """The HTML of each member heading under ``owner`` (``chronogym.RayVectorEnv``), by name."""
    starts = [
        (m.start(), m.group(1)) for m in re.finditer(rf'id="{re.escape(owner)}\.(\w+)"', page)
    ]
    ends = [s for s, _ in starts[1:]] + [len(page)] * bool(starts)
    return {name: page[start:end] for (start, name), end in zip(starts, ends, strict=True)}


def text(fragment: str) -> str:
    return html.unescape(re.sub(r"<[^>]+>", "", fragment))


@pytest.mark.parametrize("name", VECTOR_ENVS)
def test_every_public_method_of_the_vector_envs_is_documented_with_its_signature(
    site: Path, name: str
) -> None:
    cls = getattr(chronogym, name)
    methods = public_methods(cls)
    assert set(NAMED) <= set(methods), sorted(set(NAMED) - set(methods))
    page = (site / "api" / "vector" / "index.html").read_text(encoding="utf-8")
    owner = f"chronogym.{name}"
    assert f'id="{owner}"' in page
    found = sections(page, owner)
    missing = [m for m in methods if m not in found]
    assert not missing, f"{owner}: no heading for {missing}"
    unsigned = []
    for method in methods:
        signature = re.search(r'class="doc-signature.*?</code>', found[method], re.S)
        if signature is None or f"{method}(" not in text(signature.group(0)).replace(" ", ""):
            unsigned.append(method)
    assert not unsigned, f"{owner}: no signature for {unsigned}"
    # The class's own signature, its parameters one row each, defaults by value.
    head = page[page.index(f'id="{owner}"') : page.index(f'id="{owner}.')]
    assert f"{name}(" in text(head) and "env_fns:" in text(head)
    if name == "RayVectorEnv":
        signature = text(re.search(r'class="doc-signature.*?</code>', head, re.S).group(0))
        assert "worker_niceness: int | None = 0," in signature, signature
        table = text(head[head.index("Parameters") :])
        assert "num_cpus, num_gpus" not in table and "WORKER_NICENESS" not in head
        assert re.search(r"num_cpus\s+float \| None", table) and re.search(
            r"num_gpus\s+float", table
        )


def test_every_public_name_is_on_an_api_page(site: Path) -> None:
    pages = [p.read_text(encoding="utf-8") for p in sorted((site / "api").rglob("*.html"))]
    assert len(pages) >= 8
    headings = {
        m.group(1) for page in pages for m in re.finditer(r'id="chronogym\.([\w.]+)"', page)
    }
    words = " ".join(text(page) for page in pages)
    missing = []
    for name in chronogym.__all__:
        if name.startswith("__"):  # __version__: named in the text
            documented = f"chronogym.{name}" in words
        else:  # a class or function: its own heading, under the root or a subpackage
            documented = any(h == name or h.endswith(f".{name}") for h in headings)
        if not documented:
            missing.append(name)
    assert not missing, f"on no API page: {missing}"
