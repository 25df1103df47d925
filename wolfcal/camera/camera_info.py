"""ROS camera_info YAML (the format of camera_calibration / camera_info_manager) <-> CameraModel."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wolfcal.atomic import write_text_atomic
from wolfcal.camera.model import CameraModel
from wolfcal.camera.validate import YAML_FIELDS, checked_camera, numbers
from wolfcal.errors import WolfcalError
from wolfcal.yamlfile import dump_yaml, read_yaml


def _matrix(data: dict, key: str, rows: int, cols: int, path: Path) -> list:
    """The 'data' list of a {rows, cols, data} block; declared rows/cols must be the matrix's."""
    entry = data.get(key)
    if not isinstance(entry, dict) or "data" not in entry:
        raise WolfcalError(f"{path}: '{key}' must be a mapping with 'rows', 'cols' and 'data'")
    for name, expected in (("rows", rows), ("cols", cols)):
        if expected and name in entry and entry[name] != expected:
            raise WolfcalError(f"{path}: '{key}.{name}' is {entry[name]!r}, a {rows}x{cols} matrix has {expected}")
    values = entry["data"]
    if not isinstance(values, list):
        raise WolfcalError(f"{path}: '{key}.data' must be a list of numbers, found {values!r}")
    if rows and cols and len(values) != rows * cols:
        raise WolfcalError(f"{path}: '{key}.data' must have {rows * cols} numbers ({rows}x{cols}), found {len(values)}")
    return values


def load_camera_info(path: str | Path) -> CameraModel:
    """Read a ROS camera_info YAML file; errors name the file and the key (see `checked_camera`)."""
    path = Path(path)
    data = read_yaml(path, "camera_info file")
    if not isinstance(data, dict):
        raise WolfcalError(f"{path}: expected a camera_info mapping")
    for key in ("image_width", "image_height", "camera_matrix", "distortion_coefficients"):
        if key not in data:
            raise WolfcalError(f"{path}: missing key '{key}'")
    K = _matrix(data, "camera_matrix", 3, 3, path)
    D = _matrix(data, "distortion_coefficients", 0, 0, path)
    for key, rows, cols in (("rectification_matrix", 3, 3), ("projection_matrix", 3, 4)):
        if key in data:
            numbers(str(path), f"{key}.data", _matrix(data, key, rows, cols, path))
    model = data.get("distortion_model", "plumb_bob")
    name = str(data.get("camera_name", "camera"))
    return checked_camera(str(path), data["image_width"], data["image_height"], K, D, model, YAML_FIELDS, name)


def camera_info_dict(camera: CameraModel) -> dict:
    """CameraModel -> the camera_info YAML mapping (rectification identity, projection = K | 0)."""
    P = np.zeros((3, 4))
    P[:, :3] = camera.K

    def block(rows: int, cols: int, values) -> dict:
        return {"rows": rows, "cols": cols, "data": [float(v) for v in np.asarray(values).ravel()]}

    return {
        "image_width": int(camera.width),
        "image_height": int(camera.height),
        "camera_name": camera.name,
        "camera_matrix": block(3, 3, camera.K),
        "distortion_model": camera.distortion_model,
        "distortion_coefficients": block(1, len(camera.D), camera.D),
        "rectification_matrix": block(3, 3, np.eye(3)),
        "projection_matrix": block(3, 4, P),
    }


def save_camera_info(camera: CameraModel, path: str | Path) -> None:
    """Write a ROS camera_info YAML atomically."""
    write_text_atomic(path, dump_yaml(camera_info_dict(camera), sort_keys=False))
