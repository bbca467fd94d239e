"""Go1 velocity tracking: follow a commanded planar velocity and yaw rate on flat ground.

Observation (float32, 45), each group scaled by ``OBS_SCALES`` (layout in ``OBS_SLICES``):
base angular velocity (body frame, 3), projected gravity (body frame, 3), command (vx, vy,
yaw rate, 3), joint position offsets from the default pose (12), joint velocities (12),
previous action (12).
Action (float32, 12): normalized joint targets; target = default pose + ``action_scale`` x a,
sent to the model's position servos, torque-limited, with the task's gains ``kp`` = 35 N m/rad
and ``kd`` = 0.5 N m s/rad (``None`` keeps the model's kp 100, kv 2). With the stiff servos the
50 Hz exploration noise shakes the robot forward like a bristlebot: the stochastic policy tracked
the command in training while its mean stood still (benchmarks/README.md, "Go1 training").
Reward: named, weighted terms (``RewardWeights``) times the control interval, clipped at 0
from below (``only_positive_rewards``, as in legged_gym: with random actions the penalties
outweigh tracking, and PPO would learn to fall on purpose); the terms of
each step are in ``self.reward_terms`` and their episode sums reach ``info["log"]`` on the
last step of an episode, with the episode-mean x/y velocity tracking errors.
Episode: 20 s (1000 steps at 50 Hz); terminated when the base tilts past ``max_tilt`` or the
trunk or a hip touches the ground; truncated by the time limit.
Physics: ``dt`` = 10 ms, ``k`` = 2 (50 Hz policy), implicitfast integrator, elliptic friction
cone with ``impratio`` 100: on a 25 deg slope its feet creep ~1 mm in 2 s against ~95 mm with
the pyramidal cone. 10 ms stands as high and creeps about as little as 5 ms and 2 ms at ~0.5x the
physics time of 5 ms, and a policy trained at 10 ms walks as well at 5 ms
(``benchmarks/quadruped_physics.py``).
Terrain: ``"rigid"`` (the floor plane) or ``"soil"``: SCM soil (``chronogym.terrain``, preset
``soil``, default Chrono's "firm") under the lower legs (calf capsule and foot sphere), in a
``soil_window`` x ``soil_window`` m window at ``soil_resolution`` that follows the trunk and
archives the ruts it leaves, so an episode's ruts stay wherever it walks; the floor still holds
the trunk, hips and thighs. On soil ``dt`` = 2 ms, ``k`` = 10 (``PHYSICS_STEP``); a foot is in
contact when the soil pushes its leg up with more than 1 N. Observation, action and reward are
the same on both terrains.
"""

from __future__ import annotations

import dataclasses
import math
from typing import TYPE_CHECKING, Any

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
from chronogym.terrain.params import SoilParameters, soil_preset

if TYPE_CHECKING:
    from chronogym.terrain import MujocoSoil

#: Reward terms in the order of ``RewardWeights``' fields (the task's term vector).
REWARD_TERMS: tuple[str, ...] = tuple(f.name for f in dataclasses.fields(RewardWeights))
#: Ground under the feet: the rigid floor, or SCM soil (``chronogym.terrain``) over it.
TERRAINS: tuple[str, ...] = ("rigid", "soil")
#: Default (dt, k) per terrain, 50 Hz policy either way. Rigid ground: 10 ms keeps the
#: standing height and slope creep of 5 ms and 2 ms (``benchmarks/quadruped_physics.py``).
#: The soil's force law is explicit
#: and Chrono's soil stiffness (2e8 Pa/m) on a 20 mm foot needs dt <= 2 ms: at 5 ms the
#: robot jitters down through the soil (and at 5 ms with a 10x softer soil the rigid policy
#: fell in 3 of 4 episodes; at 2 ms it kept walking on "firm", as at 1 ms).
PHYSICS_STEP: dict[str, tuple[float, int]] = {"rigid": (0.01, 2), "soil": (0.002, 10)}
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
        dt: float | None = None,
        k: int | None = None,
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
        cone: str = "elliptic",
        impratio: float = 100.0,
        only_positive_rewards: bool = True,
        kp: float | None = 35.0,
        kd: float | None = 0.5,
        terrain: str = "rigid",
        soil: SoilParameters | str = "firm",
        soil_resolution: float = 0.01,
        soil_window: float = 3.0,
    ) -> None:
        for name, value in (
            ("action_scale", action_scale),
            ("action_clip", action_clip),
            ("max_tilt", max_tilt),
            ("base_height_target", base_height_target),
        ):
            if not (isinstance(value, (int, float)) and math.isfinite(value) and value > 0):
                raise ValueError(f"{name}={value!r}: expected a finite float > 0")
        for name, value in (("kp", kp), ("kd", kd)):
            if value is not None and not (
                isinstance(value, (int, float)) and math.isfinite(value) and value >= 0
            ):
                raise ValueError(f"{name}={value!r}: expected None (the model's) or a float >= 0")
        if not 0 <= air_time_threshold < 5:
            raise ValueError(f"air_time_threshold={air_time_threshold!r}: expected in [0, 5) s")
        if not 0 <= reset_joint_noise <= 0.5:
            raise ValueError(f"reset_joint_noise={reset_joint_noise!r}: expected in [0, 0.5] rad")
        if not (isinstance(impratio, (int, float)) and math.isfinite(impratio) and impratio >= 1):
            raise ValueError(f"impratio={impratio!r}: expected a float >= 1")
        if terrain not in TERRAINS:
            raise ValueError(f"terrain={terrain!r}: expected one of {', '.join(TERRAINS)}")
        if not (isinstance(soil_resolution, (int, float)) and 0.001 <= soil_resolution <= 0.1):
            raise ValueError(
                f"soil_resolution={soil_resolution!r}: expected a node spacing in [0.001, 0.1] m"
            )
        if not (isinstance(soil_window, (int, float)) and 0.5 <= soil_window <= 100):
            raise ValueError(f"soil_window={soil_window!r}: expected a side length in [0.5, 100] m")
        if cone not in ("pyramidal", "elliptic"):
            raise ValueError(f"cone={cone!r}: expected 'pyramidal' or 'elliptic'")
        default_dt, default_k = PHYSICS_STEP[terrain]
        self.dt = default_dt if dt is None else dt
        self.k = default_k if k is None else k
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
        self.impratio = float(impratio)
        self.only_positive_rewards = bool(only_positive_rewards)
        self.kp = kp
        self.kd = kd
        self.terrain = terrain
        self.soil_params = soil_preset(soil) if isinstance(soil, str) else soil
        if not isinstance(self.soil_params, SoilParameters):
            raise ValueError(f"soil={soil!r}: expected a SoilParameters or a preset name")
        self.soil_resolution = soil_resolution
        self.soil_window = float(soil_window)
        self.soil: MujocoSoil | None = None

    # --- init ------------------------------------------------------------------------------

    def load_model(self) -> Any:
        import mujoco

        model = mujoco.MjModel.from_xml_path(str(go1_xml_path()))
        model.opt.cone = (
            mujoco.mjtCone.mjCONE_PYRAMIDAL
            if self.cone == "pyramidal"
            else mujoco.mjtCone.mjCONE_ELLIPTIC
        )
        model.opt.impratio = self.impratio
        if self.kp is not None:  # position servo: force = kp (ctrl - q) - kv qdot
            model.actuator_gainprm[:, 0] = self.kp
            model.actuator_biasprm[:, 1] = -self.kp
        if self.kd is not None:
            model.actuator_biasprm[:, 2] = -self.kd
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
        self._floor = model.geom("floor").id
        if self.terrain == "soil":
            self._add_soil()
        self._foot_geoms = np.array([model.geom(n).id for n in FOOT_GEOM_NAMES])
        # Role of each geom in a contact: 1..4 = foot index + 1, -1 = trunk or hip (fatal), 0 other.
        fatal = {self._trunk} | {model.body(f"{leg}_hip").id for leg in LEG_NAMES}
        self._geom_roles: list[int] = [
            -1 if int(model.geom_bodyid[geom]) in fatal else 0 for geom in range(model.ngeom)
        ]
        for leg, geom in enumerate(self._foot_geoms.tolist()):
            self._geom_roles[geom] = leg + 1
        self._obs_scale = _scale_vector()
        self._rot = np.zeros(9)
        self._obs_raw = np.zeros(OBS_DIM)
        self.command = np.zeros(3)
        self.last_action = np.zeros(ACTION_DIM)
        self.prev_action = np.zeros(ACTION_DIM)
        self.feet_air_time = np.zeros(4)
        self.feet_contact = np.zeros(4, dtype=bool)
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
        self._fell = False
        self._base_contact = False

    def _add_soil(self) -> None:
        """SCM soil under the lower legs (calf capsule + foot sphere), in a window that
        follows the trunk; the floor still holds the trunk, hips and thighs."""
        from chronogym.terrain import MujocoSoil

        side = self.soil_window
        self.soil = MujocoSoil(
            self.model,
            self.data,
            self.soil_params,
            bodies=[f"{leg}_calf" for leg in LEG_NAMES],
            extent=(side, side),
            resolution=self.soil_resolution,
            follow=BASE_BODY_NAME,
        )
        self.soil.exclude_ground(self._floor)
        calves = [self.model.body(f"{leg}_calf").id for leg in LEG_NAMES]
        assert self.soil.body_ids.tolist() == calves, "soil rows must follow LEG_NAMES"
        self._leg_force = self.soil.body_forces  # (4, 6) view, one row per leg (FR, FL, RR, RL)
        self.advanceables = [self.soil, (self.model, self.data)]

    # --- reset -----------------------------------------------------------------------------

    def reset(self, rng: np.random.Generator, options: dict[str, Any] | None) -> None:
        options = options or {}
        self._apply_randomization(rng)
        self.reset_data(self._home_key)
        if self.soil is not None:
            self.soil.reset()
        data = self.data
        yaw = rng.uniform(-math.pi, math.pi)
        data.qpos[3:7] = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
        noise = self.reset_joint_noise
        if noise > 0:
            data.qpos[7:] = DEFAULT_JOINT_POS + rng.uniform(-noise, noise, size=ACTION_DIM)
        data.ctrl[:] = DEFAULT_JOINT_POS
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
        self.forward()
        self._feet_xy = self.data.geom_xpos[self._foot_geoms, :2]

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
        self.data.ctrl[:] = DEFAULT_JOINT_POS + self.action_scale * self.last_action
        self._steps += 1
        if self._next_push is not None and self._steps >= self._next_push:
            kick = self._episode_rng.uniform(-1.0, 1.0, size=2) * self.randomization.push_velocity
            self.data.qvel[0:2] += kick
            self._next_push += self._push_interval_steps()
        if self._next_command is not None and self._steps >= self._next_command:
            self.command = self._draw_command(self._episode_rng, None)
            self._next_command += self._resample_interval_steps()

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
        if self.soil is not None:  # the soil carries a leg: its upward force exceeds 1 N
            feet = (self._leg_force[:, 2] > 1.0).tolist()
        self.feet_contact_now = np.array(feet)

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
        data = self.data
        vx, vy, vz = self.base_lin_vel.tolist()
        wx, wy, wz, gx, gy = self._obs_raw[0:5].tolist()
        cmd_x, cmd_y, cmd_wz = self.command.tolist()
        np.subtract(self.last_action, self.prev_action, out=self._action_change)
        posture = self._obs_raw[9:21]
        torque = data.actuator_force
        height_error = float(data.qpos[2]) - self.base_height_target
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
        feet = self.data.geom_xpos[self._foot_geoms, :2]
        moved = feet - self._feet_xy
        self._feet_xy = feet
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
