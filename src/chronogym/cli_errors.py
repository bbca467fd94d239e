"""How the ``chronogym`` command reports a failure: a user error in a line or two, a bug in full.

A *user error* is input that the user can correct. It ends the command with
``SystemExit("chronogym COMMAND PROBLEM: what was wrong and what was expected")`` (exit
status 1, no traceback), plus a second line saying how to see the traceback when the
message comes from an exception. These count as user errors:

* :class:`UsageError`: the command line's own checks (a file that is not a checkpoint, an
  Optuna storage URL that does not open, options that contradict each other);
* ``ValueError`` and ``OSError`` (``FileNotFoundError``, ``ConnectionError``, ...) raised
  by chronogym's own code, whose argument checks name the value and what was expected;
  the same classes raised inside NumPy, torch, Ray or the standard library are bugs;
* an ``OSError`` naming a file (``PermissionError: ... '/root/runs'``), from anywhere;
* ``ModuleNotFoundError``, from anywhere: a package this command needs is not installed;
* Gymnasium's errors about ids, render modes and dependencies (``UnregisteredEnv`` and its
  subclasses, ``DeprecatedEnv``, ``UnsupportedMode``, ``DependencyNotInstalled``).

Argument parsing rejects the rest of the bad input before a command runs
(:mod:`chronogym.cli_parser`, exit status 2). Every other exception (``TypeError``,
``KeyError``, ``RuntimeError``, a Ray task error, ...) is a programming error and keeps
Python's traceback. ``--debug`` or ``CHRONOGYM_DEBUG=1`` shows the traceback of user
errors too. Ctrl-C ends the command with one line and exit status 130.
"""

from __future__ import annotations

import os
import sys
from collections.abc import Callable
from pathlib import Path
from typing import Any

PACKAGE_DIR = Path(__file__).resolve().parent
DEBUG_HINT = "(--debug or CHRONOGYM_DEBUG=1 shows the traceback)"
INTERRUPTED_STATUS = 130  # the shell's status for a command ended by SIGINT


class UsageError(Exception):
    """Input the command line rejects; its message names the value and what was expected."""


def debug_requested(args: Any = None) -> bool:
    """Whether ``--debug`` was given or ``CHRONOGYM_DEBUG`` is set (to anything but 0)."""
    flag = os.environ.get("CHRONOGYM_DEBUG", "").strip().lower()
    return getattr(args, "debug", False) or flag not in ("", "0", "false", "no")


def first_line(error: BaseException) -> str:
    """The first line of ``error``'s message, with its class name when the message is empty."""
    lines = str(error).strip().splitlines()
    return lines[0] if lines else type(error).__name__


def raised_by_chronogym(error: BaseException) -> bool:
    """Whether the innermost frame of ``error``'s traceback is in chronogym's source."""
    tb = error.__traceback__
    if tb is None:
        return False
    while tb.tb_next is not None:
        tb = tb.tb_next
    return Path(tb.tb_frame.f_code.co_filename).resolve().is_relative_to(PACKAGE_DIR)


def gymnasium_user_error(error: BaseException) -> bool:
    """Whether ``error`` is one of Gymnasium's errors about ids, modes and dependencies."""
    gym_error = sys.modules.get("gymnasium.error")
    if gym_error is None:
        return False
    return isinstance(
        error,
        (
            gym_error.UnregisteredEnv,
            gym_error.DeprecatedEnv,
            gym_error.UnsupportedMode,
            gym_error.DependencyNotInstalled,
        ),
    )


def user_error_message(error: BaseException, extra: str | None = None) -> str | None:
    """The one-line message of a user error (module docstring), or None for a bug.

    ``extra``: the ``chronogym[...]`` extra that the command needs, named when a module is
    missing.
    """
    if isinstance(error, UsageError):
        return str(error)
    if isinstance(error, ModuleNotFoundError):
        hint = f"; pip install 'chronogym[{extra}]' installs it" if extra else ""
        return first_line(error) + (hint if str(error).startswith("No module named") else "")
    own = isinstance(error, (ValueError, OSError)) and raised_by_chronogym(error)
    names_a_file = isinstance(error, OSError) and error.filename is not None
    if own or names_a_file or gymnasium_user_error(error):
        return first_line(error)
    return None


def run_command(
    command: Callable[[Any], int], args: Any, prog: str, extra: str | None = None
) -> int:
    """``command(args)``, with a user error turned into ``SystemExit("PROG: message")``."""
    debug = debug_requested(args)
    try:
        return command(args)
    except KeyboardInterrupt:
        if debug:
            raise
        print(f"{prog}: interrupted", file=sys.stderr)
        raise SystemExit(INTERRUPTED_STATUS) from None
    except Exception as error:
        message = user_error_message(error, extra)
        if message is None or debug:
            raise
        hint = "" if isinstance(error, UsageError) else f"\n{DEBUG_HINT}"
        raise SystemExit(f"{prog}: {message}{hint}") from None
