"""The engine-independent half of Go1 velocity tracking: commands, observation, reward, end.

:class:`Go1VelocityBase` holds everything the MuJoCo task (:mod:`.task`) and the Chrono task
(:mod:`.chrono_task`) share, so both engines run the same interface, observation scales,
reward terms, command sampling, pushes and termination, by the same code. An engine
subclass reads and writes its simulation through a few hooks:

===========================  =================================================================
``_reset_pose(yaw, joints)``  put the robot at rest at its home height, heading ``yaw``, with
                              these joint angles (``None``: the home pose) and servo targets
                              at the home pose; leave the state current
``_read_state(raw)``          fill ``raw[0:6]`` (base angular velocity, projected gravity, body
                              frame) and ``raw[9:33]`` (joint offsets, joint velocities); set
                              ``self.base_lin_vel`` (body frame)
``_set_joint_targets(q)``     the servo targets (rad, joint order FR, FL, RR, RL)
``_kick_base(dv)``            add ``dv`` (m/s, world x and y) to the base velocity
``_update_contacts()``        set ``self.feet_contact_now`` (4 bools) and ``self._base_contact``
``_joint_torques()``          the 12 servo torques of the last tick (N m)
``_base_height()``            the height of the base frame's origin (m)
``feet_positions()``          the foot centres, (4, 3) world positions (m)
``_set_friction(mu)``         foot-ground friction coefficient (domain randomization)
``_set_added_base_mass(dm)``  trunk mass = nominal + ``dm`` (domain randomization)
===========================  =================================================================
"""

from __future__ import annotations

import dataclasses
import math
from typing import Any

import numpy as np
from gymnasium import spaces

from chronogym.task import Task
from chronogym.tasks.quadruped.config import (
    ACTION_DIM,
    OBS_DIM,
    OBS_SCALES,
    CommandRanges,
    DomainRandomization,
    RewardWeights,
)
from chronogym.tasks.quadruped.model import DEFAULT_JOINT_POS

#: Reward terms in the order of ``RewardWeights``' fields (the task's term vector).
REWARD_TERMS: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(RewardWeights))
_TRACKING_SIGMA = 0.25  # (m/s)^2 and (rad/s)^2 of the exponential tracking kernels


def observation_scale() -> np.ndarray:
    """The (45,) vector the raw observation is multiplied by (``OBS_SCALES`` per group)."""
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


def _check_positive(name: str, value: Any) -> None:
    if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
        raise ValueError(f"{name}={value!r}: expected a finite float > 0")


class Go1VelocityBase(Task):
    """Go1 tracking a velocity command, for any engine: see the module docstring."""

    def _init_tracking(
        self,
        *,
        max_episode_steps: int | None,
        commands: CommandRanges | None,
        rewards: RewardWeights | None,
        randomization: DomainRandomization | None,
        action_scale: float,
        action_clip: float,
        max_tilt: float,
        base_height_target: float,
        air_time_threshold: float,
        reset_joint_noise: float,
        only_positive_rewards: bool,
        kp: float | None,
        kd: float | None,
    ) -> None:
        """Check and store the settings both engines share."""
        for name, value in (
            ("action_scale", action_scale),
            ("action_clip", action_clip),
            ("max_tilt", max_tilt),
            ("base_height_target", base_height_target),
        ):
            _check_positive(name, value)
        for name, value in (("kp", kp), ("kd", kd)):
            if value is not None and not (
                isinstance(value, (int, float)) and math.isfinite(value) and value >= 0
            ):
                raise ValueError(f"{name}={value!r}: expected None (the model's) or a float >= 0")
        if not 0 <= air_time_threshold < 5:
            raise ValueError(f"air_time_threshold={air_time_threshold!r}: expected in [0, 5) s")
        if not 0 <= reset_joint_noise <= 0.5:
            raise ValueError(f"reset_joint_noise={reset_joint_noise!r}: expected in [0, 0.5] rad")
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
        self.only_positive_rewards = bool(only_positive_rewards)
        self.kp = kp
        self.kd = kd

    def _setup_tracking(self) -> None:
        """Spaces and buffers; call once the simulation exists (in ``setup``)."""
        self.observation_space = spaces.Box(-np.inf, np.inf, shape=(OBS_DIM,), dtype=np.float32)
        self.action_space = spaces.Box(
            -self.action_clip, self.action_clip, shape=(ACTION_DIM,), dtype=np.float32
        )
        self.control_dt = self.dt * self.k
        self._obs_scale = observation_scale()
        self._obs_raw = np.zeros(OBS_DIM)
        self.base_lin_vel = np.zeros(3)
        self.command = np.zeros(3)
        self.last_action = np.zeros(ACTION_DIM)
        self.prev_action = np.zeros(ACTION_DIM)
        self.feet_air_time = np.zeros(4)
        self.feet_contact = np.zeros(4, dtype=bool)
        self.feet_contact_now = np.zeros(4, dtype=bool)
        weights = dataclasses.asdict(self.weights)
        self._term_weights = np.array([weights[n] for n in REWARD_TERMS]) * self.control_dt
        self._active_terms = [(i, n) for i, n in enumerate(REWARD_TERMS) if weights[n] != 0]
        self._slip_on = weights["feet_slip"] != 0  # skip the foot-velocity work when off
        self._raw = np.zeros(len(REWARD_TERMS))
        self._weighted = np.zeros(len(REWARD_TERMS))
        self._episode_sum = np.zeros(len(REWARD_TERMS))
        self._action_change = np.zeros(ACTION_DIM)
        self._steps = 0
        self._next_command: int | None = None
        self._next_push: int | None = None
        self._fell = False
        self._base_contact = False

    # --- engine hooks ----------------------------------------------------------------------

    def _reset_pose(self, yaw: float, joints: np.ndarray | None) -> None:
        raise NotImplementedError

    def _read_state(self, raw: np.ndarray) -> None:
        raise NotImplementedError

    def _set_joint_targets(self, targets: np.ndarray) -> None:
        raise NotImplementedError

    def _kick_base(self, dv: np.ndarray) -> None:
        raise NotImplementedError

    def _update_contacts(self) -> None:
        raise NotImplementedError

    def _joint_torques(self) -> np.ndarray:
        raise NotImplementedError

    def _base_height(self) -> float:
        raise NotImplementedError

    def feet_positions(self) -> np.ndarray:
        """World positions of the four foot centres, (4, 3) [m], leg order FR, FL, RR, RL."""
        raise NotImplementedError

    def _feet_xy(self) -> np.ndarray:
        return self.feet_positions()[:, :2]

    def _set_friction(self, mu: float) -> None:
        raise NotImplementedError

    def _set_added_base_mass(self, dm: float) -> None:
        raise NotImplementedError

    # --- reset -----------------------------------------------------------------------------

    def reset(self, rng: np.random.Generator, options: dict[str, Any] | None) -> None:
        options = options or {}
        self._apply_randomization(rng)
        yaw = rng.uniform(-math.pi, math.pi)
        noise = self.reset_joint_noise
        joints = (
            DEFAULT_JOINT_POS + rng.uniform(-noise, noise, size=ACTION_DIM) if noise > 0 else None
        )
        self._reset_pose(yaw, joints)
        fixed = options.get("command")
        self.command = self._draw_command(rng, fixed)
        self._next_command = None if fixed is not None else self._resample_interval_steps()
        self.last_action[:] = 0.0
        self.prev_action[:] = 0.0
        self.feet_air_time[:] = 0.0
        self.feet_contact[:] = True
        self._weighted[:] = 0.0
        self._episode_sum[:] = 0.0
        self._sq_err = [0.0, 0.0]
        self._steps = 0
        self._fell = False
        self._base_contact = False
        self._episode_rng = rng  # pushes and resampled commands draw from it
        self._next_push = self._push_interval_steps()
        self._feet_xy_before = self._feet_xy()

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
        if dr.friction is not None:
            self._set_friction(rng.uniform(*dr.friction))
        if dr.added_base_mass is not None:
            self._set_added_base_mass(rng.uniform(*dr.added_base_mass))

    def _resample_interval_steps(self) -> int | None:
        seconds = self.commands.resample_s
        return None if seconds is None else max(1, round(seconds / self.control_dt))

    def _push_interval_steps(self) -> int | None:
        dr = self.randomization
        if dr is None or dr.push_interval_s is None:
            return None
        return max(1, round(dr.push_interval_s / self.control_dt))

    # --- step ------------------------------------------------------------------------------

    def apply_action(self, action: np.ndarray) -> None:
        self.prev_action[:] = self.last_action
        self.last_action[:] = action
        self._set_joint_targets(DEFAULT_JOINT_POS + self.action_scale * self.last_action)
        self._steps += 1
        if self._next_push is not None and self._steps >= self._next_push:
            kick = self._episode_rng.uniform(-1.0, 1.0, size=2) * self.randomization.push_velocity
            self._kick_base(kick)
            self._next_push += self._push_interval_steps()
        if self._next_command is not None and self._steps >= self._next_command:
            self.command = self._draw_command(self._episode_rng, None)
            self._next_command += self._resample_interval_steps()

    def observe(self) -> np.ndarray:
        raw = self._obs_raw
        self._read_state(raw)
        raw[6:9] = self.command
        raw[33:45] = self.last_action
        return (raw * self._obs_scale).astype(np.float32)

    def reward(self, action: np.ndarray, obs: np.ndarray) -> float:
        self._update_contacts()
        weighted = np.multiply(self._raw_terms(), self._term_weights, out=self._weighted)
        self._episode_sum += weighted
        vx, vy = self.base_lin_vel[0:2].tolist()
        ex, ey = vx - self.command[0], vy - self.command[1]
        self._sq_err[0] += ex * ex
        self._sq_err[1] += ey * ey
        total = float(weighted.sum())
        if self.only_positive_rewards and total < 0:
            total = 0.0  # a step never costs reward, so ending the episode early never pays
        return total

    @property
    def reward_terms(self) -> dict[str, float]:
        """Weighted, dt-scaled value of each active term in the last step's reward."""
        return {name: float(self._weighted[i]) for i, name in self._active_terms}

    def compute_reward_terms(self) -> dict[str, float]:
        """Weighted, dt-scaled value of each active reward term for the current state."""
        weighted = self._raw_terms() * self._term_weights
        return {name: float(weighted[i]) for i, name in self._active_terms}

    def _raw_terms(self) -> np.ndarray:
        """Unweighted value of every term, in ``REWARD_TERMS`` order (one preallocated array)."""
        vx, vy, vz = self.base_lin_vel.tolist()
        wx, wy, wz, gx, gy = self._obs_raw[0:5].tolist()
        cmd_x, cmd_y, cmd_wz = self.command.tolist()
        np.subtract(self.last_action, self.prev_action, out=self._action_change)
        posture = self._obs_raw[9:21]
        torque = self._joint_torques()
        height_error = self._base_height() - self.base_height_target
        raw = self._raw
        raw[0] = math.exp(-((vx - cmd_x) ** 2 + (vy - cmd_y) ** 2) / _TRACKING_SIGMA)
        raw[1] = math.exp(-((wz - cmd_wz) ** 2) / _TRACKING_SIGMA)
        raw[2] = vz * vz
        raw[3] = wx * wx + wy * wy
        raw[4] = gx * gx + gy * gy
        raw[5] = height_error * height_error
        raw[6] = self._action_change @ self._action_change
        raw[7] = posture @ posture
        raw[8] = torque @ torque
        raw[9] = self._air_time_term(math.hypot(cmd_x, cmd_y) > 0.1)
        raw[10] = self._slip_term() if self._slip_on else 0.0
        return raw

    def _slip_term(self) -> float:
        """Sum over the feet on the ground of their squared horizontal speed, averaged over
        the last control interval (feet that slide instead of stepping)."""
        feet = self._feet_xy()
        moved = feet - self._feet_xy_before
        self._feet_xy_before = feet
        speed2 = np.einsum("ij,ij->i", moved, moved) / (self.control_dt * self.control_dt)
        return float(speed2 @ self.feet_contact_now)

    def _air_time_term(self, moving: bool) -> float:
        contact = self.feet_contact_now
        air = self.feet_air_time
        air += self.control_dt
        value = 0.0
        before = self.feet_contact.tolist()
        for foot, now in enumerate(contact.tolist()):
            if now:
                if not before[foot]:  # touchdown
                    value += float(air[foot]) - self.air_time_threshold
                air[foot] = 0.0
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
        sums = self._episode_sum
        log = {f"/reward/{name}": float(sums[i]) for i, name in self._active_terms}
        log["/metrics/x_vel_mse"] = float(self._sq_err[0] / steps)
        log["/metrics/y_vel_mse"] = float(self._sq_err[1] / steps)
        log["/metrics/survived"] = 0.0 if self._fell else 1.0
        log["/metrics/episode_length_s"] = steps * self.control_dt
        return {"log": log}
