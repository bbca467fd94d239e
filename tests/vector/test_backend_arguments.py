"""One set of arguments across backends: SerialVectorEnv takes RayVectorEnv's, make_vec every form.

Switching ``backend`` (or RayVectorEnv to SerialVectorEnv) to debug keeps the numbers,
and an argument a backend does not take is a TypeError naming it.
"""

from __future__ import annotations

import inspect
from functools import partial

import gymnasium as gym
import pytest
from gymnasium.utils.env_checker import data_equivalence
from vector_rollouts import ENV_ID, vector_rollout

from chronogym import RayVectorEnv, SerialVectorEnv, make_vec
from chronogym.vector.serial import RAY_ONLY_ARGUMENTS, SERIAL_ARGUMENTS

NUM_ENVS = 5
STEPS = 100  # several episodes end (the random policy drops the pole in ~20 steps)


def keyword_defaults(cls: type) -> dict:
    parameters = inspect.signature(cls.__init__).parameters.values()
    return {p.name: p.default for p in parameters if p.kind is p.KEYWORD_ONLY}


def sync_reference(mode: str, num_envs: int = NUM_ENVS, steps: int = STEPS, **env_kwargs) -> list:
    vec = gym.make_vec(
        ENV_ID,
        num_envs,
        vectorization_mode="sync",
        vector_kwargs={"autoreset_mode": mode},
        **env_kwargs,
    )
    try:
        return vector_rollout(vec, steps)
    finally:
        vec.close()


@pytest.fixture(scope="module")
def references() -> dict[str, list]:
    return {mode: sync_reference(mode) for mode in ("NextStep", "SameStep")}


class Recorder:
    """An env factory that counts the envs it built (to show an error came before any)."""

    def __init__(self) -> None:
        self.built = 0

    def __call__(self) -> gym.Env:
        self.built += 1
        return gym.make(ENV_ID)


# -- SerialVectorEnv's arguments against RayVectorEnv's ----------------------------------------


def test_serial_takes_or_rejects_every_ray_argument():
    ray, serial = keyword_defaults(RayVectorEnv), keyword_defaults(SerialVectorEnv)
    assert tuple(serial) == SERIAL_ARGUMENTS
    assert set(serial) | set(RAY_ONLY_ARGUMENTS) == set(ray)
    assert not set(serial) & set(RAY_ONLY_ARGUMENTS)
    assert {name: ray[name] for name in serial} == serial  # same defaults


RAY_ONLY_VALUES = {
    "num_cpus": 1,
    "num_gpus": 1,
    "address": "auto",
    "worker_niceness": 0,
    "scheduling": "spread",
    "step_timeout": 5.0,
    "start_timeout": 60.0,
    "transport": "socket",
    "spin_us": 0,
    "shared_memory": False,
    "relay_tcp": False,
    "driver_worker": True,
}


@pytest.mark.parametrize(("name", "value"), RAY_ONLY_VALUES.items())
def test_serial_rejects_a_ray_only_argument_by_name(name, value):
    assert set(RAY_ONLY_VALUES) == set(RAY_ONLY_ARGUMENTS)
    factory = Recorder()
    message = (
        rf"^{name}={value!r}: has no meaning for SerialVectorEnv \(one process; it sets "
        rf"{RAY_ONLY_ARGUMENTS[name]}\); it is a RayVectorEnv argument: leave it out$"
    )
    with pytest.raises(TypeError, match=message):
        SerialVectorEnv(factory, 2, **{name: value})
    assert factory.built == 0


def test_serial_names_an_unknown_argument_and_the_close_one():
    with pytest.raises(
        TypeError,
        match=r"^SerialVectorEnv\(\) got an unexpected keyword argument 'envs_per_workr'; "
        r"did you mean 'envs_per_worker'\? expected one of envs_per_worker, autoreset_mode, "
        r"max_restarts, invalid_action, env_kwargs, env_errors$",
    ):
        SerialVectorEnv(ENV_ID, 2, envs_per_workr=1)


@pytest.mark.parametrize("envs_per_worker", [0, 3, 1.5, True, "2"])
def test_bad_envs_per_worker_is_the_same_error_as_ray(envs_per_worker):
    # RayVectorEnv checks it before Ray starts, so no cluster is needed
    with pytest.raises(ValueError) as serial:
        SerialVectorEnv(ENV_ID, 2, envs_per_worker=envs_per_worker)
    with pytest.raises(ValueError) as ray:
        RayVectorEnv(ENV_ID, 2, envs_per_worker=envs_per_worker)
    assert type(serial.value) is type(ray.value)
    assert str(serial.value) == str(ray.value)
    assert str(serial.value).startswith(f"envs_per_worker={envs_per_worker!r}: expected an integer")


# -- same numbers whatever envs_per_worker, and as RayVectorEnv ----------------------------------


@pytest.mark.parametrize("mode", ["NextStep", "SameStep"])
@pytest.mark.parametrize("envs_per_worker", [None, 1, 2, 3, 5])
def test_serial_matches_sync_for_any_envs_per_worker(references, mode, envs_per_worker):
    vec = SerialVectorEnv(ENV_ID, NUM_ENVS, envs_per_worker=envs_per_worker, autoreset_mode=mode)
    assert vec.num_workers == (1 if envs_per_worker is None else -(-NUM_ENVS // envs_per_worker))
    assert data_equivalence(vector_rollout(vec, STEPS), references[mode], exact=True)
    vec.close()


def test_one_set_of_arguments_switches_ray_to_serial(ray_cluster):
    kwargs = {
        "envs_per_worker": 2,
        "autoreset_mode": "SameStep",
        "max_restarts": 0,
        "invalid_action": "clip",
        "env_kwargs": {"k": 2},
    }
    reference = sync_reference("SameStep", 4, 60, k=2)
    ray = make_vec(ENV_ID, 4, backend="ray", **kwargs)
    serial = make_vec(ENV_ID, 4, backend="serial", **kwargs)
    assert (ray.num_workers, serial.num_workers) == (2, 2)
    assert ray.get_attr("k") == serial.get_attr("k") == (2, 2, 2, 2)
    assert data_equivalence(vector_rollout(ray, 60), reference, exact=True)
    assert data_equivalence(vector_rollout(serial, 60), reference, exact=True)
    ray.close()
    serial.close()


def test_serial_send_steps_whole_groups_of_envs_per_worker():
    vec = SerialVectorEnv(ENV_ID, 4, envs_per_worker=2)
    vec.reset(seed=0)
    vec.send(vec.action_space.sample()[:2], [2, 3])  # one whole group: fine
    assert vec.recv()[5].tolist() == [2, 3]
    with pytest.raises(ValueError, match=r"envs \[1\] are missing.*envs_per_worker=2"):
        vec.send(vec.action_space.sample()[:1], [0])
    vec.close()


# -- make_vec: every form with every backend ---------------------------------------------------

FORMS = {
    "id": lambda n: (ENV_ID, n),
    "one factory": lambda n: (partial(gym.make, ENV_ID), n),
    "factories": lambda n: ([partial(gym.make, ENV_ID)] * n, None),
    "ids": lambda n: ([ENV_ID] * n, n),
}


@pytest.mark.parametrize("backend", ["serial", "sync", "async", "ray"])
@pytest.mark.parametrize("form", FORMS)
def test_make_vec_takes_every_form_with_every_backend(references, backend, form, request):
    if backend == "ray":
        request.getfixturevalue("ray_cluster")
    env_fns, num_envs = FORMS[form](NUM_ENVS)
    vec = make_vec(env_fns, num_envs, backend=backend, autoreset_mode="SameStep")
    assert vec.num_envs == NUM_ENVS
    assert data_equivalence(vector_rollout(vec, 40), references["SameStep"][:41], exact=True)
    vec.close()


@pytest.mark.parametrize("backend", ["serial", "sync", "async"])
def test_make_vec_env_kwargs_reach_ids_with_every_backend(backend):
    vec = make_vec([ENV_ID] * 2, backend=backend, env_kwargs={"k": 3})
    assert tuple(vec.get_attr("k")) == (3, 3)
    vec.close()


@pytest.mark.parametrize(
    ("backend", "kwargs", "message"),
    [
        (
            "sync",
            {"envs_per_worker": 4},
            r"make_vec\(backend='sync', envs_per_worker=4\): envs_per_worker does not apply to "
            r"Gymnasium's SyncVectorEnv; it is an argument of backend='ray' or 'serial' only",
        ),
        (
            "async",
            {"max_restarts": 0},
            r"max_restarts does not apply to Gymnasium's AsyncVectorEnv; it is an argument of "
            r"backend='ray' or 'serial' only",
        ),
        (
            "serial",
            {"num_gpus": 1},
            r"make_vec\(backend='serial', num_gpus=1\): num_gpus does not apply to "
            r"SerialVectorEnv \(one process; it sets the GPUs reserved for each Ray worker\); "
            r"it is an argument of backend='ray' only",
        ),
        (
            "sync",
            {"shared_memory": False},
            r"shared_memory does not apply to Gymnasium's SyncVectorEnv; it is an argument of "
            r"backend='ray' or 'async' only",
        ),
        (
            "ray",
            {"copy": False},
            r"copy does not apply to RayVectorEnv; it is an argument of backend='sync' or "
            r"'async' only",
        ),
        (
            "async",
            {"envs_per_workr": 2},
            r"make_vec\(backend='async', envs_per_workr=2\): unexpected keyword argument "
            r"'envs_per_workr'; did you mean 'envs_per_worker'\? backend='async' takes "
            r"shared_memory, copy, context, .*autoreset_mode, max_concurrency, env_kwargs$",
        ),
    ],
)
def test_make_vec_rejects_an_argument_by_name(backend, kwargs, message):
    factory = Recorder()
    with pytest.raises(TypeError, match=message):
        make_vec([factory] * 2, backend=backend, **kwargs)
    assert factory.built == 0  # before any env, any process, any Ray


@pytest.mark.parametrize("backend", ["serial", "sync", "async"])
def test_make_vec_checks_num_envs_alike(backend):
    with pytest.raises(ValueError, match="num_envs is required when a single env id or factory"):
        make_vec(ENV_ID, backend=backend)
    with pytest.raises(ValueError, match="num_envs=3 but 2 env factories were given"):
        make_vec([ENV_ID] * 2, 3, backend=backend)
