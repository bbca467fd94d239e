"""SimEnv: Gymnasium conformance, time limits, divergence, action checks, rendering."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from faulty_tasks import ExplodingCartPole
from gymnasium.utils.env_checker import check_env

import chronogym
from chronogym import SimEnv
from chronogym.engines.mujoco import gl_unavailable
from chronogym.registration import TASKS
from chronogym.tasks.cartpole import CartPoleTask

GL_PROBLEM = gl_unavailable()  # None when MuJoCo loaded an OpenGL backend (README: Rendering)
ENV_IDS = [f"chronogym/{name}" for name in TASKS]


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_registered_env_passes_gymnasium_checker(env_id):
    env = gym.make(env_id, render_mode=None if GL_PROBLEM else "rgb_array")
    check_env(env.unwrapped)  # render check on: metadata lists rgb_array only when it can render
    env.close()


def test_make_forwards_task_kwargs():
    env = gym.make("chronogym/CartPole-v0", k=4, dt=0.001)
    assert env.unwrapped.k == 4
    assert env.unwrapped.task.model.opt.timestep == 0.001
    assert env.unwrapped.control_dt == pytest.approx(0.004)


def test_step_advances_k_ticks():
    env = SimEnv(CartPoleTask(k=7))
    env.reset(seed=0)
    env.step(np.zeros(1, dtype=np.float32))
    assert env.task.data.time == pytest.approx(7 * 0.002)
    assert env.sim_time == pytest.approx(7 * 0.002)


def test_time_limit_truncates():
    env = SimEnv(CartPoleTask(max_episode_steps=3, reset_noise=0.0))
    env.reset(seed=0)
    flags = [env.step(np.zeros(1, dtype=np.float32))[3] for _ in range(3)]
    assert flags == [False, False, True]


def test_max_episode_steps_argument_overrides_task():
    env = SimEnv(CartPoleTask(reset_noise=0.0), max_episode_steps=2)
    env.reset(seed=0)
    env.step(np.zeros(1, dtype=np.float32))
    assert env.step(np.zeros(1, dtype=np.float32))[3] is True


def test_endless_cartpole_only_truncates():
    """``terminate=False`` (the throughput benchmarks): the pole falls, the episode goes on."""
    env = gym.make("chronogym/CartPole-v0", terminate=False, max_episode_steps=60)
    env.reset(seed=0)
    steps = [env.step(np.ones(1, dtype=np.float32)) for _ in range(60)]
    assert abs(steps[-1][0][1]) > CartPoleTask.max_angle  # it would have terminated
    assert not any(s[2] for s in steps) and [s[3] for s in steps].index(True) == 59
    with pytest.raises(ValueError, match=r"terminate='no': expected True or False"):
        CartPoleTask(terminate="no")


def test_divergence_terminates_with_flag():
    env = SimEnv(ExplodingCartPole(explode_at=2))
    env.reset(seed=0)
    obs, reward, terminated, _, info = env.step(np.zeros(1, dtype=np.float32))
    assert not terminated and "diverged" not in info
    obs, reward, terminated, _, info = env.step(np.zeros(1, dtype=np.float32))
    assert terminated is True and info["diverged"] is True
    assert np.isfinite(obs).all() and np.isfinite(reward)


def test_seeded_reset_is_reproducible_and_later_resets_continue_the_stream():
    env = SimEnv(CartPoleTask())
    first, _ = env.reset(seed=42)
    second, _ = env.reset()
    again, _ = env.reset(seed=42)
    np.testing.assert_array_equal(first, again)
    assert not np.array_equal(first, second)


@pytest.mark.parametrize(
    ("action", "error", "match"),
    [
        (
            np.zeros(2, dtype=np.float32),
            ValueError,
            r"action shape \(2,\) is wrong; expected \(1,\)",
        ),
        (np.array(["a"]), TypeError, "action dtype <U1 is not numeric"),
        (np.array([np.nan], dtype=np.float32), ValueError, "NaN/Inf"),
        (np.array([np.inf]), ValueError, "NaN/Inf"),
    ],
)
def test_bad_action_is_rejected(action, error, match):
    env = SimEnv(CartPoleTask())
    env.reset(seed=0)
    with pytest.raises(error, match=match):
        env.step(action)


def test_clip_mode_replaces_non_finite_actions():
    env = SimEnv(CartPoleTask(), invalid_action="clip")
    env.reset(seed=0)
    env.step(np.array([np.inf], dtype=np.float32))
    assert env.task.data.ctrl[0] == 1.0
    env.step(np.array([np.nan], dtype=np.float32))
    assert env.task.data.ctrl[0] == 0.0


def test_unknown_invalid_action_mode_is_rejected():
    with pytest.raises(ValueError, match="invalid_action='ignore'"):
        SimEnv(CartPoleTask(), invalid_action="ignore")


@pytest.mark.skipif(GL_PROBLEM is not None, reason=f"no OpenGL: {GL_PROBLEM}")
def test_render_rgb_array():
    env = gym.make("chronogym/CartPole-v0", render_mode="rgb_array")
    env.reset(seed=0)
    frame = env.render()
    assert frame.shape == (360, 480, 3) and frame.dtype == np.uint8
    assert frame.std() > 5  # a real picture, not a blank buffer
    env.close()


def test_package_import_is_light():
    import subprocess
    import sys

    code = (
        "import sys, chronogym; "
        "print(sorted(m for m in ('ray', 'mujoco', 'torch', 'pychrono') if m in sys.modules))"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    assert out.stdout.strip() == "[]"
    assert {"SimEnv", "RayVectorEnv", "Task", "advance_all"} <= set(chronogym.__all__)


def test_divergence_check_reads_the_right_mujoco_warning_counters():
    import mujoco

    from chronogym.engines import mujoco as engine

    warning = mujoco.mjtWarning
    assert (
        int(warning.mjWARN_BADQPOS),
        int(warning.mjWARN_BADQVEL),
        int(warning.mjWARN_BADQACC),
    ) == (engine._BADQPOS, engine._BADQVEL, engine._BADQACC)


# -- what observe() returns is checked against observation_space ----------------------------
class ObservesWrong(CartPoleTask):
    """CartPole whose observe() returns ``wrong(obs)`` from call ``from_call`` on (1: reset)."""

    def __init__(self, wrong, space=None, from_call: int = 1) -> None:
        super().__init__(reset_noise=0.0)
        self.wrong, self.space, self.from_call, self.calls = wrong, space, from_call, 0

    def setup(self) -> None:
        super().setup()
        if self.space is not None:
            self.observation_space = self.space

    def observe(self):
        self.calls += 1
        obs = super().observe()
        return self.wrong(obs) if self.calls >= self.from_call else obs

    def terminated(self, obs) -> bool:
        return False


FLOAT32_4 = gym.spaces.Box(-np.inf, np.inf, (4,), np.float32)
NESTED = gym.spaces.Dict(
    pos=gym.spaces.Box(-1, 1, (2,)), mode=gym.spaces.Tuple((gym.spaces.Discrete(3),))
)


@pytest.mark.parametrize(
    ("wrong", "space", "message"),
    [
        (
            lambda obs: obs[:3],
            FLOAT32_4,
            r"ObservesWrong.observe\(\) returned shape \(3,\) float64 in reset\(\); the "
            r"observation space is Box\(-inf, inf, \(4,\), float32\): expected shape \(4,\) "
            r"and float32",
        ),
        (
            lambda obs: obs.astype(np.complex64),
            FLOAT32_4,
            r"returned shape \(4,\) complex64 in reset\(\); the observation space is Box",
        ),
        (lambda obs: list(obs[:2]), None, r"returned a list of shape \(2,\) float64 in reset"),
        (
            lambda obs: {"pos": obs[:2], "mode": (0.5,)},
            NESTED,
            r"returned obs\['mode'\]\[0\]: a float of shape \(\) float64 in reset\(\); "
            r"obs\['mode'\]\[0\] in the observation space is Discrete\(3\)",
        ),
        (
            lambda obs: {"pos": obs[:2]},
            NESTED,
            r"returned a dict with keys \['pos'\] in reset\(\); the observation space is "
            r"Dict\(.*\): expected a dict with keys \['mode', 'pos'\]",
        ),
        (
            lambda obs: "far too long",
            gym.spaces.Text(5),
            r"returned a str 'far too long' in reset\(\); the observation space is Text\(1, 5",
        ),
    ],
)
def test_reset_raises_when_the_observation_does_not_fit_the_space(wrong, space, message):
    env = SimEnv(ObservesWrong(wrong, space))
    with pytest.raises(chronogym.TaskDefinitionError, match=message):
        env.reset(seed=0)


def test_first_step_raises_on_a_wrong_shape_then_steps_are_not_checked():
    env = SimEnv(ObservesWrong(lambda obs: obs[:3], from_call=2))
    env.reset(seed=0)
    message = r"ObservesWrong.observe\(\) returned shape \(3,\) float64 in step\(\)"
    with pytest.raises(chronogym.TaskDefinitionError, match=message):
        env.step(np.zeros(1, dtype=np.float32))
    late = SimEnv(ObservesWrong(lambda obs: obs[:3], from_call=3))
    late.reset(seed=0)
    late.step(np.zeros(1, dtype=np.float32))  # checked, fine
    assert late.step(np.zeros(1, dtype=np.float32))[0].shape == (3,)  # no per-step check
    with pytest.raises(chronogym.TaskDefinitionError, match=r"shape \(3,\) float64 in reset"):
        late.reset()  # every reset is checked


def test_a_dtype_that_casts_to_the_space_passes_unchanged():
    """float64 for a float32 Box: returned as is (vector envs cast it, as Gymnasium's do)."""
    env = SimEnv(ObservesWrong(lambda obs: obs, FLOAT32_4))
    obs, _ = env.reset(seed=0)
    assert obs.dtype == np.float64
    assert env.step(np.zeros(1, dtype=np.float32))[0].dtype == np.float64


def test_function_task_observation_is_named_by_its_function():
    def observe_pair(resources):
        return np.zeros(2)

    task = chronogym.FunctionTask(
        init=lambda: ([lambda dt: None], None),
        reset=lambda resources, rng, options: None,
        apply_action=lambda resources, action: None,
        observe=observe_pair,
        reward=lambda resources, action, obs: 0.0,
        terminated=lambda resources, obs: False,
        dt=0.01,
        observation_space=gym.spaces.Box(-1, 1, (3,)),
        action_space=gym.spaces.Box(-1, 1, (1,)),
    )
    message = (
        r"FunctionTask's observe=test_function_task_observation_is_named_by_its_function"
        r".<locals>.observe_pair returned shape \(2,\) float64 in reset\(\)"
    )
    with pytest.raises(chronogym.TaskDefinitionError, match=message):
        SimEnv(task).reset(seed=0)
