"""The Go1 training's task settings: ``QUADRUPED_TASK`` under the caller's, rewards merged."""

from __future__ import annotations

import pytest

from chronogym.cli import train_task_options
from chronogym.cli_parser import build_parser
from chronogym.tasks.quadruped.config import RewardWeights
from chronogym.tasks.quadruped.training import (
    QUADRUPED_TASK,
    task_settings,
    training_task_kwargs,
)


def test_training_adds_the_fine_kernel_and_observes_the_velocity_by_default():
    kwargs = training_task_kwargs(None, None)
    assert kwargs["observe_base_lin_vel"] is True
    assert kwargs["rewards"] == RewardWeights(tracking_lin_vel_fine=1.0)
    assert QUADRUPED_TASK["rewards"] == {"tracking_lin_vel_fine": 1.0}  # not changed in place


def test_a_rewards_dict_changes_only_the_weights_it_names():
    kwargs = task_settings(QUADRUPED_TASK, {"rewards": {"feet_air_time": 0.5}})
    assert kwargs["rewards"] == RewardWeights(tracking_lin_vel_fine=1.0, feet_air_time=0.5)
    # a RewardWeights replaces every weight, and a dict after it changes it in turn
    paper = task_settings(QUADRUPED_TASK, {"rewards": RewardWeights()})
    assert paper["rewards"] == RewardWeights()
    both = task_settings(QUADRUPED_TASK, {"rewards": RewardWeights()}, {"rewards": {"torques": 0}})
    assert both["rewards"] == RewardWeights(torques=0.0)


def test_an_unknown_reward_term_is_named():
    with pytest.raises(ValueError, match=r"unknown term 'tracking_fine'; expected RewardWeights'"):
        task_settings(QUADRUPED_TASK, {"rewards": {"tracking_fine": 1.0}})


@pytest.mark.parametrize(
    ("flags", "expected"),
    [
        ([], None),
        (["--fine-tracking-weight", "0"], {"rewards": {"tracking_lin_vel_fine": 0.0}}),
        (
            ["--no-observe-base-lin-vel", "--fine-tracking-weight", "2"],
            {"observe_base_lin_vel": False, "rewards": {"tracking_lin_vel_fine": 2.0}},
        ),
    ],
)
def test_train_options_set_the_task(flags, expected):
    args = build_parser().parse_args(["train", "quadruped", *flags])
    assert train_task_options(args) == expected
    if expected is not None:
        rewards = training_task_kwargs(expected, None)["rewards"]
        assert rewards.tracking_lin_vel_fine == expected["rewards"]["tracking_lin_vel_fine"]


def test_a_negative_fine_tracking_weight_is_refused(capsys):
    with pytest.raises(SystemExit):
        build_parser().parse_args(["train", "quadruped", "--fine-tracking-weight", "-1"])
    assert "--fine-tracking-weight=-1.0: expected a number >= 0" in capsys.readouterr().err
