"""chronogym.integrations.sb3: chronogym vector envs as Stable-Baselines3 VecEnvs.

Real Gymnasium, real Ray (the session's 2-CPU cluster), real SB3: the adapter is checked
number for number against SB3's own DummyVecEnv, under SB3's VecEnv wrappers, and by
training PPO on cart-pole through RayVectorEnv.
"""

from __future__ import annotations

import ctypes.util
import functools
import subprocess
import sys
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from gymnasium.vector import AutoresetMode

import chronogym

pytest.importorskip("stable_baselines3")

from sb3_compare import compare_with_dummy  # tests/integrations/sb3_compare.py
from stable_baselines3.common.env_checker import check_env
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.utils import check_for_correct_spaces
from stable_baselines3.common.vec_env import (
    DummyVecEnv,
    VecCheckNan,
    VecMonitor,
    VecNormalize,
)

from chronogym.integrations.sb3 import SB3VecEnv, make_sb3_vec_env, split_info

CARTPOLE = "chronogym/CartPole-v0"
SAME_STEP = AutoresetMode.SAME_STEP
HAS_EGL = ctypes.util.find_library("EGL") is not None


def dummy(n: int, env_id: str = CARTPOLE, **env_kwargs: Any) -> DummyVecEnv:
    """SB3's own reference: DummyVecEnv over gymnasium.make of the same id."""
    return DummyVecEnv([lambda: gym.make(env_id, **env_kwargs) for _ in range(n)])


def cartpole_actions(steps: int, n: int) -> list[np.ndarray]:
    """Env 0 pushes one way (falls: terminated), env 1 alternates (lasts: truncated), the
    rest act at random; so a short run crosses both kinds of episode end."""
    rng = np.random.default_rng(7)
    rows = []
    for t in range(steps):
        a = rng.uniform(-1, 1, (n, 1)).astype(np.float32)
        a[0] = 1.0
        a[1] = 1.0 if t % 2 else -1.0
        rows.append(a)
    return rows


# -- numbers ---------------------------------------------------------------------------
BUILDERS = {
    "ray": lambda n, kw: make_sb3_vec_env(CARTPOLE, n, env_kwargs=kw, envs_per_worker=2),
    "ray-by-id": lambda n, kw: SB3VecEnv(
        chronogym.RayVectorEnv(
            CARTPOLE, n, envs_per_worker=2, autoreset_mode=SAME_STEP, env_kwargs=kw
        )
    ),
    "serial": lambda n, kw: make_sb3_vec_env(CARTPOLE, n, "serial", env_kwargs=kw),
    "gymnasium-sync": lambda n, kw: SB3VecEnv(
        gym.make_vec(CARTPOLE, n, "sync", vector_kwargs={"autoreset_mode": SAME_STEP}, **kw)
    ),
    # subprocesses; an error in any call would shut them down (the adapter must not cause one)
    "gymnasium-async": lambda n, kw: SB3VecEnv(
        gym.make_vec(CARTPOLE, n, "async", vector_kwargs={"autoreset_mode": SAME_STEP}, **kw)
    ),
}


@pytest.mark.parametrize("backend", list(BUILDERS))
def test_numbers_match_dummy_vec_env(backend: str, request: pytest.FixtureRequest) -> None:
    if backend.startswith("ray"):
        request.getfixturevalue("ray_cluster")
    n, kw = 4, {"max_episode_steps": 25}
    venv, ref = BUILDERS[backend](n, kw), dummy(n, **kw)
    try:
        ends = compare_with_dummy(venv, ref, cartpole_actions(60, n), seed=3)
    finally:
        venv.close()
        ref.close()
    assert ends["terminated"] >= 2 and ends["truncated"] >= 2, ends


class StructuredEnv(gym.Env):
    """Dict or Tuple observations, nested infos, random episode ends (for the conversions)."""

    def __init__(self, kind: str = "dict") -> None:
        parts = {
            "pos": spaces.Box(-1.0, 1.0, (2,), np.float32),
            "mode": spaces.Discrete(3),
        }
        self.kind = kind
        self.observation_space = (
            spaces.Dict(parts) if kind == "dict" else spaces.Tuple(tuple(parts.values()))
        )
        self.action_space = spaces.Discrete(2)
        self.t = 0

    def _obs(self) -> Any:
        pos = self.np_random.uniform(-1, 1, 2).astype(np.float32)
        mode = int(self.np_random.integers(3))
        return {"pos": pos, "mode": mode} if self.kind == "dict" else (pos, mode)

    def reset(self, *, seed: int | None = None, options: dict | None = None) -> tuple:
        super().reset(seed=seed)
        self.t = 0
        return self._obs(), {"start": float(self.np_random.random())}

    def step(self, action: Any) -> tuple:
        self.t += 1
        terminated = bool(self.np_random.random() < 0.2)
        truncated = self.t >= 4
        info = {"t": self.t, "detail": {"action": int(action)}}
        return self._obs(), float(action) - 0.5, terminated, truncated, info


@pytest.mark.parametrize("kind", ["dict", "tuple"])
def test_structured_observations_and_infos_match_dummy_vec_env(kind: str) -> None:
    n = 3
    factory = functools.partial(StructuredEnv, kind)
    venv = SB3VecEnv(chronogym.SerialVectorEnv([factory] * n, autoreset_mode=SAME_STEP))
    ref = DummyVecEnv([factory] * n)
    rng = np.random.default_rng(0)
    actions = [rng.integers(0, 2, n) for _ in range(20)]
    try:
        ends = compare_with_dummy(venv, ref, actions, seed=11)
    finally:
        venv.close()
        ref.close()
    assert ends["terminated"] and ends["truncated"], ends


def test_split_info_undoes_gymnasium_batching() -> None:
    info = {
        "a": np.array([1, 0, 3]),
        "_a": np.array([True, False, True]),
        "nested": {"x": np.array([0.5, 0.0, 0.0]), "_x": np.array([True, False, False])},
        "_nested": np.array([True, False, False]),
        "shared": "same for all",  # not batched (no mask, not an array per env)
    }
    assert split_info(info, 3) == [
        {"a": 1, "nested": {"x": 0.5}, "shared": "same for all"},
        {"shared": "same for all"},
        {"a": 3, "shared": "same for all"},
    ]


def test_replaced_env_reports_restart_in_step_info() -> None:
    from faulty_tasks import FailingEnv  # tests/faulty_tasks.py: fails at step 5 of seed 1

    factory = functools.partial(FailingEnv, 1)
    venv = SB3VecEnv(
        chronogym.SerialVectorEnv([factory] * 2, autoreset_mode=SAME_STEP, env_errors="restart")
    )
    try:
        venv.seed(0)
        obs = venv.reset()
        for _ in range(5):
            last = obs
            obs, rewards, dones, infos = venv.step(np.zeros((2, 1), np.float32))
    finally:
        venv.close()
    assert dones.tolist() == [False, True] and rewards[1] == 0.0
    assert infos[1]["worker_restarted"] and "injected failure" in infos[1]["worker_error"]
    assert infos[1]["TimeLimit.truncated"] is True
    np.testing.assert_array_equal(infos[1]["terminal_observation"], last[1])


# -- SB3's own checks and wrappers -----------------------------------------------------
def test_sb3_checks_and_vec_wrappers(ray_cluster: Any) -> None:
    check_env(gym.make(CARTPOLE), warn=True)  # SB3's checker on the single env
    kw = {"max_episode_steps": 20}
    venv = make_sb3_vec_env(CARTPOLE, 4, env_kwargs=kw, envs_per_worker=2, seed=0)
    ref = gym.make(CARTPOLE, **kw)
    check_for_correct_spaces(venv, ref.observation_space, ref.action_space)
    wrapped = VecNormalize(VecMonitor(VecCheckNan(venv, raise_exception=True)), gamma=0.99)
    try:
        obs = wrapped.reset()
        assert obs.shape == (4, 4) and obs.dtype == np.float32
        episodes = []
        for a in cartpole_actions(45, 4):
            obs, _, dones, infos = wrapped.step(a)
            assert np.all(np.isfinite(obs)) and np.all(np.abs(obs) <= 10.0)  # clip_obs
            for i in np.flatnonzero(dones):
                episodes.append(infos[i]["episode"])
                raw = wrapped.unnormalize_obs(infos[i]["terminal_observation"])
                assert raw.shape == (4,)
        assert episodes and all(e["l"] == e["r"] for e in episodes)  # reward 1 per step
        assert {e["l"] for e in episodes} >= {20}  # truncations at the limit, and falls
        assert min(e["l"] for e in episodes) < 20
        assert wrapped.obs_rms.count > 45 * 4
        assert wrapped.env_is_wrapped(Monitor) == [False] * 4
    finally:
        wrapped.close()
        ref.close()


def test_ppo_improves_cartpole_through_ray(ray_cluster: Any) -> None:
    torch = pytest.importorskip("torch")
    from stable_baselines3 import PPO
    from stable_baselines3.common.evaluation import evaluate_policy

    torch.set_num_threads(1)
    kw = {"max_episode_steps": 200}
    train = VecMonitor(make_sb3_vec_env(CARTPOLE, 8, env_kwargs=kw, envs_per_worker=4))
    evaluation = VecMonitor(make_sb3_vec_env(CARTPOLE, 4, "serial", env_kwargs=kw))
    model = PPO(
        "MlpPolicy",
        train,
        n_steps=64,
        batch_size=128,
        n_epochs=10,
        learning_rate=1e-3,
        gamma=0.98,
        policy_kwargs={"net_arch": [32, 32]},
        seed=0,
        device="cpu",
    )

    def mean_return() -> float:
        evaluation.seed(123)  # the same 8 start states before and after training
        returns, _ = evaluate_policy(
            model, evaluation, n_eval_episodes=8, deterministic=True, return_episode_rewards=True
        )
        return float(np.mean(returns))

    try:
        before = mean_return()
        model.learn(8192)
        after = mean_return()
    finally:
        train.close()
        evaluation.close()
    assert model.num_timesteps == 8192
    assert after > 2 * before and after > 100, (before, after)


# -- attributes, methods, indices ------------------------------------------------------
def test_indices_reach_only_those_envs(ray_cluster: Any) -> None:
    venv = make_sb3_vec_env(CARTPOLE, 4, envs_per_worker=2)
    try:
        venv.seed(10)
        venv.reset()
        assert venv.get_attr("np_random_seed") == [10, 11, 12, 13]
        assert venv.get_attr("np_random_seed", indices=[3, 0]) == [13, 10]
        assert venv.get_attr("np_random_seed", indices=2) == [12]
        # a method with side effects runs on the chosen envs only
        (obs, _), *rest = venv.env_method("reset", seed=99, indices=[2])
        assert rest == [] and obs.shape == (4,)
        assert venv.get_attr("np_random_seed") == [10, 11, 99, 13]
        venv.set_attr("gain", 1.0)
        venv.set_attr("gain", 2.0, indices=[1, 3])
        assert venv.get_attr("gain") == [1.0, 2.0, 1.0, 2.0]
        venv.set_attr("only_here", [1, 2], indices=[2])  # a list value is one value
        assert venv.get_attr("only_here", indices=[2]) == [[1, 2]]
        with pytest.raises(AttributeError, match="only_here"):
            venv.get_attr("only_here")  # the other envs never got it
        assert venv.env_is_wrapped(Monitor) == [False] * 4
        assert venv.env_is_wrapped(gym.wrappers.OrderEnforcing, indices=[0, 2]) == [True, True]
        assert venv.has_attr("np_random_seed") and not venv.has_attr("no_such_attr")
    finally:
        venv.close()


def test_indices_on_a_vector_env_built_elsewhere() -> None:
    """Envs that do not know their index: reads and writes still reach only those envs."""
    venv = SB3VecEnv(
        chronogym.SerialVectorEnv(
            [lambda: Monitor(gym.make(CARTPOLE))] * 3, autoreset_mode=SAME_STEP
        )
    )
    try:
        venv.seed(5)
        venv.reset()
        venv.set_attr("gain", 1.0)
        venv.set_attr("gain", 3.0, indices=[0])
        assert venv.get_attr("gain") == [3.0, 1.0, 1.0]
        with pytest.raises(AttributeError, match="'fresh'.*make_sb3_vec_env"):
            venv.set_attr("fresh", 1, indices=[1])
        with pytest.warns(UserWarning, match="ran on all 3 envs"):
            assert venv.env_method("get_episode_rewards", indices=[1]) == [[]]
        assert venv.env_is_wrapped(Monitor) == [True] * 3
        assert venv.env_is_wrapped(gym.wrappers.TimeLimit, indices=[1]) == [False]
    finally:
        venv.close()


def test_seed_and_options_are_used_by_the_next_reset_only() -> None:
    venv = make_sb3_vec_env(CARTPOLE, 3, "serial")
    try:
        assert venv.seed(7) == [7, 8, 9]
        first = venv.reset()
        assert venv.get_attr("np_random_seed") == [7, 8, 9]
        assert venv._seeds == [None] * 3  # consumed
        assert not np.array_equal(venv.reset(), first)  # streams continue, no reseed
        venv.set_options({"noise": 0.0})
        np.testing.assert_array_equal(venv.reset(), np.zeros((3, 4)))
        assert np.abs(venv.reset()).max() > 0  # options consumed as well
        venv.set_options([{"noise": 0.0}, {}, {}])
        with pytest.raises(ValueError, match=r"env 1 options=\{\}.*single dict"):
            venv.reset()
        seeded = make_sb3_vec_env(CARTPOLE, 2, "serial", seed=4)
        assert seeded._seeds == [4, 5]
        seeded.close()
    finally:
        venv.close()


@pytest.mark.skipif(not HAS_EGL, reason="no EGL library: install libegl1 + libgl1-mesa-dri")
def test_render_matches_dummy_vec_env() -> None:
    venv = make_sb3_vec_env(CARTPOLE, 2, "serial", env_kwargs={"render_mode": "rgb_array"})
    ref = dummy(2, render_mode="rgb_array")
    try:
        assert venv.render_mode == "rgb_array"
        venv.seed(0)
        ref.seed(0)
        venv.reset()
        ref.reset()
        images = venv.get_images()
        assert len(images) == 2 and images[0].shape == (360, 480, 3)
        np.testing.assert_array_equal(venv.render(), ref.render())  # tiled as SB3 tiles
    finally:
        venv.close()
        ref.close()


def test_get_images_without_rgb_array_warns() -> None:
    venv = make_sb3_vec_env(CARTPOLE, 2, "serial")
    try:
        assert venv.render_mode is None
        with pytest.warns(UserWarning, match="rgb_array"):
            assert venv.get_images() == [None, None]
    finally:
        venv.close()


# -- bad input -------------------------------------------------------------------------
def test_bad_input_names_the_value() -> None:
    next_step = chronogym.SerialVectorEnv(CARTPOLE, 2)
    with pytest.raises(ValueError, match="autoreset_mode=<AutoresetMode.NEXT_STEP"):
        SB3VecEnv(next_step)
    next_step.close()
    with pytest.raises(ValueError, match="autoreset_mode='NextStep'"):
        make_sb3_vec_env(CARTPOLE, 2, "serial", autoreset_mode="NextStep")
    with pytest.raises(ValueError, match="backend='gpu'"):
        make_sb3_vec_env(CARTPOLE, 2, "gpu")
    with pytest.raises(ValueError, match="num_envs=0"):
        make_sb3_vec_env(CARTPOLE, 0, "serial")
    with pytest.raises(TypeError, match="env_id=<function.*expected a registered Gymnasium id"):
        make_sb3_vec_env(lambda: gym.make(CARTPOLE), 2, "serial")
    with pytest.raises(gym.error.NameNotFound, match="NoSuch"):
        make_sb3_vec_env("chronogym/NoSuch-v0", 2, "ray")  # in the driver, before any worker
    from_spec = make_sb3_vec_env(gym.spec(CARTPOLE), 2, "serial")
    assert from_spec.get_attr("spec")[0].id == CARTPOLE
    from_spec.close()
    venv = make_sb3_vec_env(CARTPOLE, 3, "serial")
    try:
        for bad, error in (
            (3, IndexError),
            ([0, -4], IndexError),
            ("0", TypeError),
            (1.0, TypeError),
        ):
            with pytest.raises(error, match=rf"indices={bad!r}".replace("[", r"\[")):
                venv.get_attr("np_random_seed", indices=bad)
        with pytest.raises(chronogym.BoolArgumentError, match=r"indices=\[True\] holds the bool"):
            venv.get_attr("np_random_seed", indices=[True])
        with pytest.raises(IndexError, match=r"indices=\[4\]"):
            venv.set_attr("gain", 1.0, indices=[4])
        with pytest.raises(RuntimeError, match="step_async"):
            venv.step_wait()
    finally:
        venv.close()


# -- optional dependency ---------------------------------------------------------------
def run_python(code: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-c", code], capture_output=True, text=True)


def test_import_chronogym_loads_neither_sb3_nor_torch() -> None:
    out = run_python(
        "import sys, chronogym, chronogym.integrations; "
        "print(sorted(m for m in ('stable_baselines3', 'torch') if m in sys.modules))"
    )
    assert out.returncode == 0, out.stderr
    assert out.stdout.strip() == "[]"


def test_without_sb3_the_import_error_says_how_to_install() -> None:
    # sys.modules[name] = None is how Python marks a module as not importable
    out = run_python(
        "import sys; sys.modules['stable_baselines3'] = None; import chronogym.integrations.sb3"
    )
    assert out.returncode != 0
    assert "ImportError" in out.stderr
    assert 'pip install "chronogym[sb3]"' in out.stderr
