"""Honest render modes: a task declares whether it renders, SimEnv's metadata says so.

Gymnasium's ``check_env`` runs here with its render check on: for an env built by
``gym.make`` it re-makes the env once per mode in ``metadata["render_modes"]`` and renders
it, so a listed mode that cannot render fails the check. "Without OpenGL" is tested in a
subprocess whose libEGL cannot be loaded (empty ``libEGL.so*`` files first on
``LD_LIBRARY_PATH``: the dynamic loader stops at them) and in one with GLFW and no display.
"""

from __future__ import annotations

import json
import os
import re
import subprocess
import sys
import textwrap
import warnings

import gymnasium as gym
import mujoco
import numpy as np
import pytest
from gymnasium import spaces
from gymnasium.utils.env_checker import check_env

from chronogym import FunctionTask, RenderModeError, SimEnv, TaskDefinitionError, register_task
from chronogym.engines.mujoco import gl_unavailable
from chronogym.registration import NAMESPACE, OPTIONAL_TASKS
from chronogym.tasks.cartpole import XML_PATH, CartPoleTask, ChronoCartPoleTask

# Every registered chronogym id but those on an optional engine (tests/chrono checks those).
ENV_IDS = sorted(  # the shipped tasks (not chronogym/Synthetic-v0, a plain env that never renders)
    env_id
    for env_id, spec in gym.registry.items()
    if spec.namespace == NAMESPACE
    and env_id.removeprefix(f"{NAMESPACE}/") not in OPTIONAL_TASKS
    and "task" in spec.kwargs
)


def gl_problem() -> str | None:
    """None when MuJoCo really renders in this process (an 8x8 frame), else why not."""
    reason = gl_unavailable()
    if reason is not None:
        return reason
    try:
        model = mujoco.MjModel.from_xml_string("<mujoco><worldbody/></mujoco>")
        with mujoco.Renderer(model, 8, 8) as renderer:
            renderer.render()
    except Exception as error:  # GL context creation fails in library-specific ways
        return f"{type(error).__name__}: {error}"
    return None


GL_PROBLEM = gl_problem()
needs_gl = pytest.mark.skipif(GL_PROBLEM is not None, reason=f"no OpenGL: {GL_PROBLEM}")


def checked(env: gym.Env) -> list[str]:
    """Run ``check_env`` with the render check on; return the render-related warnings."""
    with warnings.catch_warnings(record=True) as caught:
        warnings.simplefilter("always")
        check_env(env.unwrapped)
    return [str(w.message) for w in caught if "render" in str(w.message).lower()]


class NoRenderCartPole(CartPoleTask):
    """A MuJoCo task that opts out of rendering."""

    render_modes = ()


class SmallFrameCartPole(CartPoleTask):
    render_width, render_height = 64, 48


FRAME = np.arange(4 * 6 * 3, dtype=np.uint8).reshape(4, 6, 3)


def draw_frame(res) -> np.ndarray:
    """A render function: ``FRAME``, plus 1 when the cart is right of 0."""
    return FRAME + np.uint8(res["data"].qpos[0] > 0)


def function_cartpole(render=None) -> FunctionTask:
    """The cart-pole in the function form, with the given render function."""

    def init():
        model = mujoco.MjModel.from_xml_path(str(XML_PATH))
        data = mujoco.MjData(model)
        return [(model, data)], {"model": model, "data": data}

    def reset(res, rng, options):
        mujoco.mj_resetData(res["model"], res["data"])
        res["data"].qpos[:] = rng.uniform(-0.05, 0.05, size=res["model"].nq)
        mujoco.mj_forward(res["model"], res["data"])

    def apply_action(res, action):
        res["data"].ctrl[0] = action[0]

    return FunctionTask(
        init=init,
        reset=reset,
        apply_action=apply_action,
        observe=lambda res: np.concatenate([res["data"].qpos, res["data"].qvel]),
        reward=lambda res, action, obs: 1.0,
        terminated=lambda res, obs: False,
        dt=0.002,
        k=10,
        observation_space=spaces.Box(-np.inf, np.inf, (4,), np.float64),
        action_space=spaces.Box(-1.0, 1.0, (1,), np.float32),
        render=render,
        max_episode_steps=50,
    )


def make_function_env(with_render: bool, render_mode: str | None = None) -> SimEnv:
    return SimEnv(function_cartpole(draw_frame if with_render else None), render_mode=render_mode)


register_task("chronogym-test/NoRenderCartPole-v0", NoRenderCartPole)
for _flag in (True, False):
    gym.register(
        f"chronogym-test/FunctionCartPole{'Render' if _flag else ''}-v0",
        entry_point=make_function_env,
        kwargs={"with_render": _flag},
    )


def test_the_synthetic_env_refuses_every_render_mode_by_name():
    assert gym.make("chronogym/Synthetic-v0").unwrapped.metadata["render_modes"] == []
    with pytest.raises(RenderModeError, match="SyntheticEnv does not render; expected None"):
        gym.make("chronogym/Synthetic-v0", render_mode="rgb_array")


def test_ids_cover_the_shipped_mujoco_tasks():
    assert {"chronogym/CartPole-v0", "chronogym/Go1Velocity-v0"} <= set(ENV_IDS)
    assert "chronogym/ChronoCartPole-v0" not in ENV_IDS


@pytest.mark.parametrize("env_id", ENV_IDS)
def test_registered_env_passes_check_env_with_render_check(env_id):
    expected = [] if gl_unavailable() else ["rgb_array"]
    env = gym.make(env_id)
    assert env.unwrapped.metadata["render_modes"] == expected
    assert checked(env) == []  # renders once per listed mode through env.spec
    env.close()
    if expected:  # and the env built for rendering passes the render checker itself
        env = gym.make(env_id, render_mode="rgb_array")
        assert env.unwrapped.render_mode == "rgb_array"
        assert checked(env) == []
        env.close()


def test_task_without_render_lists_no_mode_and_refuses_rgb_array():
    env = gym.make("chronogym-test/NoRenderCartPole-v0")
    assert env.unwrapped.metadata["render_modes"] == []
    assert checked(env) == []
    env.close()
    refusal = (
        r"^chronogym-test/NoRenderCartPole-v0: render_mode='rgb_array': NoRenderCartPole does "
        r"not render.*expected None$"
    )
    with pytest.raises(ValueError, match=refusal):
        gym.make("chronogym-test/NoRenderCartPole-v0", render_mode="rgb_array")
    # also a TypeError: SB3's make_vec_env then retries without a render mode, as it does
    with pytest.raises(TypeError, match=refusal) as raised:
        gym.make("chronogym-test/NoRenderCartPole-v0", render_mode="rgb_array")
    assert isinstance(raised.value, RenderModeError)


def test_chrono_task_refuses_rgb_array_before_building_anything():
    """No PyChrono needed: the refusal comes before ``init()`` would import it."""
    assert ChronoCartPoleTask.render_modes == ()
    task = ChronoCartPoleTask()
    with pytest.raises(ValueError, match=r"render_mode='rgb_array': ChronoCartPoleTask does not"):
        SimEnv(task, render_mode="rgb_array")
    assert not hasattr(task, "system")
    with pytest.raises(ValueError, match=r"ChronoCartPoleTask does not render"):
        gym.make("chronogym/ChronoCartPole-v0", render_mode="rgb_array")


def test_function_task_renders_iff_given_a_render_function():
    assert function_cartpole(render=None).render_modes == ()
    assert function_cartpole(render=draw_frame).render_modes == ("rgb_array",)

    env = gym.make("chronogym-test/FunctionCartPole-v0")
    assert env.unwrapped.metadata["render_modes"] == []
    assert checked(env) == []
    with pytest.raises(ValueError, match=r"render_mode='rgb_array': FunctionTask does not render"):
        gym.make("chronogym-test/FunctionCartPole-v0", render_mode="rgb_array")

    env = gym.make("chronogym-test/FunctionCartPoleRender-v0")
    assert env.unwrapped.metadata["render_modes"] == ["rgb_array"]
    assert checked(env) == []
    env = gym.make("chronogym-test/FunctionCartPoleRender-v0", render_mode="rgb_array")
    assert checked(env) == []
    env.reset(seed=0)
    np.testing.assert_array_equal(env.render(), draw_frame(env.unwrapped.task.resources))


@needs_gl
def test_mujoco_task_renders_an_rgb_frame():
    env = SimEnv(SmallFrameCartPole(), render_mode="rgb_array")
    assert env.metadata == {"render_modes": ["rgb_array"], "render_fps": 50.0}
    env.reset(seed=0)
    frame = env.render()
    assert isinstance(frame, np.ndarray)
    assert frame.shape == (48, 64, 3) and frame.dtype == np.uint8
    assert frame.std() > 5  # a real picture, not a blank buffer
    env.close()


def test_metadata_is_a_fresh_dict_per_env_and_the_class_attribute_is_untouched():
    rendering = SimEnv(CartPoleTask())
    silent = SimEnv(NoRenderCartPole())
    assert silent.metadata["render_modes"] == []
    assert rendering.metadata is not silent.metadata
    assert isinstance(rendering.metadata, dict)
    assert isinstance(rendering.metadata["render_modes"], list)
    assert gym.Env.metadata == {"render_modes": []}
    assert SimEnv.metadata is gym.Env.metadata


@pytest.mark.parametrize("render_mode", ["human", "rgb_array_list", 3])
def test_unknown_render_mode_names_the_value_and_the_task(render_mode):
    with pytest.raises(ValueError, match=rf"render_mode={render_mode!r}: CartPoleTask .*expected"):
        SimEnv(CartPoleTask(), render_mode=render_mode)


@pytest.mark.parametrize(
    ("render_modes", "message"),
    [
        (("human",), r"render_modes=\('human',\), expected \(\) or \('rgb_array',\)"),
        ("rgb_array", r"render_modes='rgb_array', expected \(\) or \('rgb_array',\)"),
        (None, r"render_modes=None, expected"),
    ],
)
def test_bad_render_modes_declaration_is_a_definition_error(render_modes, message):
    task = CartPoleTask()
    task.render_modes = render_modes
    with pytest.raises(TaskDefinitionError, match=message):
        SimEnv(task)


def test_declaring_rgb_array_without_render_is_a_definition_error():
    class Declares(ChronoCartPoleTask):
        render_modes = ("rgb_array",)

    with pytest.raises(TaskDefinitionError, match=r"Declares declares render_modes=.*render\(\)"):
        SimEnv(Declares())
    with pytest.raises(TaskDefinitionError, match=r"render=42, expected a callable or None"):
        function_cartpole(render=42)


NO_GL_SCRIPT = textwrap.dedent(
    """
    import json, os, warnings
    import gymnasium as gym
    import chronogym
    from gymnasium.utils.env_checker import check_env

    out = {"MUJOCO_GL": os.environ.get("MUJOCO_GL"), "ids": {}}
    for env_id in json.loads(os.environ["IDS"]):
        env = gym.make(env_id)
        with warnings.catch_warnings(record=True) as caught:
            warnings.simplefilter("always")
            check_env(env.unwrapped)
        env.close()
        try:
            gym.make(env_id, render_mode="rgb_array")
            refusal = None
        except ValueError as error:
            refusal = str(error)
        out["ids"][env_id] = {
            "render_modes": env.unwrapped.metadata["render_modes"],
            "render_warnings": [str(w.message) for w in caught if "render" in str(w.message)],
            "refusal": refusal,
        }
    print(json.dumps(out))
    """
)


@pytest.mark.skipif(not sys.platform.startswith("linux"), reason="libEGL and MUJOCO_GL=egl: Linux")
@pytest.mark.parametrize("scenario", ["libEGL cannot be loaded", "GLFW without a display"])
def test_without_opengl_check_env_passes_and_rgb_array_is_refused(scenario, tmp_path):
    env = {k: v for k, v in os.environ.items() if k not in ("DISPLAY", "PYOPENGL_PLATFORM")}
    env["IDS"] = json.dumps(ENV_IDS)
    if scenario == "GLFW without a display":
        env["MUJOCO_GL"] = "glfw"
        gl, reason = "glfw", r"MuJoCo uses the GLFW backend \(MUJOCO_GL='glfw'\) but there is no"
    else:
        env.pop("MUJOCO_GL", None)  # chronogym's own choice, as on a fresh machine
        for name in ["libEGL.so", *(f"libEGL.so.{i}" for i in range(10))]:
            (tmp_path / name).write_bytes(b"")
        env["LD_LIBRARY_PATH"] = os.pathsep.join(
            p for p in (str(tmp_path), env.get("LD_LIBRARY_PATH", "")) if p
        )
        gl, reason = "disable", r"MUJOCO_GL='disable' turns MuJoCo's rendering off.*libegl1"
    run = subprocess.run(
        [sys.executable, "-c", NO_GL_SCRIPT], env=env, capture_output=True, text=True, timeout=300
    )
    assert run.returncode == 0, run.stderr[-3000:]
    out = json.loads(run.stdout.strip().splitlines()[-1])
    assert out["MUJOCO_GL"] == gl
    assert sorted(out["ids"]) == ENV_IDS
    for env_id, result in out["ids"].items():
        task = gym.spec(env_id).kwargs["task"].rpartition(":")[2]  # "module:TaskClass"
        assert result["render_modes"] == [], env_id
        assert result["render_warnings"] == [], env_id
        assert result["refusal"] is not None, env_id
        # gymnasium.make's re-raise puts the id first
        pattern = (
            rf"^{env_id}: render_mode='rgb_array': {task} cannot render in this process: {reason}"
        )
        assert re.search(pattern, result["refusal"]), result["refusal"]
        ending = "; until then, expected render_mode=None (runs without rendering)"
        assert result["refusal"].endswith(ending)
