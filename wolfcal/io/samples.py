"""Plain data read from and written to capture files.

A sample is one still moment: the joint angles the encoders reported (radians, `q_measured`, before any calibration
offset) and the image of each camera that saw the moment: the head camera (`HEAD_CAMERA`) and/or external cameras
(by their config names). Images stay encoded bytes, decoded on demand (hundreds of full-resolution images do not fit
in memory at once), each with the intrinsics at its own resolution (binning already applied).
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import cv2
import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.errors import WolfcalError
from wolfcal.observations import HEAD_CAMERA

__all__ = ["HEAD_CAMERA", "Capture", "Sample", "SampleImage"]


@dataclass
class SampleImage:
    data: bytes  # encoded image (png or jpeg)
    format: str  # 'png' | 'jpeg'
    camera: CameraModel  # intrinsics at this image's resolution
    source: str = ""  # capture file and topic, for messages
    stamp_ns: int = 0  # header stamp of the image [ns]

    def decode(self) -> np.ndarray:
        """Decoded image: (H, W) uint8 for mono, (H, W, 3) uint8 BGR for colour."""
        image = cv2.imdecode(np.frombuffer(self.data, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
        if image is None:
            raise WolfcalError(
                f"{self.source}: the {self.format} image at t={self.stamp_ns} ns cannot be decoded "
                f"({len(self.data)} bytes); the file is damaged or the image was not stored as png/jpeg"
            )
        return image


@dataclass
class Sample:
    stamp_ns: int
    joint_names: list[str]
    positions: np.ndarray  # (J,) measured joint angles [rad]
    images: dict[str, SampleImage]  # camera name ('head' or an external camera's name) -> its image
    velocities: np.ndarray | None = None  # (J,) [rad/s]
    source: str = ""  # capture file the sample came from

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
    cameras: list[str] = field(default_factory=list)  # camera names with images in the file, config order

    def samples_of(self, camera: str) -> list[Sample]:
        """The samples that hold an image of `camera`."""
        return [s for s in self.samples if camera in s.images]
