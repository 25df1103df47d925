"""Write a calibrated URDF by editing the input URDF's text, so everything else in it (meshes, transmissions,
gazebo tags, comments, line endings) is kept byte for byte (`wolfcal.robot.urdf_splice`).

The written URDF is the model wolfcal fitted, read the way URDF tools read it:
- frame corrections: origin_new = origin @ Delta, written back into `<origin xyz rpy>`; the correction of a frame the
  robot config adds (a body-axes camera's optical frame) goes into the URDF joint above it, conjugated so that the
  frame ends up where the model puts it;
- encoder offsets: `<calibration rising="offset"/>` on the robot's own joints (ROS convention: q_model = q_measured
  + offset); a mimic joint follows its master's calibrated value, value = multiplier * (q_master + offset) + mimic
  offset, so it carries no calibration of its own;
- with `fold_offsets=True` the offsets are folded into the joint origins instead, for tools that ignore
  `<calibration>` (robot_state_publisher does): origin @ Motion(axis, offset), and a mimic joint's origin @
  Motion(axis, multiplier * master's offset).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wolfcal.atomic import write_bytes_atomic
from wolfcal.errors import WolfcalError
from wolfcal.geometry import axis_angle_matrix, invert_transform, matrix_to_rpy, transform_from_twist_params
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.kinematics import JointModel, KinematicModel
from wolfcal.robot.urdf_splice import JointEdit, apply_joint_edits, robot_joints
from wolfcal.robot.urdf_xml import read_urdf_xml


def _fmt(values) -> str:
    return " ".join(f"{float(v):.17g}" for v in values)


def joint_motion(joint: JointModel, value: float) -> np.ndarray:
    """(4, 4) motion of `joint` by `value` [rad or m] about/along its axis."""
    T = np.eye(4)
    if joint.type == "prismatic":
        T[:3, 3] = value * joint.axis
    else:
        T[:3, :3] = axis_angle_matrix(joint.axis, np.array([value]))[0]
    return T


def calibrated_origins(model: KinematicModel, corrections: Corrections, fold_offsets: bool) -> dict[str, np.ndarray]:
    """The new <origin> (4, 4) of every URDF joint whose origin changes: frame corrections (those of added frames
    moved to the URDF joint above them) and, with `fold_offsets`, the offsets of joints and of their mimic joints."""
    factors: dict[str, list[np.ndarray]] = {}  # per URDF joint: what its origin is multiplied by, in order
    for name, delta in corrections.frames.items():
        if name not in model.joints:
            raise WolfcalError(f"{model.source}: joint '{name}' of the calibration is not in this URDF")
        joint, D = model.joints[name], transform_from_twist_params(delta)
        if not joint.in_urdf:  # T_u @ (T_s @ D @ T_s^-1) @ T_s = T_u @ T_s @ D: the added frame lands as modelled
            target = model.urdf_parent_joint(joint.parent)
            if target.type != "fixed":
                raise WolfcalError(
                    f"{model.source}: the correction of '{name}' cannot be written: '{joint.parent}' "
                    f"hangs from the movable joint '{target.name}' (attach it by a fixed joint)"
                )
            D = joint.T_parent_origin @ D @ invert_transform(joint.T_parent_origin)
            name = target.name
        factors.setdefault(name, []).append(D)
    if fold_offsets:
        for joint in model.joints.values():
            master = joint.mimic[0] if joint.mimic is not None else joint.name
            offset = corrections.offsets.get(master, 0.0) if joint.actuated or joint.mimic is not None else 0.0
            if offset != 0.0:
                factor = joint.mimic[1] if joint.mimic is not None else 1.0
                factors.setdefault(joint.name, []).append(joint_motion(joint, factor * offset))
    out = {}
    for name, Ts in factors.items():
        T = model.joints[name].T_parent_origin
        for factor_T in Ts:
            T = T @ factor_T
        out[name] = T
    return out


def calibrated_urdf_bytes(
    urdf_path: str | Path, model: KinematicModel, corrections: Corrections, fold_offsets: bool = False
) -> bytes:
    """The input URDF with `corrections` applied (module docstring), as bytes."""
    urdf_path = Path(urdf_path)
    read_urdf_xml(urdf_path)  # a well-formed URDF: the one strict parser
    raw = urdf_path.read_bytes()
    try:
        text = raw.decode("utf-8")
    except UnicodeDecodeError:
        raise WolfcalError(f"{urdf_path}: the URDF is not UTF-8 text; save it as UTF-8") from None
    in_file = robot_joints(text)
    edits: dict[str, JointEdit] = {}
    for name, T in calibrated_origins(model, corrections, fold_offsets).items():
        edits[name] = JointEdit(origin={"xyz": _fmt(T[:3, 3]), "rpy": _fmt(matrix_to_rpy(T[:3, :3]))})
    if not fold_offsets:
        for name, offset in corrections.offsets.items():
            edits.setdefault(name, JointEdit()).calibration = {"rising": f"{float(offset):.17g}"}
    for name in edits:
        if name not in in_file or name not in model.joints:
            raise WolfcalError(f"{urdf_path}: joint '{name}' of the calibration is not in this URDF")
    return apply_joint_edits(text, edits).encode("utf-8")


def write_calibrated_urdf(
    urdf_path: str | Path,
    model: KinematicModel,
    corrections: Corrections,
    out_path: str | Path,
    fold_offsets: bool = False,
) -> None:
    """Write the calibrated URDF atomically (never over the input)."""
    if Path(out_path).resolve() == Path(urdf_path).resolve():
        raise WolfcalError(f"{out_path}: refusing to overwrite the input URDF; choose another output folder")
    write_bytes_atomic(out_path, calibrated_urdf_bytes(urdf_path, model, corrections, fold_offsets))
