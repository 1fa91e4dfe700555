"""Index layout of a compiled variant: where legs, arms, feet and sensors live in qpos/qvel/ctrl.

Everything here is static (numpy ints), computed once from the names `robots.bases.model` gives
every base's parts (whatever its file calls them), and safe to close over in jit.
"""

from __future__ import annotations

import dataclasses

import mujoco
import numpy as np

from dpc_mjx.errors import DpcError
from dpc_mjx.robots import arms
from dpc_mjx.robots.arms.mount import arm_prefix
from dpc_mjx.robots.bases import model as base_model
from dpc_mjx.robots.bases.file import LEGS


@dataclasses.dataclass(frozen=True)
class ArmLayout:
    """One attached arm."""

    prefix: str  # "arm<i>/"
    qpos: np.ndarray  # (n_arm_joints,) qpos addresses, kinematic order
    dof: np.ndarray  # (n_arm_joints,) qvel addresses
    act: np.ndarray  # (n_arm_joints,) position-servo actuator ids
    bodies: np.ndarray  # ids of every body of the arm (its subtree)
    mount_site: int
    ee_site: int
    force_adr: int  # sensordata address of the (3,) mount force, N, mount-site frame
    torque_adr: int  # sensordata address of the (3,) mount torque, N·m, mount-site frame


@dataclasses.dataclass(frozen=True)
class Layout:
    """A compiled variant's indices (see `layout`)."""

    leg_joints: np.ndarray  # (12,) joint ids, legs in bases.file.LEGS order, each hip, thigh, calf
    leg_qpos: np.ndarray  # (12,) in leg_joints order
    leg_dof: np.ndarray  # (12,)
    leg_act: np.ndarray  # (12,) torque motors, N·m
    arms: tuple[ArmLayout, ...]
    trunk: int  # body id
    imu_site: int
    foot_sites: np.ndarray  # (4,) FR, FL, RR, RL foot sphere centres
    foot_radius: float  # m, the feet's spheres' (the largest)
    torque_limits: np.ndarray  # (12,) N·m, the leg motors' ranges, in leg_joints order
    sensor_adr: dict[str, int]  # trunk_quat, gyro, accelerometer, local_linvel

    @property
    def arm_qpos(self) -> np.ndarray:
        """(n,) qpos addresses of every arm joint, arm after arm."""
        return np.concatenate([a.qpos for a in self.arms]) if self.arms else np.zeros(0, int)

    @property
    def arm_bodies(self) -> np.ndarray:
        """(n_b,) ids of every arm body (each arm's subtree), arm after arm."""
        return np.concatenate([a.bodies for a in self.arms]) if self.arms else np.zeros(0, int)

    @property
    def arm_dof(self) -> np.ndarray:
        return np.concatenate([a.dof for a in self.arms]) if self.arms else np.zeros(0, int)

    @property
    def arm_act(self) -> np.ndarray:
        return np.concatenate([a.act for a in self.arms]) if self.arms else np.zeros(0, int)


def layout(model: mujoco.MjModel) -> Layout:
    """Indices of a model built by `dpc_mjx.robots.build`."""
    try:
        leg_act = [
            model.actuator(base_model.actuator_name(place, part)).id
            for place in LEGS
            for part in base_model.LEG_PARTS
        ]
        leg_joints = [model.joint(model.actuator_trnid[a, 0]) for a in leg_act]
        feet = [model.site(base_model.foot_name(place)).id for place in LEGS]
        radius = max(model.geom(base_model.foot_name(place)).size[0] for place in LEGS)
        sensor_adr = {
            n: int(model.sensor(n).adr[0])
            for n in ("trunk_quat", "gyro", "accelerometer", "local_linvel")
        }
        trunk = int(model.joint(base_model.ROOT_JOINT).bodyid[0])
        imu = model.site(base_model.IMU_SITE).id
    except KeyError as e:
        raise DpcError(f"This model was not built by dpc_mjx.robots.build: missing {e}.") from e
    arm_list = []
    i = 0
    while _has_site(model, arm_prefix(i) + arms.MOUNT_SITE):
        arm_list.append(_arm_layout(model, arm_prefix(i)))
        i += 1
    return Layout(
        leg_joints=np.array([j.id for j in leg_joints]),
        leg_qpos=np.array([j.qposadr[0] for j in leg_joints]),
        leg_dof=np.array([j.dofadr[0] for j in leg_joints]),
        leg_act=np.array(leg_act),
        arms=tuple(arm_list),
        trunk=trunk,
        imu_site=imu,
        foot_sites=np.array(feet),
        foot_radius=float(radius),
        torque_limits=model.actuator_ctrlrange[leg_act, 1].copy(),
        sensor_adr=sensor_adr,
    )


def _has_site(model: mujoco.MjModel, name: str) -> bool:
    return mujoco.mj_name2id(model, mujoco.mjtObj.mjOBJ_SITE, name) >= 0


def _arm_layout(model: mujoco.MjModel, prefix: str) -> ArmLayout:
    joints = [j for j in range(model.njnt) if model.joint(j).name.startswith(prefix)]
    acts = {model.actuator_trnid[a, 0]: a for a in range(model.nu)}
    mount = model.site(prefix + arms.MOUNT_SITE).id
    root = model.site_bodyid[mount]
    bodies = [b for b in range(model.nbody) if _is_in_subtree(model, b, root)]
    return ArmLayout(
        prefix=prefix,
        qpos=np.array([model.jnt_qposadr[j] for j in joints]),
        dof=np.array([model.jnt_dofadr[j] for j in joints]),
        act=np.array([acts[j] for j in joints]),
        bodies=np.array(bodies),
        mount_site=mount,
        ee_site=model.site(prefix + arms.EE_SITE).id,
        force_adr=int(model.sensor(prefix + arms.FORCE_SENSOR).adr[0]),
        torque_adr=int(model.sensor(prefix + arms.TORQUE_SENSOR).adr[0]),
    )


def _is_in_subtree(model: mujoco.MjModel, body: int, root: int) -> bool:
    while body > root:
        body = model.body_parentid[body]
    return body == root


def mount_wrench(arm: ArmLayout, data) -> tuple:
    """(force (3,) N, torque (3,) N·m) that the arm exerts on the trunk, world frame, at the mount.

    Works on `mujoco.MjData` and `mjx.Data` alike (numpy or jax arrays). The sensors read the
    wrench of the trunk on the arm in the mount-site frame; we rotate it to world and negate it.
    """
    rot = data.site_xmat[arm.mount_site].reshape(3, 3)  # site -> world
    force = data.sensordata[arm.force_adr : arm.force_adr + 3]
    torque = data.sensordata[arm.torque_adr : arm.torque_adr + 3]
    return -(rot @ force), -(rot @ torque)
