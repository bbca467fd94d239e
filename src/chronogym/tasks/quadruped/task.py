"""Go1 velocity tracking: follow a commanded planar velocity and yaw rate on flat ground.

Settings: ``Go1TaskConfig`` (shared with the Chrono Go1; each field is also a keyword argument)
plus MuJoCo's own: the physics step, the friction cone and the terrain.
Observation (float32, 45), each group scaled by ``OBS_SCALES`` (layout in ``OBS_SLICES``):
base angular velocity (body frame, 3), projected gravity (body frame, 3), command (vx, vy,
yaw rate, 3), joint position offsets from the default pose (12), joint velocities (12),
previous action (12).
Action (float32, 12): normalized joint targets; target = default pose + ``action_scale`` x a,
sent to the model's position servos, torque-limited, with the task's gains ``kp`` = 35 N m/rad
and ``kd`` = 0.5 N m s/rad (``None`` keeps the model's kp 100, kv 2). With the stiff servos the
50 Hz exploration noise shakes the robot forward like a bristlebot: the stochastic policy tracked
the command in training while its mean stood still (docs/performance/rl.md, "Go1 training").
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
(``benchmarks/rl/quadruped_physics.py``).
Terrain: ``"rigid"`` (the floor plane) or ``"soil"``: SCM soil (``chronogym.terrain``, preset
``soil``, default Chrono's "firm") under the lower legs (calf capsule and foot sphere), in a
``soil_window`` x ``soil_window`` m window at ``soil_resolution`` that follows the trunk and
archives the ruts it leaves, so an episode's ruts stay wherever it walks; the floor still holds
the trunk, hips and thighs. On soil ``dt`` = 2 ms, ``k`` = 10 (``PHYSICS_STEP``); a foot is in
contact when the soil pushes its leg up with more than 1 N. Observation, action and reward are
the same on both terrains.
"""

from __future__ import annotations

import math
from typing import TYPE_CHECKING, Any

import numpy as np

from chronogym.engines.mujoco import MujocoTask
from chronogym.tasks.quadruped.config import (
    OBS_ANG_VEL,
    OBS_GRAVITY,
    OBS_JOINT_POS,
    OBS_JOINT_VEL,
    Go1TaskConfig,
)
from chronogym.tasks.quadruped.engines import ENGINE_TERRAINS
from chronogym.tasks.quadruped.model import (
    BASE_BODY_NAME,
    CAMERA_NAME,
    DEFAULT_JOINT_POS,
    FOOT_GEOM_NAMES,
    HOME_KEYFRAME,
    LEG_NAMES,
    go1_xml_path,
)
from chronogym.tasks.quadruped.velocity import REWARD_TERMS, Go1VelocityBase
from chronogym.terrain.params import SoilParameters, soil_preset
from chronogym.validation import check_number

if TYPE_CHECKING:
    from chronogym.terrain import MujocoSoil

__all__ = ["PHYSICS_STEP", "REWARD_TERMS", "TERRAINS", "Go1VelocityTask"]

#: Ground under the feet: the rigid floor, or SCM soil (``chronogym.terrain``) over it.
TERRAINS: tuple[str, ...] = ENGINE_TERRAINS["mujoco"]
#: Default (dt, k) per terrain, 50 Hz policy either way. Rigid ground: 10 ms keeps the
#: standing height and slope creep of 5 ms and 2 ms (``benchmarks/rl/quadruped_physics.py``).
#: The soil's force law is explicit
#: and Chrono's soil stiffness (2e8 Pa/m) on a 20 mm foot needs dt <= 2 ms: at 5 ms the
#: robot jitters down through the soil (and at 5 ms with a 10x softer soil the rigid policy
#: fell in 3 of 4 episodes; at 2 ms it kept walking on "firm", as at 1 ms).
PHYSICS_STEP: dict[str, tuple[float, int]] = {"rigid": (0.01, 2), "soil": (0.002, 10)}


class Go1VelocityTask(Go1VelocityBase, MujocoTask):
    """Unitree Go1 tracking a velocity command (the paper's locomotion task), in MuJoCo."""

    render_camera = CAMERA_NAME

    def __init__(
        self,
        *,
        config: Go1TaskConfig | None = None,
        dt: float | None = None,
        k: int | None = None,
        cone: str = "elliptic",
        impratio: float = 100.0,
        terrain: str = "rigid",
        soil: SoilParameters | str = "firm",
        soil_resolution: float = 0.01,
        soil_window: float = 3.0,
        **options: Any,
    ) -> None:
        """``config``: the settings shared with the Chrono Go1; ``options``: any of its fields
        by name (``max_tilt=0.8``), replacing the value in ``config``. The rest are MuJoCo's:
        physics step ``dt`` x ``k`` (``None``: ``PHYSICS_STEP`` of the terrain), friction
        ``cone`` and ``impratio``, and the terrain with its soil."""
        super().__init__(config=config, **options)
        check_number("impratio", impratio, low=1, expected="a float >= 1")
        if terrain not in TERRAINS:
            raise ValueError(
                f"terrain={terrain!r}: expected one of {', '.join(TERRAINS)} for the MuJoCo Go1"
                + (
                    " ('scm' is Chrono's SCMTerrain: chronogym/ChronoGo1Velocity-v0)"
                    if terrain == "scm"
                    else ""
                )
            )
        check_number(
            "soil_resolution",
            soil_resolution,
            low=0.001,
            high=0.1,
            expected="a node spacing in [0.001, 0.1] m",
        )
        check_number(
            "soil_window", soil_window, low=0.5, high=100, expected="a side length in [0.5, 100] m"
        )
        if cone not in ("pyramidal", "elliptic"):
            raise ValueError(f"cone={cone!r}: expected 'pyramidal' or 'elliptic'")
        default_dt, default_k = PHYSICS_STEP[terrain]
        self.dt = default_dt if dt is None else dt
        self.k = default_k if k is None else k
        self.cone = cone
        self.impratio = float(impratio)
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
        kp, kd = self.config.kp, self.config.kd
        if kp is not None:  # position servo: force = kp (ctrl - q) - kv qdot
            model.actuator_gainprm[:, 0] = kp
            model.actuator_biasprm[:, 1] = -kp
        if kd is not None:
            model.actuator_biasprm[:, 2] = -kd
        return model

    def _setup_engine(self) -> None:
        model = self.model
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
        self._rot = np.zeros(9)

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

    # --- engine hooks ----------------------------------------------------------------------

    def _reset_pose(self, yaw: float, joints: np.ndarray | None) -> None:
        self.reset_data(self._home_key)
        if self.soil is not None:
            self.soil.reset()
        data = self.data
        data.qpos[3:7] = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
        if joints is not None:
            data.qpos[7:] = joints
        data.ctrl[:] = DEFAULT_JOINT_POS
        self.forward()

    def _set_friction(self, mu: float) -> None:
        self.model.geom_friction[self._floor, 0] = mu
        self.model.geom_friction[self._foot_geoms, 0] = mu

    def _set_added_base_mass(self, dm: float) -> None:
        self.model.body_mass[self._trunk] = self._nominal_trunk_mass + dm

    def _set_joint_targets(self, targets: np.ndarray) -> None:
        self.data.ctrl[:] = targets

    def _kick_base(self, dv: np.ndarray) -> None:
        self.data.qvel[0:2] += dv

    def _read_state(self, raw: np.ndarray) -> None:
        import mujoco

        data = self.data
        mujoco.mju_quat2Mat(self._rot, data.qpos[3:7])
        rot = self._rot.reshape(3, 3)
        raw[OBS_ANG_VEL] = data.qvel[3:6]  # the free joint's angular velocity is in the body frame
        raw[OBS_GRAVITY] = -rot[2]  # R^T (0, 0, -1)
        raw[OBS_JOINT_POS] = data.qpos[7:] - DEFAULT_JOINT_POS
        raw[OBS_JOINT_VEL] = data.qvel[6:]
        self.base_lin_vel = rot.T @ data.qvel[0:3]

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

    def _joint_torques(self) -> np.ndarray:
        return self.data.actuator_force

    def _base_height(self) -> float:
        return float(self.data.qpos[2])

    def feet_positions(self) -> np.ndarray:
        return self.data.geom_xpos[self._foot_geoms]
