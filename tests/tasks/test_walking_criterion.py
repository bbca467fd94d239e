"""Walking criterion v2 on synthetic velocity traces: each clause fails alone; v1 beside it."""

from __future__ import annotations

import math

import gymnasium as gym
import numpy as np
import pytest

import chronogym  # noqa: F401
from chronogym.tasks.quadruped.engines import ENV_ID
from chronogym.tasks.quadruped.evaluation import run_episode
from chronogym.tasks.quadruped.walking import (
    CommandSwitch,
    EpisodeSpec,
    VelocityTrace,
    WalkingCriterion,
    WalkingCriterionV1,
    criterion_for_episode,
    load_traces,
    save_traces,
)

DT = 0.02
STEPS = 1000  # 20 s at 50 Hz


def response(command, seed, *, rise_s=0.4, offset=(0.0, 0.0, 0.0), fall_at=None,
             switch=None, switch_rise_s=0.4, noise=0.02):  # fmt: skip
    """A trace that ramps linearly from rest to ``command`` in ``rise_s`` (then holds it plus
    ``offset`` and a little noise); with ``switch`` (a CommandSwitch), ramps again to its
    ``after`` in ``switch_rise_s``; ``fall_at`` (s) ends it early."""
    t = (np.arange(STEPS) + 1) * DT
    commands = np.tile(np.asarray(command, float), (STEPS, 1))
    ramp = np.clip(t / rise_s, 0, 1)[:, None]
    velocity = ramp * (commands + np.asarray(offset))
    schedule = ()
    if switch is not None:
        after = t >= switch.at_s - 1e-9
        commands[after] = switch.after
        step = np.clip((t - switch.at_s) / switch_rise_s, 0, 1)[:, None]
        delta = np.asarray(switch.after) - np.asarray(switch.before)
        velocity = velocity + step * delta
        schedule = ((switch.at_s, switch.after),)
    rng = np.random.default_rng(seed)
    velocity = velocity + rng.normal(0, noise, velocity.shape)
    n = STEPS if fall_at is None else round(fall_at / DT)
    return VelocityTrace(
        command=tuple(float(c) for c in command), seed=seed, dt=DT,
        vx=velocity[:n, 0], vy=velocity[:n, 1], wz=velocity[:n, 2], commands=commands[:n],
        survived=fall_at is None, schedule=schedule,
    )  # fmt: skip


def traces_for(criterion, **change):
    """A trace for each of ``criterion``'s episodes; ``change`` maps a group label (or
    ``"switch"``) to ``response`` keyword arguments for that group's episodes."""
    out = []
    for group in criterion.groups():
        for spec in group.specs:
            key = "switch" if spec.schedule else group.label
            kwargs = dict(change.get(key, {}))
            if spec.schedule:
                kwargs["switch"] = criterion.switch
            seed_only = kwargs.pop("seed_only", None)
            if seed_only is not None and spec.seed != seed_only:
                kwargs = {"switch": criterion.switch} if spec.schedule else {}
            out.append(response(spec.command, spec.seed, **kwargs))
    return out


CRITERION = WalkingCriterion()
LABELS = [g.label for g in CRITERION.groups()]


def test_a_good_response_walks_and_v1_agrees():
    traces = traces_for(CRITERION)
    verdict = CRITERION.judge(traces)
    assert verdict.walks, verdict.failures
    assert verdict.commands_passed == verdict.groups == 7
    assert verdict.worst_ratio < 1
    assert WalkingCriterionV1().judge(traces).walks


@pytest.mark.parametrize(
    ("label", "change", "clause"),
    [
        ("(+1.00, +0.00, +0.00)", {"rise_s": 1.5}, "rise time: vx t90 1.4"),
        ("(+0.00, +0.30, +0.00)", {"offset": (0.0, 0.12, 0.0)}, "steady state: y-velocity MSE"),
        ("(+0.50, +0.00, +0.00)", {"offset": (0.12, 0.0, 0.0)}, "steady state: x-velocity MSE"),
        ("(+0.50, +0.00, +0.50)", {"offset": (0.0, 0.0, 0.25)}, "yaw: yaw-rate MSE"),
        ("switch", {"switch_rise_s": 1.8}, "rise time: vx t90 after the switch 1.5"),
        ("(-0.30, +0.00, +0.00)", {"fall_at": 12.0, "seed_only": 3}, "survival: 1/5"),
    ],
)
def test_each_clause_fails_alone(label, change, clause):
    verdict = CRITERION.judge(traces_for(CRITERION, **{label: change}))
    assert not verdict.walks
    failed = [c for c in verdict.checks if not c.passed]
    assert len(failed) == 1, verdict.failures
    assert len(failed[0].failures) == 1 and failed[0].failures[0].startswith(clause), failed
    index = LABELS.index(failed[0].label)
    assert verdict.commands_passed == index
    assert verdict.worst_ratio > 1  # a fall too: 1 + the share of episodes that fell


def test_a_slow_start_fails_v2_only_where_v1_would_pass_it():
    # A 1.5 s ramp to 0.5 m/s costs v1 only v^2 T / 3 / 20 s of whole-episode MSE
    traces = traces_for(CRITERION, **{"(+0.50, +0.00, +0.00)": {"rise_s": 1.5}})
    assert WalkingCriterionV1().judge(traces).walks
    verdict = CRITERION.judge(traces)
    assert not verdict.walks and "rise time" in verdict.failures[0]


def test_a_steady_offset_after_a_fast_start_is_what_v1_also_sees():
    traces = traces_for(CRITERION, **{"(+1.00, +0.00, +0.00)": {"offset": (0.15, 0, 0)}})
    assert not WalkingCriterionV1().judge(traces).walks
    assert not CRITERION.judge(traces).walks


def test_rise_time_is_the_trailing_moving_average_reaching_90_percent():
    trace = response((1.0, 0.0, 0.0), 0, rise_s=1.0, noise=0.0)
    # a linear ramp over 1 s: the 0.2 s trailing mean reaches 0.9 at t = 1.0 s
    assert trace.rise_time(0, 1.0) == pytest.approx(1.0, abs=DT)
    backwards = response((-0.3, 0.0, 0.0), 0, rise_s=0.5, noise=0.0)
    assert backwards.rise_time(0, -0.3) == pytest.approx(0.55, abs=DT)
    standing = response((0.0, 0.0, 0.0), 0, noise=0.0)
    assert math.isinf(standing.rise_time(0, 0.5))


def test_the_standing_command_has_no_rise_time_and_yaw_is_judged_only_with_a_yaw_rate():
    checks = {c.label: c for c in CRITERION.judge(traces_for(CRITERION)).checks}
    assert checks["(+0.00, +0.00, +0.00)"].rise_s is None
    assert checks["(+0.00, +0.00, +0.00)"].yaw_mse is None
    assert checks["(+0.50, +0.00, +0.50)"].yaw_mse is not None


def test_missing_groups_are_not_evaluated_and_do_not_walk():
    traces = traces_for(CRITERION)[:10]  # the first two commands only
    verdict = CRITERION.judge(traces)
    assert len(verdict.checks) == 2 and verdict.commands_passed == 2 and not verdict.walks


def test_traces_are_saved_and_read_back(tmp_path):
    traces = [*traces_for(CRITERION)[-3:], response((0.5, 0, 0), 9, fall_at=3.0)]
    path = save_traces(tmp_path / "t.npz", traces)
    back = load_traces(path)
    assert len(back) == len(traces)
    for a, b in zip(traces, back, strict=True):
        assert (a.command, a.seed, a.schedule, a.survived, a.dt) == (
            b.command, b.seed, b.schedule, b.survived, b.dt,
        )  # fmt: skip
        for name in ("vx", "vy", "wz", "commands"):
            np.testing.assert_array_equal(getattr(a, name), getattr(b, name))
    assert CRITERION.judge(back).as_dict() == CRITERION.judge(traces).as_dict()
    with pytest.raises(ValueError, match=r"t\.csv.*expected a file name ending in \.npz"):
        save_traces(tmp_path / "t.csv", traces)


@pytest.mark.parametrize(
    ("kwargs", "message"),
    [
        ({"max_rise_s": 0}, "max_rise_s=0: expected a time > 0 s"),
        ({"max_yaw_mse": -1}, "max_yaw_mse=-1: expected a threshold > 0"),
        ({"rise_fraction": 1.5}, r"rise_fraction=1.5: expected a fraction in \(0, 1\]"),
        ({"settle_s": -1.0}, "settle_s=-1.0: expected a time >= 0 s"),
        ({"episodes": 0}, "episodes=0"),
        ({"commands": ((1.0, 0.0),)}, r"commands\[\]=\(1.0, 0.0\): expected 3 finite floats"),
        ({"switch": (0.5, 1.0)}, r"switch=\(0.5, 1.0\): expected a CommandSwitch or None"),
    ],
)
def test_bad_settings_name_the_value(kwargs, message):
    with pytest.raises((ValueError, TypeError), match=message):
        WalkingCriterion(**kwargs)


def test_a_bad_switch_names_the_value():
    with pytest.raises(ValueError, match=r"switch.at_s=0: expected a time > 0 s"):
        CommandSwitch(at_s=0)
    with pytest.raises(ValueError, match=r"switch.after=\(1.0,\): expected 3 finite floats"):
        CommandSwitch(after=(1.0,))


def test_short_episodes_move_the_switch_half_way():
    assert criterion_for_episode(CRITERION, 20.0) is CRITERION
    assert criterion_for_episode(CRITERION, 4.0).switch.at_s == 2.0
    assert criterion_for_episode(WalkingCriterion(switch=None), 4.0).switch is None


def test_the_task_switches_the_command_on_schedule():
    """The real Go1 episode of a switch: the trace's commands change at the switch time."""
    env = gym.make(ENV_ID, max_episode_steps=20)
    try:
        spec = EpisodeSpec((0.5, 0.0, 0.0), 0, ((0.1, (1.0, 0.0, 0.2)),))
        trace = run_episode(env, lambda obs: np.zeros(12), spec).trace
    finally:
        env.close()
    assert len(trace.vx) == 20 and trace.schedule == spec.schedule
    switched = trace.time >= 0.1 - 1e-9
    np.testing.assert_array_equal(trace.commands[~switched], [[0.5, 0.0, 0.0]] * 4)
    np.testing.assert_array_equal(trace.commands[switched], [[1.0, 0.0, 0.2]] * 16)
    assert np.isfinite(trace.wz).all() and np.abs(trace.wz).max() > 0
