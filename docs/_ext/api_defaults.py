"""Griffe extension for the API reference: constant defaults by value, quiet foreign docstrings.

A parameter whose default is a module constant (``worker_niceness=WORKER_NICENESS``) is shown
with the constant's value (``0``) when that value is a literal. Docstrings of Gymnasium (whose
methods ``RayVectorEnv`` and ``SerialVectorEnv`` inherit, and which the reference loads for
them) are parsed without warnings: their style is theirs, and the strict build checks ours.
"""

from __future__ import annotations

import ast
from typing import Any

import griffe

_QUIET = ("gymnasium",)


class ConstantDefaults(griffe.Extension):
    """Replaces constant names in chronogym's defaults with their literal values."""

    def on_instance(self, *, obj: griffe.Object, **kwargs: Any) -> None:
        if obj.docstring is not None and obj.path.split(".", 1)[0] in _QUIET:
            obj.docstring.parser_options = {**obj.docstring.parser_options, "warnings": False}

    def on_package(self, *, pkg: griffe.Module, **kwargs: Any) -> None:
        if pkg.name != "chronogym":
            return
        for func in _functions(pkg):
            for param in func.parameters:
                if isinstance(param.default, griffe.ExprName):
                    value = _literal(pkg, param.default)
                    if value is not None:
                        param.default = value


def _functions(obj: griffe.Object) -> list[griffe.Function]:
    """Every function and method defined under ``obj`` (aliases skipped)."""
    found = []
    for member in obj.members.values():
        if member.is_alias:
            continue
        if isinstance(member, griffe.Function):
            found.append(member)
        elif isinstance(member, (griffe.Module, griffe.Class)):
            found.extend(_functions(member))
    return found


def _literal(pkg: griffe.Module, name: griffe.ExprName) -> str | None:
    """The source of the literal value of the constant ``name`` refers to, else None."""
    try:
        target = pkg.modules_collection[name.canonical_path]
        if target.is_alias:
            target = target.final_target
    except (KeyError, griffe.AliasResolutionError, griffe.CyclicAliasError):
        return None
    if not isinstance(target, griffe.Attribute) or target.value is None:
        return None
    source = str(target.value)
    try:
        ast.literal_eval(source)
    except (ValueError, SyntaxError):
        return None
    return source
