"""Same seeds, same numbers: SimEnv loop, serial and Ray vector envs, Gymnasium SyncVectorEnv."""

from __future__ import annotations

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import data_equivalence
from vector_rollouts import ENV_ID, single_env_rollouts, vector_rollout

from chronogym import RayVectorEnv, SerialVectorEnv, make_vec

NUM_ENVS = 5
STEPS = 150  # long enough for several episodes to end (the random policy falls in ~20 steps)


def sync_reference(mode: str, steps: int = STEPS) -> list:
    vec = gym.make_vec(
        ENV_ID, NUM_ENVS, vectorization_mode="sync", vector_kwargs={"autoreset_mode": mode}
    )
    try:
        return vector_rollout(vec, steps)
    finally:
        vec.close()


@pytest.fixture(scope="module")
def reference_next_step():
    return sync_reference("NextStep")


def test_reference_has_episode_ends(reference_next_step):
    ends = sum(int(step[2].sum() + step[3].sum()) for step in reference_next_step[1:])
    assert ends >= NUM_ENVS  # the comparison below covers autoresets


def test_serial_matches_gymnasium_sync(reference_next_step):
    vec = SerialVectorEnv(ENV_ID, NUM_ENVS)
    assert data_equivalence(vector_rollout(vec, STEPS), reference_next_step, exact=True)
    vec.close()


def test_simenv_loop_matches_vector(reference_next_step):
    per_env = single_env_rollouts(lambda: gym.make(ENV_ID), NUM_ENVS, STEPS)
    for t, step in enumerate(reference_next_step):
        obs = step[0]
        for i in range(NUM_ENVS):
            np.testing.assert_array_equal(obs[i], per_env[i][t][0])
            if t:
                assert step[1][i] == per_env[i][t][1]
                assert (step[2][i], step[3][i]) == per_env[i][t][2:]


@pytest.mark.parametrize("envs_per_worker", [1, 2, 5])
def test_ray_matches_gymnasium_sync(ray_cluster, reference_next_step, envs_per_worker):
    vec = RayVectorEnv(ENV_ID, NUM_ENVS, envs_per_worker=envs_per_worker)
    assert vec.num_workers == -(-NUM_ENVS // envs_per_worker)
    assert data_equivalence(vector_rollout(vec, STEPS), reference_next_step, exact=True)
    vec.close()


def test_same_step_autoreset_matches_gymnasium(ray_cluster):
    reference = sync_reference("SameStep")
    finals = [step[4] for step in reference[1:] if "final_obs" in step[4]]
    assert finals, "expected at least one SAME_STEP autoreset with final_obs"
    serial = vector_rollout(SerialVectorEnv(ENV_ID, NUM_ENVS, autoreset_mode="SameStep"), STEPS)
    assert data_equivalence(serial, reference, exact=True)
    vec = RayVectorEnv(ENV_ID, NUM_ENVS, envs_per_worker=2, autoreset_mode="SameStep")
    assert data_equivalence(vector_rollout(vec, STEPS), reference, exact=True)
    vec.close()


def test_reset_seed_conventions():
    vec = SerialVectorEnv(ENV_ID, 3)
    by_int, _ = vec.reset(seed=100)
    by_list, _ = vec.reset(seed=[100, 101, 102])
    np.testing.assert_array_equal(by_int, by_list)
    continued, _ = vec.reset()
    assert not np.array_equal(continued, by_int)
    with pytest.raises(ValueError, match="seed list has length 2; expected num_envs=3"):
        vec.reset(seed=[1, 2])


def test_reset_mask_resets_only_masked_envs():
    vec = SerialVectorEnv(ENV_ID, 3)
    reference = SerialVectorEnv(ENV_ID, 3)
    _obs, _ = vec.reset(seed=5)
    reference.reset(seed=5)
    actions = np.zeros((3, 1), dtype=np.float32)
    stepped = vec.step(actions)[0]
    reference.step(actions)
    mask = np.array([False, True, False])
    after, _info = vec.reset(seed=[None, 6, None], options={"reset_mask": mask})
    np.testing.assert_array_equal(after[[0, 2]], stepped[[0, 2]])
    fresh, _ = SerialVectorEnv(ENV_ID, 2).reset(seed=5)  # env 1 of a vector seeded 5 => seed 6
    np.testing.assert_array_equal(after[1], fresh[1])


def test_make_vec_backends_agree(ray_cluster, reference_next_step):
    for backend in ("serial", "sync"):
        vec = make_vec(ENV_ID, NUM_ENVS, backend=backend)
        assert data_equivalence(vector_rollout(vec, 20), reference_next_step[:21], exact=True)
        vec.close()
    with pytest.raises(ValueError, match="backend='mpi'"):
        make_vec(ENV_ID, 2, backend="mpi")


def test_call_get_attr_set_attr_close(ray_cluster):
    vec = RayVectorEnv(ENV_ID, 3, envs_per_worker=2, env_kwargs={"k": 3})
    assert vec.get_attr("k") == (3, 3, 3)
    vec.set_attr("max_episode_steps", [7, 8, 9])
    assert vec.get_attr("max_episode_steps") == (7, 8, 9)
    assert vec.call("control_dt") == pytest.approx((0.006,) * 3)
    with pytest.raises(AttributeError):
        vec.get_attr("no_such_attribute")
    vec.close()
    vec.close()  # idempotent
    assert vec.closed
    with pytest.raises(RuntimeError, match="closed"):
        vec.reset()


def test_a_first_reset_with_a_mask_names_the_envs_never_reset():
    vec = SerialVectorEnv(ENV_ID, 3)
    mask = np.array([True, False, True])
    with pytest.raises(ValueError, match=r"leaves envs \[1\] unreset.*never reset"):
        vec.reset(seed=[1, 2, 3], options={"reset_mask": mask})
    vec.reset(seed=0)
    vec.reset(options={"reset_mask": mask})  # fine once every env has been reset
