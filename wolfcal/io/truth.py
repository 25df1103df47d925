"""A simulation's truth files beside its capture (FILE.truth.yaml, FILE.truth.urdf), and the true poses of simulated
external cameras kept in FILE.truth.yaml under `external_cameras`.

Here (io), not in the simulator, because evaluation and the emulated capture read what the simulator wrote.

`external_cameras: {<name>: {T_base_camera: 4x4 list, meaning: ...}}`: the pose of the camera's optical frame
(z forward, x right, y down) in the robot's base frame, p_base = T_base_camera @ p_camera [m]. One placement per
capture file.

`floor_tags: {<id>: {x, y, yaw}}`: the true place of each floor tag lying face up in the true floor frame (the plane of
the standing soles, `wolfcal.robot.floor`) [m, rad], as `wolfcal simulate --floor` writes it.

`field_pose: {x, y, yaw}`: where the robot's floor frame truly stands on the field (field frame: origin at the centre
mark, x toward the opponent goal) [m, m, rad], as `wolfcal simulate --system field` writes it.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.yamlfile import read_yaml

MEANING = (
    "pose of the external camera's optical frame (z forward, x right, y down) in the robot's base frame: "
    "p_base = T_base_camera @ p_camera [m]; one placement per capture file"
)


def truth_paths(capture: Path) -> tuple[Path, Path]:
    """FILE.truth.yaml (true corrections, cameras, settings) and FILE.truth.urdf beside the capture FILE.mcap."""
    stem = capture.with_suffix("")
    return Path(f"{stem}.truth.yaml"), Path(f"{stem}.truth.urdf")


def external_truth_entry(T_base_camera: np.ndarray) -> dict:
    """The YAML entry of one external camera's true pose."""
    return {"T_base_camera": [[float(v) for v in row] for row in np.asarray(T_base_camera)], "meaning": MEANING}


def _truth_section(path: Path, key: str) -> object:
    """The `key` section of a simulation's FILE.truth.yaml, or None when the file has none."""
    data = read_yaml(path, "simulation truth", "give the .truth.yaml written beside a simulated capture")
    return data.get(key) if isinstance(data, dict) else None


def load_external_truth(path: str | Path) -> dict[str, np.ndarray]:
    """camera name -> (4, 4) true T_base_camera from a simulation's FILE.truth.yaml (empty for a head-only one)."""
    path = Path(path)
    cameras = _truth_section(path, "external_cameras")
    if cameras is None:
        return {}
    if not isinstance(cameras, dict):
        raise WolfcalError(f"{path}: 'external_cameras' must map camera names to {{T_base_camera, meaning}}")
    poses = {}
    for name, entry in cameras.items():
        T = np.asarray(entry.get("T_base_camera") if isinstance(entry, dict) else None, dtype=float)
        if T.shape != (4, 4) or not np.all(np.isfinite(T)) or not np.allclose(T[3], [0, 0, 0, 1]):
            raise WolfcalError(f"{path}: 'external_cameras.{name}.T_base_camera' must be a 4x4 rigid transform")
        poses[str(name)] = T
    return poses


def load_floor_places(path: str | Path) -> dict[int, np.ndarray]:
    """floor tag id -> true (x, y, yaw) [m, rad] from a simulation's FILE.truth.yaml (empty when it has none)."""
    path = Path(path)
    tags = _truth_section(path, "floor_tags")
    if tags is None:
        return {}
    places = {}
    for tag_id, entry in tags.items() if isinstance(tags, dict) else [(None, None)]:
        place = [entry.get(k) if isinstance(entry, dict) else None for k in ("x", "y", "yaw")]
        if not isinstance(tag_id, int) or not all(isinstance(v, (int, float)) for v in place):
            raise WolfcalError(f"{path}: 'floor_tags' must map floor tag ids to {{x, y, yaw}} (m, rad)")
        places[tag_id] = np.array(place, dtype=float)
    return places


def load_field_pose(path: str | Path) -> np.ndarray | None:
    """The robot's true place (x, y, yaw) [m, m, rad] on the field from a simulation's FILE.truth.yaml (`field_pose`,
    as `wolfcal simulate --system field` writes it); None when it has none."""
    path = Path(path)
    pose = _truth_section(path, "field_pose")
    if pose is None:
        return None
    values = [pose.get(k) if isinstance(pose, dict) else None for k in ("x", "y", "yaw")]
    if not all(isinstance(v, (int, float)) and not isinstance(v, bool) and np.isfinite(v) for v in values):
        raise WolfcalError(f"{path}: 'field_pose' must be {{x, y, yaw}} (m, m, rad), found {pose!r}")
    return np.array(values, dtype=float)
