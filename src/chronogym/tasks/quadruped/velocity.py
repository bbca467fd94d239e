"""The engine-independent half of Go1 velocity tracking: commands, observation, reward, end.

:class:`Go1VelocityBase` holds everything the MuJoCo task (:mod:`.task`) and the Chrono task
(:mod:`.chrono_task`) share, so both engines run the same interface, settings
(:class:`~.config.Go1TaskConfig`), observation scales, reward terms, command sampling, pushes
and termination, by the same code. An engine subclass reads and writes its simulation through
a few hooks, abstract methods of the base that each engine must implement:

===========================  =================================================================
``_setup_engine()``           once the simulation exists: the engine's ids, contact bookkeeping
                              and buffers (before the shared spaces and buffers)
``_reset_pose(yaw, joints)``  put the robot at rest at its home height, heading ``yaw``, with
                              these joint angles (``None``: the home pose) and servo targets
                              at the home pose; leave the state current
``_read_state(raw)``          fill the ``OBS_ANG_VEL``, ``OBS_GRAVITY`` (body frame),
                              ``OBS_JOINT_POS`` (offsets from the home pose) and
                              ``OBS_JOINT_VEL`` groups of ``raw`` (:mod:`.config`); set
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

Settings and setup: the base's ``__init__`` stores the shared settings (an engine's
``__init__`` starts with ``super().__init__(config=config, **options)``, then checks its own
arguments); the base's ``setup()`` runs the engine's ``_setup_engine()`` once the simulation
exists and then makes the spaces and buffers both engines share, so no engine calls the
shared setup itself.

Reward: each ``RewardWeights`` field names a method ``_reward_<field>(motion)`` that computes
the term's unweighted value from the current state and changes nothing; ``_reward_functions``
lists them all by name, in ``REWARD_TERMS`` order. ``reward()`` sums the weighted terms, and
then, in one place, carries the step over to the next: the episode's sums
(``_record_episode``), the feet's air time, contact memory and slip reference positions
(``_update_feet_state``).
"""

from __future__ import annotations

import dataclasses
import inspect
import math
from abc import ABC, abstractmethod
from collections.abc import Callable
from typing import Any, NamedTuple

import numpy as np
from gymnasium import spaces

from chronogym.task import Task
from chronogym.tasks.quadruped.config import (
    ACTION_DIM,
    LIN_VEL_SCALE,
    OBS_ANG_VEL,
    OBS_COMMAND,
    OBS_DIM,
    OBS_GRAVITY,
    OBS_GRAVITY_Z,
    OBS_JOINT_POS,
    OBS_LAST_ACTION,
    OBS_SCALES,
    OBS_SLICES,
    Go1TaskConfig,
    RewardWeights,
)
from chronogym.tasks.quadruped.model import DEFAULT_JOINT_POS
from chronogym.tasks.quadruped.walking import as_command

#: Reward terms in the order of ``RewardWeights``' fields (the task's term vector).
REWARD_TERMS: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(RewardWeights))
#: ``None`` given for these keywords means the field's default (as for ``Go1TaskConfig()``).
_NONE_IS_DEFAULT = ("commands", "rewards")


def observation_scale() -> np.ndarray:
    """The (45,) vector the raw observation is multiplied by (``OBS_SCALES`` per group)."""
    scale = np.zeros(OBS_DIM)
    for name, group in OBS_SLICES.items():
        scale[slice(*group)] = OBS_SCALES[name]
    return scale


def _task_config(
    task: type, config: Go1TaskConfig | None, options: dict[str, Any]
) -> Go1TaskConfig:
    """``config`` (``None``: ``Go1TaskConfig()``) with the fields named in ``options``
    replaced; a keyword that is no field is a TypeError naming it and what ``task`` takes."""
    if config is None:
        config = Go1TaskConfig()
    elif not isinstance(config, Go1TaskConfig):
        raise ValueError(f"config={config!r}: expected a Go1TaskConfig or None")
    fields = [f.name for f in dataclasses.fields(Go1TaskConfig)]
    unknown = [name for name in options if name not in fields]
    if unknown:
        own = [
            p.name
            for p in inspect.signature(task.__init__).parameters.values()
            if p.kind is inspect.Parameter.KEYWORD_ONLY
        ]
        raise TypeError(
            f"{task.__name__}() got an unexpected keyword argument {unknown[0]!r}: expected "
            f"a Go1TaskConfig field ({', '.join(fields)}) or one of {', '.join(own)}"
        )
    changes = {
        name: getattr(Go1TaskConfig(), name)
        if value is None and name in _NONE_IS_DEFAULT
        else value
        for name, value in options.items()
    }
    return dataclasses.replace(config, **changes) if changes else config


def _config_field(name: str) -> property:
    """A read-only attribute that reads ``self.config.<name>``."""

    def get(self: Go1VelocityBase) -> Any:
        return getattr(self.config, name)

    return property(get, doc=f"``config.{name}`` (read-only).")


class BaseMotion(NamedTuple):
    """The base's motion and the command at one decision, as floats (body frame)."""

    lin_vel: list[float]  # (vx, vy, vz) m/s
    ang_vel: list[float]  # (wx, wy, wz) rad/s
    gravity: list[float]  # projected gravity (gx, gy, gz), unit vector
    command: list[float]  # (vx, vy, yaw rate) commanded


def _planar_error2(motion: BaseMotion) -> float:
    """|v_xy - cmd_xy|^2, the squared planar velocity-tracking error."""
    vx, vy, _ = motion.lin_vel
    cmd_x, cmd_y, _ = motion.command
    return (vx - cmd_x) ** 2 + (vy - cmd_y) ** 2


#: One reward term of a task: its unweighted value for the motion of the step.
RewardTerm = Callable[[BaseMotion], float]


class Go1VelocityBase(Task, ABC):
    """Go1 tracking a velocity command, for any engine: see the module docstring."""

    #: The settings shared by both engines (``Go1TaskConfig``).
    config: Go1TaskConfig
    weights = _config_field("rewards")
    action_scale = _config_field("action_scale")
    base_height_target = _config_field("base_height_target")

    def __init__(self, *, config: Go1TaskConfig | None = None, **options: Any) -> None:
        """Store the settings both engines share: ``config`` with ``options`` (keyword
        arguments named as ``Go1TaskConfig`` fields) replacing its fields."""
        super().__init__()
        self.config = _task_config(type(self), config, options)
        self.max_episode_steps = self.config.max_episode_steps  # SimEnv writes the one in force

    def setup(self) -> None:
        """Once the simulation exists: the engine's ids and buffers (``_setup_engine``), then
        the spaces and buffers both engines share (``_setup_tracking``)."""
        self._setup_engine()
        self._setup_tracking()

    def _setup_tracking(self) -> None:
        """Spaces and buffers both engines share (``setup``, after the engine's own)."""
        config = self.config
        obs_dim = OBS_DIM + 3 if config.observe_base_lin_vel else OBS_DIM
        self.observation_space = spaces.Box(-np.inf, np.inf, shape=(obs_dim,), dtype=np.float32)
        self.action_space = spaces.Box(
            -config.action_clip, config.action_clip, shape=(ACTION_DIM,), dtype=np.float32
        )
        self.control_dt = self.dt * self.k
        scale = observation_scale()
        if config.observe_base_lin_vel:  # the base's velocity after the 45, in the same buffer
            scale = np.concatenate([scale, np.full(3, LIN_VEL_SCALE)])
        self._obs_scale = scale
        self._obs_raw = np.zeros(obs_dim)
        self.base_lin_vel = np.zeros(3)
        self.command = np.zeros(3)
        self.last_action = np.zeros(ACTION_DIM)
        self.prev_action = np.zeros(ACTION_DIM)
        self.feet_air_time = np.zeros(4)
        self.feet_contact = np.zeros(4, dtype=bool)
        self.feet_contact_now = np.zeros(4, dtype=bool)
        weights = dataclasses.asdict(config.rewards)
        self._term_weights = np.array([weights[n] for n in REWARD_TERMS]) * self.control_dt
        self._active_terms = [(i, n) for i, n in enumerate(REWARD_TERMS) if weights[n] != 0]
        functions = self._reward_functions()
        self._term_functions: list[tuple[int, RewardTerm]] = [
            (i, functions[name]) for i, name in self._active_terms
        ]
        self._slip_on = weights["feet_slip"] != 0  # skip the foot-velocity work when off
        self._raw = np.zeros(len(REWARD_TERMS))
        self._weighted = np.zeros(len(REWARD_TERMS))
        self._episode_sum = np.zeros(len(REWARD_TERMS))
        self._steps = 0
        self._next_command: int | None = None
        self._schedule: list[tuple[int, np.ndarray]] = []
        self._next_push: int | None = None
        self._fell = False
        self._base_contact = False

    # --- engine hooks ----------------------------------------------------------------------

    @abstractmethod
    def _setup_engine(self) -> None:
        """Once the simulation exists, before the shared spaces and buffers: the engine's ids,
        contact bookkeeping and buffers (``setup`` calls it)."""

    @abstractmethod
    def _reset_pose(self, yaw: float, joints: np.ndarray | None) -> None:
        """Put the robot at rest at its home height, heading ``yaw``, with these joint angles
        (``None``: the home pose) and servo targets at the home pose; leave the state current."""

    @abstractmethod
    def _read_state(self, raw: np.ndarray) -> None:
        """Fill the ``OBS_ANG_VEL``, ``OBS_GRAVITY`` (body frame), ``OBS_JOINT_POS`` (offsets
        from the home pose) and ``OBS_JOINT_VEL`` groups of ``raw``; set ``self.base_lin_vel``
        (body frame)."""

    @abstractmethod
    def _set_joint_targets(self, targets: np.ndarray) -> None:
        """The servo targets (rad, joint order FR, FL, RR, RL)."""

    @abstractmethod
    def _kick_base(self, dv: np.ndarray) -> None:
        """Add ``dv`` (m/s, world x and y) to the base velocity."""

    @abstractmethod
    def _update_contacts(self) -> None:
        """Set ``self.feet_contact_now`` (4 bools) and ``self._base_contact``."""

    @abstractmethod
    def _joint_torques(self) -> np.ndarray:
        """The 12 servo torques of the last tick (N m)."""

    @abstractmethod
    def _base_height(self) -> float:
        """The height of the base frame's origin (m)."""

    @abstractmethod
    def feet_positions(self) -> np.ndarray:
        """World positions of the four foot centres, (4, 3) [m], leg order FR, FL, RR, RL."""

    def _feet_xy(self) -> np.ndarray:
        return self.feet_positions()[:, :2]

    @abstractmethod
    def _set_friction(self, mu: float) -> None:
        """Foot-ground friction coefficient (domain randomization)."""

    @abstractmethod
    def _set_added_base_mass(self, dm: float) -> None:
        """Trunk mass = nominal + ``dm`` (domain randomization)."""

    # --- reset -----------------------------------------------------------------------------

    def reset(self, rng: np.random.Generator, options: dict[str, Any] | None) -> None:
        options = options or {}
        self._apply_randomization(rng)
        yaw = rng.uniform(-math.pi, math.pi)
        self._reset_pose(yaw, self._initial_joints(rng))
        if self.config.reset_base_velocity > 0:
            self._kick_base(rng.uniform(-1.0, 1.0, size=2) * self.config.reset_base_velocity)
        fixed = options.get("command")
        self.command = self._draw_command(rng, fixed)
        self._next_command = None if fixed is not None else self._resample_interval_steps()
        self._schedule = self._command_schedule(options.get("command_schedule"), fixed)
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

    def _initial_joints(self, rng: np.random.Generator) -> np.ndarray | None:
        """Joint angles to start from (``None``: the home pose), per the reset settings."""
        config = self.config
        if config.reset_joint_scale is None and config.reset_joint_noise <= 0:
            return None
        joints = DEFAULT_JOINT_POS.copy()
        if config.reset_joint_scale is not None:
            joints *= rng.uniform(*config.reset_joint_scale, size=ACTION_DIM)
        noise = config.reset_joint_noise
        if noise > 0:
            joints += rng.uniform(-noise, noise, size=ACTION_DIM)
        return joints

    def _draw_command(self, rng: np.random.Generator, fixed: Any) -> np.ndarray:
        if fixed is not None:
            command = np.asarray(fixed, dtype=np.float64)
            if command.shape != (3,) or not np.isfinite(command).all():
                raise ValueError(
                    f"options['command']={fixed!r}: expected 3 finite floats (vx, vy, yaw_rate)"
                )
            return command.copy()
        ranges = self.config.commands
        command = np.array(
            [rng.uniform(*ranges.vx), rng.uniform(*ranges.vy), rng.uniform(*ranges.yaw_rate)]
        )
        return ranges.shape(command, rng)

    def _command_schedule(self, schedule: Any, fixed: Any) -> list[tuple[int, np.ndarray]]:
        """``options["command_schedule"]``, ``((time_s, command), ...)``: the command becomes
        ``command`` after ``round(time_s / control_dt)`` steps; as (step, command) pairs."""
        if schedule is None:
            return []
        if fixed is None:
            raise ValueError(
                f"options['command_schedule']={schedule!r} without options['command']: "
                "a schedule changes a fixed command; give the first one as 'command'"
            )
        expected = "((time_s, (vx, vy, yaw_rate)), ...) with times > 0 s in increasing order"
        try:
            pairs = [(float(t), c) for t, c in schedule]
        except (TypeError, ValueError):
            raise ValueError(
                f"options['command_schedule']={schedule!r}: expected {expected}"
            ) from None
        steps = [round(t / self.control_dt) for t, _ in pairs]
        times = [t for t, _ in pairs]
        if not all(math.isfinite(t) and t > 0 for t in times) or steps != sorted(set(steps)):
            raise ValueError(f"options['command_schedule']={schedule!r}: expected {expected}")
        return [
            (n, np.array(as_command(c, "options['command_schedule'] command")))
            for n, (_, c) in zip(steps, pairs, strict=True)
        ]

    def _apply_randomization(self, rng: np.random.Generator) -> None:
        dr = self.config.randomization
        if dr is None:
            return
        if dr.friction is not None:
            self._set_friction(rng.uniform(*dr.friction))
        if dr.added_base_mass is not None:
            self._set_added_base_mass(rng.uniform(*dr.added_base_mass))

    def _resample_interval_steps(self) -> int | None:
        seconds = self.config.commands.resample_s
        return None if seconds is None else max(1, round(seconds / self.control_dt))

    def _push_interval_steps(self) -> int | None:
        dr = self.config.randomization
        if dr is None or dr.push_interval_s is None:
            return None
        return max(1, round(dr.push_interval_s / self.control_dt))

    # --- step ------------------------------------------------------------------------------

    def apply_action(self, action: np.ndarray) -> None:
        self.prev_action[:] = self.last_action
        self.last_action[:] = action
        self._set_joint_targets(DEFAULT_JOINT_POS + self.config.action_scale * self.last_action)
        self._steps += 1
        if self._next_push is not None and self._steps >= self._next_push:
            velocity = self.config.randomization.push_velocity
            self._kick_base(self._episode_rng.uniform(-1.0, 1.0, size=2) * velocity)
            self._next_push += self._push_interval_steps()
        if self._schedule and self._steps >= self._schedule[0][0]:
            self.command = self._schedule.pop(0)[1]
        if self._next_command is not None and self._steps >= self._next_command:
            self.command = self._draw_command(self._episode_rng, None)
            self._next_command += self._resample_interval_steps()

    def observe(self) -> np.ndarray:
        raw = self._obs_raw
        self._read_state(raw)
        raw[OBS_COMMAND] = self.command
        raw[OBS_LAST_ACTION] = self.last_action
        if self.config.observe_base_lin_vel:
            raw[OBS_DIM:] = self.base_lin_vel
        return (raw * self._obs_scale).astype(np.float32)

    def reward(self, action: np.ndarray, obs: np.ndarray) -> float:
        self._update_contacts()
        motion = self._motion()
        raw = self._raw_terms(motion, self._raw)
        weighted = np.multiply(raw, self._term_weights, out=self._weighted)
        total = float(weighted.sum())
        if self.config.only_positive_rewards and total < 0:
            total = 0.0  # a step never costs reward, so ending the episode early never pays
        # after the reward, the only place where a step's reward state carries over:
        self._record_episode(motion, weighted)
        self._update_feet_state()
        return total

    def _record_episode(self, motion: BaseMotion, weighted: np.ndarray) -> None:
        """Add the step to the episode's term sums and squared velocity-tracking errors."""
        self._episode_sum += weighted
        vx, vy, _ = motion.lin_vel
        cmd_x, cmd_y, _ = motion.command
        ex, ey = vx - cmd_x, vy - cmd_y
        self._sq_err[0] += ex * ex
        self._sq_err[1] += ey * ey

    def _update_feet_state(self) -> None:
        """Carry the feet over to the next step: air time (0 on the ground), the contacts the
        next touchdowns are found against, and the positions the next slip is measured from."""
        contact = self.feet_contact_now
        air = self.feet_air_time
        air += self.control_dt
        air[contact] = 0.0
        self.feet_contact[:] = contact
        if self._slip_on:
            self._feet_xy_before = self._feet_xy()

    @property
    def base_yaw_rate(self) -> float:
        """The base's yaw rate (rad/s, body frame) as last observed."""
        return float(self._obs_raw[OBS_ANG_VEL][2])

    @property
    def reward_terms(self) -> dict[str, float]:
        """Weighted, dt-scaled value of each active term in the last step's reward."""
        return {name: float(self._weighted[i]) for i, name in self._active_terms}

    def compute_reward_terms(self) -> dict[str, float]:
        """Weighted, dt-scaled value of each active reward term for the current state (and
        contacts as last updated); changes nothing."""
        raw = self._raw_terms(self._motion(), np.zeros(len(REWARD_TERMS)))
        weighted = raw * self._term_weights
        return {name: float(weighted[i]) for i, name in self._active_terms}

    def _motion(self) -> BaseMotion:
        """The base's velocities, projected gravity and the command, as last observed."""
        raw = self._obs_raw
        return BaseMotion(
            self.base_lin_vel.tolist(),
            raw[OBS_ANG_VEL].tolist(),
            raw[OBS_GRAVITY].tolist(),
            self.command.tolist(),
        )

    def _raw_terms(self, motion: BaseMotion, out: np.ndarray) -> np.ndarray:
        """Unweighted value of each active term, written into ``out`` at its ``REWARD_TERMS``
        index (inactive terms are left as they are)."""
        for index, term in self._term_functions:
            out[index] = term(motion)
        return out

    def _reward_functions(self) -> dict[str, RewardTerm]:
        """Every reward term by its ``RewardWeights`` field, in ``REWARD_TERMS`` order (the
        order of the term vector ``reward()`` sums)."""
        return {
            "tracking_lin_vel": self._reward_tracking_lin_vel,
            "tracking_ang_vel": self._reward_tracking_ang_vel,
            "lin_vel_z": self._reward_lin_vel_z,
            "ang_vel_xy": self._reward_ang_vel_xy,
            "orientation": self._reward_orientation,
            "base_height": self._reward_base_height,
            "action_rate": self._reward_action_rate,
            "joint_posture": self._reward_joint_posture,
            "torques": self._reward_torques,
            "feet_air_time": self._reward_feet_air_time,
            "feet_slip": self._reward_feet_slip,
            "tracking_lin_vel_fine": self._reward_tracking_lin_vel_fine,
        }

    # --- reward terms: one per RewardWeights field, unweighted, without side effects --------

    def _reward_tracking_lin_vel(self, motion: BaseMotion) -> float:
        """exp(-|v_xy - cmd_xy|^2 / sigma)."""
        return math.exp(-_planar_error2(motion) / self.config.tracking_sigma)

    def _reward_tracking_ang_vel(self, motion: BaseMotion) -> float:
        """exp(-(w_z - cmd_wz)^2 / sigma)."""
        error = motion.ang_vel[2] - motion.command[2]
        return math.exp(-(error**2) / self.config.tracking_sigma)

    def _reward_tracking_lin_vel_fine(self, motion: BaseMotion) -> float:
        """exp(-|v_xy - cmd_xy|^2 / fine_tracking_sigma)."""
        return math.exp(-_planar_error2(motion) / self.config.fine_tracking_sigma)

    def _reward_lin_vel_z(self, motion: BaseMotion) -> float:
        """v_z^2."""
        vz = motion.lin_vel[2]
        return vz * vz

    def _reward_ang_vel_xy(self, motion: BaseMotion) -> float:
        """w_x^2 + w_y^2 (roll and pitch rate)."""
        wx, wy, _ = motion.ang_vel
        return wx * wx + wy * wy

    def _reward_orientation(self, motion: BaseMotion) -> float:
        """|projected gravity_xy|^2 (0 upright)."""
        gx, gy, _ = motion.gravity
        return gx * gx + gy * gy

    def _reward_base_height(self, motion: BaseMotion) -> float:
        """(h - target)^2."""
        error = self._base_height() - self.config.base_height_target
        return error * error

    def _reward_action_rate(self, motion: BaseMotion) -> float:
        """|a - a_prev|^2."""
        change = self.last_action - self.prev_action
        return change @ change

    def _reward_joint_posture(self, motion: BaseMotion) -> float:
        """|q - q_default|^2."""
        offsets = self._obs_raw[OBS_JOINT_POS]
        return offsets @ offsets

    def _reward_torques(self, motion: BaseMotion) -> float:
        """|tau|^2."""
        torque = self._joint_torques()
        return torque @ torque

    def _reward_feet_air_time(self, motion: BaseMotion) -> float:
        """Sum over the feet touching down this step of (air time - threshold), while the
        command asks to move (0 for a standing command)."""
        cmd_x, cmd_y, _ = motion.command
        if not math.hypot(cmd_x, cmd_y) > 0.1:
            return 0.0
        before = self.feet_contact.tolist()
        value = 0.0
        for foot, now in enumerate(self.feet_contact_now.tolist()):
            if now and not before[foot]:  # touchdown: its swing lasted until this step's end
                air = float(self.feet_air_time[foot]) + self.control_dt
                value += air - self.config.air_time_threshold
        return value

    def _reward_feet_slip(self, motion: BaseMotion) -> float:
        """Sum over the feet on the ground of their squared horizontal speed, averaged over
        the last control interval (feet that slide instead of stepping)."""
        moved = self._feet_xy() - self._feet_xy_before
        speed2 = np.einsum("ij,ij->i", moved, moved) / (self.control_dt * self.control_dt)
        return float(speed2 @ self.feet_contact_now)

    def terminated(self, obs: np.ndarray) -> bool:
        tilt = math.acos(min(1.0, max(-1.0, -self._obs_raw[OBS_GRAVITY_Z])))
        self._fell = tilt > self.config.max_tilt or self._base_contact
        return self._fell

    def info(self) -> dict[str, Any]:
        extra = {"critic_obs": self.critic_observation()} if self.config.privileged_critic else {}
        horizon = self.max_episode_steps
        if not (self._fell or (horizon is not None and self._steps >= horizon)):
            return extra
        steps = max(self._steps, 1)
        sums = self._episode_sum
        log = {f"/reward/{name}": float(sums[i]) for i, name in self._active_terms}
        log["/metrics/x_vel_mse"] = float(self._sq_err[0] / steps)
        log["/metrics/y_vel_mse"] = float(self._sq_err[1] / steps)
        log["/metrics/survived"] = 0.0 if self._fell else 1.0
        log["/metrics/episode_length_s"] = steps * self.control_dt
        return {**extra, "log": log}

    def critic_observation(self) -> np.ndarray:
        """The critic's privileged observation (``privileged_critic``): the scaled 45
        observations, the base's linear velocity x 2 and its height error x 10 (float32)."""
        height = (self._base_height() - self.config.base_height_target) * 10.0
        return np.concatenate(
            [
                self._obs_raw[:OBS_DIM] * self._obs_scale[:OBS_DIM],
                self.base_lin_vel * LIN_VEL_SCALE,
                [height],
            ]
        ).astype(np.float32)
