"""What a training run does with an env's exception: its own explicit choice."""

from __future__ import annotations

import inspect

import pytest

from chronogym.cli_parser import build_parser
from chronogym.rl import train_quadruped
from chronogym.tasks.quadruped.training import make_quadruped_vec_env


def test_training_restarts_by_default_and_says_so():
    assert inspect.signature(train_quadruped).parameters["env_errors"].default == "restart"
    args = build_parser().parse_args(["train", "quadruped", "--iterations", "1"])
    assert args.env_errors == "restart"
    args = build_parser().parse_args(
        ["train", "quadruped", "--iterations", "1", "--env-errors", "raise"]
    )
    assert args.env_errors == "raise"


def test_the_choice_reaches_the_vector_env():
    vec = make_quadruped_vec_env(2, backend="serial", env_errors="restart")
    try:
        assert vec.env_errors == "restart"
    finally:
        vec.close()


def test_a_bad_choice_is_rejected_before_anything_starts(tmp_path):
    with pytest.raises(ValueError, match="env_errors='often'"):
        train_quadruped(tmp_path, backend="serial", iterations=1, env_errors="often")
