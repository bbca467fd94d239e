"""Go1 velocity tracking in Project Chrono (``chronogym/ChronoGo1Velocity-v0``; needs ``pychrono``).

The same task as :class:`~.task.Go1VelocityTask` (MuJoCo): the observation, action, reward
terms, command sampling, pushes and termination are the same code (:mod:`.velocity`), and
the robot is built from the same MJCF numbers (:mod:`.chrono_model`). So a policy trained
in one engine runs unchanged in the other (sim-to-sim: ``chronogym play quadruped CKPT
--engine chrono``, ``benchmarks/chrono/sim_to_sim.py``).

Terrain: ``"rigid"``, a fixed box with its top at z = 0, or ``"scm"``: Chrono's own
``SCMTerrain`` (``pychrono.vehicle``) with a chronogym soil preset (``soil``, default
"firm": the same Bekker/Janosi numbers as the MuJoCo task's ``terrain="soil"``), flat at
z = 0, active under each foot and around the trunk (hips and thighs included), so a fall
onto the soil ends the episode as a fall onto the ground does. On SCM a foot is in contact
when the soil pushes its calf up with more than 1 N.

Pictures: Chrono's own visual systems need a display or a GPU, so ``render()`` draws the
MuJoCo model of the same robot at the Chrono bodies' pose (base frame and joint angles).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from chronogym.engines.chrono import (
    ChronoTask,
    body_ang_vel,
    body_lin_vel,
    body_pos,
    body_rot,
    finish_reset,
    set_body_state,
    vec3,
)
from chronogym.tasks.quadruped.chrono_model import (
    ChronoGo1Model,
    ChronoGo1Settings,
    Go1Servos,
    build_chrono_go1,
    quat_from_matrix,
    quat_to_matrix,
)
from chronogym.tasks.quadruped.config import (
    OBS_ANG_VEL,
    OBS_GRAVITY,
    OBS_JOINT_POS,
    OBS_JOINT_VEL,
    Go1TaskConfig,
)
from chronogym.tasks.quadruped.engines import ENGINE_TERRAINS
from chronogym.tasks.quadruped.model import (
    CAMERA_NAME,
    DEFAULT_JOINT_POS,
    KP,
    KV,
    go1_xml_path,
)
from chronogym.tasks.quadruped.velocity import Go1VelocityBase
from chronogym.terrain.params import SoilParameters, soil_preset
from chronogym.validation import check_number

__all__ = ["CHRONO_PHYSICS_STEP", "CHRONO_TERRAINS", "ChronoGo1VelocityTask"]

#: Ground under the Chrono Go1: a rigid box, or Chrono's SCMTerrain.
CHRONO_TERRAINS: tuple[str, ...] = ENGINE_TERRAINS["chrono"]
#: Default (dt, k) per contact method on rigid ground, 50 Hz policy.
CHRONO_PHYSICS_STEP: dict[str, tuple[float, int]] = {"nsc": (0.002, 10), "smc": (0.0005, 40)}
#: Default (dt, k) on SCM (its soil forces are explicit). A rigid-trained policy at 0.5 m/s on
#: "firm" (5 s, seed 0): mean vx 0.45 / 0.49 / 0.50 at 2 / 1 / 0.5 ms (docs/performance/chrono.md).
CHRONO_SCM_STEP: tuple[float, int] = (0.001, 20)
#: SCM active domains: (centre, full size) of a box around each foot (calf frame) and one
#: around the trunk (trunk frame, hips and thighs inside) [m].
FOOT_DOMAIN = (0.12, 0.12, 0.12)
TRUNK_DOMAIN = ((0.0, 0.0, 0.0), (0.62, 0.40, 0.30))
#: A foot is on the ground when the ground pushes its calf up with more than this [N].
FOOT_CONTACT_FORCE = 1.0
#: The trunk or a hip touches the ground when its contact force exceeds this [N].
BASE_CONTACT_FORCE = 1.0


class ChronoGo1VelocityTask(Go1VelocityBase, ChronoTask):
    """Unitree Go1 tracking a velocity command, simulated by Project Chrono."""

    render_modes = ("rgb_array",)
    render_width: int = 480
    render_height: int = 360
    render_camera = CAMERA_NAME

    def __init__(
        self,
        *,
        config: Go1TaskConfig | None = None,
        dt: float | None = None,
        k: int | None = None,
        terrain: str = "rigid",
        soil: SoilParameters | str = "firm",
        soil_resolution: float = 0.02,
        soil_extent: float = 20.0,
        settings: ChronoGo1Settings | None = None,
        **options: Any,
    ) -> None:
        """``config``: the settings shared with the MuJoCo Go1; ``options``: any of its fields
        by name (``max_tilt=0.8``), replacing the value in ``config``. The rest are Chrono's:
        physics step ``dt`` x ``k`` (``None``: by contact method and terrain), the terrain with
        its soil, and the model's ``settings``."""
        super().__init__(config=config, **options)
        if terrain not in CHRONO_TERRAINS:
            raise ValueError(
                f"terrain={terrain!r}: expected one of {', '.join(CHRONO_TERRAINS)} for the "
                "Chrono Go1"
                + (
                    " ('soil' is chronogym's SCM for MuJoCo: chronogym/Go1Velocity-v0)"
                    if terrain == "soil"
                    else ""
                )
            )
        self.settings = settings if settings is not None else ChronoGo1Settings()
        if not isinstance(self.settings, ChronoGo1Settings):
            raise ValueError(f"settings={settings!r}: expected a ChronoGo1Settings or None")
        if self.settings.collision != "bullet" and terrain != "scm":
            raise ValueError(
                f"settings.collision={self.settings.collision!r} on terrain={terrain!r}: "
                "expected 'bullet' on rigid ground (on Chrono's multicore collision system a "
                "foot went through the ground box); multicore is for terrain='scm'"
            )
        check_number(
            "soil_resolution",
            soil_resolution,
            low=0.005,
            high=0.1,
            expected="a node spacing in [0.005, 0.1] m",
        )
        check_number("soil_extent", soil_extent, low=1, high=1000, expected="a side in [1, 1000] m")
        self.soil_params = soil_preset(soil) if isinstance(soil, str) else soil
        if not isinstance(self.soil_params, SoilParameters):
            raise ValueError(f"soil={soil!r}: expected a SoilParameters or a preset name")
        self.soil_resolution = float(soil_resolution)
        self.soil_extent = float(soil_extent)
        default_dt, default_k = (
            CHRONO_SCM_STEP if terrain == "scm" else CHRONO_PHYSICS_STEP[self.settings.contact]
        )
        self.dt = default_dt if dt is None else dt
        self.k = default_k if k is None else k
        self.terrain = terrain
        self.scm: Any = None

    # --- init ------------------------------------------------------------------------------

    def build_system(self) -> Any:
        if self.terrain == "scm":
            from chronogym.engines.chrono_scm import import_chrono_vehicle

            import_chrono_vehicle()  # the clear error before anything is built
        self.robot: ChronoGo1Model = build_chrono_go1(
            self.settings, rigid_ground=self.terrain == "rigid"
        )
        return self.robot.system

    def _setup_engine(self) -> None:
        import mujoco

        robot = self.robot
        self.servos = Go1Servos(
            robot.motors,
            robot.torque_functions,
            kp=KP if self.config.kp is None else self.config.kp,
            kd=KV if self.config.kd is None else self.config.kd,
            ranges=robot.layout.joint_ranges,
            joint_inertia=robot.layout.joint_inertia,
            limit_time_constant=self.settings.limit_time_constant,
        )
        self.advanceables = [self.servos, self.system]
        if self.terrain == "scm":
            self.scm = self._add_scm()
            self.advanceables = [self.servos, self.scm, self.system]
        # a MuJoCo copy of the robot: the reset pose's kinematics, and the pictures
        self._mj_model = mujoco.MjModel.from_xml_path(str(go1_xml_path()))
        self._mj_data = mujoco.MjData(self._mj_model)
        self._scene: Any = None  # a SceneRenderer of the MuJoCo copy, made on first render
        self._nominal_trunk_mass = float(robot.trunk.GetMass())
        self._trunk_ipos = robot.layout.trunk_ipos
        self._trunk_irot = robot.layout.trunk_irot
        self._body_ids = [body.mujoco_id for body in robot.layout.bodies]
        self._foot_offsets = robot.layout.foot_offsets
        self._calf_contact = [calf.GetContactForce for calf in robot.calves]
        self._fatal_contact = [body.GetContactForce for body in robot.fatal]
        self._torques = np.zeros(12)

    def _add_scm(self) -> Any:
        from chronogym.engines.chrono_scm import ChronoSCM

        robot = self.robot
        domains = [(robot.trunk, *TRUNK_DOMAIN)]
        domains += [
            (calf, offset, FOOT_DOMAIN)
            for calf, offset in zip(robot.calves, robot.layout.foot_offsets, strict=True)
        ]
        side = self.soil_extent
        return ChronoSCM(self.system, self.soil_params, (side, side), self.soil_resolution, domains)

    # --- engine hooks ----------------------------------------------------------------------

    def _reset_pose(self, yaw: float, joints: np.ndarray | None) -> None:
        import mujoco

        m, d = self._mj_model, self._mj_data
        mujoco.mj_resetDataKeyframe(m, d, m.key("home").id)
        d.qpos[3:7] = (math.cos(yaw / 2), 0.0, 0.0, math.sin(yaw / 2))
        if joints is not None:
            d.qpos[7:] = joints
        mujoco.mj_kinematics(m, d)
        zero = (0.0, 0.0, 0.0)
        for body, b in zip(self.robot.bodies, self._body_ids, strict=True):
            rot = quat_from_matrix(d.ximat[b].reshape(3, 3))
            set_body_state(body, pos=d.xipos[b], rot=rot, lin_vel=zero, ang_vel=zero)
        finish_reset(self.system)
        if self.scm is not None:
            self.scm.reset()
        self.servos.set_targets(DEFAULT_JOINT_POS)
        self.servos.zero()
        self._torques[:] = 0.0

    def _set_friction(self, mu: float) -> None:
        for material in self.robot.materials:
            material.SetFriction(float(mu))

    def _set_added_base_mass(self, dm: float) -> None:
        self.robot.trunk.SetMass(self._nominal_trunk_mass + float(dm))

    def _set_joint_targets(self, targets: np.ndarray) -> None:
        self.servos.set_targets(targets)

    def _kick_base(self, dv: np.ndarray) -> None:
        kick = np.array([dv[0], dv[1], 0.0])
        for body in self.robot.bodies:  # every body, as MuJoCo's free-joint velocity does
            set_body_state(body, lin_vel=body_lin_vel(body) + kick)

    def base_frame(self) -> tuple[np.ndarray, np.ndarray]:
        """Position and 3x3 orientation of the MuJoCo trunk frame (the base), in the world."""
        trunk = self.robot.trunk
        rot = quat_to_matrix(body_rot(trunk)) @ self._trunk_irot.T
        return body_pos(trunk) - rot @ self._trunk_ipos, rot

    def _read_state(self, raw: np.ndarray) -> None:
        trunk = self.robot.trunk
        pos, rot = self.base_frame()
        omega = body_ang_vel(trunk)  # world frame
        v_origin = body_lin_vel(trunk) + np.cross(omega, pos - body_pos(trunk))
        raw[OBS_ANG_VEL] = rot.T @ omega
        raw[OBS_GRAVITY] = -rot[2]
        raw[OBS_JOINT_POS] = self.servos.angles() - DEFAULT_JOINT_POS
        raw[OBS_JOINT_VEL] = self.servos.rates()
        self.base_lin_vel = rot.T @ v_origin
        self._base_z = float(pos[2])

    def _update_contacts(self) -> None:
        if self.scm is not None:
            force_on = self.scm.force_on
            self.feet_contact_now = np.array(
                [force_on(calf)[0][2] > FOOT_CONTACT_FORCE for calf in self.robot.calves]
            )
            self._base_contact = any(
                float(np.linalg.norm(force_on(body)[0])) > BASE_CONTACT_FORCE
                for body in self.robot.fatal
            )
            return
        self.feet_contact_now = np.array(
            [vec3(force())[2] > FOOT_CONTACT_FORCE for force in self._calf_contact]
        )
        self._base_contact = any(
            float(np.linalg.norm(vec3(force()))) > BASE_CONTACT_FORCE
            for force in self._fatal_contact
        )

    def _joint_torques(self) -> np.ndarray:
        return self.servos.torque

    def _base_height(self) -> float:
        return self._base_z

    def feet_positions(self) -> np.ndarray:
        return np.array(
            [
                body_pos(calf) + quat_to_matrix(body_rot(calf)) @ offset
                for calf, offset in zip(self.robot.calves, self._foot_offsets, strict=True)
            ]
        )

    # --- pictures --------------------------------------------------------------------------

    def mujoco_qpos(self) -> np.ndarray:
        """The MuJoCo ``qpos`` of the Chrono robot's pose: base frame and joint angles."""
        pos, rot = self.base_frame()
        return np.concatenate([pos, quat_from_matrix(rot), self.servos.angles()])

    def render_unavailable(self) -> str | None:
        from chronogym.engines.mujoco import gl_unavailable

        return gl_unavailable()

    def render(self) -> np.ndarray:
        import mujoco

        from chronogym.engines.mujoco import SceneRenderer

        m, d = self._mj_model, self._mj_data
        if self._scene is None:
            self._scene = SceneRenderer(
                m, self.render_width, self.render_height, self.render_camera
            )
        d.qpos[:] = self.mujoco_qpos()
        d.qvel[:] = 0.0
        mujoco.mj_forward(m, d)
        return self._scene.frame(d)

    def close(self) -> None:
        scene = getattr(self, "_scene", None)
        if scene is not None:
            scene.close()
