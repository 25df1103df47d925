"""The Bit-Bots ROS 2 stack's calibration files (bit-bots/bitbots_main), read and written.

- `bitbots_extrinsic_calibration.yaml` (package bitbots_extrinsic_calibration, one file per robot in its `config/`):
  two nodes, `/bitbots_extrinsic_camera_calibration` and `/bitbots_extrinsic_imu_calibration`, each with
  `ros__parameters: {offset_x, offset_y, offset_z}` [rad]. Each node publishes one static transform from its
  `parent_frame` (the camera's: `camera_optical_frame_uncalibrated`) to its `child_frame` (`camera_optical_frame`)
  with the rotation rot_conv's `QuatFromEuler(offset_z, offset_y, offset_x)`, i.e. R = Rz(offset_z) Ry(offset_y)
  Rx(offset_x): the same angles as URDF rpy (roll = offset_x, pitch = offset_y, yaw = offset_z). Rotation only: no
  translation.
- The hardware interface's servo table (bitbots_ros_control `config/wolfgang.yaml`): `wolfgang_hardware_interface:
  ros__parameters: device_info: <joint>: {id, model_number, mounting_offset, joint_offset, ...}`; on read the
  interface adds `mounting_offset + joint_offset` [rad] to the servo's position: q_used = q_read + mounting_offset +
  joint_offset, the convention of wolfcal's encoder offsets with offset = mounting_offset + joint_offset.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wolfcal.encoders import RAD_PER_TICK
from wolfcal.errors import WolfcalError
from wolfcal.geometry import matrix_to_rpy, rpy_to_matrix
from wolfcal.yamlfile import read_yaml

EXTRINSIC_FILE = "bitbots_extrinsic_calibration.yaml"
CAMERA_NODE = "/bitbots_extrinsic_camera_calibration"
IMU_NODE = "/bitbots_extrinsic_imu_calibration"
OFFSET_KEYS = ("offset_x", "offset_y", "offset_z")
NODE_FRAME_KEYS = ("parent_frame", "child_frame", "use_sim_time")  # parameters the team's launch file may also set
HARDWARE_NODE = "wolfgang_hardware_interface"
HARDWARE_FILE = "wolfgang_hardware_interface_offsets.yaml"


def euler_offsets(R: np.ndarray) -> tuple[float, float, float]:
    """(offset_x, offset_y, offset_z) [rad] of a rotation matrix (3, 3): R = Rz(offset_z) Ry(offset_y) Rx(offset_x)."""
    roll, pitch, yaw = (float(v) for v in matrix_to_rpy(np.asarray(R, dtype=float)))
    return roll, pitch, yaw


def rotation_of_offsets(offsets: tuple[float, float, float]) -> np.ndarray:
    """(3, 3) rotation Rz(offset_z) Ry(offset_y) Rx(offset_x) of (offset_x, offset_y, offset_z) [rad]."""
    return rpy_to_matrix(np.asarray(offsets, dtype=float))


@dataclass(frozen=True)
class ExtrinsicFile:
    """The two blocks of a bitbots_extrinsic_calibration YAML: (offset_x, offset_y, offset_z) [rad], None when the
    file has no such node."""

    camera: tuple[float, float, float] | None
    imu: tuple[float, float, float] | None


def _node_offsets(path: Path, node: str, data) -> tuple[float, float, float]:
    """The offsets of one node's `ros__parameters` (missing keys: 0, as the node's parameter defaults)."""
    if not isinstance(data, dict) or set(data) != {"ros__parameters"}:
        raise WolfcalError(f"{path}: '{node}' must hold only 'ros__parameters' (the layout of "
                           f"bitbots_extrinsic_calibration's config files)")  # fmt: skip
    params = data["ros__parameters"] or {}
    if not isinstance(params, dict):
        raise WolfcalError(f"{path}: '{node}.ros__parameters' must be a mapping of {', '.join(OFFSET_KEYS)}")
    unknown = sorted(set(params) - set(OFFSET_KEYS) - set(NODE_FRAME_KEYS))
    if unknown:
        raise WolfcalError(f"{path}: '{node}.ros__parameters.{unknown[0]}' is not a parameter of the extrinsic "
                           f"calibration node (it reads {', '.join(OFFSET_KEYS)} [rad])")  # fmt: skip
    values = []
    for key in OFFSET_KEYS:
        value = params.get(key, 0.0)
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
            raise WolfcalError(f"{path}: '{node}.ros__parameters.{key}' must be a number [rad], found {value!r}")
        values.append(float(value))
    return values[0], values[1], values[2]


def read_extrinsic_file(path: Path) -> ExtrinsicFile:
    """A bitbots_extrinsic_calibration YAML; node names with or without the leading '/'. Another layout: an error
    naming the file and the key."""
    data = read_yaml(Path(path), "bitbots_extrinsic_calibration file")
    nodes = {CAMERA_NODE: None, IMU_NODE: None}
    if not isinstance(data, dict):
        raise WolfcalError(f"{path}: not a bitbots_extrinsic_calibration file (expected the nodes {CAMERA_NODE} "
                           f"and {IMU_NODE} at the top)")  # fmt: skip
    for key, value in data.items():
        name = "/" + str(key).lstrip("/")
        if name not in nodes:
            raise WolfcalError(
                f"{path}: '{key}' is not a node of bitbots_extrinsic_calibration (expected "
                f"{CAMERA_NODE} and {IMU_NODE}); is this the robot's extrinsic calibration file?"
            )
        nodes[name] = _node_offsets(path, str(key), value)  # type: ignore[assignment]
    if nodes[CAMERA_NODE] is None and nodes[IMU_NODE] is None:
        raise WolfcalError(f"{path}: holds neither {CAMERA_NODE} nor {IMU_NODE}")
    return ExtrinsicFile(nodes[CAMERA_NODE], nodes[IMU_NODE])


def ros_double(value: float) -> str:
    """A number as a ROS 2 parameter file must hold a double: with a decimal point, never an exponent (rclcpp
    refuses an integer for a double parameter) [10 decimals]."""
    text = f"{float(value):.10f}".rstrip("0")
    return text + "0" if text.endswith(".") else text


def _block(node: str, offsets: tuple[float, float, float], comment: str) -> list[str]:
    lines = [f"{node}:", f"  # {comment}", "  ros__parameters:"]
    for key, value in zip(OFFSET_KEYS, offsets):
        lines.append(f"    {key}: {ros_double(value)}  # {np.rad2deg(value):+.3f} deg")
    return lines


def extrinsic_text(
    camera: tuple[float, float, float], imu: tuple[float, float, float] | None, camera_comment: str, imu_comment: str
) -> str:
    """The text of a bitbots_extrinsic_calibration YAML: the camera block and the IMU block (None: 0, no
    correction), each with a comment line saying where its values come from."""
    lines = [
        "# Extrinsic calibration for bitbots_extrinsic_calibration: R = Rz(offset_z) Ry(offset_y) Rx(offset_x) [rad]",
        "# from parent_frame (..._uncalibrated) to child_frame; rotation only.",
        *_block(CAMERA_NODE, camera, camera_comment),
        "",
        *_block(IMU_NODE, imu if imu is not None else (0.0, 0.0, 0.0), imu_comment),
    ]
    return "\n".join(lines) + "\n"


def read_hardware_offsets(path: Path) -> dict[str, tuple[float, float]]:
    """joint -> (mounting_offset, joint_offset) [rad] of a hardware interface parameter file (`<node>:
    ros__parameters: device_info: <joint>: {mounting_offset, joint_offset, ...}`; a missing mounting_offset is 0);
    devices without a joint_offset (IMU, LEDs, buttons) are skipped."""
    data = read_yaml(Path(path), "hardware interface parameter file")
    if not isinstance(data, dict) or len(data) != 1:
        raise WolfcalError(f"{path}: not a hardware interface parameter file (expected one node, e.g. "
                           f"{HARDWARE_NODE}: ros__parameters: device_info: ...)")  # fmt: skip
    node, body = next(iter(data.items()))
    params = body.get("ros__parameters") if isinstance(body, dict) else None
    devices = params.get("device_info") if isinstance(params, dict) else None
    if not isinstance(devices, dict):
        raise WolfcalError(f"{path}: '{node}.ros__parameters.device_info' missing; not a hardware interface "
                           "parameter file with per-joint joint_offset values")  # fmt: skip
    offsets = {}
    for joint, device in devices.items():
        if isinstance(device, dict) and "joint_offset" in device:
            values = []
            for key in ("mounting_offset", "joint_offset"):
                value = device.get(key, 0.0)
                if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
                    raise WolfcalError(f"{path}: '{node}.ros__parameters.device_info.{joint}.{key}' must be a "
                                       f"number [rad], found {value!r}")  # fmt: skip
                values.append(float(value))
            offsets[str(joint)] = (values[0], values[1])
    return offsets


def hardware_offsets_text(offsets: dict[str, tuple[float, str]], mounting: dict[str, float]) -> str:
    """The hardware interface's per-joint `joint_offset` values as a parameter-file snippet: joint -> (encoder offset
    [rad], note), in the given order; each joint_offset is the offset less the joint's `mounting_offset` (which the
    interface adds as well; written beside it, unchanged, where not 0; 0 where not given)."""
    lines = [
        "# joint_offset per joint for the hardware interface (bitbots_ros_control config/wolfgang.yaml,",
        "# device_info.<joint>.joint_offset): q_used = q_read + mounting_offset + joint_offset [rad].",
        "# Copy each value into the joint's entry; joints not listed keep theirs.",
        f"{HARDWARE_NODE}:",
        "  ros__parameters:",
        "    device_info:" + ("" if offsets else " {}"),
    ]
    for joint, (total, note) in offsets.items():
        value = total - mounting.get(joint, 0.0)
        lines.append(f"      {joint}:")
        if mounting.get(joint):
            lines.append(f"        mounting_offset: {ros_double(mounting[joint])}  # unchanged")
        lines.append(f"        joint_offset: {ros_double(value)}  # {np.rad2deg(value):+.3f} deg, "
                     f"{value / RAD_PER_TICK:+.1f} ticks{'; ' + note if note else ''}")  # fmt: skip
    return "\n".join(lines) + "\n"
