"""The robot's present calibration (`--current`): what it runs today, as wolfcal corrections.

Each path is one of
- a bitbots_extrinsic_calibration YAML (`team_formats`): its camera block becomes the camera's frame correction
  (rotation only), its IMU block is kept as it is and copied unchanged into the deploy files;
- a hardware interface parameter file (`device_info.<joint>.joint_offset`): encoder offsets [rad];
- wolfcal's own deploy files: `joint_offsets.yaml` (offsets), `camera_correction.yaml` (the camera's frame
  correction with its translation);
- a folder of files wolfcal deployed before: each of the files above that it holds.
The camera correction is the frame correction of the joint above the camera frame (`Robot.camera_joint`), in that
frame (`Corrections`); the team's file gives it in the optical frame, converted here when the config's camera frame
has body axes. A value given twice must agree; a joint or frame this robot does not have is an error naming the file
and the key (the file of another robot).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.geometry import exp_so3, log_so3, rotation_angle, rpy_to_matrix
from wolfcal.io.team_formats import (
    CAMERA_NODE,
    EXTRINSIC_FILE,
    HARDWARE_FILE,
    IMU_NODE,
    read_extrinsic_file,
    read_hardware_offsets,
    rotation_of_offsets,
)
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import Robot
from wolfcal.yamlfile import read_yaml

JOINT_OFFSETS_FILE = "joint_offsets.yaml"
CAMERA_CORRECTION_FILE = "camera_correction.yaml"
FOLDER_FILES = (EXTRINSIC_FILE, HARDWARE_FILE, JOINT_OFFSETS_FILE, CAMERA_CORRECTION_FILE)
AGREE_RAD = 1e-6  # two files giving one value must agree to this [rad, m]

# R_body_optical: the optical axes (z forward, x right, y down) in ROS body axes (x forward, y left, z up)


@dataclass
class CurrentCalibration:
    """The robot's present calibration: corrections (offsets [rad], the camera's frame correction [m, rad]), the
    team file's IMU block (offset_x, offset_y, offset_z) [rad] or None, the files it was read from, and the hardware
    interface's mounting_offset per joint [rad] (part of each offset; kept as it is when deploying)."""

    corrections: Corrections = field(default_factory=Corrections)
    imu: tuple[float, float, float] | None = None
    sources: list[str] = field(default_factory=list)
    mounting: dict[str, float] = field(default_factory=dict)

    def to_dict(self) -> dict:
        return {"sources": list(self.sources), "corrections": self.corrections.to_dict(),
                "imu_offsets": None if self.imu is None else [float(v) for v in self.imu],
                "mounting_offsets": dict(self.mounting)}  # fmt: skip

    @classmethod
    def from_dict(cls, data: dict, source: str) -> CurrentCalibration:
        if not isinstance(data, dict) or "corrections" not in data:
            raise WolfcalError(f"{source}: 'current' must hold sources, corrections and imu_offsets")
        imu = data.get("imu_offsets")
        return cls(Corrections.from_dict(data["corrections"], f"{source}: current.corrections"),
                   None if imu is None else (float(imu[0]), float(imu[1]), float(imu[2])),
                   [str(s) for s in data.get("sources") or []],
                   {str(k): float(v) for k, v in (data.get("mounting_offsets") or {}).items()})  # fmt: skip


def optical_rotation(robot: Robot, corrections: Corrections) -> np.ndarray:
    """(3, 3) rotation of the camera correction between the optical frames: R_uncalibrated_calibrated (the camera's
    frame correction is in its optical frame, whatever `camera.axes` says of the URDF link)."""
    vec = corrections.frames.get(robot.camera_joint, np.zeros(6))
    return exp_so3(np.asarray(vec[3:], dtype=float))


def _camera_vector(robot: Robot, R_optical: np.ndarray, translation: np.ndarray) -> np.ndarray:
    """The camera's frame correction (x, y, z, rx, ry, rz) [m, rad] in its optical frame."""
    return np.concatenate([translation, log_so3(R_optical)])


def _joint_offsets(path: Path, data: dict) -> dict[str, float]:
    """wolfcal's joint_offsets.yaml -> joint -> offset [rad]."""
    offsets = data.get("joint_offsets") or {}
    if not isinstance(offsets, dict):
        raise WolfcalError(f"{path}: 'joint_offsets' must map joint names to offsets [rad]")
    for joint, value in offsets.items():
        if isinstance(value, bool) or not isinstance(value, (int, float)) or not np.isfinite(value):
            raise WolfcalError(f"{path}: 'joint_offsets.{joint}' must be a number [rad], found {value!r}")
    return {str(k): float(v) for k, v in offsets.items()}


def _camera_correction(path: Path, data: dict, robot: Robot) -> np.ndarray:
    """wolfcal's camera_correction.yaml -> the camera's frame correction vector (6,)."""
    frame = robot.config.head_camera().frame
    if data.get("child_frame") != frame:
        raise WolfcalError(
            f"{path}: 'child_frame' is {data.get('child_frame')!r}, but this robot's camera frame is "
            f"{frame!r} ({robot.config.path}); is this the calibration of another robot?"
        )
    try:
        t = np.array([float(data["translation"][k]) for k in "xyz"])
        rpy = np.array([float(v) for v in data["rpy"]])
    except (KeyError, TypeError, ValueError):
        raise WolfcalError(f"{path}: 'translation' {{x, y, z}} [m] and 'rpy' [roll, pitch, yaw] [rad] expected"
                           ) from None  # fmt: skip
    if rpy.shape != (3,):
        raise WolfcalError(f"{path}: 'rpy' must be 3 numbers [rad]")
    return np.concatenate([t, log_so3(rpy_to_matrix(rpy))])


def _read_one(path: Path, robot: Robot) -> tuple[dict[str, float], np.ndarray | None, tuple | None, dict]:
    """(offsets, camera correction vector or None, IMU block or None, mounting offsets) of one file."""
    data = read_yaml(path, "calibration file (--current)")
    keys = list(data) if isinstance(data, dict) else []
    names = {"/" + str(k).lstrip("/") for k in keys}
    if keys and names <= {CAMERA_NODE, IMU_NODE}:
        team = read_extrinsic_file(path)
        camera = None if team.camera is None else _camera_vector(robot, rotation_of_offsets(team.camera), np.zeros(3))
        return {}, camera, team.imu, {}
    if keys == ["joint_offsets"]:
        return _joint_offsets(path, data), None, None, {}
    if {"parent_frame", "child_frame", "translation", "rpy"} <= set(keys):
        return {}, _camera_correction(path, data, robot), None, {}
    if len(keys) == 1 and isinstance(data[keys[0]], dict) and "ros__parameters" in data[keys[0]]:
        hardware = read_hardware_offsets(path)
        return {j: m + o for j, (m, o) in hardware.items()}, None, None, {j: m for j, (m, _) in hardware.items()}
    first = keys[0] if keys else None
    raise WolfcalError(
        f"{path}: {'key ' + repr(first) if first is not None else 'the content'} is not of a calibration file wolfcal "
        f"reads for --current (a {EXTRINSIC_FILE} with {CAMERA_NODE}, a hardware interface file with "
        f"device_info.<joint>.joint_offset, or wolfcal's {JOINT_OFFSETS_FILE} / {CAMERA_CORRECTION_FILE})"
    )


def current_files(paths: list[Path]) -> list[Path]:
    """The files `paths` stand for: each file, and each calibration file (FOLDER_FILES) a folder holds; a missing
    path or a folder without one is an error."""
    out = []
    for path in map(Path, paths):
        if path.is_dir():
            found = [path / name for name in FOLDER_FILES if (path / name).is_file()]
            if not found:
                raise WolfcalError(f"{path}: --current folder holds none of {', '.join(FOLDER_FILES)}")
            out += found
        elif not path.exists():
            raise WolfcalError(f"{path}: --current file not found")
        else:
            out.append(path)
    return out


def load_current(paths: list[Path], robot: Robot) -> CurrentCalibration:
    """The present calibration from `paths` (files or folders, see the module docstring)."""
    offsets: dict[str, tuple[float, Path]] = {}
    camera: tuple[np.ndarray, Path] | None = None
    imu: tuple[tuple, Path] | None = None
    mounting: dict[str, float] = {}
    for path in current_files(paths):
        file_offsets, file_camera, file_imu, file_mounting = _read_one(path, robot)
        mounting.update({j: m for j, m in file_mounting.items() if m != 0.0})
        for joint, value in file_offsets.items():
            if joint not in robot.joint_names:
                raise WolfcalError(f"{path}: '{joint}' is not a movable joint of {robot.config.urdf}; is this the "
                                   "calibration of another robot?")  # fmt: skip
            if joint in offsets and abs(offsets[joint][0] - value) > AGREE_RAD:
                raise WolfcalError(f"{path}: offset of {joint} ({value:.6g} rad) differs from {offsets[joint][1]} "
                                   f"({offsets[joint][0]:.6g} rad); give the file the robot runs")  # fmt: skip
            offsets[joint] = (value, path)
        if file_camera is not None:
            camera = _merge_camera(camera, file_camera, path)
        if file_imu is not None:
            imu = (file_imu, path)
    frames = {robot.camera_joint: camera[0]} if camera is not None else {}
    return CurrentCalibration(Corrections({j: v for j, (v, _) in offsets.items()}, frames),
                              None if imu is None else imu[0], [str(p) for p in current_files(paths)],
                              mounting)  # fmt: skip


def _merge_camera(known: tuple[np.ndarray, Path] | None, vec: np.ndarray, path: Path) -> tuple[np.ndarray, Path]:
    """The camera correction of two files: the rotations must agree; a translation (wolfcal's file) is kept."""
    if known is None:
        return vec, path
    turn = float(rotation_angle(exp_so3(known[0][3:]).T @ exp_so3(vec[3:])))
    if turn > AGREE_RAD:
        raise WolfcalError(f"{path}: the camera rotation differs from {known[1]} by {np.rad2deg(turn):.3f} deg; give "
                           "the file the robot runs")  # fmt: skip
    return (vec, path) if np.linalg.norm(vec[:3]) > np.linalg.norm(known[0][:3]) else known
