"""Plain data read from and written to capture files.

A sample is one still moment: the joint angles the encoders reported (radians, `q_measured`, before any calibration
offset) and the image of each camera that saw the moment: the head camera (`HEAD_CAMERA`) and/or external cameras
(by their config names). An image read from a file holds only its location there, and its bytes are read back
when needed (`wolfcal.io.stream`; hundreds of full-resolution images do not fit in memory at once); an image made
in memory holds its encoded bytes. Each has the intrinsics at its own resolution (binning already applied). A frame of a
plain recording also names its still span (frames of one camera at one still pose, one after the other), which a fit
averages into one sample; a capture file's samples have none.
"""

from __future__ import annotations

from collections.abc import Iterable, Iterator
from dataclasses import dataclass, field
from itertools import groupby
from pathlib import Path

import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.errors import WolfcalError
from wolfcal.io.stream import ImageLocation, stream_images
from wolfcal.observations import HEAD_CAMERA

__all__ = ["HEAD_CAMERA", "Capture", "Sample", "SampleImage", "encoded_images"]


@dataclass(slots=True)  # no per-object dict: a long recording holds thousands
class SampleImage:
    data: bytes  # encoded image (png or jpeg); empty when `location` says where to read it
    format: str  # 'png' | 'jpeg'
    camera: CameraModel  # intrinsics at this image's resolution
    source: str = ""  # capture file and topic, for messages
    stamp_ns: int = 0  # header stamp of the image [ns]
    location: ImageLocation | None = None  # where its bytes lie in the file it was read from
    span: int = -1  # still span of a recording's frame (`wolfcal.io.recording.still_spans`), per camera; -1: none

    def encoded(self) -> bytes:
        """The encoded bytes (read from the file when the image holds only its location)."""
        if self.data or self.location is None:
            return self.data
        return next(stream_images([self.location]))

    def decode(self) -> np.ndarray:
        """Decoded image: (H, W) uint8 for mono, (H, W, 3) uint8 BGR for colour."""
        import cv2  # here, not at the top: a fit from cached detections does not load OpenCV

        data = self.encoded()
        image = cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_UNCHANGED)
        if image is None:
            raise WolfcalError(
                f"{self.source}: the {self.format} image at t={self.stamp_ns} ns cannot be decoded "
                f"({len(data)} bytes); the file is damaged or the image was not stored as png/jpeg"
            )
        return image


def encoded_images(images: Iterable[SampleImage]) -> Iterator[bytes]:
    """The encoded bytes of each image, in order; images of files are streamed (`stream_images`): consecutive
    ones of one file in one pass, none kept after it is handed on."""
    for from_file, run in groupby(images, key=lambda image: image.location is not None):
        if from_file:
            yield from stream_images(image.location for image in run)  # type: ignore[misc]
        else:
            yield from (image.data for image in run)


@dataclass(slots=True)
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
