"""Argument checks shared across chronogym: each error names the value and what was expected.

A bad value raises ``ValueError``; a bool where a number belongs, or a non-bool where a bool
belongs, raises :class:`~chronogym.errors.BoolArgumentError` (a ``TypeError`` and a
``ValueError``), the one class every bool check uses.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from chronogym.errors import BoolArgumentError


def show(value: Any, limit: int = 80) -> str:
    """A short ``repr`` of a user's value for an error message (arrays as lists)."""
    text = repr(value.tolist() if isinstance(value, np.ndarray) else value)
    return text if len(text) <= limit else text[: limit - 3] + "..."


def is_int(value: Any) -> bool:
    """An integer (Python or NumPy), and not a bool."""
    return isinstance(value, (int, np.integer)) and not isinstance(value, (bool, np.bool_))


def is_number(value: Any) -> bool:
    """A real number (Python or NumPy), and not a bool."""
    return isinstance(value, (int, float, np.integer, np.floating)) and not isinstance(
        value, (bool, np.bool_)
    )


def is_bool(value: Any) -> bool:
    """A bool (Python or NumPy)."""
    return isinstance(value, (bool, np.bool_))


def invalid(message: str, value: Any) -> ValueError:
    """The error for a failed check of ``value``: :class:`BoolArgumentError` if it is a bool."""
    return BoolArgumentError(message) if is_bool(value) else ValueError(message)


def _bounds(name: str, low: float | None, high: float | None, kind: str) -> str:
    if low is not None and high is not None:
        return f"{kind} with {low:g} <= {name} <= {high:g}"
    if low is not None:
        return f"{kind} >= {low:g}"
    if high is not None:
        return f"{kind} <= {high:g}"
    return kind


def check_int(
    name: str,
    value: Any,
    low: int | None = None,
    high: int | None = None,
    expected: str | None = None,
) -> int:
    """``value`` as an int, if it is an integer in ``[low, high]``; else a ValueError
    (:class:`BoolArgumentError` for a bool).

    ``expected`` replaces the generated "an integer >= low" in the message.
    """
    too_low = low is not None and is_int(value) and value < low
    too_high = high is not None and is_int(value) and value > high
    if not is_int(value) or too_low or too_high:
        what = expected or _bounds(name, low, high, "an integer")
        raise invalid(f"{name}={show(value)}: expected {what}", value)
    return int(value)


def check_number(
    name: str,
    value: Any,
    low: float | None = None,
    high: float | None = None,
    expected: str | None = None,
) -> float:
    """``value`` as a float, if it is a finite number in ``[low, high]``; else a ValueError
    (:class:`BoolArgumentError` for a bool)."""
    if (
        not is_number(value)
        or not math.isfinite(value)
        or (low is not None and value < low)
        or (high is not None and value > high)
    ):
        what = expected or _bounds(name, low, high, "a finite number")
        raise invalid(f"{name}={show(value)}: expected {what}", value)
    return float(value)


def check_positive(name: str, value: Any, expected: str | None = None) -> float:
    """``value`` as a float, if it is a finite number > 0; else a ValueError
    (:class:`BoolArgumentError` for a bool)."""
    if not is_number(value) or not math.isfinite(value) or value <= 0:
        what = expected or "a finite number > 0"
        raise invalid(f"{name}={show(value)}: expected {what}", value)
    return float(value)


def check_bool(name: str, value: Any) -> bool:
    """``value`` if it is a bool; else a :class:`BoolArgumentError` (a TypeError and a
    ValueError)."""
    if not is_bool(value):
        raise BoolArgumentError(f"{name}={show(value)}: expected True or False")
    return bool(value)
