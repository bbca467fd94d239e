"""Go1 velocity tracking: follow a commanded planar velocity and yaw rate on flat ground.

Observation (float32, 45), each group scaled by ``OBS_SCALES`` (layout in ``OBS_SLICES``):
base angular velocity (body frame, 3), projected gravity (body frame, 3), command (vx, vy,
yaw rate, 3), joint position offsets from the default pose (12), joint velocities (12),
previous action (12).
Action (float32, 12): normalized joint targets; target = default pose + ``action_scale`` x a,
sent to the model's position servos (kp 100, kv 2, torque-limited).
Reward: named, weighted terms (``RewardWeights``) times the control interval, clipped at 0
from below (``only_positive_rewards``, as in legged_gym: with random actions the penalties
outweigh tracking, and PPO would learn to fall on purpose); the terms of
each step are in ``self.reward_terms`` and their episode sums reach ``info["log"]`` on the
last step of an episode, with the episode-mean x/y velocity tracking errors.
Episode: 20 s (1000 steps at 50 Hz); terminated when the base tilts past ``max_tilt`` or the
trunk or a hip touches the ground; truncated by the time limit.
Physics: ``dt`` = 5 ms, ``k`` = 4 (50 Hz policy), implicitfast integrator, pyramidal friction
cone (see ``benchmarks/quadruped_physics.py`` for the measurements behind this choice).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np
from gymnasium import spaces

from chronogym.engines.mujoco import MujocoTask
from chronogym.tasks.quadruped.config import (
    ACTION_DIM,
    OBS_DIM,
    OBS_SCALES,
    CommandRanges,
    DomainRandomization,
    RewardWeights,
)
from chronogym.tasks.quadruped.model import (
    BASE_BODY_NAME,
    CAMERA_NAME,
    DEFAULT_JOINT_POS,
    FOOT_GEOM_NAMES,
    HOME_BASE_HEIGHT,
    HOME_KEYFRAME,
    LEG_NAMES,
    go1_xml_path,
)

_TRACKING_SIGMA = 0.25  # (m/s)^2 and (rad/s)^2 of the exponential tracking kernels


def _scale_vector() -> np.ndarray:
    parts = []
    for name, size in (
        ("base_ang_vel", 3),
        ("projected_gravity", 3),
        ("command", 3),
        ("joint_pos", 12),
        ("joint_vel", 12),
        ("last_action", 12),
    ):
        scale = OBS_SCALES[name]
        parts.append(np.broadcast_to(np.asarray(scale, dtype=np.float64), (size,)))
    return np.concatenate(parts)


class Go1VelocityTask(MujocoTask):
    """Unitree Go1 tracking a velocity command (the paper's locomotion task)."""

    render_camera = CAMERA_NAME

    def __init__(
        self,
        *,
        dt: float = 0.005,
        k: int = 4,
        max_episode_steps: int | None = 1000,
        commands: CommandRanges | None = None,
        rewards: RewardWeights | None = None,
        randomization: DomainRandomization | None = None,
        action_scale: float = 0.25,
        action_clip: float = 10.0,
        max_tilt: float = 1.0,
        base_height_target: float = HOME_BASE_HEIGHT,
        air_time_threshold: float = 0.25,
        reset_joint_noise: float = 0.1,
        cone: str = "pyramidal",
        only_positive_rewards: bool = True,
    ) -> None:
        for name, value in (
            ("action_scale", action_scale),
            ("action_clip", action_clip),
            ("max_tilt", max_tilt),
            ("base_height_target", base_height_target),
        ):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name}={value!r}: expected a finite float > 0")
        if not 0 <= air_time_threshold < 5:
            raise ValueError(f"air_time_threshold={air_time_threshold!r}: expected in [0, 5) s")
        if not 0 <= reset_joint_noise <= 0.5:
            raise ValueError(f"reset_joint_noise={reset_joint_noise!r}: expected in [0, 0.5] rad")
        if cone not in ("pyramidal", "elliptic"):
            raise ValueError(f"cone={cone!r}: expected 'pyramidal' or 'elliptic'")
        self.dt = dt
        self.k = k
        self.max_episode_steps = max_episode_steps
        self.commands = commands or CommandRanges()
        self.weights = rewards or RewardWeights()
        self.randomization = randomization
        self.action_scale = float(action_scale)
        self.action_clip = float(action_clip)
        self.max_tilt = float(max_tilt)
        self.base_height_target = float(base_height_target)
        self.air_time_threshold = float(air_time_threshold)
        self.reset_joint_noise = float(reset_joint_noise)
        self.cone = cone
        self.only_positive_rewards = bool(only_positive_rewards)

    # --- init ------------------------------------------------------------------------------

    def load_model(self) -> Any:
        import mujoco

        model = mujoco.MjModel.from_xml_path(str(go1_xml_path()))
        model.opt.cone = (
            mujoco.mjtCone.mjCONE_PYRAMIDAL
            if self.cone == "pyramidal"
            else mujoco.mjtCone.mjCONE_ELLIPTIC
        )
        return model

    def setup(self) -> None:
        model = self.model
        self.observation_space = spaces.Box(-np.inf, np.inf, shape=(OBS_DIM,), dtype=np.float32)
        self.action_space = spaces.Box(
            -self.action_clip, self.action_clip, shape=(ACTION_DIM,), dtype=np.float32
        )
        self.control_dt = self.dt * self.k
        self._home_key = model.key(HOME_KEYFRAME).id
        self._trunk = model.body(BASE_BODY_NAME).id
        self._nominal_trunk_mass = float(model.body_mass[self._trunk])
        floor = model.geom("floor").id
        self._floor = floor
        self._nominal_floor_friction = model.geom_friction[floor].copy()
        self._foot_geoms = np.array([model.geom(n).id for n in FOOT_GEOM_NAMES])
        self._nominal_foot_friction = model.geom_friction[self._foot_geoms].copy()
        # Role of each geom in a contact: 1..4 = foot index + 1, -1 = trunk or hip (fatal), 0 other.
        self._geom_role = np.zeros(model.ngeom, dtype=np.int64)
        for leg, geom in enumerate(self._foot_geoms):
            self._geom_role[geom] = leg + 1
        fatal = [self._trunk] + [model.body(f"{leg}_hip").id for leg in LEG_NAMES]
        for geom in range(model.ngeom):
            if model.geom_bodyid[geom] in fatal:
                self._geom_role[geom] = -1
        self._geom_roles: list[int] = self._geom_role.tolist()
        self._obs_scale = _scale_vector()
        self._weights = self.weights.active()
        self._rot = np.zeros(9)
        self._obs_raw = np.zeros(OBS_DIM)
        self.command = np.zeros(3)
        self.last_action = np.zeros(ACTION_DIM)
        self.prev_action = np.zeros(ACTION_DIM)
        self.feet_air_time = np.zeros(4)
        self.feet_contact = np.zeros(4, dtype=bool)
        self.reward_terms: dict[str, float] = {}
        self._episode_sums: dict[str, float] = {}
        self._steps = 0
        self._fell = False
        self._base_contact = False

    # --- reset -----------------------------------------------------------------------------

    def reset(self, rng: np.random.Generator, options: dict[str, Any] | None) -> None:
        options = options or {}
        self._apply_randomization(rng)
        self.reset_data(self._home_key)
        data = self.data
        yaw = rng.uniform(-math.pi, math.pi)
        data.qpos[3:7] = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
        noise = self.reset_joint_noise
        if noise > 0:
            data.qpos[7:] = DEFAULT_JOINT_POS + rng.uniform(-noise, noise, size=ACTION_DIM)
        data.ctrl[:] = DEFAULT_JOINT_POS
        self.command = self._draw_command(rng, options.get("command"))
        self.last_action[:] = 0.0
        self.prev_action[:] = 0.0
        self.feet_air_time[:] = 0.0
        self.feet_contact[:] = True
        self.reward_terms = {}
        self._episode_sums = dict.fromkeys(self._weights, 0.0)
        self._sq_err = np.zeros(2)
        self._steps = 0
        self._fell = False
        self._base_contact = False
        self._push_rng = rng
        self._next_push = self._push_interval_steps()
        self.forward()

    def _draw_command(self, rng: np.random.Generator, fixed: Any) -> np.ndarray:
        if fixed is not None:
            command = np.asarray(fixed, dtype=np.float64)
            if command.shape != (3,) or not np.isfinite(command).all():
                raise ValueError(
                    f"options['command']={fixed!r}: expected 3 finite floats (vx, vy, yaw_rate)"
                )
            return command.copy()
        ranges = self.commands
        return np.array(
            [rng.uniform(*ranges.vx), rng.uniform(*ranges.vy), rng.uniform(*ranges.yaw_rate)]
        )

    def _apply_randomization(self, rng: np.random.Generator) -> None:
        dr = self.randomization
        if dr is None:
            return
        model = self.model
        if dr.friction is not None:
            mu = rng.uniform(*dr.friction)
            model.geom_friction[self._floor, 0] = mu
            model.geom_friction[self._foot_geoms, 0] = mu
        if dr.added_base_mass is not None:
            model.body_mass[self._trunk] = self._nominal_trunk_mass + rng.uniform(
                *dr.added_base_mass
            )

    def _push_interval_steps(self) -> int | None:
        dr = self.randomization
        if dr is None or dr.push_interval_s is None:
            return None
        return max(1, round(dr.push_interval_s / self.control_dt))

    # --- step ------------------------------------------------------------------------------

    def apply_action(self, action: np.ndarray) -> None:
        self.prev_action[:] = self.last_action
        self.last_action[:] = action
        self.data.ctrl[:] = DEFAULT_JOINT_POS + self.action_scale * self.last_action
        self._steps += 1
        if self._next_push is not None and self._steps >= self._next_push:
            kick = self._push_rng.uniform(-1.0, 1.0, size=2) * self.randomization.push_velocity
            self.data.qvel[0:2] += kick
            self._next_push += self._push_interval_steps()

    def observe(self) -> np.ndarray:
        import mujoco

        data = self.data
        mujoco.mju_quat2Mat(self._rot, data.qpos[3:7])
        rot = self._rot.reshape(3, 3)
        raw = self._obs_raw
        raw[0:3] = data.qvel[3:6]  # the free joint's angular velocity is in the body frame
        raw[3:6] = -rot[2]  # R^T (0, 0, -1)
        raw[6:9] = self.command
        raw[9:21] = data.qpos[7:] - DEFAULT_JOINT_POS
        raw[21:33] = data.qvel[6:]
        raw[33:45] = self.last_action
        self.base_lin_vel = rot.T @ data.qvel[0:3]
        return (raw * self._obs_scale).astype(np.float32)

    def _update_contacts(self) -> None:
        data = self.data
        roles = self._geom_roles
        feet = [False, False, False, False]
        base = False
        for pair in data.contact.geom[: data.ncon].tolist():
            for geom in pair:
                role = roles[geom]
                if role > 0:
                    feet[role - 1] = True
                elif role < 0:
                    base = True
        self._base_contact = base
        self.feet_contact_now = np.array(feet)

    def reward(self, action: np.ndarray, obs: np.ndarray) -> float:
        self._update_contacts()
        terms = self.compute_reward_terms()
        self.reward_terms = terms
        total = 0.0
        sums = self._episode_sums
        for name, value in terms.items():
            total += value
            sums[name] += value
        err = self.base_lin_vel[0:2] - self.command[0:2]
        self._sq_err += err * err
        if self.only_positive_rewards and total < 0:
            total = 0.0  # a step never costs reward, so ending the episode early never pays
        return total

    def compute_reward_terms(self) -> dict[str, float]:
        """Weighted, dt-scaled value of each active reward term for the current state."""
        data = self.data
        vx, vy, vz = self.base_lin_vel.tolist()
        wx, wy, wz, gx, gy = self._obs_raw[0:5].tolist()
        cmd_x, cmd_y, cmd_wz = self.command.tolist()
        action_change = self.last_action - self.prev_action
        posture = self._obs_raw[9:21]
        torque = data.actuator_force
        raw = {
            "tracking_lin_vel": math.exp(
                -((vx - cmd_x) ** 2 + (vy - cmd_y) ** 2) / _TRACKING_SIGMA
            ),
            "tracking_ang_vel": math.exp(-((wz - cmd_wz) ** 2) / _TRACKING_SIGMA),
            "lin_vel_z": vz * vz,
            "ang_vel_xy": wx * wx + wy * wy,
            "orientation": gx * gx + gy * gy,
            "base_height": (float(data.qpos[2]) - self.base_height_target) ** 2,
            "action_rate": float(np.dot(action_change, action_change)),
            "joint_posture": float(np.dot(posture, posture)),
            "torques": float(np.dot(torque, torque)),
            "feet_air_time": self._air_time_term(),
        }
        scale = self.control_dt
        return {name: weight * scale * raw[name] for name, weight in self._weights.items()}

    def _air_time_term(self) -> float:
        contact = self.feet_contact_now
        touchdown = contact & ~self.feet_contact
        self.feet_air_time += self.control_dt
        moving = math.hypot(self.command[0], self.command[1]) > 0.1
        value = float(((self.feet_air_time - self.air_time_threshold) * touchdown).sum())
        self.feet_air_time[contact] = 0.0
        self.feet_contact = contact
        return value if moving else 0.0

    def terminated(self, obs: np.ndarray) -> bool:
        tilt = math.acos(min(1.0, max(-1.0, -self._obs_raw[5])))
        self._fell = tilt > self.max_tilt or self._base_contact
        return self._fell

    def info(self) -> dict[str, Any]:
        horizon = self.max_episode_steps
        if not (self._fell or (horizon is not None and self._steps >= horizon)):
            return {}
        steps = max(self._steps, 1)
        log = {f"/reward/{name}": value for name, value in self._episode_sums.items()}
        log["/metrics/x_vel_mse"] = float(self._sq_err[0] / steps)
        log["/metrics/y_vel_mse"] = float(self._sq_err[1] / steps)
        log["/metrics/survived"] = 0.0 if self._fell else 1.0
        log["/metrics/episode_length_s"] = steps * self.control_dt
        return {"log": log}
