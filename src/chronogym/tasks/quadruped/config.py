"""Settings of the Go1 velocity-tracking task: commands, reward weights, randomization.

Every setting is a small frozen dataclass with the defaults the documented training run used,
so a variant is ``Go1VelocityTask(rewards=RewardWeights(feet_air_time=0.5))``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass

#: Scale of each observation group (observation = raw value x scale).
OBS_SCALES: dict[str, float | tuple[float, float, float]] = {
    "base_ang_vel": 0.25,
    "projected_gravity": 1.0,
    "command": (2.0, 2.0, 0.25),
    "joint_pos": 1.0,
    "joint_vel": 0.05,
    "last_action": 1.0,
}

#: Observation layout: group name -> (start, stop) in the 45-vector.
OBS_SLICES: dict[str, tuple[int, int]] = {
    "base_ang_vel": (0, 3),
    "projected_gravity": (3, 6),
    "command": (6, 9),
    "joint_pos": (9, 21),
    "joint_vel": (21, 33),
    "last_action": (33, 45),
}
OBS_DIM = 45
ACTION_DIM = 12


def _check_range(name: str, bounds: tuple[float, float]) -> None:
    low, high = bounds
    if not (math.isfinite(low) and math.isfinite(high) and low <= high):
        raise ValueError(f"{name}={bounds!r}: expected (low, high) finite with low <= high")


@dataclass(frozen=True)
class CommandRanges:
    """Uniform ranges the velocity command is drawn from at each reset (body frame).

    ``resample_s``: draw a new command every this many seconds of an episode (as legged_gym
    does), so an episode holds several speed changes; ``None`` keeps one command per episode.
    A command fixed by ``reset(options={"command": ...})`` is never resampled.
    """

    vx: tuple[float, float] = (-0.5, 1.0)  # m/s, forward
    vy: tuple[float, float] = (-0.3, 0.3)  # m/s, left
    yaw_rate: tuple[float, float] = (-0.5, 0.5)  # rad/s
    resample_s: float | None = None

    def __post_init__(self) -> None:
        for name in ("vx", "vy", "yaw_rate"):
            _check_range(name, getattr(self, name))
        value = self.resample_s
        if value is not None and (
            isinstance(value, bool)
            or not isinstance(value, (int, float))
            or not math.isfinite(value)
            or value <= 0
        ):
            raise ValueError(f"resample_s={value!r}: expected None or seconds > 0")


@dataclass(frozen=True)
class RewardWeights:
    """Weight of each reward term; the step reward is sum(weight x term) x control dt.

    Tracking terms are positive and dominate, so a fall costs the reward the robot would have
    kept earning (mostly-negative rewards teach PPO to end episodes on purpose). A weight of 0
    switches a term off (it is then neither computed into the reward nor logged).
    """

    tracking_lin_vel: float = 1.0  # exp(-|v_xy - cmd_xy|^2 / sigma)
    tracking_ang_vel: float = 0.5  # exp(-(w_z - cmd_wz)^2 / sigma)
    lin_vel_z: float = -1.0  # v_z^2
    ang_vel_xy: float = -0.02  # w_x^2 + w_y^2 (roll and pitch rate)
    orientation: float = -1.0  # |projected gravity_xy|^2
    base_height: float = -10.0  # (h - target)^2
    action_rate: float = -0.005  # |a - a_prev|^2
    joint_posture: float = -0.05  # |q - q_default|^2
    torques: float = -1e-4  # |tau|^2
    feet_air_time: float = 1.0  # sum over touchdowns of (air time - threshold), if moving
    feet_slip: float = 0.0  # sum over feet on the ground of their horizontal speed^2

    def __post_init__(self) -> None:
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if isinstance(value, bool) or not isinstance(value, (int, float)):
                raise ValueError(f"{field.name}={value!r}: expected a float weight")
            if not math.isfinite(value):
                raise ValueError(f"{field.name}={value!r}: expected a finite weight")

    def active(self) -> dict[str, float]:
        """Name -> weight of the terms with a non-zero weight."""
        return {
            f.name: float(getattr(self, f.name))
            for f in dataclasses.fields(self)
            if getattr(self, f.name) != 0
        }


@dataclass(frozen=True)
class DomainRandomization:
    """Per-episode randomization, off unless passed to the task.

    ``friction``: range of the foot-ground friction coefficient; ``added_base_mass``: kg added
    to the trunk; ``push_interval_s`` / ``push_velocity``: every interval the base gets a random
    horizontal velocity kick of at most this magnitude (m/s). ``None`` switches an item off.
    """

    friction: tuple[float, float] | None = (0.5, 1.25)
    added_base_mass: tuple[float, float] | None = (-1.0, 1.0)
    push_interval_s: float | None = 8.0
    push_velocity: float = 0.5

    def __post_init__(self) -> None:
        if self.friction is not None:
            _check_range("friction", self.friction)
            if self.friction[0] <= 0:
                raise ValueError(f"friction={self.friction!r}: expected coefficients > 0")
        if self.added_base_mass is not None:
            _check_range("added_base_mass", self.added_base_mass)
        if self.push_interval_s is not None and not self.push_interval_s > 0:
            raise ValueError(f"push_interval_s={self.push_interval_s!r}: expected None or > 0")
        if not self.push_velocity >= 0:
            raise ValueError(f"push_velocity={self.push_velocity!r}: expected >= 0")
