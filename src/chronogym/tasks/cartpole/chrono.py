"""Cart-pole balancing on Project Chrono (PyChrono 10 API; needs ``pychrono``).

A 1 kg cart on a prismatic joint along x, pushed by a ``ChLinkMotorLinearForce``; a
0.1 kg, 1 m pole on a revolute joint about y. Observation (float64, 4): x, theta
(0 = upright, positive towards +x), xdot, thetadot. Action (float32, 1): force in
[-1, 1] times ``force_scale`` N. Reward 1 per step alive; terminated when
|theta| > 0.2 rad or |x| > 2.4 m; truncated after ``max_episode_steps``.
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium import spaces

from chronogym.engines.chrono import (
    ChronoTask,
    MotorInput,
    body_ang_vel,
    body_lin_vel,
    body_pos,
    body_rot,
    set_body_state,
)


class ChronoCartPoleTask(ChronoTask):
    """Keep a pole upright by pushing its cart, simulated by Chrono."""

    max_angle, max_position = 0.2, 2.4
    pole_length = 1.0

    def __init__(
        self,
        dt: float = 0.005,
        k: int = 4,
        max_episode_steps: int | None = 500,
        force_scale: float = 10.0,
        reset_noise: float = 0.05,
    ) -> None:
        if not reset_noise >= 0:
            raise ValueError(f"reset_noise={reset_noise!r}: expected a float >= 0")
        self.dt, self.k, self.max_episode_steps = dt, k, max_episode_steps
        self.force_scale, self.reset_noise = float(force_scale), float(reset_noise)

    def build_system(self) -> Any:
        import pychrono as chrono

        system = chrono.ChSystemNSC()
        system.SetGravitationalAcceleration(chrono.ChVector3d(0, 0, -9.81))
        ground = chrono.ChBody()
        ground.SetFixed(True)
        self.cart = chrono.ChBodyEasyBox(0.4, 0.2, 0.1, 125.0, False, False)  # 1 kg
        self.pole = chrono.ChBodyEasyBox(0.04, 0.04, self.pole_length, 62.5, False, False)
        self.pole.SetPos(chrono.ChVector3d(0, 0, self.pole_length / 2))  # 0.1 kg
        along_x = chrono.ChFramed(chrono.VNULL, chrono.Q_ROTATE_Z_TO_X)  # joint axis = frame z
        along_y = chrono.ChFramed(chrono.VNULL, chrono.Q_ROTATE_Z_TO_Y)
        rail = chrono.ChLinkLockPrismatic()
        rail.Initialize(self.cart, ground, along_x)
        hinge = chrono.ChLinkLockRevolute()
        hinge.Initialize(self.pole, self.cart, along_y)
        self.motor = chrono.ChLinkMotorLinearForce()  # pushes along its frame's z
        self.motor.SetGuideConstraint(chrono.ChLinkMotorLinear.GuideConstraint_FREE)
        self.motor.Initialize(self.cart, ground, along_x)
        for item in (ground, self.cart, self.pole, rail, hinge, self.motor):
            system.Add(item)
        return system

    def setup(self) -> None:
        self.force = MotorInput(self.motor)
        high = np.array([np.inf, np.pi, np.inf, np.inf])
        self.observation_space = spaces.Box(-high, high, dtype=np.float64)
        self.action_space = spaces.Box(-1.0, 1.0, shape=(1,), dtype=np.float32)

    def reset(self, rng: np.random.Generator, options: dict[str, Any] | None) -> None:
        self.reset_system()
        x, theta, xdot, thetadot = rng.uniform(-self.reset_noise, self.reset_noise, 4)
        h, s, c = self.pole_length / 2, math.sin(theta), math.cos(theta)
        set_body_state(self.cart, pos=(x, 0, 0), lin_vel=(xdot, 0, 0))
        set_body_state(
            self.pole,
            pos=(x + h * s, 0, h * c),
            rot=(math.cos(theta / 2), 0, math.sin(theta / 2), 0),
            lin_vel=(xdot + h * c * thetadot, 0, -h * s * thetadot),
            ang_vel=(0, thetadot, 0),
        )
        self.system.Update()
        self.force.set(0.0)

    def apply_action(self, action: np.ndarray) -> None:
        self.force.set(self.force_scale * float(action[0]))

    def observe(self) -> np.ndarray:
        w, qx, qy, qz = body_rot(self.pole)
        up = (2 * (qx * qz + w * qy), 1 - 2 * (qx * qx + qy * qy))  # pole axis: x, z
        theta = math.atan2(*up)
        xdot, thetadot = body_lin_vel(self.cart)[0], body_ang_vel(self.pole)[1]
        return np.array([body_pos(self.cart)[0], theta, xdot, thetadot])

    def reward(self, action: np.ndarray, obs: np.ndarray) -> float:
        return 1.0

    def terminated(self, obs: np.ndarray) -> bool:
        return abs(obs[1]) > self.max_angle or abs(obs[0]) > self.max_position
