"""The IMU's mount: the robot config's `imu:` section, the fixed joint that places the IMU, and its parameters.

Config (all lengths SI):

    imu:
      frame: imu_frame        # the URDF link of the IMU, attached by a fixed joint whose origin is the nominal mount
      topic: /imu/data        # sensor_msgs/msg/Imu (linear_acceleration [m/s^2])
      bias: 0.03              # accelerometer bias level per axis [m/s^2] (1 sigma), default 0.03
      stances: [{...}, ...]   # standing stances of `capture --standing` (joint -> reading [rad]; others 0)
      bus: {id, accel, gyro}  # the IMU as a device on the servo bus, read by `capture --standing`
                              #   (`wolfcal.robot.imu_bus`)

The mount correction is a frame correction of that fixed joint (origin_new = origin * Exp(rx, ry, rz), in the
joint's child frame: the IMU's own axes), named `imu.rx`, `imu.ry` [rad]. `imu.rz` (a turn about the IMU's z axis)
is not among them: gravity, along the IMU's z axis while the robot stands, does not turn with it; it stays at the
nominal mount and is reported as not determined.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.floor import floor_frames
from wolfcal.robot.imu_bus import ImuBusConfig, parse_imu_bus
from wolfcal.robot.parameters import Parameter
from wolfcal.robot.robot import Robot

IMU_KEY = "imu"
DEFAULT_TOPIC = "/imu/data"
DEFAULT_BIAS_M_S2 = 0.03  # MEMS accelerometers: up to about 0.03 m/s^2 of constant bias per axis
MOUNT_PRIOR_RAD = 0.05  # prior of the mount's roll and pitch correction [rad] (about 3 deg)
MOUNT_COMPONENTS = (3, 4)  # rx, ry of (x, y, z, rx, ry, rz): what gravity determines


@dataclass(frozen=True)
class ImuConfig:
    """The robot config's `imu:` section (module docstring)."""

    frame: str  # URDF link of the IMU
    topic: str = DEFAULT_TOPIC  # sensor_msgs/msg/Imu
    bias: float = DEFAULT_BIAS_M_S2  # accelerometer bias level per axis [m/s^2]
    stances: tuple[dict[str, float], ...] = ()  # standing stances for `capture --standing` [rad]
    bus: ImuBusConfig | None = None  # the IMU on the servo bus (`capture --standing`); None: not on the bus


def parse_imu_config(path: Path, data: object) -> ImuConfig:
    """The `imu:` section of the robot config at `path`; a WolfcalError naming the key otherwise."""
    if not isinstance(data, dict):
        raise WolfcalError(f"{path}: 'imu' must be a mapping {{frame, topic, bias, stances, bus}}")
    unknown = sorted(set(data) - {"frame", "topic", "bias", "stances", "bus"})
    if unknown:
        raise WolfcalError(
            f"{path}: unknown key(s) under 'imu': {', '.join(unknown)} (known: frame, topic, bias, stances, bus)"
        )
    frame, topic = data.get("frame"), data.get("topic", DEFAULT_TOPIC)
    if not isinstance(frame, str) or not frame:
        raise WolfcalError(f"{path}: 'imu.frame' must name the URDF link of the IMU")
    if not isinstance(topic, str) or not topic.startswith("/"):
        raise WolfcalError(f"{path}: 'imu.topic' must be a ROS topic name such as /imu/data")
    bias = data.get("bias", DEFAULT_BIAS_M_S2)
    if not isinstance(bias, (int, float)) or isinstance(bias, bool) or not 0 < bias < 1:
        raise WolfcalError(
            f"{path}: 'imu.bias' must be the accelerometer's bias level per axis in m/s^2, above 0 "
            "and below 1 (typically 0.03)"
        )
    stances = data.get("stances", [])
    if not isinstance(stances, list) or not all(
        isinstance(s, dict) and all(isinstance(v, (int, float)) for v in s.values()) for s in stances
    ):
        raise WolfcalError(f"{path}: 'imu.stances' must be a list of joint -> reading [rad] maps")
    bus = parse_imu_bus(path, data["bus"]) if data.get("bus") is not None else None
    return ImuConfig(frame, topic, float(bias), tuple({str(k): float(v) for k, v in s.items()} for s in stances), bus)


def imu_config(robot: Robot, why: str = "the IMU needs it") -> ImuConfig:
    """The robot's `imu:` section; a WolfcalError naming the config file when it has none."""
    section: ImuConfig = robot.config.section(IMU_KEY, why)
    return section


def imu_joint(robot: Robot) -> str:
    """The fixed joint that attaches the IMU's link (`imu.frame`); a WolfcalError naming the key when the link is
    not in the URDF or is attached by a joint that moves."""
    frame, config = imu_config(robot).frame, robot.config
    if frame not in robot.model.links:
        raise WolfcalError(
            f"{config.path}: 'imu.frame' {frame!r} is not a link of {config.urdf}; name the link of the IMU"
        )
    joint = robot.model.joint_to_child.get(frame)
    if joint is None or joint.type != "fixed":
        how = "is the URDF's root" if joint is None else f"is attached by the {joint.type} joint {joint.name!r}"
        raise WolfcalError(
            f"{config.path}: 'imu.frame' {frame!r} {how}; the IMU's link must be attached by a "
            "fixed joint, whose origin is the nominal mount"
        )
    return joint.name


def imu_parameters(robot: Robot) -> list[Parameter]:
    """The `--free imu` preset's chain parameters: imu.rx, imu.ry [rad] of the IMU joint's frame correction."""
    joint = imu_joint(robot)
    return [Parameter(f"imu.{name}", "frame", joint, component, "rad", MOUNT_PRIOR_RAD)
            for name, component in zip(("rx", "ry"), MOUNT_COMPONENTS)]  # fmt: skip


def true_gravity(robot: Robot, truth: Corrections, q_true: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The floor's normal in the IMU frame (N, 3) and R_floor_imu (N, 3, 3) at true angles q_true (N, J), under the
    true geometry (`truth` without its offsets: q_true are the angles themselves)."""
    geometry = Corrections(frames=truth.frames, tags=truth.tags)
    link, soles = imu_config(robot).frame, list(robot.config.floor_config().soles)
    poses = robot.model.link_poses(q_true, [link, *soles], geometry, base=robot.config.base_link)
    T_base_floor = floor_frames(np.stack([poses[s] for s in soles]))
    R_floor_imu = np.swapaxes(T_base_floor[:, :3, :3], 1, 2) @ poses[link][:, :3, :3]
    return np.swapaxes(R_floor_imu, 1, 2)[:, :, 2], R_floor_imu
