"""ROS camera_info YAML (the format of camera_calibration / camera_info_manager) <-> CameraModel."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wolfcal.atomic import write_text_atomic
from wolfcal.camera.model import MODELS, CameraModel
from wolfcal.errors import WolfcalError
from wolfcal.yamlfile import dump_yaml, read_yaml


def _matrix(data: dict, key: str, rows: int, cols: int, path: Path) -> np.ndarray:
    entry = data.get(key)
    if not isinstance(entry, dict) or "data" not in entry:
        raise WolfcalError(f"{path}: '{key}' must be a mapping with 'rows', 'cols' and 'data'")
    values = np.asarray(entry["data"], dtype=float).ravel()
    if rows and cols and values.size != rows * cols:
        raise WolfcalError(f"{path}: '{key}.data' must have {rows * cols} numbers, found {values.size}")
    return values.reshape(rows, cols) if rows and cols else values


def load_camera_info(path: str | Path) -> CameraModel:
    """Read a ROS camera_info YAML file; errors name the file and the key."""
    path = Path(path)
    data = read_yaml(path, "camera_info file")
    if not isinstance(data, dict):
        raise WolfcalError(f"{path}: expected a camera_info mapping")
    for key in ("image_width", "image_height", "camera_matrix", "distortion_coefficients"):
        if key not in data:
            raise WolfcalError(f"{path}: missing key '{key}'")
    model = data.get("distortion_model", "plumb_bob")
    if model not in MODELS:
        raise WolfcalError(f"{path}: 'distortion_model' {model!r} is not one of {', '.join(MODELS)}")
    K = _matrix(data, "camera_matrix", 3, 3, path)
    D = _matrix(data, "distortion_coefficients", 0, 0, path)
    return CameraModel(
        int(data["image_width"]), int(data["image_height"]), K, D, model, str(data.get("camera_name", "camera"))
    )


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
