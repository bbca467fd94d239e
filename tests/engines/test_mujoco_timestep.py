"""MujocoTask: dt against the MJCF timestep (dt wins; a class dt that differs warns once)."""

from __future__ import annotations

import warnings

import gymnasium as gym
import mujoco
import numpy as np
import pytest

from chronogym import MujocoTask, SimEnv
from chronogym.tasks.cartpole import CartPoleTask


def pendulum_xml(timestep: float | None) -> str:
    option = "" if timestep is None else f'<option timestep="{timestep}"/>'
    return f"""<mujoco>{option}<worldbody><body><joint name="hinge" type="hinge"/>
      <geom type="capsule" fromto="0 0 0 0 0 -0.5" size="0.02"/></body></worldbody>
      <actuator><motor joint="hinge"/></actuator></mujoco>"""


class Pendulum(MujocoTask):
    timestep: float | None = 0.005  # what the MJCF says

    def load_model(self):
        return mujoco.MjModel.from_xml_string(pendulum_xml(self.timestep))

    def setup(self):
        self.observation_space = gym.spaces.Box(-np.inf, np.inf, (2,), np.float64)
        self.action_space = gym.spaces.Box(-1, 1, (1,), np.float32)

    def reset(self, rng, options):
        self.reset_data()

    def apply_action(self, action):
        self.data.ctrl[:] = action

    def observe(self):
        return np.concatenate([self.data.qpos, self.data.qvel])

    def reward(self, action, obs):
        return 0.0

    def terminated(self, obs):
        return False


class ClassDt(Pendulum):
    dt = 0.01


class ClassDtDefaultMjcf(Pendulum):
    dt, timestep = 0.01, None


class SameDt(Pendulum):
    dt = 0.005


def test_a_class_dt_that_differs_from_the_mjcf_warns_once_with_both_values():
    with pytest.warns(UserWarning) as record:
        first = SimEnv(ClassDt())
        SimEnv(ClassDt())  # same class: no second warning
    assert len(record) == 1
    assert str(record[0].message).startswith(
        "ClassDt.dt = 0.01 differs from its MuJoCo model's timestep 0.005 (<option timestep> "
        "in the MJCF, 0.002 when it sets none); dt wins: the model steps at 0.01 s. Make the "
        "two equal to silence this warning (given once per class)"
    )
    assert first.task.model.opt.timestep == 0.01 and first.dt == 0.01  # dt wins, as before
    with pytest.warns(UserWarning, match=r"ClassDtDefaultMjcf.dt = 0.01 .* timestep 0.002 "):
        SimEnv(ClassDtDefaultMjcf())  # an MJCF without <option timestep>: MuJoCo's 0.002


def test_matching_and_constructor_dt_do_not_warn():
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        assert SimEnv(SameDt()).dt == 0.005
        env = gym.make("chronogym/CartPole-v0", dt=0.001)  # an argument: chosen on purpose
        assert env.unwrapped.task.model.opt.timestep == 0.001
        assert SimEnv(CartPoleTask()).task.model.opt.timestep == 0.002


@pytest.mark.parametrize(("timestep", "expected"), [(0.005, 0.005), (None, 0.002)])
def test_a_task_without_dt_takes_the_models_timestep(timestep, expected):
    class NoDt(Pendulum):
        pass

    NoDt.timestep = timestep
    env = SimEnv(NoDt())
    assert env.dt == expected and env.unwrapped.task.model.opt.timestep == expected
    env.reset(seed=0)
    env.step(np.zeros(1, np.float32))
    assert env.sim_time == pytest.approx(expected)
    env.close()


def test_a_task_whose_init_leaves_dt_none_is_rejected():
    class StillNone(Pendulum):
        def init(self):
            super().init()
            self.dt = None

    with pytest.raises(ValueError, match="Task StillNone: dt=None, expected a finite float > 0"):
        SimEnv(StillNone())
