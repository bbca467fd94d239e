"""The Task contract: both forms, and clear errors for incomplete tasks."""

from __future__ import annotations

import mujoco
import numpy as np
import pytest
from gymnasium import spaces

from chronogym import FunctionTask, SimEnv, Task, TaskDefinitionError
from chronogym.tasks.cartpole import XML_PATH, CartPoleTask


def cartpole_function_task() -> FunctionTask:
    """The cart-pole written in the function form, for comparison with CartPoleTask."""

    def init():
        model = mujoco.MjModel.from_xml_path(str(XML_PATH))
        data = mujoco.MjData(model)
        return [(model, data)], {"model": model, "data": data}

    def reset(res, rng, options):
        mujoco.mj_resetData(res["model"], res["data"])
        res["data"].qpos[:] = rng.uniform(-0.05, 0.05, size=res["model"].nq)
        res["data"].qvel[:] = rng.uniform(-0.05, 0.05, size=res["model"].nv)
        mujoco.mj_forward(res["model"], res["data"])

    def apply_action(res, action):
        res["data"].ctrl[0] = action[0]

    def observe(res):
        obs = np.concatenate([res["data"].qpos, res["data"].qvel])
        obs[1] = (obs[1] + np.pi) % (2 * np.pi) - np.pi
        return obs

    high = np.array([np.inf, np.pi, np.inf, np.inf])
    return FunctionTask(
        init=init,
        reset=reset,
        apply_action=apply_action,
        observe=observe,
        reward=lambda res, action, obs: 1.0,
        terminated=lambda res, obs: abs(obs[1]) > 0.2 or abs(obs[0]) > 0.9,
        dt=0.002,
        k=10,
        observation_space=spaces.Box(-high, high, dtype=np.float64),
        action_space=spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32),
        max_episode_steps=500,
    )


def rollout(env: SimEnv, seed: int, steps: int) -> list:
    obs, _ = env.reset(seed=seed)
    rng = np.random.default_rng(0)
    out = [obs]
    for _ in range(steps):
        obs, reward, terminated, truncated, _ = env.step(rng.uniform(-1, 1, 1).astype(np.float32))
        out.append((obs, reward, terminated, truncated))
        if terminated or truncated:
            out.append(env.reset()[0])
    return out


def test_function_form_matches_subclass_form():
    by_class = rollout(SimEnv(CartPoleTask()), seed=3, steps=120)
    by_functions = rollout(SimEnv(cartpole_function_task()), seed=3, steps=120)
    assert len(by_class) == len(by_functions)
    for a, b in zip(by_class, by_functions, strict=True):
        np.testing.assert_array_equal(
            np.asarray(a[0] if isinstance(a, tuple) else a),
            np.asarray(b[0] if isinstance(b, tuple) else b),
        )


def test_subclass_missing_piece_is_named():
    class NoObserve(Task):
        dt = 0.01

        def init(self):
            pass

        def reset(self, rng, options):
            pass

        def apply_action(self, action):
            pass

        def reward(self, action, obs):
            return 0.0

        def terminated(self, obs):
            return False

    with pytest.raises(TaskDefinitionError, match=r"NoObserve is missing observe\(\)"):
        SimEnv(NoObserve())


def test_function_form_missing_piece_is_named():
    with pytest.raises(TaskDefinitionError, match="reward=None"):
        FunctionTask(
            init=lambda: ([], None),
            reset=lambda r, rng, o: None,
            apply_action=lambda r, a: None,
            observe=lambda r: np.zeros(1),
            reward=None,  # type: ignore[arg-type]
            terminated=lambda r, o: False,
            dt=0.01,
        )


@pytest.mark.parametrize("dt", [0.0, -0.01, float("nan"), "0.01"])
def test_bad_dt_is_rejected(dt):
    with pytest.raises(ValueError, match=r"dt="):
        SimEnv(CartPoleTask(dt=dt))


@pytest.mark.parametrize("k", [0, -1, 2.5])
def test_bad_k_is_rejected(k):
    with pytest.raises(ValueError, match=r"k="):
        SimEnv(CartPoleTask(k=k))


def test_spaces_must_exist_after_init():
    task = cartpole_function_task()
    task._space_sources = (None, task._space_sources[1])
    with pytest.raises(TaskDefinitionError, match="observation_space is None"):
        SimEnv(task)


def test_reset_mutates_without_rebuilding():
    env = SimEnv(CartPoleTask())
    model, data = env.task.model, env.task.data
    env.reset(seed=0)
    env.step(np.zeros(1, dtype=np.float32))
    env.reset(seed=1)
    assert env.task.model is model and env.task.data is data
    assert env.sim_time == 0.0 and env.task.data.time == 0.0
