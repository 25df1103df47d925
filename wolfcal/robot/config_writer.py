"""Write `calibrated_robot.yaml`: the robot config with the fitted tag mounts, so that a later fit can start from
them or hold them fixed (`--fix-tags`).

The input config is copied key by key (comments are not kept); each tag's `xyz` / `rpy` become
T_link_tag_new = T_link_tag @ Delta of the fit; relative paths (URDF, intrinsics) are made absolute so the file
works from wherever it is written.
"""

from __future__ import annotations

from pathlib import Path

from wolfcal.atomic import write_text_atomic
from wolfcal.geometry import matrix_to_rpy
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import Robot
from wolfcal.yamlfile import dump_yaml, read_yaml


def _absolute(base: Path, value: str) -> str:
    path = Path(value).expanduser()
    return str(path if path.is_absolute() else (base / path).resolve())


def calibrated_config(robot: Robot, corrections: Corrections) -> dict:
    """The robot config's data with fitted tag mounts and absolute paths."""
    source = robot.config.path
    data = read_yaml(source, "robot config")
    base = source.parent
    data["urdf"] = _absolute(base, data["urdf"])
    if isinstance(data.get("camera"), dict) and data["camera"].get("intrinsics"):
        data["camera"]["intrinsics"] = _absolute(base, data["camera"]["intrinsics"])
    for camera in data.get("external_cameras") or []:
        if isinstance(camera, dict) and camera.get("intrinsics"):
            camera["intrinsics"] = _absolute(base, camera["intrinsics"])
    for tag in data.get("tags") or []:
        if int(tag["id"]) in corrections.tags:
            T_link_tag = robot.T_link_tag(int(tag["id"]), corrections)
            tag["xyz"] = [float(f"{v:.9g}") for v in T_link_tag[:3, 3]]
            tag["rpy"] = [float(f"{v:.9g}") for v in matrix_to_rpy(T_link_tag[:3, :3])]
    return data


def write_calibrated_config(robot: Robot, corrections: Corrections, path: Path) -> None:
    """Write the calibrated robot config (see the module docstring) atomically."""
    header = (
        f"# {robot.config.name}: robot config of {robot.config.path} with the tag mounts fitted by wolfcal fit.\n"
        "# Use it as --robot for a later fit (add --fix-tags to hold these mounts).\n"
    )
    body = dump_yaml(calibrated_config(robot, corrections), sort_keys=False, width=120, default_flow_style=None)
    write_text_atomic(path, header + body)
