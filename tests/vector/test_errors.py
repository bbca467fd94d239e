"""Bad input to the vector envs: a clear error, raised early, naming the value."""

from __future__ import annotations

import numpy as np
import pytest
from vector_rollouts import ENV_ID

from chronogym import RayVectorEnv, SerialVectorEnv


@pytest.fixture(scope="module")
def serial():
    vec = SerialVectorEnv(ENV_ID, 3)
    vec.reset(seed=0)
    yield vec
    vec.close()


@pytest.mark.parametrize("num_envs", [0, -2])
def test_num_envs_below_one(num_envs):
    with pytest.raises(ValueError, match=rf"num_envs={num_envs}: expected an integer >= 1"):
        SerialVectorEnv(ENV_ID, num_envs)


def test_envs_per_worker_larger_than_num_envs(ray_cluster):
    with pytest.raises(ValueError, match="envs_per_worker=5.*num_envs=4"):
        RayVectorEnv(ENV_ID, 4, envs_per_worker=5)


def test_too_many_cpus_per_worker(ray_cluster):
    with pytest.raises(ValueError, match=r"num_cpus=1 per worker x 4 workers = 4 CPUs.*has 2"):
        RayVectorEnv(ENV_ID, 4, envs_per_worker=1, num_cpus=1)


def test_unreachable_ray_address():
    with pytest.raises(ConnectionError, match=r"Ray address '127.0.0.1:1' is unreachable"):
        RayVectorEnv(ENV_ID, 2, address="127.0.0.1:1")


@pytest.mark.parametrize(
    ("actions", "error", "match"),
    [
        (
            np.zeros((2, 1), np.float32),
            ValueError,
            r"action shape \(2, 1\) is wrong; expected \(3, 1\)",
        ),
        (np.zeros(3, np.float32), ValueError, r"expected \(3, 1\)"),
        (np.full((3, 1), "x"), TypeError, "not numeric"),
        (np.array([[0.0], [np.nan], [0.0]]), ValueError, r"NaN/Inf at envs \['1'\]"),
    ],
)
def test_bad_actions(serial, actions, error, match):
    with pytest.raises(error, match=match):
        serial.step(actions)


def test_clip_mode_accepts_non_finite_actions():
    vec = SerialVectorEnv(ENV_ID, 2, invalid_action="clip")
    vec.reset(seed=0)
    vec.step(np.array([[np.inf], [np.nan]]))
    assert vec.get_attr("task")[0].data.ctrl[0] == 1.0
    assert vec.get_attr("task")[1].data.ctrl[0] == 0.0


def test_bad_options():
    with pytest.raises(ValueError, match="invalid_action='drop'"):
        SerialVectorEnv(ENV_ID, 2, invalid_action="drop")
    with pytest.raises(ValueError, match="max_restarts=-5"):
        SerialVectorEnv(ENV_ID, 2, max_restarts=-5)
    with pytest.raises(ValueError, match="'Sometimes' is not a valid AutoresetMode"):
        SerialVectorEnv(ENV_ID, 2, autoreset_mode="Sometimes")
    with pytest.raises(TypeError, match="env_fns=42"):
        SerialVectorEnv(42, 2)  # type: ignore[arg-type]


def test_step_before_reset():
    with pytest.raises(RuntimeError, match=r"step\(\) called before reset\(\)"):
        SerialVectorEnv(ENV_ID, 2).step(np.zeros((2, 1), np.float32))


def test_envs_with_different_spaces_are_rejected():
    import gymnasium as gym

    fns = [lambda: gym.make(ENV_ID), lambda: gym.make("Pendulum-v1")]
    with pytest.raises(RuntimeError, match="env 1 has spaces"):
        SerialVectorEnv(fns)
