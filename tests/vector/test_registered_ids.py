"""An id registered by the user's script works on the workers (they get the spec, not the id)."""

from __future__ import annotations

import textwrap

import gymnasium as gym
import pytest
from user_scripts import DRIFT_TASK, run_user_script

from chronogym import RayVectorEnv, SerialVectorEnv

SCRIPT = DRIFT_TASK + textwrap.dedent(
    """
    register_task("me/Drift-v0", Drift)
    ray.init(num_cpus=2, include_dashboard=False, log_to_driver=False)

    def rollout(vec):
        out = [vec.reset(seed=5)[0]]
        for t in range(20):
            out.append(vec.step(np.full((4, 1), 0.3 * np.sin(t), np.float32))[0])
        vec.close()
        return np.stack(out)

    ray_run = rollout(chronogym.RayVectorEnv("me/Drift-v0", 4, envs_per_worker=2))
    sync_run = rollout(gym.make_vec("me/Drift-v0", 4, vectorization_mode="sync"))
    assert np.array_equal(ray_run, sync_run), (ray_run, sync_run)
    print("same numbers", ray_run.shape)
    # factories that make the script's id inside the worker (as CleanRL's make_env does)
    fns = [lambda: gym.make("me/Drift-v0") for _ in range(4)]
    factory_run = rollout(chronogym.RayVectorEnv(fns, envs_per_worker=2))
    assert np.array_equal(factory_run, sync_run), (factory_run, sync_run)
    print("factories too")
    """
)


def test_id_registered_in_the_users_script_runs_on_workers(tmp_path):
    done = run_user_script(tmp_path, SCRIPT)
    assert done.returncode == 0, done.stderr[-3000:]
    assert "same numbers (21, 4, 1)" in done.stdout
    assert "factories too" in done.stdout


@pytest.fixture
def unimportable_id():
    env_id = "me/Unimportable-v0"
    gym.register(id=env_id, entry_point="not_a_module_anywhere:Env")
    yield env_id
    del gym.registry[env_id]


def test_unknown_id_fails_in_the_driver_before_any_worker_starts():
    with pytest.raises(gym.error.NameNotFound, match="NoSuchEnv"):
        SerialVectorEnv("chronogym/NoSuchEnv-v0", 2)


def test_unimportable_entry_point_names_the_module_and_the_fix(ray_cluster, unimportable_id):
    with pytest.raises(ModuleNotFoundError, match="not_a_module_anywhere.*PYTHONPATH"):
        SerialVectorEnv(unimportable_id, 2)
    with pytest.raises(ModuleNotFoundError, match="not_a_module_anywhere.*PYTHONPATH") as raised:
        RayVectorEnv(unimportable_id, 2, envs_per_worker=1)  # the worker's own exception
    assert f"env 0 ({unimportable_id}) in make()" in str(raised.value.__cause__)
