"""Project Chrono engine: state readers, ChronoTask reset, the Chrono cart-pole on Ray.

Every test but the last needs PyChrono (conda only) and is skipped without it (the
``chrono`` fixture of conftest.py). Ray workers import pychrono too: a local cluster
started by the test session inherits the driver's environment (``PYTHONPATH`` included,
see tests/conftest.py), so a PyChrono found through ``PYTHONPATH`` is found by the
workers as well.
"""

from __future__ import annotations

import math
import os
import signal
import subprocess
import sys
import time

import gymnasium as gym
import numpy as np
import pytest
from gymnasium.utils.env_checker import check_env
from vector_rollouts import vector_rollout

from chronogym import RayVectorEnv, SerialVectorEnv, SimEnv

ENV_ID = "chronogym/ChronoCartPole-v0"
G = 9.81


def falling_system(chrono, timestepper: str = "Type_TRAPEZOIDAL"):
    """A free 1 kg-ish sphere under gravity -z, integrated exactly for constant acceleration."""
    system = chrono.ChSystemNSC()
    system.SetGravitationalAcceleration(chrono.ChVector3d(0, 0, -G))
    system.SetTimestepperType(getattr(chrono.ChTimestepper, timestepper))
    body = chrono.ChBodyEasySphere(0.1, 1000, False, False)
    system.Add(body)
    return system, body


def test_free_fall_readers(chrono):
    from chronogym.engines.chrono import body_ang_vel, body_lin_vel, body_pos, body_rot

    system, body = falling_system(chrono)
    dt = 1e-3
    for _ in range(500):
        system.DoStepDynamics(dt)
    t = system.GetChTime()
    assert t == pytest.approx(0.5)
    np.testing.assert_allclose(body_pos(body), [0, 0, -G * t**2 / 2], atol=1e-6)
    np.testing.assert_allclose(body_lin_vel(body), [0, 0, -G * t], atol=1e-6)
    np.testing.assert_allclose(body_rot(body), [1, 0, 0, 0], atol=1e-12)
    np.testing.assert_allclose(body_ang_vel(body), 0, atol=1e-12)


def test_renewed_collision_system_keeps_every_contact(chrono):
    """A box resting on the ground stays there across a renewal: every model is bound again
    in a new collision system (a model left unbound would let the box fall through)."""
    from chronogym.engines.chrono import body_pos, renew_collision_system

    system = chrono.ChSystemNSC()
    system.SetCollisionSystemType(chrono.ChCollisionSystem.Type_BULLET)
    system.SetGravitationalAcceleration(chrono.ChVector3d(0, 0, -G))
    material = chrono.ChContactMaterialNSC()
    ground = chrono.ChBodyEasyBox(2, 2, 0.2, 1000, False, True, material)
    ground.SetFixed(True)
    ground.SetPos(chrono.ChVector3d(0, 0, -0.1))
    box = chrono.ChBodyEasyBox(0.2, 0.2, 0.2, 1000, False, True, material)
    box.SetPos(chrono.ChVector3d(0, 0, 0.12))
    system.Add(ground)
    system.Add(box)
    for _ in range(300):
        system.DoStepDynamics(1e-3)
    resting, contacts = body_pos(box)[2], system.GetNumContacts()
    assert 0.09 < resting < 0.11 and contacts > 0
    renew_collision_system(system)
    for _ in range(300):
        system.DoStepDynamics(1e-3)
    assert body_pos(box)[2] == pytest.approx(resting, abs=1e-3)
    assert system.GetNumContacts() == contacts


def test_advancer_checks_who_steps_a_real_system(chrono):
    """The first tick reads ``GetChTime`` of a real ChSystem: one listing passes, two fail."""
    from chronogym import Advancer

    system, _ = falling_system(chrono)
    Advancer([system], 1e-3).run(0.0, 3)
    assert system.GetChTime() == pytest.approx(3e-3)
    with pytest.raises(RuntimeError, match=r"advanced its time by 0\.002 s .*stepped 2 times"):
        Advancer([system, system], 1e-3)(system.GetChTime())


def test_default_integrator_matches_semi_implicit_euler(chrono):
    from chronogym.engines.chrono import body_pos

    system, body = falling_system(chrono, "Type_EULER_IMPLICIT_LINEARIZED")
    dt, n = 1e-3, 200
    for _ in range(n):
        system.DoStepDynamics(dt)
    assert body_pos(body)[2] == pytest.approx(-G * dt**2 * n * (n + 1) / 2, abs=1e-12)


def test_body_frame_readers(chrono):
    from chronogym.engines.chrono import body_ang_vel, body_lin_vel, body_state, set_body_state

    _, body = falling_system(chrono)
    quarter_turn_z = (math.cos(math.pi / 4), 0, 0, math.sin(math.pi / 4))
    set_body_state(body, pos=(1, 2, 3), rot=quarter_turn_z, lin_vel=(1, 0, 0), ang_vel=(0, 2, 0))
    np.testing.assert_allclose(body_lin_vel(body, local=True), [0, -1, 0], atol=1e-12)
    np.testing.assert_allclose(body_ang_vel(body, local=True), [2, 0, 0], atol=1e-12)
    np.testing.assert_allclose(body_ang_vel(body), [0, 2, 0], atol=1e-12)
    state = body_state(body)
    assert state.shape == (13,) and state.dtype == np.float64
    np.testing.assert_allclose(state[:3], [1, 2, 3])


def test_divergence_and_motor_input(chrono):
    from chronogym.engines.chrono import MotorInput, bodies_diverged, set_body_state

    _, body = falling_system(chrono)
    assert not bodies_diverged([body])
    set_body_state(body, lin_vel=(0, 0, 1e7))
    assert bodies_diverged([body])
    set_body_state(body, lin_vel=(0, 0, math.nan))
    assert bodies_diverged([body])
    motor = chrono.ChLinkMotorLinearForce()
    force = MotorInput(motor, 2.5)
    assert force.function.GetConstant() == 2.5
    force.set(-4.0)
    assert motor.GetMotorFunction().GetVal(0.0) == -4.0
    with pytest.raises(ValueError, match=r"value=nan: expected a finite float"):
        force.set(math.nan)


def test_registered_env_passes_gymnasium_checker(chrono):
    """With the render check on: the Chrono cart-pole declares no render mode, honestly."""
    env = gym.make(ENV_ID)
    assert env.unwrapped.metadata["render_modes"] == []
    check_env(env.unwrapped)
    env.close()
    with pytest.raises(ValueError, match=r"render_mode='rgb_array': ChronoCartPoleTask does not"):
        gym.make(ENV_ID, render_mode="rgb_array")


def episode(env: SimEnv, seed: int, steps: int = 200) -> list[np.ndarray]:
    rng = np.random.default_rng(3)
    rows = [np.concatenate([env.reset(seed=seed)[0], [0, 0, 0]])]
    for _ in range(steps):
        obs, reward, terminated, truncated, _ = env.step(rng.uniform(-1, 1, 1).astype(np.float32))
        rows.append(np.concatenate([obs, [reward, terminated, truncated]]))
        if terminated or truncated:
            break
    return rows


def test_reset_restores_the_initial_state(chrono):
    env = gym.make(ENV_ID).unwrapped
    first = episode(env, seed=5)
    episode(env, seed=6)  # a different episode in between
    again = episode(env, seed=5)
    assert len(first) > 10
    np.testing.assert_array_equal(np.array(first), np.array(again))
    assert env.task.system.GetChTime() == pytest.approx(env.sim_time)


def test_pushing_the_cart_tilts_the_pole_back(chrono):
    env = gym.make(ENV_ID, reset_noise=0.0)
    env.reset(seed=0)
    obs, *_ = env.step(np.ones(1, dtype=np.float32))
    assert obs[0] > 0 and obs[2] > 0 and obs[1] < 0 and obs[3] < 0


@pytest.mark.parametrize("transport", ["socket", "fork"])
def test_ray_matches_serial_bit_for_bit(chrono, ray_cluster, transport):
    serial = vector_rollout(SerialVectorEnv(ENV_ID, 4), 80)
    vec = RayVectorEnv(ENV_ID, 4, envs_per_worker=2, transport=transport)
    parallel = vector_rollout(vec, 80)
    vec.close()
    assert any(step[2].any() for step in serial[1:])  # episodes ended and were reset
    for got, want in zip(parallel, serial, strict=True):
        for a, b in zip(got[:-1], want[:-1], strict=True):  # all but infos
            np.testing.assert_array_equal(a, b)


@pytest.mark.parametrize("transport", ["socket", "fork"])
def test_sigkilled_worker_is_replaced(chrono, ray_cluster, transport):
    def kill(t, vec):
        if t == 10:
            os.kill(vec.worker_pids()[1], signal.SIGKILL)
            time.sleep(0.3)

    undisturbed = vector_rollout(SerialVectorEnv(ENV_ID, 4), 30)
    vec = RayVectorEnv(ENV_ID, 4, envs_per_worker=2, transport=transport)
    old = vec.worker_pids()
    run = vector_rollout(vec, 30, kill=kill)
    assert vec.worker_pids()[0] == old[0] and vec.worker_pids()[1] != old[1]
    _, rewards, _, truncated, info = run[11]
    assert truncated[2:].all() and (rewards[2:] == 0).all() and info["worker_restarted"][2:].all()
    for got, want in zip(run, undisturbed, strict=True):  # the other worker is undisturbed
        np.testing.assert_array_equal(got[0][:2], want[0][:2])
    assert np.isfinite(run[-1][0]).all()
    vec.close()


class Chrono8Vector:  # Chrono 8 vectors and quaternions have no to_numpy()
    def __init__(self, *values: float) -> None:
        self.x, self.y, self.z = values


class Chrono8Quaternion:
    def __init__(self, *values: float) -> None:
        self.e0, self.e1, self.e2, self.e3 = values


class Chrono8Body:
    """A body with Chrono 8's method names, to check the readers' probing."""

    def GetPos(self):
        return Chrono8Vector(1, 2, 3)

    def GetRot(self):
        return Chrono8Quaternion(math.cos(math.pi / 4), 0, 0, math.sin(math.pi / 4))

    def GetPos_dt(self):
        return Chrono8Vector(1, 0, 0)

    def GetWvel_par(self):
        return Chrono8Vector(0, 2, 0)

    def GetWvel_loc(self):
        return Chrono8Vector(2, 0, 0)


def test_readers_probe_chrono_8_names_without_pychrono():
    from chronogym.engines.chrono import body_ang_vel, body_lin_vel, body_state, probe

    body = Chrono8Body()
    np.testing.assert_allclose(body_lin_vel(body, local=True), [0, -1, 0], atol=1e-12)
    np.testing.assert_array_equal(body_ang_vel(body, local=True), [2, 0, 0])
    np.testing.assert_allclose(body_state(body)[[0, 1, 2, 7, 11]], [1, 2, 3, 1, 2])
    with pytest.raises(AttributeError, match=r"Chrono8Body has none of GetBodies, Get_bodylist"):
        probe(body, ("GetBodies", "Get_bodylist"))


NO_PYCHRONO = """
import sys
sys.modules["pychrono"] = None  # as if PyChrono were not installed
import gymnasium as gym
import chronogym
assert "chronogym/ChronoCartPole-v0" in gym.registry
try:
    gym.make("chronogym/ChronoCartPole-v0")
except ModuleNotFoundError as exc:
    print("ERROR:", exc)
else:
    raise SystemExit("gym.make succeeded without pychrono")
"""


def test_without_pychrono_make_names_pychrono_and_conda():
    result = subprocess.run(
        [sys.executable, "-c", NO_PYCHRONO], capture_output=True, text=True, timeout=120
    )
    assert result.returncode == 0, result.stderr
    message = result.stdout
    assert "pychrono" in message and "conda install projectchrono::pychrono" in message
