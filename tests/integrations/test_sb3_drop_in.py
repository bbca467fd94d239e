"""RayVecEnv and SerialVecEnv: SB3's SubprocVecEnv / DummyVecEnv shape on chronogym.

Real Ray (the session's 2-CPU cluster), real SB3: every SB3 action space and Dict/Tuple
observations number for number against DummyVecEnv, ``indices=`` on attributes and
methods only some envs have (the same assertions pass on DummyVecEnv), SB3's
``make_vec_env``, SB3's VecEnv wrappers and PPO over it, and bad input.
"""

from __future__ import annotations

import functools
import os
import signal
import time
from collections.abc import Iterator
from typing import Any

import gymnasium as gym
import numpy as np
import pytest
from gymnasium import spaces

pytest.importorskip("stable_baselines3")

import sb3_envs  # tests/integrations/sb3_envs.py
from sb3_compare import assert_same_obs, compare_with_dummy  # tests/integrations/
from sb3_envs import MIXED_FACTORIES, EchoEnv, Marker, PlainEnv
from space_envs import TESTING_SPACES  # tests/space_envs.py
from stable_baselines3.common.env_util import make_vec_env
from stable_baselines3.common.monitor import Monitor
from stable_baselines3.common.utils import check_for_correct_spaces
from stable_baselines3.common.vec_env import (
    DummyVecEnv,
    VecCheckNan,
    VecEnv,
    VecFrameStack,
    VecMonitor,
    VecNormalize,
)

from chronogym.integrations.sb3 import RayVecEnv, SB3VecEnv, SerialVecEnv

CARTPOLE = "chronogym/CartPole-v0"
BACKENDS = ["ray", "serial"]


@pytest.fixture
def ray_by_value(ray_cluster: Any) -> Any:
    """The Ray cluster, with this folder's helper envs sent to workers by value."""
    ray_cluster.cloudpickle.register_pickle_by_value(sb3_envs)
    return ray_cluster


def build(backend: str, factories: list, request: pytest.FixtureRequest, **kwargs: Any) -> VecEnv:
    """The SB3 VecEnv of ``backend`` ("ray", "serial" or SB3's own "dummy") on ``factories``."""
    if backend == "ray":
        request.getfixturevalue("ray_by_value")
        return RayVecEnv(factories, envs_per_worker=2, **kwargs)
    if backend == "serial":
        return SerialVecEnv(factories, **kwargs)
    assert backend == "dummy" and not kwargs
    return DummyVecEnv(factories)


def sb3_actions(space: spaces.Space, n: int, steps: int) -> Iterator[Any]:
    """Actions as SB3 passes them: an array with a row per env, or (Dict, Tuple) a list."""
    space.seed(1)
    for _ in range(steps):
        items = [space.sample() for _ in range(n)]
        yield items if isinstance(space, (spaces.Dict, spaces.Tuple)) else np.stack(items)


# -- numbers ---------------------------------------------------------------------------
BOX = TESTING_SPACES["box"]
CASES = {  # name: (observation space, action space)
    "box-action": (BOX, BOX),
    "discrete-action": (BOX, TESTING_SPACES["discrete"]),
    "discrete-start-action": (BOX, TESTING_SPACES["discrete-start"]),
    "multi-discrete-action": (BOX, TESTING_SPACES["multi-discrete"]),
    "multi-binary-action": (BOX, TESTING_SPACES["multi-binary"]),
    "dict-action": (BOX, TESTING_SPACES["dict"]),
    "tuple-action": (BOX, TESTING_SPACES["tuple"]),
    "dict-obs": (TESTING_SPACES["dict"], TESTING_SPACES["multi-discrete"]),
    "tuple-obs": (TESTING_SPACES["tuple"], TESTING_SPACES["dict"]),
}


@pytest.mark.parametrize("case", list(CASES))
@pytest.mark.parametrize("backend", BACKENDS)
def test_every_sb3_space_matches_dummy_vec_env(
    backend: str, case: str, request: pytest.FixtureRequest
) -> None:
    n = 3
    obs_space, act_space = CASES[case]
    factories = [functools.partial(EchoEnv, obs_space, act_space)] * n
    venv, ref = build(backend, factories, request), DummyVecEnv(factories)
    try:
        assert venv.observation_space == ref.observation_space
        assert venv.action_space == ref.action_space
        ends = compare_with_dummy(venv, ref, list(sb3_actions(act_space, n, 14)), seed=5)
    finally:
        venv.close()
        ref.close()
    assert ends["terminated"] >= 1 and ends["truncated"] >= 1, ends


def test_dict_actions_also_as_one_gymnasium_batch() -> None:
    space = TESTING_SPACES["dict"]
    venv = SerialVecEnv([functools.partial(EchoEnv, BOX, space)] * 2)
    ref = SerialVecEnv([functools.partial(EchoEnv, BOX, space)] * 2)
    per_env = [{"position": np.full(2, 0.5, np.float32), "mode": m} for m in (0, 2)]
    batch = {"position": np.full((2, 2), 0.5, np.float32), "mode": np.array([0, 2])}
    try:
        venv.seed(0)
        ref.seed(0)
        assert_same_obs(venv.reset(), ref.reset())
        _, rewards, _, _ = venv.step(batch)
        _, rewards_ref, _, _ = ref.step(per_env)
    finally:
        venv.close()
        ref.close()
    np.testing.assert_array_equal(rewards, rewards_ref)


@pytest.mark.parametrize("backend", BACKENDS)
def test_per_env_options_match_dummy_vec_env(backend: str, request: pytest.FixtureRequest) -> None:
    factories = [functools.partial(gym.make, CARTPOLE)] * 3
    venv, ref = build(backend, factories, request), DummyVecEnv(factories)
    try:
        for options in ([{"noise": 0.0}, {}, {"noise": 0.0}], {"noise": 0.0}, None):
            venv.seed(4)
            ref.seed(4)
            venv.set_options(options)
            ref.set_options(options)
            obs = venv.reset()
            assert_same_obs(obs, ref.reset())
            assert venv.reset_infos == list(ref.reset_infos)
        assert np.abs(obs).max() > 0  # options are used once
    finally:
        venv.close()
        ref.close()
    assert np.array_equal(ref.envs[0].unwrapped.np_random_seed, 4)


# -- indices ---------------------------------------------------------------------------
@pytest.mark.parametrize("backend", [*BACKENDS, "dummy"])
def test_indices_touch_only_the_chosen_envs(backend: str, request: pytest.FixtureRequest) -> None:
    """Env 1 and 3 have ``bonus`` and ``shout``; env 2 is wrapped in Marker.

    The same assertions run on SB3's DummyVecEnv: the semantics are SB3's.
    """
    venv = build(backend, MIXED_FACTORIES, request)
    try:
        if backend != "dummy":  # each env knows its index though two share a callable
            assert venv.get_attr("chronogym_env_index") == [0, 1, 2, 3]
        assert venv.get_attr("bonus", indices=[1, 3]) == [10, 10]
        with pytest.raises(AttributeError, match="bonus"):
            venv.get_attr("bonus")
        assert not venv.has_attr("bonus")
        assert venv.has_attr("bump") and venv.get_attr("counter") == [0, 0, 0, 0]  # not called
        venv.set_attr("bonus", 5, indices=[1])
        assert venv.get_attr("bonus", indices=[3, 1]) == [10, 5]
        venv.set_attr("dummy1", "only env 0", indices=[0])  # an attribute no env had
        assert venv.get_attr("dummy1", indices=0) == ["only env 0"]
        for i in (1, 2, 3):
            with pytest.raises(AttributeError, match="dummy1"):
                venv.get_attr("dummy1", indices=[i])
        assert venv.env_method("bump", 2, indices=[2]) == [2]
        assert venv.env_method("bump", by=3, indices=[3, 0]) == [3, 3]
        assert venv.get_attr("counter") == [3, 0, 2, 3]
        assert venv.env_method("shout", "hi", indices=[3]) == ["hi (counter 3)"]
        with pytest.raises(AttributeError, match="shout"):
            venv.env_method("shout", "hi", indices=[0, 1])
        assert venv.get_attr("counter") == [3, 0, 2, 3]
        venv.set_attr("counter", 7)
        # The one difference: chronogym sets an attribute where the env has it (Gymnasium's
        # set_wrapper_attr); SB3 sets it on the outermost wrapper (Marker, for env 2),
        # where the env's own method does not see it.
        assert venv.env_method("bump") == [8, 8, 3 if backend == "dummy" else 8, 8]
        assert venv.env_is_wrapped(Marker) == [False, False, True, False]
        assert venv.env_is_wrapped(Marker, indices=[2, 0]) == [True, False]
        assert venv.env_is_wrapped(Monitor) == [False] * 4
    finally:
        venv.close()


# Every form SB3's VecEnv._get_indices and DummyVecEnv take: None, an int, an iterable.
SB3_INDICES = [None, 2, -1, [3, 0], [-1, -4], [1, 1, 2], (0, 2), range(1, 4), np.array([2, 0])]


@pytest.mark.parametrize("backend", BACKENDS)
def test_indices_follow_sb3s_convention(backend: str, request: pytest.FixtureRequest) -> None:
    """Each form of ``indices`` picks the envs DummyVecEnv picks, in its order and as many
    times (negative and repeated indices included); bad ones raise DummyVecEnv's class."""
    reference = build("dummy", [PlainEnv] * 4, request)
    venv = build(backend, [PlainEnv] * 4, request)
    try:
        for env in (reference, venv):
            env.set_attr("counter", 0)
            env.set_attr("counter", 10, indices=[-1, 1, -1])
        for indices in SB3_INDICES:
            want = reference.env_method("bump", indices=indices)
            assert venv.env_method("bump", indices=indices) == want, indices
            want = reference.get_attr("counter", indices=indices)
            assert venv.get_attr("counter", indices=indices) == want, indices
        assert venv.get_attr("counter") == reference.get_attr("counter") == [5, 14, 6, 15]
        assert venv.get_attr("counter", indices=(i for i in (-3, 0))) == [14, 5]
        assert venv.get_attr("counter", indices=[]) == reference.get_attr("counter", indices=[])
        assert venv.env_is_wrapped(Marker, indices=-2) == [False]
        for bad in (4, -5, [0, 4], ["0"], [1.0], 1.5):
            with pytest.raises(Exception) as sb3_error:
                reference.get_attr("counter", indices=bad)
            with pytest.raises(sb3_error.type, match=r"indices=.*integer with -num_envs <="):
                venv.get_attr("counter", indices=bad)
    finally:
        venv.close()
        reference.close()


# -- SB3's make_vec_env, checks and wrappers -------------------------------------------
@pytest.mark.parametrize("cls", [RayVecEnv, SerialVecEnv])
def test_make_vec_env_builds_it(cls: type, request: pytest.FixtureRequest) -> None:
    if cls is RayVecEnv:
        request.getfixturevalue("ray_cluster")
    kw: dict[str, Any] = {"n_envs": 3, "seed": 2, "env_kwargs": {"max_episode_steps": 15}}
    vec_env_kwargs = {"envs_per_worker": 3} if cls is RayVecEnv else {}
    venv = make_vec_env(CARTPOLE, vec_env_cls=cls, vec_env_kwargs=vec_env_kwargs, **kw)
    ref = make_vec_env(CARTPOLE, vec_env_cls=DummyVecEnv, **kw)
    try:
        assert type(venv) is cls and venv.num_envs == 3
        assert venv._seeds == ref._seeds == [2, 3, 4]  # make_vec_env's seed()
        assert venv.env_is_wrapped(Monitor) == [True] * 3  # make_vec_env adds Monitor
        assert venv.render_mode == ref.render_mode == "rgb_array"
        actions = [np.random.default_rng(t).integers(0, 2, (3, 1)) * 2.0 - 1 for t in range(40)]
        actions = [a.astype(np.float32) for a in actions]
        ends = compare_with_dummy(venv, ref, actions, seed=2, clock_keys=frozenset({"t"}))
        assert [len(r) for r in venv.env_method("get_episode_rewards")] == [
            len(r) for r in ref.env_method("get_episode_rewards")
        ]
    finally:
        venv.close()
        ref.close()
    assert ends["terminated"] + ends["truncated"] >= 3, ends


def check_vec_env(venv: VecEnv, single: gym.Env, steps: int = 30) -> None:
    """What SB3's ``check_env`` asks of one env, asked of a VecEnv: spaces, the reset and
    step returns' types and shapes, observations in the space, terminal observations and
    ``TimeLimit.truncated`` at every episode end, no NaN (``VecCheckNan``)."""
    n = venv.num_envs
    check_for_correct_spaces(venv, single.observation_space, single.action_space)
    checked = VecCheckNan(venv, raise_exception=True)
    obs = checked.reset()
    assert obs.shape == (n, *single.observation_space.shape)
    assert all(single.observation_space.contains(row) for row in obs)
    assert len(venv.reset_infos) == n and all(isinstance(i, dict) for i in venv.reset_infos)
    done_seen = 0
    for _ in range(steps):
        actions = np.stack([single.action_space.sample() for _ in range(n)])
        obs, rewards, dones, infos = checked.step(actions)
        assert all(single.observation_space.contains(row) for row in obs)
        assert rewards.shape == (n,) and rewards.dtype == np.float32
        assert dones.shape == (n,) and dones.dtype == np.bool_
        assert isinstance(infos, list) and len(infos) == n
        for i, info in enumerate(infos):
            assert isinstance(info["TimeLimit.truncated"], bool)
            if dones[i]:
                done_seen += 1
                assert single.observation_space.contains(info["terminal_observation"])
    assert done_seen > 0


@pytest.mark.parametrize("backend", BACKENDS)
def test_sb3_checks_wrappers_and_ppo_run_over_it(
    backend: str, request: pytest.FixtureRequest
) -> None:
    torch = pytest.importorskip("torch")
    from stable_baselines3 import PPO

    torch.set_num_threads(1)
    make = functools.partial(gym.make, CARTPOLE, max_episode_steps=12)
    single = make()
    single.action_space.seed(0)
    venv, ref = build(backend, [make] * 2, request), DummyVecEnv([make] * 2)
    try:
        check_vec_env(venv, single)
        # VecNormalize and VecFrameStack: the same numbers as over DummyVecEnv
        stacked = VecFrameStack(VecNormalize(venv, gamma=0.9), n_stack=3)
        stacked_ref = VecFrameStack(VecNormalize(ref, gamma=0.9), n_stack=3)
        actions = [np.full((2, 1), (-1.0) ** (t // 3), np.float32) for t in range(30)]
        ends = compare_with_dummy(stacked, stacked_ref, actions, seed=1)
        assert ends["terminated"] + ends["truncated"] >= 2
        assert stacked.observation_space.shape == (12,)
        # VecMonitor, then PPO through the whole stack
        monitored = VecMonitor(stacked)
        model = PPO("MlpPolicy", monitored, n_steps=32, batch_size=32, n_epochs=1, seed=0)
        model.learn(128)
        assert model.num_timesteps == 128
        assert len(model.ep_info_buffer) > 0
        assert all(info["l"] <= 12 for info in model.ep_info_buffer)
    finally:
        venv.close()
        ref.close()
        single.close()


# -- a dead worker ----------------------------------------------------------------------
def test_dead_worker_ends_its_episodes_truncated(ray_cluster: Any) -> None:
    factories = [functools.partial(gym.make, CARTPOLE)] * 4
    venv = RayVecEnv(factories, envs_per_worker=2)
    hold = np.zeros((4, 1), np.float32)
    try:
        venv.seed(0)
        venv.reset()
        before, _, _, _ = venv.step(hold)
        os.kill(venv.vector_env.worker_pids()[1], signal.SIGKILL)  # envs 2 and 3
        time.sleep(0.3)  # let it die before the next call reaches it
        obs, rewards, dones, infos = venv.step(hold)
        assert dones.tolist() == [False, False, True, True]
        assert rewards[2:].tolist() == [0.0, 0.0]
        for i in (2, 3):
            assert infos[i]["TimeLimit.truncated"] is True and infos[i]["worker_restarted"]
            np.testing.assert_array_equal(infos[i]["terminal_observation"], before[i])
        assert "worker_restarted" not in infos[0]
        obs, _, _, _ = venv.step(hold)  # training goes on
        assert np.isfinite(obs).all()
    finally:
        venv.close()


# -- bad input -------------------------------------------------------------------------
def test_bad_input_names_the_value() -> None:
    with pytest.raises(ValueError, match=r"env_fns='CartPole-v1'.*make_vec_env"):
        SerialVecEnv("CartPole-v1")  # type: ignore[arg-type]
    with pytest.raises(ValueError, match=r"env_fns=\[\]"):
        SerialVecEnv([])
    with pytest.raises(ValueError, match=r"env_fns\[1\]=3 is not callable"):
        SerialVecEnv([PlainEnv, 3])  # type: ignore[list-item]
    with pytest.raises(ValueError, match="autoreset_mode='NextStep'"):
        SerialVecEnv([PlainEnv], autoreset_mode="NextStep")
    with pytest.raises(ValueError, match=r"env_kwargs=\{'x': 1\}"):
        SerialVecEnv([PlainEnv], env_kwargs={"x": 1})
    with pytest.raises(TypeError, match=r"env_fns\[0\]=.*returned 'oops'.*gymnasium.Env"):
        SerialVecEnv([lambda: "oops"])
    env = PlainEnv()
    with pytest.raises(ValueError, match="same env instance"):
        SerialVecEnv([lambda: env, lambda: env])
    with pytest.raises(TypeError, match="unexpected keyword argument 'start_method'"):
        SerialVecEnv([PlainEnv], start_method="fork")

    dict_space = TESTING_SPACES["dict"]
    venv = SerialVecEnv([functools.partial(EchoEnv, BOX, dict_space)] * 2)
    try:
        venv.reset()
        good = {"position": np.zeros(2, np.float32), "mode": 1}
        with pytest.raises(ValueError, match=r"actions=\[\{'position'.*holds 1 actions"):
            venv.step([good])
        with pytest.raises(ValueError, match=r"actions=\[\{'mode': 1\}, \{'mode': 1\}\].*"):
            venv.step([{"mode": 1}, {"mode": 1}])  # no 'position'
        with pytest.raises(ValueError, match="actions='ab'"):
            venv.step("ab")
        with pytest.raises(IndexError, match=r"indices=\[2\]: index 2 is out of range"):
            venv.env_method("bump", indices=[2])
        _, _, dones, _ = venv.step([good, good])  # still works after the errors
        assert dones.shape == (2,)
    finally:
        venv.close()
    assert isinstance(venv, SB3VecEnv) and repr(venv).startswith("SerialVecEnv(")
