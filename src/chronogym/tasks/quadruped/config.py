"""Settings of the Go1 velocity-tracking task: commands, reward weights, randomization.

Every setting is a small frozen dataclass with the defaults the documented training run used.
:class:`Go1TaskConfig` holds what the MuJoCo and the Chrono Go1 share, so a variant is
``Go1VelocityTask(config=Go1TaskConfig(rewards=RewardWeights(feet_air_time=0.5)))`` or, field
by field, ``Go1VelocityTask(rewards=RewardWeights(feet_air_time=0.5))``.
"""

from __future__ import annotations

import dataclasses
import math
from dataclasses import dataclass
from typing import Any

import numpy as np

from chronogym.tasks.quadruped.model import HOME_BASE_HEIGHT
from chronogym.validation import check_bool, check_int, check_number, check_positive, is_number

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
#: Scale of the base's linear velocity (body frame) where an observation holds it: the
#: policy's with ``observe_base_lin_vel``, the critic's with ``privileged_critic``.
LIN_VEL_SCALE = 2.0
ACTION_DIM = 12


def obs_group(name: str) -> slice:
    """The slice of observation group ``name`` (an ``OBS_SLICES`` key) in the 45-vector."""
    start, stop = OBS_SLICES[name]
    return slice(start, stop)


#: Each group's slice of the observation, for the code that reads or writes it (the task's
#: engine hooks and reward terms): ``OBS_SLICES`` as ``slice`` objects.
OBS_ANG_VEL = obs_group("base_ang_vel")
OBS_GRAVITY = obs_group("projected_gravity")
OBS_COMMAND = obs_group("command")
OBS_JOINT_POS = obs_group("joint_pos")
OBS_JOINT_VEL = obs_group("joint_vel")
OBS_LAST_ACTION = obs_group("last_action")
#: Index of the projected gravity's z component (``-1`` upright).
OBS_GRAVITY_Z = OBS_SLICES["projected_gravity"][0] + 2


def _check_range(name: str, bounds: tuple[float, float]) -> None:
    low, high = bounds
    if not (math.isfinite(low) and math.isfinite(high) and low <= high):
        raise ValueError(f"{name}={bounds!r}: expected (low, high) finite with low <= high")


@dataclass(frozen=True)
class CommandRanges:
    """Uniform ranges the velocity command is drawn from at each reset (body frame).

    ``resample_s``: draw a new command every this many seconds of an episode (as legged_gym
    does), so an episode holds several speed changes; ``None`` keeps one command per episode.
    A command fixed by ``reset(options={"command": ...})`` is never resampled; with it,
    ``options={"command_schedule": ((time_s, command), ...)}`` changes it to each ``command``
    after ``round(time_s / control_dt)`` steps (the walking criterion's command switch).

    Shaping of the drawn command (all off by default): with probability ``single_axis_share``
    only one of its three components (chosen uniformly) is kept; with probability
    ``standing_share`` it is all zero (Isaac Lab's standing envs); a planar speed below
    ``zero_below`` m/s is set to zero (legged_gym uses 0.2).
    """

    vx: tuple[float, float] = (-0.5, 1.0)  # m/s, forward
    vy: tuple[float, float] = (-0.3, 0.3)  # m/s, left
    yaw_rate: tuple[float, float] = (-0.5, 0.5)  # rad/s
    resample_s: float | None = None
    single_axis_share: float = 0.0
    standing_share: float = 0.0
    zero_below: float = 0.0  # m/s

    def __post_init__(self) -> None:
        for name in ("vx", "vy", "yaw_rate"):
            _check_range(name, getattr(self, name))
        if self.resample_s is not None:
            check_positive("resample_s", self.resample_s, expected="None or seconds > 0")
        for name in ("single_axis_share", "standing_share"):
            value = getattr(self, name)
            check_number(name, value, low=0, high=1, expected="a probability in [0, 1]")
        check_number("zero_below", self.zero_below, low=0, expected="a speed >= 0 in m/s")

    def shape(self, command: np.ndarray, rng: np.random.Generator) -> np.ndarray:
        """Apply the single-axis, standing and dead-zone rules to a drawn ``command`` (in
        place; returns it). Draws from ``rng`` only for the rules that are on."""
        if self.single_axis_share > 0 and rng.random() < self.single_axis_share:
            keep = int(rng.integers(3))
            command[[i for i in range(3) if i != keep]] = 0.0
        if self.standing_share > 0 and rng.random() < self.standing_share:
            command[:] = 0.0
        if self.zero_below > 0 and math.hypot(command[0], command[1]) < self.zero_below:
            command[:2] = 0.0
        return command


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
    # last, so that the term vector's sum, and every reward, stays bit for bit what it was
    # before this term existed whenever it is off
    tracking_lin_vel_fine: float = 0.0  # exp(-|v_xy - cmd_xy|^2 / fine_tracking_sigma)

    def __post_init__(self) -> None:
        for field in dataclasses.fields(self):
            value = getattr(self, field.name)
            if not is_number(value):
                raise ValueError(f"{field.name}={value!r}: expected a float weight")
            check_number(field.name, value, expected="a finite weight")

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


def _check_type(name: str, value: Any, kind: type, optional: bool = False) -> None:
    """A ValueError naming ``name`` unless ``value`` is a ``kind`` (or, if ``optional``, None)."""
    if not (isinstance(value, kind) or (optional and value is None)):
        expected = f"None or a {kind.__name__}" if optional else f"a {kind.__name__}"
        raise ValueError(f"{name}={value!r}: expected {expected}")


#: The ``Go1TaskConfig`` fields that must be finite floats > 0.
_POSITIVE_FIELDS = (
    "action_scale",
    "action_clip",
    "max_tilt",
    "base_height_target",
    "tracking_sigma",
    "fine_tracking_sigma",
)
_AIR_TIME_RANGE = "in [0, 5) s"


def _check_flag(name: str, value: Any) -> None:
    """:func:`~chronogym.validation.check_bool`, raising a ValueError as every other bad
    ``Go1TaskConfig`` field does (the message is the same)."""
    try:
        check_bool(name, value)
    except TypeError as error:
        raise ValueError(str(error)) from None


@dataclass(frozen=True)
class Go1TaskConfig:
    """The settings the MuJoCo and the Chrono Go1 velocity tasks share, checked when made.

    Each field is also a keyword argument of both tasks (``Go1VelocityTask(max_tilt=0.8)``
    is ``Go1VelocityTask(config=Go1TaskConfig(max_tilt=0.8))``); the physics step, terrain and
    engine options are the engine's own arguments.
    """

    #: Decisions per episode before the time limit truncates it; ``None``: no limit.
    max_episode_steps: int | None = 1000
    #: Ranges the velocity command is drawn from.
    commands: CommandRanges = dataclasses.field(default_factory=CommandRanges)
    #: Weight of each reward term.
    rewards: RewardWeights = dataclasses.field(default_factory=RewardWeights)
    #: Per-episode friction, trunk mass and pushes; ``None``: off.
    randomization: DomainRandomization | None = None
    #: Joint target = default pose + ``action_scale`` x action [rad].
    action_scale: float = 0.25
    #: Bound of the action space (each component in [-clip, clip]).
    action_clip: float = 10.0
    #: The episode ends when the base tilts more than this from upright [rad].
    max_tilt: float = 1.0
    #: Base height the ``base_height`` term pulls towards [m].
    base_height_target: float = HOME_BASE_HEIGHT
    #: Width of the exponential tracking kernels, exp(-error^2 / sigma) [(m/s)^2, (rad/s)^2]
    #: (legged_gym, Isaac Lab and MuJoCo Playground: 0.25); smaller rewards close tracking more.
    tracking_sigma: float = 0.25
    #: Width of the ``tracking_lin_vel_fine`` kernel [(m/s)^2] (off by default: weight 0).
    #: Narrow, it pays for the last 0.1-0.2 m/s of a command, which the 0.25 kernel barely
    #: tells apart (exp(-0.01/0.25) = 0.96): 0.05 gives 0.82 at an error of 0.1 m/s, 0.45 at
    #: 0.2 m/s. Criterion v2's rise time and steady state are decided in that range.
    fine_tracking_sigma: float = 0.05
    #: A swing longer than this earns the ``feet_air_time`` term [s], in [0, 5).
    air_time_threshold: float = 0.25
    #: Joint angles start uniform within +- this of the home pose [rad], in [0, 0.5].
    reset_joint_noise: float = 0.1
    #: Joint angles start at the home pose times a factor drawn per joint from this range
    #: (legged_gym: (0.5, 1.5)), before ``reset_joint_noise``; ``None``: off.
    reset_joint_scale: tuple[float, float] | None = None
    #: The base starts with a horizontal velocity uniform within +- this per axis [m/s]
    #: (legged_gym: 0.5).
    reset_base_velocity: float = 0.0
    #: Clip the step reward at 0 from below (legged_gym's ``only_positive_rewards``).
    only_positive_rewards: bool = True
    #: Report ``info["critic_obs"]`` every step: the 45 observations, then the base's linear
    #: velocity (body frame, x 2) and its height above ``base_height_target`` (x 10), what the
    #: tracking and height rewards are computed from. RSL-RL's critic then trains on it (an
    #: asymmetric actor-critic, as legged_gym's and MuJoCo Playground's); the policy's 45
    #: observations do not change.
    privileged_critic: bool = False
    #: Append the base's linear velocity (body frame, x ``LIN_VEL_SCALE``) to the policy's
    #: observation, which then has 48 values, the first 45 as without it. legged_gym, Isaac Lab
    #: and MuJoCo Playground all give their policies this velocity (a state estimator's on the
    #: robot); off, the policy infers its speed from its joints.
    observe_base_lin_vel: bool = False
    #: Servo stiffness [N m/rad]; ``None``: the model's (100).
    kp: float | None = 35.0
    #: Servo damping [N m s/rad]; ``None``: the model's (2).
    kd: float | None = 0.5

    def __post_init__(self) -> None:
        if self.max_episode_steps is not None:
            check_int(
                "max_episode_steps",
                self.max_episode_steps,
                low=1,
                expected="None or an integer >= 1",
            )
        _check_type("commands", self.commands, CommandRanges)
        _check_type("rewards", self.rewards, RewardWeights)
        _check_type("randomization", self.randomization, DomainRandomization, optional=True)
        for name in _POSITIVE_FIELDS:
            check_positive(name, getattr(self, name), expected="a finite float > 0")
        for name in ("kp", "kd"):
            value = getattr(self, name)
            if value is not None:
                check_number(name, value, low=0, expected="None (the model's) or a float >= 0")
        threshold = check_number(
            "air_time_threshold", self.air_time_threshold, low=0, expected=_AIR_TIME_RANGE
        )
        if threshold >= 5:
            raise ValueError(
                f"air_time_threshold={self.air_time_threshold!r}: expected {_AIR_TIME_RANGE}"
            )
        check_number(
            "reset_joint_noise", self.reset_joint_noise, low=0, high=0.5, expected="in [0, 0.5] rad"
        )
        if self.reset_joint_scale is not None:
            _check_range("reset_joint_scale", self.reset_joint_scale)
            low, high = self.reset_joint_scale
            if not (low >= 0 and high <= 2):
                raise ValueError(
                    f"reset_joint_scale={self.reset_joint_scale!r}: expected None or "
                    "(low, high) within [0, 2]"
                )
        check_number(
            "reset_base_velocity", self.reset_base_velocity, low=0, high=2, expected="in [0, 2] m/s"
        )
        _check_flag("privileged_critic", self.privileged_critic)
        _check_flag("observe_base_lin_vel", self.observe_base_lin_vel)
        _check_flag("only_positive_rewards", self.only_positive_rewards)
