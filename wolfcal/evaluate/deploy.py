"""Files a team deploys to its robot: the team's own formats, URDFs, and wolfcal's records of the corrections.

Every file holds the new total calibration (the robot's present calibration with the fitted parameters replaced),
never the change. `DEPLOY_TABLE` says what each holds and where it goes on a Wolfgang (bit-bots/bitbots_main):
- `bitbots_extrinsic_calibration.yaml`: the camera correction's rotation for the team's extrinsic calibration node
  (`io.team_formats`), the IMU block copied unchanged from the present calibration (0 without one);
- `wolfgang_hardware_interface_offsets.yaml`: the encoder offsets as the hardware interface's per-joint
  `joint_offset`;
- `calibrated.urdf` / `calibrated_folded.urdf`: the model with every correction, for stacks without the team's
  nodes (offsets as `<calibration rising>`, or folded into the joint origins);
- `joint_offsets.yaml`, `camera_correction.yaml`: wolfcal's records (degrees and ticks; the camera correction with
  its translation), which `--current` reads back.
The camera correction is not written as a static-transform command: the team's node already publishes that
transform, and elsewhere calibrated(_folded).urdf carries it; two publishers of one transform fight.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from scipy.spatial.transform import Rotation

from wolfcal.atomic import remove_output, write_text_atomic
from wolfcal.encoders import RAD_PER_TICK
from wolfcal.geometry import matrix_to_rpy, transform_from_twist_params
from wolfcal.io.current import CAMERA_CORRECTION_FILE, JOINT_OFFSETS_FILE, CurrentCalibration, optical_rotation
from wolfcal.io.team_formats import EXTRINSIC_FILE, HARDWARE_FILE, euler_offsets, extrinsic_text, hardware_offsets_text
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import Robot
from wolfcal.robot.urdf_writer import write_calibrated_urdf
from wolfcal.yamlfile import dump_yaml

TRANSLATION_WARN_M = 1e-3  # a camera translation beyond this is lost by the rotation-only team file [m]

# (file, what it holds, where it goes on a Wolfgang running bit-bots/bitbots_main)
DEPLOY_TABLE = (
    (EXTRINSIC_FILE, "camera rotation correction (offset_x/y/z [rad], R = Rz Ry Rx) for the extrinsic calibration "
     "node; IMU block unchanged from --current (0 without)",
     "bitbots_misc/bitbots_extrinsic_calibration/config/<ROBOT_NAME>.yaml"),
    (HARDWARE_FILE, "encoder offsets as per-joint joint_offset [rad] (q_used = q_read + joint_offset)",
     "bitbots_lowlevel/bitbots_ros_control/config/wolfgang.yaml: each value into device_info.<joint>.joint_offset"),
    ("calibrated.urdf", "the input URDF with every correction: frames in <origin>, offsets as <calibration rising>",
     "not with the two files above (they apply the same corrections); for tools that read <calibration>"),
    ("calibrated_folded.urdf", "the same model with each offset folded into its joint's <origin>",
     "robot_description of a stack without the team's nodes, instead of the two files above"),
    (JOINT_OFFSETS_FILE, "wolfcal's record of the offsets (degrees, servo ticks)", "kept; --current reads it"),
    (CAMERA_CORRECTION_FILE, "wolfcal's record of the camera correction, translation included",
     "kept; --current reads it"),
)  # fmt: skip
DEPLOY_FILES = tuple(name for name, _, _ in DEPLOY_TABLE)


def camera_correction(robot: Robot, corrections: Corrections) -> dict:
    """T_uncalibrated_calibrated of the camera frame: translation [m], rotation as a quaternion and as URDF rpy
    [rad], and the team file's offsets of the optical frames [rad]."""
    frame = robot.config.head_camera().frame
    parent = f"{frame}_uncalibrated"
    T = transform_from_twist_params(corrections.frames.get(robot.camera_joint, np.zeros(6)))
    x, y, z = (float(v) for v in T[:3, 3])
    qx, qy, qz, qw = (float(v) for v in Rotation.from_matrix(T[:3, :3]).as_quat())
    roll, pitch, yaw = (float(v) for v in matrix_to_rpy(T[:3, :3]))
    ox, oy, oz = euler_offsets(optical_rotation(robot, corrections))
    return {
        "meaning": f"pose of the calibrated '{frame}' in the frame where the input URDF puts the camera "
        f"('{parent}'): p_{parent} = T @ p_{frame}. Lengths in metres, angles in radians.",
        "parent_frame": parent,
        "child_frame": frame,
        "translation": {"x": x, "y": y, "z": z},
        "rotation": {"x": qx, "y": qy, "z": qz, "w": qw},
        "rpy": [roll, pitch, yaw],
        "bitbots_offsets": {"offset_x": ox, "offset_y": oy, "offset_z": oz},
    }


def listed_offsets(corrections: Corrections, present: CurrentCalibration | None, joint_names: list[str]) -> dict:
    """joint -> (offset [rad], note) of the joints the deploy files list, in the robot's joint order: every offset
    of the model except a present 0 left as it was."""
    before = present.corrections.offsets if present is not None else {}
    out = {}
    for name in joint_names:
        if name not in corrections.offsets:
            continue
        value = float(corrections.offsets[name])
        unchanged = name in before and before[name] == value
        if unchanged and value == 0.0:
            continue
        out[name] = (value, "present value, not changed" if unchanged else "")
    return out


def joint_offsets_text(offsets: dict[str, tuple[float, str]]) -> str:
    """wolfcal's joint_offsets.yaml: offsets [rad] with degrees and servo ticks as comments."""
    lines = [
        "# Encoder offsets (totals): q_used = q_read + offset [rad] (add on read, subtract on write).",
        "# Joints not listed have no offset.",
        "joint_offsets:" + ("" if offsets else " {}"),
    ]
    for name, (value, note) in offsets.items():
        lines.append(f"  {name}: {value:.9g}  # {np.rad2deg(value):+.3f} deg, {value / RAD_PER_TICK:+.1f} ticks"
                     + (f"; {note}" if note else ""))  # fmt: skip
    return "\n".join(lines) + "\n"


def team_extrinsic_text(robot: Robot, corrections: Corrections, present: CurrentCalibration | None) -> str:
    """bitbots_extrinsic_calibration.yaml: the camera block from the model, the IMU block from `present`."""
    camera = euler_offsets(optical_rotation(robot, corrections))
    imu = present.imu if present is not None else None
    imu_note = (
        f"unchanged from {', '.join(present.sources)}"
        if imu is not None and present is not None
        else "0: not calibrated here and no present value given (--current); put the robot's own values here"
    )
    return extrinsic_text(camera, imu, "camera correction fitted by wolfcal (total)", imu_note)


def deploy_warnings(robot: Robot, corrections: Corrections, present: CurrentCalibration | None) -> list[str]:
    """What the team's formats cannot hold, and IMU values that are not the robot's."""
    warnings = []
    if robot.config.camera is not None:
        t = corrections.frames.get(robot.camera_joint, np.zeros(6))[:3]
        if np.linalg.norm(t) > TRANSLATION_WARN_M:
            warnings.append(
                f"The camera correction moves the camera by {np.linalg.norm(t) * 1000:.1f} mm ({t[0] * 1000:+.1f}, "
                f"{t[1] * 1000:+.1f}, {t[2] * 1000:+.1f} mm), which {EXTRINSIC_FILE} cannot hold (rotation only): "
                "on the team's stack that part is lost; calibrated_folded.urdf holds it."
            )
    if present is None or present.imu is None:
        warnings.append(f"{EXTRINSIC_FILE}: the IMU block is 0 (no present value given with --current); copy the "
                        "robot's own IMU offsets into it before deploying.")  # fmt: skip
    return warnings


def write_deploy_files(
    robot: Robot, corrections: Corrections, out_dir: Path, present: CurrentCalibration | None = None
) -> list[Path]:
    """Write the deploy files (DEPLOY_FILES) of the model `corrections` (totals) atomically; returns their paths.
    `present`: the robot's present calibration (its IMU block is copied; offsets it holds unchanged are noted)."""
    urdf, model = robot.config.urdf, robot.model
    paths = {name: out_dir / name for name in DEPLOY_FILES}
    offsets = listed_offsets(corrections, present, robot.joint_names)
    write_calibrated_urdf(urdf, model, corrections, paths["calibrated.urdf"], fold_offsets=False)
    write_calibrated_urdf(urdf, model, corrections, paths["calibrated_folded.urdf"], fold_offsets=True)
    write_text_atomic(paths[JOINT_OFFSETS_FILE], joint_offsets_text(offsets))
    write_text_atomic(paths[HARDWARE_FILE], hardware_offsets_text(offsets, present.mounting if present else {}))
    if robot.config.camera is None:
        return [p for name, p in paths.items() if name not in (EXTRINSIC_FILE, CAMERA_CORRECTION_FILE)]
    write_text_atomic(paths[EXTRINSIC_FILE], team_extrinsic_text(robot, corrections, present))
    write_text_atomic(paths[CAMERA_CORRECTION_FILE],
                      dump_yaml(camera_correction(robot, corrections), sort_keys=False, width=200))  # fmt: skip
    return list(paths.values())


def remove_deploy_files(out_dir: Path) -> list[Path]:
    """Delete deploy files a previous run left in out_dir (a refused calibration must not look deployable)."""
    return [out_dir / name for name in DEPLOY_FILES if remove_output(out_dir / name)]


def deploy_lines(record: dict, out_dir: Path) -> list[str]:
    """The console's list of the written deploy files: name, what it holds, where it goes."""
    if not record["written"] or not record["files"]:
        return []
    width = max(len(name) for name in record["files"])
    rows = [(n, h, w) for n, h, w in DEPLOY_TABLE if n in record["files"]]
    return [f"deploy files in {out_dir}:"] + [f"  {n:<{width}}  {h}\n  {'':<{width}}  -> {w}" for n, h, w in rows]


def write_or_withhold_deploy_files(
    robot: Robot,
    corrections: Corrections,
    out_dir: Path,
    refused: str | None,
    override: bool,
    present: CurrentCalibration | None = None,
) -> dict:
    """Write the deploy files of the model `corrections` (totals), or (refused: the verdict's reason, without the
    override --deploy-worse) remove any an earlier run left. Returns metrics.json's 'deploy' record: written,
    forced, files (names in out_dir), reason, warnings (what the team's formats cannot hold)."""
    if refused and not override:
        removed = remove_deploy_files(out_dir)
        earlier = f" ({len(removed)} file(s) of an earlier run removed)" if removed else ""
        return {
            "written": False,
            "forced": False,
            "files": [],
            "reason": f"{refused} The deploy files were not written{earlier}; --deploy-worse writes them anyway.",
            "warnings": [],
        }
    paths = write_deploy_files(robot, corrections, out_dir, present)
    return {
        "written": True,
        "forced": bool(refused),
        "files": [p.name for p in paths],
        "reason": f"written despite the verdict (--deploy-worse): {refused}" if refused else None,
        "warnings": deploy_warnings(robot, corrections, present),
    }
