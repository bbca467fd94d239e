"""chronogym.rl as a package: light to import, lazy public names, functions one can read."""

from __future__ import annotations

import ast
import subprocess
import sys
from pathlib import Path

import pytest

import chronogym
import chronogym.rl

RL_DIR = Path(chronogym.rl.__file__).parent
MAX_FUNCTION_LINES = 100


def test_importing_chronogym_rl_imports_neither_torch_nor_rsl_rl():
    heavy = ("torch", "rsl_rl", "ray", "mujoco")
    code = f"import sys, chronogym.rl; print(sys.modules.keys() & {set(heavy)!r})"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "set()"


def test_public_names_resolve_lazily_and_are_listed():
    pytest.importorskip("rsl_rl")
    from chronogym.rl import trainer

    assert set(chronogym.rl.__all__) <= set(dir(chronogym.rl))
    assert chronogym.rl.train is trainer.train
    assert chronogym.rl.load_policy is trainer.load_policy
    assert chronogym.rl.TrainResult is trainer.TrainResult
    for name in chronogym.rl.__all__:
        assert getattr(chronogym.rl, name) is not None, name
    assert set(chronogym.__all__) - {"__version__"} <= set(dir(chronogym))


@pytest.mark.parametrize(
    ("package", "name"), [(chronogym, "chronogym"), (chronogym.rl, "chronogym.rl")]
)
def test_an_unknown_name_raises_attribute_error_naming_the_package(package, name):
    with pytest.raises(AttributeError, match=rf"module '{name}' has no attribute 'no_such_name'"):
        package.no_such_name  # noqa: B018


def test_no_function_in_rl_is_over_100_lines():
    long = []
    for path in sorted(RL_DIR.glob("*.py")):
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, (ast.FunctionDef, ast.AsyncFunctionDef)):
                lines = node.end_lineno - node.lineno + 1
                if lines > MAX_FUNCTION_LINES:
                    long.append(f"{path.name}:{node.lineno} {node.name} ({lines} lines)")
    assert len(list(RL_DIR.glob("*.py"))) >= 8
    assert long == []
