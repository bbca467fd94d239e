"""Every Gymnasium space type through SerialVectorEnv and RayVectorEnv, as SyncVectorEnv does.

Real Gymnasium and a real 2-CPU Ray cluster. Each space is both the observation
and the action space of ``SpaceEnv``; results are compared with
``gymnasium.vector.SyncVectorEnv`` by ``data_equivalence`` (exact), in both
autoreset modes, through ``step``, ``step_async``/``step_wait`` and
``send``/``recv`` in reversed halves.
"""

from __future__ import annotations

from functools import partial

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence
from gymnasium.vector import AutoresetMode
from gymnasium.vector.utils import concatenate, create_empty_array, iterate
from space_envs import TESTING_SPACES, SpaceEnv

from chronogym import RayVectorEnv, SerialVectorEnv

NUM_ENVS = 4
STEPS = 12
SEED = 11
MODES = [AutoresetMode.NEXT_STEP, AutoresetMode.SAME_STEP]


def space_fns(space: gym.Space) -> list:
    return [partial(SpaceEnv, space, space)] * NUM_ENVS


def actions_for(vec: gym.vector.VectorEnv) -> list:
    """A fixed sequence of batched actions (the action space seeded once)."""
    vec.action_space.seed(SEED)
    return [vec.action_space.sample() for _ in range(STEPS)]


def sub_batch(vec: gym.vector.VectorEnv, actions, ids: list[int]):
    """Rows ``ids`` (in that order) of a batched action."""
    rows = list(iterate(vec.action_space, actions))
    space = vec.single_action_space
    return concatenate(space, [rows[i] for i in ids], create_empty_array(space, len(ids)))


def rollout(vec: gym.vector.VectorEnv, actions: list, ways: bool = False) -> list:
    """reset, then every batched action; with ``ways``, cycle step / step_async+step_wait /
    send in reversed order (two halves when there are two workers) + recv: every env once
    per round, so it equals a step."""
    out = [vec.reset(seed=SEED)]
    half = NUM_ENVS // 2
    for t, batch in enumerate(actions):
        way = t % 3 if ways else 0
        if way == 0:
            out.append(vec.step(batch))
        elif way == 1:
            vec.step_async(batch)
            out.append(vec.step_wait())
        else:
            high, low = list(range(NUM_ENVS - 1, half - 1, -1)), list(range(half - 1, -1, -1))
            for ids in [high, low] if vec.num_workers > 1 else [high + low]:
                vec.send(sub_batch(vec, batch, ids), ids)
            *result, env_ids = vec.recv()
            assert env_ids.tolist() == list(range(NUM_ENVS))
            out.append(tuple(result))
    return out


def sync_rollout(space: gym.Space, mode: AutoresetMode, actions: list) -> list:
    sync = gym.vector.SyncVectorEnv(space_fns(space), autoreset_mode=mode)
    try:
        return rollout(sync, actions)
    finally:
        sync.close()


def assert_equivalent(got: list, want: list) -> None:
    assert len(got) == len(want)
    for t, (a, b) in enumerate(zip(got, want, strict=True)):
        assert data_equivalence(a, b, exact=True), f"step {t} differs:\n{a}\n!=\n{b}"


@pytest.mark.parametrize("mode", MODES, ids=lambda m: m.value)
@pytest.mark.parametrize("name", list(TESTING_SPACES))
def test_serial_matches_sync(name, mode):
    space = TESTING_SPACES[name]
    vec = SerialVectorEnv(space_fns(space), autoreset_mode=mode)
    try:
        assert vec.observation_space == gym.vector.utils.batch_space(space, NUM_ENVS)
        actions = actions_for(vec)
        assert_equivalent(rollout(vec, actions, ways=True), sync_rollout(space, mode, actions))
    finally:
        vec.close()


@pytest.mark.parametrize("transport", ["socket", "fork"])
@pytest.mark.parametrize("mode", MODES, ids=lambda m: m.value)
@pytest.mark.parametrize("name", list(TESTING_SPACES))
def test_ray_matches_sync(ray_cluster, name, mode, transport):
    space = TESTING_SPACES[name]
    vec = RayVectorEnv(
        space_fns(space), envs_per_worker=NUM_ENVS // 2, autoreset_mode=mode, transport=transport
    )
    try:
        actions = actions_for(vec)
        assert_equivalent(rollout(vec, actions, ways=True), sync_rollout(space, mode, actions))
    finally:
        vec.close()


def test_np_random_seed_and_np_random_per_env(ray_cluster):
    space = TESTING_SPACES["box"]
    sync = gym.vector.SyncVectorEnv(space_fns(space))
    ray_vec = RayVectorEnv(space_fns(space), envs_per_worker=2)
    serial = SerialVectorEnv(space_fns(space))
    try:
        for vec in (sync, ray_vec, serial):
            vec.reset(seed=SEED)
        assert ray_vec.np_random_seed == serial.np_random_seed == sync.np_random_seed
        assert ray_vec.np_random_seed == tuple(SEED + i for i in range(NUM_ENVS))
        states = [[g.bit_generator.state for g in vec.np_random] for vec in (sync, ray_vec, serial)]
        assert states[0] == states[1] == states[2]
        assert len({str(s) for s in states[0]}) == NUM_ENVS  # one stream per env
    finally:
        for vec in (sync, ray_vec, serial):
            vec.close()


def _one_more(batch):
    """A batch (array or tuple) with its first row repeated at the end."""
    if isinstance(batch, tuple):
        return (*batch, batch[0])
    return np.concatenate([batch, batch[:1]])


def _raised(fn) -> BaseException:
    with pytest.raises(Exception) as caught:
        fn()
    return caught.value


BAD_CALLS = {
    "too-few-actions": lambda vec: vec.step(vec.action_space.sample()[:-1]),
    "too-many-actions": lambda vec: vec.step(_one_more(vec.action_space.sample())),
    "reset-mask-list": lambda vec: vec.reset(options={"reset_mask": [True] * NUM_ENVS}),
    "reset-mask-shape": lambda vec: vec.reset(options={"reset_mask": np.ones(3, dtype=bool)}),
    "reset-mask-dtype": lambda vec: vec.reset(options={"reset_mask": np.ones(NUM_ENVS)}),
    "reset-mask-all-false": lambda vec: vec.reset(
        options={"reset_mask": np.zeros(NUM_ENVS, dtype=bool)}
    ),
    "seed-list-length": lambda vec: vec.reset(seed=[1, 2]),
    "scalar-action": lambda vec: vec.step(1),
}
#: Calls whose error text is Gymnasium's own, word for word (then what was expected).
SAME_TEXT = {"reset-mask-list", "reset-mask-shape", "reset-mask-dtype", "reset-mask-all-false"}
SAME_TEXT |= {"scalar-action"}


@pytest.mark.parametrize("space_name", ["box", "text", "multi-discrete"])
@pytest.mark.parametrize("call", list(BAD_CALLS))
def test_bad_input_raises_what_gymnasium_raises(space_name, call):
    space = TESTING_SPACES[space_name]
    sync = gym.vector.SyncVectorEnv(space_fns(space))
    serial = SerialVectorEnv(space_fns(space))
    try:
        for vec in (sync, serial):
            vec.reset(seed=SEED)
        want, got = _raised(lambda: BAD_CALLS[call](sync)), _raised(lambda: BAD_CALLS[call](serial))
        assert isinstance(got, type(want)), f"{call}: {type(got)} but Gymnasium {type(want)}"
        assert "expected" in str(got), f"{call}: message names no expectation: {got}"
        if call in SAME_TEXT:
            assert str(want) in str(got), f"{call}: {got!r} lacks Gymnasium's {want!r}"
    finally:
        sync.close()
        serial.close()


def test_wrong_action_count_names_the_counts(ray_cluster):
    space = TESTING_SPACES["text"]
    vec = RayVectorEnv(space_fns(space), envs_per_worker=2)
    try:
        vec.reset(seed=SEED)
        with pytest.raises(ValueError, match=r"got 3 actions for 4 envs; expected one action"):
            vec.step(vec.action_space.sample()[:3])
    finally:
        vec.close()


@pytest.mark.parametrize("mode", MODES, ids=lambda m: m.value)
@pytest.mark.parametrize("name", ["box", "dict", "tuple", "text"])
def test_driver_worker_matches_sync(ray_cluster, name, mode):
    space = TESTING_SPACES[name]
    vec = RayVectorEnv(space_fns(space), envs_per_worker=NUM_ENVS // 2, autoreset_mode=mode,
                       driver_worker=True)  # fmt: skip
    try:
        actions = actions_for(vec)
        assert_equivalent(rollout(vec, actions, ways=True), sync_rollout(space, mode, actions))
    finally:
        vec.close()
