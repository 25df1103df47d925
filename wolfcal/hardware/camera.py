"""Camera sources for capture: a live V4L camera, a video file, a folder of images (cycled), or `sim`.

`grab()` returns the newest frame (gray uint8 or BGR uint8) or raises `CameraError` naming the source. Live
cameras queue frames: `grab` drops the queued ones so that the frame returned was exposed after the call
began. `sim` renders the robot served by `wolfcal emulate` on the bus port at its true joint angles.
"""

from __future__ import annotations

from pathlib import Path
from typing import Protocol

import cv2
import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.errors import WolfcalError

IMAGE_SUFFIXES = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm")
QUEUED_FRAMES = 4  # frames a V4L driver may hold before the newest one


class CameraError(WolfcalError):
    """The camera failed (cannot open, no frame, wrong size)."""

    exit_code = 4


class CameraSource(Protocol):
    name: str

    def grab(self) -> np.ndarray: ...

    def close(self) -> None: ...


def _check_size(name: str, image: np.ndarray, size: tuple[int, int]) -> np.ndarray:
    if (image.shape[1], image.shape[0]) != size:
        raise CameraError(
            f"{name}: frames are {image.shape[1]}x{image.shape[0]} px, the camera intrinsics with the chosen binning "
            f"give {size[0]}x{size[1]}; pass matching --intrinsics / --binning"
        )
    return image


class OpenCVCamera:
    """A V4L device (index or /dev/video path) or a video file (cycled) through OpenCV."""

    def __init__(self, source: str, size: tuple[int, int], live: bool):
        self.name, self.size, self.live = source, size, live
        target: int | str = int(source) if source.isdigit() else source
        self.capture = cv2.VideoCapture(target, cv2.CAP_V4L2) if live else cv2.VideoCapture(target)
        if not self.capture.isOpened():
            raise CameraError(
                f"camera {source}: cannot open it; check the device index/path and that no other program uses it"
            )
        if live:
            self.capture.set(cv2.CAP_PROP_FRAME_WIDTH, size[0])
            self.capture.set(cv2.CAP_PROP_FRAME_HEIGHT, size[1])

    def grab(self) -> np.ndarray:
        if self.live:
            for _ in range(QUEUED_FRAMES):
                self.capture.grab()
        ok, frame = self.capture.read()
        if not ok and not self.live:  # end of the video: start again
            self.capture.set(cv2.CAP_PROP_POS_FRAMES, 0)
            ok, frame = self.capture.read()
        if not ok or frame is None:
            raise CameraError(f"camera {self.name}: no frame (unplugged, or the video cannot be decoded)")
        return _check_size(f"camera {self.name}", frame, self.size)

    def close(self) -> None:
        self.capture.release()


class FolderCamera:
    """The images of a folder in name order, cycled."""

    def __init__(self, folder: Path, size: tuple[int, int]):
        self.name, self.size = str(folder), size
        self.files = sorted(p for p in folder.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
        if not self.files:
            raise CameraError(f"{folder}: no images ({', '.join(IMAGE_SUFFIXES)}) in this folder")
        self.index = 0

    def grab(self) -> np.ndarray:
        path = self.files[self.index % len(self.files)]
        self.index += 1
        image = cv2.imread(str(path), cv2.IMREAD_UNCHANGED)
        if image is None:
            raise CameraError(f"{path}: cannot read this image")
        return _check_size(str(path), image, self.size)

    def close(self) -> None:
        pass


def open_camera(source: str, camera: CameraModel) -> CameraSource:
    """A camera source from the --camera text (device, video file, image folder); `camera` is the intrinsics at
    the images' resolution. The simulated camera (`sim`) is `wolfcal.capture.sim_camera.SimCamera`."""
    size = (camera.width, camera.height)
    path = Path(source)
    if source.isdigit() or source.startswith("/dev/video"):
        return OpenCVCamera(source, size, live=True)
    if path.is_dir():
        return FolderCamera(path, size)
    if path.is_file():
        return OpenCVCamera(source, size, live=False)
    raise CameraError(f"--camera {source!r}: not a device index, /dev/video path, video file, image folder or 'sim'")
