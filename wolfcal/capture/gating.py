"""Decide whether a moment is still enough to become a sample; a rejected moment says why.

Three gates: every joint still to within `tolerance_ticks` over the last `settle_s` seconds of bus readings;
the image sharp (variance of the Laplacian over the detected tags, or the whole image when none is seen); the
tag corners stable between two consecutive frames (max corner motion in pixels). A field view (the field's lines,
no tags) must instead show at least `min_line_points` line points (`wolfcal.field.detect`) and be sharp over the
whole image.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass

import cv2
import numpy as np

from wolfcal.field.detect import detect_line_points
from wolfcal.hardware.bus import JointState


@dataclass(frozen=True)
class GateSettings:
    settle_s: float = 0.3  # window over which every joint must be still [s]
    tolerance_ticks: int = 1  # allowed spread of each joint's readings over the window [ticks]
    min_sharpness: float = 100.0  # variance of the Laplacian over the tags [grey levels^2]
    max_corner_motion_px: float = 0.5  # corner motion between two consecutive frames [px]
    moved_rad: float = 0.05  # manual mode: a joint must move this far from the last sample [rad]
    min_line_points: int = 40  # field views: line points a view must show


class StillnessWindow:
    """Bus readings of the last `settle_s` seconds."""

    def __init__(self, joints: list[str], settings: GateSettings):
        self.joints, self.settings = joints, settings
        self.readings: deque[tuple[float, np.ndarray]] = deque()

    def add(self, t: float, state: JointState) -> None:
        self.readings.append((t, state.ticks.copy()))
        while len(self.readings) > 2 and self.readings[1][0] <= t - self.settings.settle_s:
            self.readings.popleft()

    def clear(self) -> None:
        self.readings.clear()

    def spread(self) -> np.ndarray:
        """(J,) max - min ticks over the window."""
        ticks = np.array([r for _, r in self.readings])
        return ticks.max(axis=0) - ticks.min(axis=0)

    def why_not_still(self, now: float) -> str | None:
        """None when still, else the reason."""
        if not self.readings or now - self.readings[0][0] < self.settings.settle_s:
            return f"settling (still for less than {self.settings.settle_s:.1f} s)"
        spread = self.spread()
        worst = int(np.argmax(spread))
        if spread[worst] > self.settings.tolerance_ticks:
            return (
                f"joints not still: {self.joints[worst]} moved {int(spread[worst])} ticks in the last "
                f"{self.settings.settle_s:.1f} s"
            )
        return None


def sharpness(image: np.ndarray, corners: dict[int, np.ndarray]) -> float:
    """Variance of the Laplacian over the tags' bounding boxes (whole image without tags) [grey levels^2]."""
    gray = image if image.ndim == 2 else cv2.cvtColor(image, cv2.COLOR_BGR2GRAY)
    lap = cv2.Laplacian(gray, cv2.CV_64F)
    if not corners:
        return float(lap.var())
    h, w = gray.shape
    values = []
    for c in corners.values():
        x0, y0 = np.clip(np.floor(c.min(axis=0)).astype(int), 0, [w, h])
        x1, y1 = np.clip(np.ceil(c.max(axis=0)).astype(int) + 1, 0, [w, h])
        values.append(lap[y0:y1, x0:x1].ravel())
    return float(np.concatenate(values).var())


def corner_motion(a: dict[int, np.ndarray], b: dict[int, np.ndarray]) -> float:
    """Largest corner displacement [px] of the tags seen in both frames; inf when the sets of tags differ."""
    if set(a) != set(b):
        return float("inf")
    if not a:
        return 0.0
    return float(max(np.max(np.linalg.norm(a[t] - b[t], axis=1)) for t in a))


def why_not_sharp(
    image: np.ndarray,
    corners_a: dict[int, np.ndarray],
    corners_b: dict[int, np.ndarray],
    settings: GateSettings,
) -> tuple[str | None, float]:
    """(reason or None, sharpness) of two consecutive frames of a still moment; `corners_b` are `image`'s."""
    if not corners_b:
        return "no tag in view", sharpness(image, corners_b)
    value = sharpness(image, corners_b)
    if value < settings.min_sharpness:
        return f"image blurred: sharpness {value:.0f} < {settings.min_sharpness:.0f}", value
    motion = corner_motion(corners_a, corners_b)
    if motion > settings.max_corner_motion_px:
        what = "tags changed" if motion == float("inf") else f"tag corners moved {motion:.2f} px"
        return f"{what} between consecutive frames (limit {settings.max_corner_motion_px} px)", value
    return None, value


def why_not_field_view(image: np.ndarray, settings: GateSettings) -> tuple[str | None, float, int]:
    """(reason or None, sharpness of the whole image, line points found) of a field view's frame: a colour image
    that shows at least `min_line_points` points of the field's lines and is sharp."""
    if image.ndim != 3:
        return "grey image: field lines are told from the turf by colour; record the head camera in colour", 0.0, 0
    points = len(detect_line_points(image).uv)
    value = sharpness(image, {})
    if points < settings.min_line_points:
        return (f"no field lines in view ({points} line points, at least {settings.min_line_points})", value,
                points)  # fmt: skip
    if value < settings.min_sharpness:
        return f"image blurred: sharpness {value:.0f} < {settings.min_sharpness:.0f}", value, points
    return None, value, points
