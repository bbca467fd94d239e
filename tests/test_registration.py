"""Gymnasium's registry: vector entry points, the horizon in the spec, re-registration,
and the py.typed marker."""

from __future__ import annotations

import importlib.resources
import shutil
import subprocess
import sys
import textwrap
import warnings
import zipfile
from pathlib import Path

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces
from user_scripts import DRIFT_TASK, run_user_script

import chronogym
from chronogym import RayVectorEnv, SerialVectorEnv, SimEnv, register_task
from chronogym.cli import main as cli_main
from chronogym.registration import ENVS, NAMESPACE, VECTOR_ENTRY_POINT
from chronogym.tasks.cartpole.mujoco import CartPoleTask

CARTPOLE = "chronogym/CartPole-v0"


class Walk(chronogym.Task):
    """A cheap task whose horizon is an argument (as the Go1 task's is)."""

    dt, k = 0.1, 1

    def __init__(self, horizon: int | None = 9, gain: float = 1.0) -> None:
        self.max_episode_steps = horizon
        self.gain = gain

    def init(self):
        self.observation_space = spaces.Box(-np.inf, np.inf, (1,), np.float64)
        self.action_space = spaces.Box(-1, 1, (1,), np.float32)

    def reset(self, rng, options):
        self.x = float(rng.uniform(-1, 1))

    def apply_action(self, action):
        self.x += self.gain * float(action[0])

    def observe(self):
        return np.array([self.x])

    def reward(self, action, obs):
        return -abs(self.x)

    def terminated(self, obs):
        return abs(self.x) > 50

    def info(self):
        return {"x": self.x}


class Other(Walk):
    pass


@pytest.fixture
def test_ids():
    """Ids registered by a test, removed afterwards."""
    ids: list[str] = []
    yield ids
    for env_id in ids:
        gym.registry.pop(env_id, None)


def actions(t: int, n: int) -> np.ndarray:
    return np.full((n, 1), np.sin(1.7 * t), np.float32)


def rollout(vec, steps: int = 30, seed: int = 3) -> list:
    """Every number a vector env returns (obs, rewards, flags, final obs) over ``steps``."""
    obs, _ = vec.reset(seed=seed)
    out = [obs]
    for t in range(steps):
        obs, rew, term, trunc, info = vec.step(actions(t, vec.num_envs))
        out += [obs, rew, term, trunc, info.get("_final_obs", np.zeros(vec.num_envs, bool))]
    vec.close()
    return out


def assert_same(a: list, b: list) -> None:
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        np.testing.assert_array_equal(x, y)


# --- vector_entry_point -----------------------------------------------------------------


def test_every_chronogym_id_has_the_vector_entry_point():
    ids = [i for i in gym.registry if i.startswith(f"{NAMESPACE}/")]
    plain = {f"{NAMESPACE}/{name}": entry for name, entry in ENVS.items()}
    tasks = [i for i in ids if i not in plain]
    assert tasks and set(plain) <= set(ids)
    assert {gym.spec(i).vector_entry_point for i in tasks} == {VECTOR_ENTRY_POINT}
    assert {i: (gym.spec(i).entry_point, gym.spec(i).vector_entry_point) for i in plain} == plain


def test_make_vec_vector_entry_point_is_ray_and_matches_sync(ray_cluster):
    # max_episode_steps=12: episodes truncate and autoreset within the 30 steps.
    vec = gym.make_vec(
        CARTPOLE,
        4,
        vectorization_mode="vector_entry_point",
        max_episode_steps=12,
        vector_options={"envs_per_worker": 2},
    )
    assert isinstance(vec, RayVectorEnv)
    assert (vec.num_workers, vec.envs_per_worker) == (2, 2)
    assert vec.spec.id == CARTPOLE
    ray_run = rollout(vec)
    sync = gym.make_vec(CARTPOLE, 4, vectorization_mode="sync", max_episode_steps=12)
    sync_run = rollout(sync)
    assert any(trunc.any() for trunc in ray_run[4::5])  # a truncation was compared
    assert_same(ray_run, sync_run)


def test_vector_entry_point_other_backends_and_task_kwargs(test_ids):
    register_task("test/Walk-v0", Walk, gain=0.5)
    test_ids.append("test/Walk-v0")
    sync_run = rollout(gym.make_vec("test/Walk-v0", 3, vectorization_mode="sync", horizon=5))
    for backend, cls in (("serial", SerialVectorEnv), ("sync", gym.vector.SyncVectorEnv)):
        vec = gym.make_vec(
            "test/Walk-v0", 3, vectorization_mode="vector_entry_point", backend=backend, horizon=5
        )
        assert type(vec) is cls
        assert_same(rollout(vec), sync_run)


def test_vector_entry_point_bad_backend_and_options_name_the_value():
    with pytest.raises(ValueError, match=r"backend='threads': expected one of \('ray', 'serial'"):
        gym.make_vec(CARTPOLE, 2, vectorization_mode="vector_entry_point", backend="threads")
    with pytest.raises(TypeError, match=r"vector_options=\[2\]: expected a dict"):
        gym.make_vec(CARTPOLE, 2, vectorization_mode="vector_entry_point", vector_options=[2])


SCRIPT = DRIFT_TASK + textwrap.dedent(
    """
    register_task("newuser/Drift-v0", Drift)
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)

    def rollout(vec):
        out = [vec.reset(seed=5)[0]]
        for t in range(20):
            obs, rew, term, trunc, _ = vec.step(np.full((4, 1), 0.3 * np.sin(t), np.float32))
            out += [obs, rew[:, None], term[:, None], trunc[:, None]]
        vec.close()
        return np.concatenate(out, axis=1)

    vec = gym.make_vec(
        "newuser/Drift-v0", 4, vectorization_mode="vector_entry_point",
        vector_options={"envs_per_worker": 2},
    )
    assert type(vec).__name__ == "RayVectorEnv", vec
    ray_run = rollout(vec)
    sync_run = rollout(gym.make_vec("newuser/Drift-v0", 4, vectorization_mode="sync"))
    assert np.array_equal(ray_run, sync_run), (ray_run, sync_run)
    print("same numbers", ray_run.shape)
    """
)


def test_vector_entry_point_with_an_id_registered_in_the_users_script(tmp_path):
    done = run_user_script(tmp_path, SCRIPT)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "same numbers (4, 81)" in done.stdout


# --- the horizon in the spec ----------------------------------------------------------


def episode(env, seed: int, steps: int) -> list:
    """Every number and info of ``steps`` steps from a reset (resetting after an end)."""
    obs, info = env.reset(seed=seed)
    out = [(obs, info)]
    for t in range(steps):
        obs, rew, term, trunc, info = env.step(actions(t, 1)[0])
        out.append((obs, rew, term, trunc, info))
        if term or trunc:
            out.append(env.reset())
    return out


def assert_same_episodes(a: list, b: list) -> None:
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        assert len(x) == len(y)
        for u, v in zip(x, y, strict=True):
            if isinstance(u, dict):
                assert u.keys() == v.keys() and all(np.array_equal(u[k], v[k]) for k in u)
            else:
                np.testing.assert_array_equal(u, v)


def ends(run: list) -> list[int]:
    """The step numbers (1-based, from each reset) at which the episodes truncated."""
    out, t = [], 0
    for item in run[1:]:
        if len(item) == 2:
            t = 0
            continue
        t += 1
        if item[3]:
            out.append(t)
    return out


def test_spec_shows_the_tasks_horizon():
    env = gym.make(CARTPOLE)
    assert env.spec.max_episode_steps == 500 == env.unwrapped.max_episode_steps
    assert gym.make(CARTPOLE, max_episode_steps=30).spec.max_episode_steps == 30
    env.close()


def test_the_horizon_follows_the_tasks_arguments_and_trajectories_are_unchanged(test_ids):
    register_task("test/Walk-v0", Walk)
    test_ids.append("test/Walk-v0")
    env = gym.make("test/Walk-v0", horizon=4)
    assert env.spec.max_episode_steps == 4
    # No TimeLimit: the SimEnv alone truncates, as before; one truncation per episode.
    assert not any(isinstance(w, gym.wrappers.TimeLimit) for w in wrappers_of(env))
    run = episode(env, seed=1, steps=13)
    assert ends(run) == [4, 4, 4]
    assert_same_episodes(run, episode(SimEnv(Walk(horizon=4)), seed=1, steps=13))
    # gymnasium.make's own max_episode_steps: its TimeLimit, shown in the spec.
    env = gym.make("test/Walk-v0", max_episode_steps=3)
    assert env.spec.max_episode_steps == 3
    assert ends(episode(env, seed=1, steps=8)) == [3, 3]
    # A task without a horizon: none in the spec, and episodes run on.
    env = gym.make("test/Walk-v0", horizon=None)
    assert env.spec.max_episode_steps is None
    assert ends(episode(env, seed=1, steps=30)) == []


def test_a_default_horizon_at_registration_and_the_spec_remakes_the_same_env(test_ids):
    register_task("test/ShortCartPole-v0", CartPoleTask, max_episode_steps=7)
    test_ids.append("test/ShortCartPole-v0")
    env = gym.make("test/ShortCartPole-v0")
    assert env.spec.max_episode_steps == 7
    run = episode(env, seed=2, steps=20)
    assert_same_episodes(run, episode(SimEnv(CartPoleTask(), max_episode_steps=7), 2, 20))
    assert_same_episodes(run, episode(gym.make(env.spec), seed=2, steps=20))


def wrappers_of(env) -> list:
    out = []
    while isinstance(env, gym.Wrapper):
        out.append(env)
        env = env.env
    return out


def test_envs_command_prints_the_horizon(capsys):
    assert cli_main(["envs", CARTPOLE]) == 0
    assert "episode steps    : 500" in capsys.readouterr().out


# --- registering again ----------------------------------------------------------------


def test_registering_the_same_task_again_is_silent(test_ids):
    register_task("test/Walk-v0", Walk, gain=2.0)
    test_ids.append("test/Walk-v0")
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        register_task("test/Walk-v0", Walk, gain=2.0)
        chronogym.registration.register_envs()
    assert gym.make("test/Walk-v0").unwrapped.task.gain == 2.0


def test_registering_another_task_replaces_it_with_a_warning(test_ids):
    register_task("test/Walk-v0", Walk)
    test_ids.append("test/Walk-v0")
    with pytest.warns(UserWarning, match=r"register_task\('test/Walk-v0'\): replacing .*\.Walk"):
        register_task("test/Walk-v0", Other)
    assert type(gym.make("test/Walk-v0").unwrapped.task) is Other
    with pytest.warns(UserWarning, match=r"replacing .*'gain': 3\.0"):
        register_task("test/Walk-v0", Other, gain=3.0)
    assert gym.make("test/Walk-v0").unwrapped.task.gain == 3.0


# --- py.typed -------------------------------------------------------------------------


def test_py_typed_is_in_the_package_and_in_its_wheel(tmp_path):
    assert importlib.resources.files("chronogym").joinpath("py.typed").is_file()
    root = Path(__file__).resolve().parents[1]  # the repository: build its wheel
    source = tmp_path / "source"
    ignore = shutil.ignore_patterns("__pycache__", "*.egg-info")
    shutil.copytree(root / "src", source / "src", ignore=ignore)
    for name in ("pyproject.toml", "README.md"):
        shutil.copy(root / name, source / name)
    pip_wheel = [sys.executable, "-m", "pip", "wheel", "--no-deps", "--no-build-isolation"]
    subprocess.run(
        [*pip_wheel, "-q", "-w", str(tmp_path / "dist"), str(source)],
        check=True,
        capture_output=True,
        timeout=240,
    )
    (wheel,) = (tmp_path / "dist").glob("chronogym-*.whl")
    assert "chronogym/py.typed" in zipfile.ZipFile(wheel).namelist()
