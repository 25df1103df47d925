"""Plain data read from and written to capture files.

A sample is one still moment: the joint angles the encoders reported (radians, `q_measured`, before any calibration
offset), the camera image as encoded bytes (decoded on demand: hundreds of full-resolution images do not fit in
memory at once), and the intrinsics at the image's own resolution (binning already applied).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.errors import WolfcalError


@dataclass
class Sample:
    stamp_ns: int
    joint_names: list[str]
    positions: np.ndarray  # (J,) measured joint angles [rad]
    image_data: bytes  # encoded image (png or jpeg)
    image_format: str  # 'png' | 'jpeg'
    camera: CameraModel  # intrinsics at this image's resolution
    velocities: np.ndarray | None = None  # (J,) [rad/s]
    source: str = ""  # capture file the sample came from

    def image(self) -> np.ndarray:
        """Decoded image: (H, W) uint8 for mono, (H, W, 3) uint8 BGR for colour."""
        buffer = np.frombuffer(self.image_data, dtype=np.uint8)
        image = cv2.imdecode(buffer, cv2.IMREAD_UNCHANGED)
        if image is None:
            raise WolfcalError(f"{self.source}: the image of the sample at t={self.stamp_ns} ns cannot be decoded")
        return image

    def joint_positions(self, names: list[str]) -> np.ndarray:
        """Positions [rad] in the order of `names`; a clear error when a joint is missing."""
        index = {n: i for i, n in enumerate(self.joint_names)}
        missing = [n for n in names if n not in index]
        if missing:
            raise WolfcalError(
                f"{self.source}: joint state at t={self.stamp_ns} ns lacks joint(s) {', '.join(missing)}; "
                "record every joint of the robot config"
            )
        return self.positions[[index[n] for n in names]]


@dataclass
class Capture:
    path: Path
    samples: list[Sample]
    urdf_text: str | None = None  # URDF attached to the file
    robot_config_text: str | None = None  # robot config attached to the file
    skipped: list[str] = field(default_factory=list)  # why frames of a recording were not used
