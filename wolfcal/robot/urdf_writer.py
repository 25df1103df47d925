"""Write a calibrated URDF by editing the input URDF's XML, so everything else in it (meshes, transmissions,
gazebo tags, comments) is kept as it was.

- frame corrections: origin_new = origin @ Delta, written back into `<origin xyz rpy>`;
- encoder offsets: `<calibration rising="offset"/>` (ROS convention), or with `fold_offsets=True` folded into the
  joint origin as origin @ Rot(axis, offset) for tools that ignore `<calibration>` (robot_state_publisher does).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from lxml import etree

from wolfcal.atomic import write_bytes_atomic
from wolfcal.errors import WolfcalError
from wolfcal.geometry import (
    axis_angle_matrix,
    make_transform,
    matrix_to_rpy,
    transform_from_twist_params,
)
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.kinematics import KinematicModel
from wolfcal.robot.urdf_xml import read_urdf_xml


def _fmt(values) -> str:
    return " ".join(f"{float(v):.17g}" for v in values)


def calibrated_urdf_bytes(
    urdf_path: str | Path, model: KinematicModel, corrections: Corrections, fold_offsets: bool = False
) -> bytes:
    """The input URDF with `corrections` applied, as bytes."""
    urdf_path = Path(urdf_path)
    tree = read_urdf_xml(urdf_path)
    joints = {j.get("name"): j for j in tree.getroot().iter("joint")}
    touched = set(corrections.frames) | {j for j, v in corrections.offsets.items() if fold_offsets and v != 0.0}
    for name in touched:
        if name not in joints or name not in model.joints:
            raise WolfcalError(f"{urdf_path}: joint '{name}' of the calibration is not in this URDF")
        joint = model.joints[name]
        T = joint.T_parent_origin
        if name in corrections.frames:
            T = T @ transform_from_twist_params(corrections.frames[name])
        if fold_offsets and corrections.offsets.get(name, 0.0) != 0.0:
            R = axis_angle_matrix(joint.axis, np.array([corrections.offsets[name]]))[0]
            T = T @ make_transform(R, np.zeros(3))
        origin = joints[name].find("origin")
        if origin is None:
            origin = etree.SubElement(joints[name], "origin")
        origin.set("xyz", _fmt(T[:3, 3]))
        origin.set("rpy", _fmt(matrix_to_rpy(T[:3, :3])))
    if not fold_offsets:
        for name, offset in corrections.offsets.items():
            if name not in joints:
                raise WolfcalError(f"{urdf_path}: joint '{name}' of the calibration is not in this URDF")
            element = joints[name].find("calibration")
            if element is None:
                element = etree.SubElement(joints[name], "calibration")
            element.set("rising", f"{float(offset):.17g}")
    return etree.tostring(tree, xml_declaration=True, encoding="utf-8")


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

