"""The intrinsics of each image of one camera in a capture, at the image's own resolution.

First that applies: the `--intrinsics` override (head camera only), the camera's CameraInfo stamped nearest to the
image (binning applied, ROS convention; an uncalibrated one, K all zero, counts as none), the camera's `intrinsics`
in the robot config. Any of them at another resolution than the image is scaled to it (by a whole binning factor
only). Every source is validated by `wolfcal.camera.validate` (errors name the file, topic and field).
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wolfcal.camera.camera_info import load_camera_info
from wolfcal.camera.model import CameraModel
from wolfcal.camera.validate import MESSAGE_FIELDS, YAML_FIELDS, check_image_size, checked_camera
from wolfcal.config import RobotConfig
from wolfcal.errors import WolfcalError
from wolfcal.observations import HEAD_CAMERA

InfoModel = tuple[CameraModel, tuple[int, int]]  # (full-resolution model, binning) of a CameraInfo


def camera_info_model(path: Path, topic: str, message) -> InfoModel | None:
    """(full-resolution model, binning) of a decoded CameraInfo; None for an uncalibrated one (K all zero).
    WolfcalError naming file, topic and field when it is not valid (`checked_camera`)."""
    if not np.any(np.asarray(message.k, dtype=float)) or message.width == 0 or message.height == 0:
        return None
    model = message.distortion_model or "plumb_bob"
    where = f"{path}: CameraInfo on {topic}"
    camera = checked_camera(where, message.width, message.height, message.k, message.d, model, MESSAGE_FIELDS)
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
        image_topic, info_topic = self.config.camera_topics(self.camera)
        images = f"the images of camera '{self.camera}' ({image_topic})"
        override = f"pass --intrinsics FILE calibrated for {images}"
        if self.override is not None:
            base, binning = self.override, (1, 1)
            what = (f"{self.path}: the --intrinsics", YAML_FIELDS, override)
        elif info is not None:
            base, binning = info[0], info[1]
            fix = override if self.camera == HEAD_CAMERA else (
                f"record the camera_info of {images} at their resolution, or record none and set "
                f"'{self.config.camera_intrinsics(self.camera)[1]}' in {self.config.path}"
            )  # fmt: skip
            what = (f"{self.path}: CameraInfo on {info_topic}", MESSAGE_FIELDS, fix)
        else:
            base, binning = self._config_intrinsics(), (1, 1)
            file, key = self.config.camera_intrinsics(self.camera)
            fix = f"set '{key}' in {self.config.path} to a file calibrated for {images}"
            fix = f"{override}, or {fix}" if self.camera == HEAD_CAMERA else fix
            what = (f"{file} (intrinsics of camera '{self.camera}' for {self.path})", YAML_FIELDS, fix)
        cache_key = (id(base), binning, size)
        if cache_key not in self.cache:
            self.cache[cache_key] = self._at_size(base, binning, size, what)
        return self.cache[cache_key]

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

    def _at_size(
        self, base: CameraModel, binning: tuple[int, int], size: tuple[int, int], what: tuple[str, dict[str, str], str]
    ) -> CameraModel:
        """`base` binned, then scaled to `size`; `what` = (where, field names, advice) for the error."""
        if binning != (1, 1):
            bx, by = binning
            base = base.scaled(1 / bx, 1 / by, base.width // bx, base.height // by)
        width, height = size
        if (base.width, base.height) == (width, height):
            return base
        where, fields, advice = what
        check_image_size(where, fields, base, size, advice)
        return base.scaled(width / base.width, height / base.height, width, height)
