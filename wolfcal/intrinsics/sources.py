"""Input sources: image files, globs and folders (loaded lazily), video files and live cameras."""

from __future__ import annotations

import glob
from collections.abc import Iterator
from dataclasses import dataclass, field
from functools import partial
from pathlib import Path

import cv2
import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.intrinsics.detect import Failure, Job

IMAGE_SUFFIXES = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff", ".pgm", ".ppm", ".webp"}
VIDEO_SUFFIXES = {".mp4", ".avi", ".mkv", ".mov", ".webm", ".m4v", ".mpg", ".mpeg"}


@dataclass
class Inputs:
    """INPUT arguments sorted by kind; `missing` lists arguments that named nothing."""

    images: list[Path] = field(default_factory=list)
    videos: list[Path] = field(default_factory=list)
    missing: list[Failure] = field(default_factory=list)


def expand_inputs(arguments: list[str]) -> Inputs:
    """Files, globs (`*.png`) and folders (their images, sorted) -> image and video paths."""
    found = Inputs()
    for arg in arguments:
        path = Path(arg)
        if path.is_dir():
            paths = sorted(p for p in path.iterdir() if p.suffix.lower() in IMAGE_SUFFIXES)
            if not paths:
                found.missing.append(Failure(arg, "folder holds no images (" + ", ".join(sorted(IMAGE_SUFFIXES)) + ")"))
        elif path.is_file():
            paths = [path]
        elif glob.has_magic(arg):
            paths = [Path(p) for p in sorted(glob.glob(arg)) if Path(p).is_file()]
            if not paths:
                found.missing.append(Failure(arg, "pattern matches no files"))
        else:
            found.missing.append(Failure(arg, "no such file or folder"))
            continue
        for p in paths:
            (found.videos if p.suffix.lower() in VIDEO_SUFFIXES else found.images).append(p)
    return found


def read_image(path: Path) -> np.ndarray:
    """Image file -> array; OSError with the reason if it cannot be read."""
    try:
        data = np.fromfile(path, dtype=np.uint8)
    except OSError as exc:
        raise OSError(f"cannot read file ({exc.strerror})") from None
    image = cv2.imdecode(data, cv2.IMREAD_UNCHANGED) if data.size else None
    if image is None:
        raise OSError("not a readable image (empty, truncated or unknown format)")
    return image


def image_jobs(paths: list[Path]) -> list[Job]:
    """One lazy load per image file, for `detect.detect_many`."""
    return [(str(p), partial(read_image, p)) for p in paths]


def open_stream(source: str | int) -> cv2.VideoCapture:
    """A video file path, camera index or device path -> an opened capture; a clear error otherwise."""
    capture = cv2.VideoCapture(source)
    if not capture.isOpened():
        what = f"camera {source}" if isinstance(source, int) or str(source).startswith("/dev/") else str(source)
        raise WolfcalError(
            f"{what}: cannot open (check the device or file, its permissions, and that no other program is "
            "using the camera)"
        )
    return capture


def _frames(capture: cv2.VideoCapture, label: str) -> Iterator[tuple[str, np.ndarray]]:
    try:
        index = 0
        while True:
            ok, frame = capture.read()
            if not ok:
                return
            yield f"{label}#{index}", frame
            index += 1
    finally:
        capture.release()


def stream_frames(source: str | int, name: str | None = None) -> Iterator[tuple[str, np.ndarray]]:
    """Open a video file or camera now (errors here), then yield (name#index, image) until the stream ends."""
    return _frames(open_stream(source), name or str(source))


def camera_source(text: str) -> str | int:
    """--camera value: '0' -> 0 (index), '/dev/video2' -> the path."""
    return int(text) if text.isdigit() else text
