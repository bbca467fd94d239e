"""SB3 with an id registered in the user's script: both routes build the envs on Ray workers.

The user's script runs in a subprocess, as a user runs it: the workers never run it, so
they lack its ids unless chronogym sends them (NamespaceNotFound before this was fixed).
"""

from __future__ import annotations

import textwrap

import cloudpickle
import gymnasium as gym
import pytest

pytest.importorskip("stable_baselines3")

from user_scripts import run_user_script

from chronogym.integrations._indexed import DriverRegistry, build_indexed_env

SCRIPT = textwrap.dedent(
    """
    import chronogym  # first: it picks MuJoCo's headless GL backend

    import mujoco
    import numpy as np
    import ray
    from gymnasium import spaces
    from stable_baselines3.common.env_util import make_vec_env
    from stable_baselines3.common.vec_env import DummyVecEnv

    from chronogym.engines.mujoco import MujocoTask
    from chronogym.integrations.sb3 import RayVecEnv, make_sb3_vec_env

    XML = '''
    <mujoco><option timestep="0.02"/><worldbody><body>
      <joint name="hinge" type="hinge" axis="0 1 0" damping="0.1"/>
      <geom type="capsule" fromto="0 0 0 0 0 -0.5" size="0.04" mass="1"/>
    </body></worldbody><actuator><motor joint="hinge" gear="2"/></actuator></mujoco>
    '''


    class Swing(MujocoTask):
        dt, max_episode_steps = 0.02, 6  # dt: the model's timestep

        def load_model(self):
            return mujoco.MjModel.from_xml_string(XML)

        def setup(self):
            self.observation_space = spaces.Box(-np.inf, np.inf, (2,), np.float64)
            self.action_space = spaces.Box(-1.0, 1.0, (1,), np.float32)

        def reset(self, rng, options):
            self.data.qpos[:] = rng.uniform(-0.5, 0.5, 1)

        def apply_action(self, action):
            self.data.ctrl[:] = action

        def observe(self):
            return np.concatenate([self.data.qpos, self.data.qvel])

        def reward(self, action, obs):
            return -float(obs[0] ** 2)

        def terminated(self, obs):
            return False


    ENV_ID = "newuser/Swing-v0"
    chronogym.register_task(ENV_ID, Swing)
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)


    def rollout(venv):
        venv.seed(3)
        out = [venv.reset()]
        for t in range(9):  # crosses the end of the 6-step episodes
            obs, rewards, dones, infos = venv.step(np.full((4, 1), np.sin(t), np.float32))
            out.append(np.concatenate([obs, rewards[:, None], dones[:, None]], axis=1))
        venv.close()
        return np.stack(out[1:]), out[0]


    reference = rollout(make_vec_env(ENV_ID, 4, vec_env_cls=DummyVecEnv))
    routes = {
        "make_vec_env": make_vec_env(
            ENV_ID, 4, vec_env_cls=RayVecEnv, vec_env_kwargs={"envs_per_worker": 2}
        ),
        "make_sb3_vec_env": make_sb3_vec_env(ENV_ID, 4, envs_per_worker=2),
    }
    for name, venv in routes.items():
        steps, first = rollout(venv)
        assert np.array_equal(first, reference[1]), (name, first, reference[1])
        assert np.array_equal(steps, reference[0]), (name, steps, reference[0])
        print(name, "same numbers as DummyVecEnv", steps.shape)
    """
)


def test_script_registered_id_works_through_both_sb3_routes(tmp_path):
    done = run_user_script(tmp_path, SCRIPT, timeout=300)
    assert done.returncode == 0, done.stderr[-3000:]
    for route in ("make_vec_env", "make_sb3_vec_env"):
        assert f"{route} same numbers as DummyVecEnv (9, 4, 4)" in done.stdout, done.stdout


@pytest.fixture
def forget_ids():
    """Ids a test registers, removed from this process's registry afterwards."""
    ids: list[str] = []
    yield ids
    for env_id in ids:
        gym.registry.pop(env_id, None)


def test_a_worker_registers_the_drivers_missing_ids_and_builds_again(forget_ids) -> None:
    """In one process: an id the 'worker' lacks is registered from the driver's snapshot."""
    env_id = "newuser/CartPoleCopy-v0"
    forget_ids.append(env_id)
    gym.register(
        env_id,
        entry_point=gym.spec("chronogym/CartPole-v0").entry_point,
        kwargs=gym.spec("chronogym/CartPole-v0").kwargs,
    )
    registry = DriverRegistry(cloudpickle.dumps)
    del gym.registry[env_id]  # as in a worker, which never ran the user's script
    env = build_indexed_env(lambda: gym.make(env_id), 3, registry)
    assert env.chronogym_env_index == 3 and env.spec.id == env_id
    env.close()
    with pytest.raises(gym.error.NameNotFound):  # not in the driver either: Gymnasium's error
        build_indexed_env(lambda: gym.make("newuser/NoSuch-v0"), 0, registry)


def test_a_spec_the_worker_cannot_load_is_named_in_the_error(forget_ids) -> None:
    registry = DriverRegistry(cloudpickle.dumps)
    registry.specs["elsewhere/Env-v0"] = b"not a pickle"
    forget_ids.append("elsewhere/Env-v0")
    with pytest.raises(
        gym.error.NamespaceNotFound,
        match=r"'elsewhere/Env-v0'\] could not be loaded here: UnpicklingError",
    ):
        build_indexed_env(lambda: gym.make("elsewhere/Env-v0"), 0, registry)
