"""Files a team deploys to its robot: URDFs, per-joint encoder offsets, the camera correction as a static transform.

- `calibrated.urdf`: the input URDF with frame corrections in `<origin>` and encoder offsets as
  `<calibration rising="offset"/>` (ROS convention: q_model = q_measured + offset [rad]).
- `calibrated_folded.urdf`: the same model with each offset folded into its joint origin (origin * Rot(axis,
  offset)), for tools that ignore `<calibration>` (robot_state_publisher does); same forward kinematics for the same
  encoder readings.
- `joint_offsets.yaml`: offset per joint [rad] for a hardware interface that adds it on read and subtracts it on write.
- `camera_correction.yaml`: T_uncalibrated_calibrated, the pose of the calibrated optical frame in the optical frame
  of the input URDF (translation [m], quaternion x y z w, rpy [rad]), and the matching static_transform_publisher call.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from wolfcal.atomic import remove_output, write_text_atomic
from wolfcal.encoders import RAD_PER_TICK
from wolfcal.geometry import matrix_to_rpy, transform_from_twist_params
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import Robot
from wolfcal.robot.urdf_writer import write_calibrated_urdf
from wolfcal.yamlfile import dump_yaml

DEPLOY_FILES = ("calibrated.urdf", "calibrated_folded.urdf", "joint_offsets.yaml", "camera_correction.yaml")


def camera_correction(robot: Robot, corrections: Corrections) -> dict:
    """T_uncalibrated_calibrated of the camera's optical frame as a static-transform description: translation [m],
    rotation as a quaternion and as URDF rpy [rad]."""
    frame = robot.config.head_camera().frame
    parent = f"{frame}_uncalibrated"
    T = transform_from_twist_params(corrections.frames.get(robot.camera_joint, np.zeros(6)))
    x, y, z = (float(v) for v in T[:3, 3])
    qx, qy, qz, qw = (float(v) for v in Rotation.from_matrix(T[:3, :3]).as_quat())
    roll, pitch, yaw = (float(v) for v in matrix_to_rpy(T[:3, :3]))
    return {
        "meaning": f"pose of the calibrated '{frame}' in the optical frame where the input URDF puts the camera "
        f"('{parent}'): p_{parent} = T @ p_{frame}. Lengths in metres, angles in radians.",
        "parent_frame": parent,
        "child_frame": frame,
        "translation": {"x": x, "y": y, "z": z},
        "rotation": {"x": qx, "y": qy, "z": qz, "w": qw},
        "rpy": [roll, pitch, yaw],
        "static_transform_publisher": (
            f"ros2 run tf2_ros static_transform_publisher --x {x:.9g} --y {y:.9g} --z {z:.9g} "
            f"--qx {qx:.9g} --qy {qy:.9g} --qz {qz:.9g} --qw {qw:.9g} --frame-id {parent} --child-frame-id {frame}"
        ),
    }


def joint_offsets_text(robot: Robot, corrections: Corrections) -> str:
    """YAML of the estimated encoder offsets, with degrees and servo ticks as comments."""
    lines = [
        "# Encoder offsets estimated by wolfcal: q_used = q_read + offset [rad] (add on read, subtract on write).",
        "# Joints not listed were not calibrated: keep their offset at 0.",
        "joint_offsets:" + ("" if corrections.offsets else " {}"),
    ]
    for name in robot.joint_names:
        if name in corrections.offsets:
            value = float(corrections.offsets[name])
            lines.append(
                f"  {name}: {value:.9g}  # {np.rad2deg(value):+.3f} deg, {value / RAD_PER_TICK:+.1f} ticks"
            )
    return "\n".join(lines) + "\n"


def write_deploy_files(robot: Robot, corrections: Corrections, out_dir: Path) -> list[Path]:
    """Write the four deploy files atomically; returns their paths."""
    urdf, model = robot.config.urdf, robot.model
    paths = [out_dir / name for name in DEPLOY_FILES]
    write_calibrated_urdf(urdf, model, corrections, paths[0], fold_offsets=False)
    write_calibrated_urdf(urdf, model, corrections, paths[1], fold_offsets=True)
    write_text_atomic(paths[2], joint_offsets_text(robot, corrections))
    write_text_atomic(
        paths[3], dump_yaml(camera_correction(robot, corrections), sort_keys=False, width=200)
    )
    return paths


def remove_deploy_files(out_dir: Path) -> list[Path]:
    """Delete deploy files a previous run left in out_dir (a refused calibration must not look deployable)."""
    return [out_dir / name for name in DEPLOY_FILES if remove_output(out_dir / name)]


def write_or_withhold_deploy_files(
    robot: Robot, corrections: Corrections, out_dir: Path, refused: str | None, override: bool
) -> dict:
    """Write the deploy files, or (refused: the verdict's reason, without the override --deploy-worse) remove any
    an earlier run left. Returns metrics.json's 'deploy' record: written, forced, files (names in out_dir), reason.
    """
    if refused and not override:
        removed = remove_deploy_files(out_dir)
        earlier = f" ({len(removed)} file(s) of an earlier run removed)" if removed else ""
        return {
            "written": False,
            "forced": False,
            "files": [],
            "reason": f"{refused} The deploy files were not written{earlier}; --deploy-worse writes them anyway.",
        }
    paths = write_deploy_files(robot, corrections, out_dir)
    return {
        "written": True,
        "forced": bool(refused),
        "files": [p.name for p in paths],
        "reason": f"written despite the verdict (--deploy-worse): {refused}" if refused else None,
    }
