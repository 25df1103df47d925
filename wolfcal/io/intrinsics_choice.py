"""The intrinsics of each image of one camera in a capture, at the image's own resolution.

First that applies: the `--intrinsics` override (head camera only), the camera's CameraInfo stamped nearest to the
image (binning applied, ROS convention; an uncalibrated one, K all zero, counts as none), the camera's `intrinsics`
in the robot config. Any of them at another resolution than the image is scaled to it (same aspect ratio only).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wolfcal.camera.camera_info import load_camera_info
from wolfcal.camera.model import MODELS, CameraModel
from wolfcal.config import RobotConfig
from wolfcal.errors import WolfcalError
from wolfcal.observations import HEAD_CAMERA

InfoModel = tuple[CameraModel, tuple[int, int]]  # (full-resolution model, binning) of a CameraInfo


def camera_info_model(path: Path, topic: str, message) -> InfoModel | None:
    """(full-resolution model, binning) of a decoded CameraInfo; None for an uncalibrated one (K all zero)."""
    K = np.asarray(message.k, dtype=float).reshape(3, 3)
    if not np.any(K) or message.width == 0 or message.height == 0:
        return None
    model = message.distortion_model or "plumb_bob"
    if model not in MODELS:
        raise WolfcalError(
            f"{path}: CameraInfo on {topic} uses distortion model {model!r}, wolfcal knows {', '.join(MODELS)}; "
            "calibrate the camera with a supported model (`wolfcal intrinsics`) and give its YAML"
        )
    camera = CameraModel(int(message.width), int(message.height), K, np.asarray(message.d, float), model)
    return camera, (max(int(message.binning_x), 1), max(int(message.binning_y), 1))


class IntrinsicsChooser:
    """Chooses and scales the intrinsics of each image of one camera, caching one model per source and size."""

    def __init__(self, path: Path, config: RobotConfig, camera: str, override: CameraModel | None) -> None:
        self.path, self.config, self.camera = path, config, camera
        self.override = override if camera == HEAD_CAMERA else None  # --intrinsics is the head camera's
        self.cache: dict[tuple, CameraModel] = {}
        self.fallback: CameraModel | None = None

    def for_image(self, size: tuple[int, int], info: InfoModel | None) -> CameraModel:
        """Intrinsics for an image of `size` (width, height) given the CameraInfo nearest to it (or None)."""
        if self.override is not None:
            base, binning, what = self.override, (1, 1), "the --intrinsics"
        elif info is not None:
            base, binning, what = info[0], info[1], f"the CameraInfo of camera '{self.camera}'"
        else:
            base, binning, what = self._config_intrinsics(), (1, 1), "the robot config's"
        key = (id(base), binning, size)
        if key not in self.cache:
            self.cache[key] = self._at_size(base, binning, size, what)
        return self.cache[key]

    def _config_intrinsics(self) -> CameraModel:
        if self.fallback is None:
            intrinsics, key = self.config.camera_intrinsics(self.camera)
            if intrinsics is None:
                info_topic = self.config.camera_topics(self.camera)[1]
                hint = "pass --intrinsics FILE or " if self.camera == HEAD_CAMERA else ""
                raise WolfcalError(
                    f"{self.path}: no CameraInfo on {info_topic} and no intrinsics for camera '{self.camera}'; "
                    f"{hint}set '{key}' in {self.config.path}"
                )
            self.fallback = load_camera_info(intrinsics)
        return self.fallback

    def _at_size(self, base: CameraModel, binning: tuple[int, int], size: tuple[int, int], what: str) -> CameraModel:
        if binning != (1, 1):
            bx, by = binning
            base = base.scaled(1 / bx, 1 / by, base.width // bx, base.height // by)
        width, height = size
        if (base.width, base.height) == (width, height):
            return base
        sx, sy = width / base.width, height / base.height
        if abs(sx / sy - 1) > 0.01:
            fix = "pass --intrinsics FILE" if self.camera == HEAD_CAMERA else "set the camera's 'intrinsics' to a file"
            raise WolfcalError(
                f"{self.path}: {what} intrinsics are for {base.width}x{base.height} px images, the images of "
                f"camera '{self.camera}' are {width}x{height} px (another aspect ratio); {fix} calibrated for "
                "these images"
            )
        return base.scaled(sx, sy, width, height)
