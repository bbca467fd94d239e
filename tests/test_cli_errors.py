"""The `chronogym` command line on bad input, run as a user would: a line or two, no traceback.

Every bad input here is rejected before any training, study or Ray worker starts.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from importlib.metadata import version

import numpy as np
import pytest

from chronogym.cli import main
from chronogym.cli_errors import UsageError, user_error_message
from chronogym.optim import open_storage

CLI = [sys.executable, "-m", "chronogym.cli"]
SUBCOMMANDS = ["demo", "optimize", "train", "play", "envs", "bench"]


def run_cli(*args: str, cwd=None, debug: bool = False) -> subprocess.CompletedProcess:
    env = {**os.environ, "RAY_ADDRESS": "", "COLUMNS": "100"}
    env.pop("CHRONOGYM_DEBUG", None)
    if debug:
        env["CHRONOGYM_DEBUG"] = "1"
    return subprocess.run(
        [*CLI, *args], capture_output=True, text=True, timeout=120, env=env, cwd=cwd
    )


#: Each bad input ({tmp}: a folder holding notacheckpoint.pt, a text file, and a_file),
#: with a piece of the message that it must give.
BAD_INPUTS: dict[str, tuple[list[str], str]] = {
    "storage URL": (
        ["optimize", "lander", "--storage", "bogus://x"],
        "--storage=bogus://x: cannot open this Optuna storage",
    ),
    "storage driver": (
        ["optimize", "lander", "--storage", "mysql://user@host:port/db"],
        "--storage=mysql://user@host:port/db: cannot open",
    ),
    "not a checkpoint (play)": (
        ["play", "quadruped", "{tmp}/notacheckpoint.pt"],
        "checkpoint='{tmp}/notacheckpoint.pt': expected a chronogym/RSL-RL checkpoint",
    ),
    "not a checkpoint (resume)": (
        ["train", "quadruped", "--minutes", "1", "--resume", "{tmp}/notacheckpoint.pt"],
        "--resume='{tmp}/notacheckpoint.pt': expected a chronogym/RSL-RL checkpoint",
    ),
    "a folder as checkpoint": (["play", "quadruped", "{tmp}"], "Is a directory"),
    "env id": (
        ["envs", "chronogym/CartPol-v0"],
        "chronogym/CartPol-v0: Environment `CartPol` doesn't exist",
    ),
    "problem id": (["train", "biped"], "invalid choice: 'biped'"),
    "command": (["trian"], "invalid choice: 'trian'"),
    "negative --num-envs": (
        ["demo", "--num-envs", "-3"],
        "--num-envs=-3: expected an integer >= 1",
    ),
    "zero --workers": (["optimize", "lander", "--workers", "0"], "--workers=0: expected"),
    "negative --seed": (["train", "quadruped", "--seed", "-1"], "--seed=-1: expected"),
    "NaN --minutes": (["train", "quadruped", "--minutes", "nan"], "--minutes=nan: expected"),
    "not a number": (["play", "quadruped", "x.pt", "--episodes", "two"], "invalid int value"),
    "serial with 2 workers": (
        ["optimize", "lander", "--backend", "serial"],
        "--workers=2 with --backend serial",
    ),
    "--out is a file": (
        ["train", "quadruped", "--minutes", "1", "--out", "{tmp}/a_file"],
        "--out={tmp}/a_file: cannot create this folder",
    ),
    "Ray address": (["demo", "--address", "nowhere"], "Ray address 'nowhere': expected"),
    "negative --eval-episodes": (
        ["train", "quadruped", "--minutes", "1", "--eval-episodes", "-1"],
        "--eval-episodes=-1: expected an integer >= 0",
    ),
    "--check-walking with --command": (
        ["play", "quadruped", "x.pt", "--check-walking", "--command", "1", "0", "0"],
        "--check-walking with --command: the walking criterion runs its own commands",
    ),
    "--check-walking with --steps and --seed": (
        ["play", "quadruped", "x.pt", "--check-walking", "--steps", "50", "--seed", "2"],
        "--check-walking with --steps, --seed:",
    ),
    "--traces not .npz": (
        ["play", "quadruped", "x.pt", "--traces", "t.csv"],
        "--traces=t.csv: expected a .npz path",
    ),
    "--step-response not .png": (
        ["play", "quadruped", "x.pt", "--step-response", "s.pdf"],
        "--step-response=s.pdf: expected a .png path",
    ),
    "--friction LO > HI": (
        ["play", "quadruped", "x.pt", "--friction", "1.0", "0.5"],
        "--friction 1 0.5: expected 0 < LO <= HI",
    ),
    "--friction zero": (
        ["play", "quadruped", "x.pt", "--friction", "0", "1"],
        "--friction 0 1: expected 0 < LO <= HI",
    ),
    "--friction one value": (
        ["play", "quadruped", "x.pt", "--friction", "0.5"],
        "--friction: expected 2 arguments",
    ),
    "zero --push-velocity": (
        ["play", "quadruped", "x.pt", "--push", "--push-velocity", "0"],
        "--push-velocity=0.0: expected a number > 0",
    ),
    "NaN --push-interval": (
        ["play", "quadruped", "x.pt", "--push", "--push-interval", "nan"],
        "--push-interval=nan: expected a number > 0",
    ),
}


@pytest.mark.parametrize("case", list(BAD_INPUTS))
def test_bad_input_is_a_short_message_without_traceback(case, tmp_path):
    (tmp_path / "notacheckpoint.pt").write_text("these are notes, not tensors\n")
    (tmp_path / "a_file").write_text("")
    args, message = BAD_INPUTS[case]
    result = run_cli(*(arg.format(tmp=tmp_path) for arg in args), cwd=tmp_path)
    output = (result.stdout + result.stderr).strip().splitlines()
    assert result.returncode != 0, output
    assert "Traceback" not in result.stderr, result.stderr
    assert len(output) <= 3, output
    assert message.format(tmp=tmp_path) in result.stderr, result.stderr
    assert "Started a local Ray instance" not in result.stderr  # failed before Ray started
    assert not list(tmp_path.glob("*.db"))  # no study was created


def test_debug_flag_and_variable_show_the_traceback(tmp_path):
    for args, debug in [(["--debug"], False), ([], True)]:
        result = run_cli(
            "optimize", "lander", "--storage", "bogus://x", *args, cwd=tmp_path, debug=debug
        )
        assert result.returncode != 0
        assert "Traceback (most recent call last)" in result.stderr
        assert "NoSuchModuleError" in result.stderr  # the cause, chained
        assert "--storage=bogus://x: cannot open this Optuna storage" in result.stderr
    before_command = run_cli("--debug", "play", "quadruped", str(tmp_path))
    assert "Traceback (most recent call last)" in before_command.stderr


def test_a_bug_keeps_its_traceback():
    script = (
        "import chronogym.cli as cli\n"
        "def broken(args):\n"
        "    return {}['missing']\n"
        "cli.COMMANDS['envs'] = (broken, None)\n"
        "cli.main(['envs'])\n"
    )
    result = subprocess.run(
        [sys.executable, "-c", script], capture_output=True, text=True, timeout=120
    )
    assert result.returncode != 0
    assert "Traceback (most recent call last)" in result.stderr
    assert "KeyError: 'missing'" in result.stderr


def test_main_raises_systemexit_naming_the_command_and_the_value(tmp_path, monkeypatch):
    monkeypatch.chdir(tmp_path)
    monkeypatch.delenv("CHRONOGYM_DEBUG", raising=False)
    with pytest.raises(SystemExit) as exit_info:
        main(["optimize", "lander", "--storage", "bogus://x"])
    lines = str(exit_info.value).splitlines()
    assert lines[0].startswith("chronogym optimize lander: --storage=bogus://x: cannot open")
    assert len(lines) == 1  # the CLI's own check: no "--debug" hint


def raised(call) -> BaseException:
    try:
        call()
    except BaseException as error:
        return error
    raise AssertionError(f"{call} raised nothing")


def test_which_exceptions_count_as_user_errors(tmp_path):
    own_value_error = raised(lambda: open_storage("notaurl"))
    assert "storage='notaurl': expected" in user_error_message(own_value_error)
    assert user_error_message(raised(lambda: np.random.default_rng(-1))) is None  # NumPy's
    assert user_error_message(raised(lambda: int("x") + None)) is None  # a ValueError here
    assert user_error_message(raised(lambda: len(3))) is None  # TypeError: a bug
    missing = raised((tmp_path / "nope.txt").read_text)
    assert "nope.txt" in user_error_message(missing)  # an OSError naming a file
    module = raised(lambda: __import__("chronogym_no_such_module"))
    assert user_error_message(module, extra="rl") == (
        "No module named 'chronogym_no_such_module'; pip install 'chronogym[rl]' installs it"
    )
    assert user_error_message(UsageError("--x=1: expected 2")) == "--x=1: expected 2"


def test_version_prints_the_installed_version():
    result = run_cli("--version")
    assert result.returncode == 0
    assert result.stdout.strip() == f"chronogym {version('chronogym')}"


def help_entries(text: str) -> dict[str, str]:
    """The entries of argparse's help: first word of each argument -> its help text."""
    entries: dict[str, list[str]] = {}
    current: list[str] | None = None
    in_section = False
    for line in text.splitlines():
        if line and not line[0].isspace():
            in_section = line.endswith(":")
            current = None
        elif in_section and re.match(r"^  \S", line):
            invocation, _, help_text = line.strip().partition("  ")
            flags = re.findall(r"(?:^|, )(--?[\w-]+)", invocation)  # "-h, --help": --help
            current = entries.setdefault(flags[-1] if flags else invocation.split()[0], [])
            current.append(help_text)
            for flag in flags[:-1]:  # "--x, --no-x": both name the entry
                entries[flag] = current
        elif in_section and current is not None:
            current.append(line)
    return {name: " ".join(" ".join(parts).split()) for name, parts in entries.items()}


@pytest.mark.parametrize("command", ["", *SUBCOMMANDS])
def test_help_gives_every_option_a_help_text_and_its_default(command):
    result = run_cli(*command.split(), "--help")
    assert result.returncode == 0, result.stderr
    entries = help_entries(result.stdout)
    usage = result.stdout.split("\n\n")[0]
    options = set(re.findall(r"\[(--[\w-]+)", usage))  # each option, as the usage lists it
    assert "--debug" in options and options <= set(entries), (options, entries)
    for name, text in entries.items():
        assert text, f"{command} {name}: no help text"
        if name.startswith("--") and name not in ("--help", "--version"):
            assert "default" in text, f"chronogym {command} {name}: no default in {text!r}"
