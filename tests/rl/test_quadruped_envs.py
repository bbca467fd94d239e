"""The Go1 training envs: task arguments reach every env; the physics step default."""

from __future__ import annotations

import pytest

from chronogym.tasks.quadruped.engines import env_kwargs_for
from chronogym.tasks.quadruped.task import PHYSICS_STEP
from chronogym.tasks.quadruped.training import make_quadruped_vec_env


def test_task_kwargs_reach_every_env():
    vec = make_quadruped_vec_env(3, "serial", task_kwargs={"dt": 0.005, "k": 4})
    try:
        assert vec.get_attr("dt") == (0.005,) * 3
        assert vec.get_attr("k") == (4,) * 3
        assert vec.get_attr("control_dt") == pytest.approx((0.02,) * 3)
    finally:
        vec.close()


def test_default_physics_step_is_the_tasks():
    vec = make_quadruped_vec_env(2, "serial")
    try:
        assert vec.get_attr("dt") == (PHYSICS_STEP["rigid"][0],) * 2
        assert vec.get_attr("k") == (PHYSICS_STEP["rigid"][1],) * 2
    finally:
        vec.close()
    assert PHYSICS_STEP["rigid"] == (0.01, 2)  # 50 Hz decisions, 2 ticks of 10 ms


def test_terrain_goes_in_its_own_argument():
    assert env_kwargs_for("soil", {"dt": 0.001, "k": 20}) == {
        "terrain": "soil",
        "dt": 0.001,
        "k": 20,
    }
    with pytest.raises(ValueError, match="give the terrain as terrain=..., not in task_kwargs"):
        env_kwargs_for("rigid", {"terrain": "soil"})
