"""Where a simulated external camera stands, and what it sees of the robot's tags.

A tripod camera in front of the robot (base frame: x forward, z up), 1-2 m away, raised so it looks down on the
feet at 30-50 deg: the foot tags lie face up on their plates and the torso tag faces forward, so both face it.
"""

from __future__ import annotations

import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.geometry import make_transform
from wolfcal.vision.tags import tag_corners


def look_at(eye: np.ndarray, target: np.ndarray) -> np.ndarray:
    """T_base_camera (4, 4) of an optical frame (z forward, x right, y down) at `eye` looking at `target`,
    image rows parallel to the base's horizontal plane [m]."""
    z = target - eye
    z = z / np.linalg.norm(z)
    x = np.cross(z, [0.0, 0.0, 1.0])
    x = x / np.linalg.norm(x)
    y = np.cross(z, x)
    return make_transform(np.stack([x, y, z], axis=1), eye)


def random_tripod_placement(rng: np.random.Generator, target: np.ndarray | None = None) -> np.ndarray:
    """T_base_camera of a tripod 1-2 m in front of the robot (bearing within +-30 deg), looking down at 30-50 deg
    onto `target` (default: between torso and feet, (0.1, 0, -0.2) m in the base frame)."""
    target = np.array([0.1, 0.0, -0.2]) if target is None else np.asarray(target, dtype=float)
    distance = rng.uniform(1.0, 2.0)
    bearing = np.deg2rad(rng.uniform(-30.0, 30.0))
    elevation = np.deg2rad(rng.uniform(30.0, 50.0))
    eye = target + distance * np.array(
        [np.cos(elevation) * np.cos(bearing), np.cos(elevation) * np.sin(bearing), np.sin(elevation)]
    )
    return look_at(eye, target)


def visible_tags(
    camera: CameraModel, T_camera_tag: np.ndarray, sizes: np.ndarray, margin_px: float, min_size_px: float,
    max_angle_rad: float = np.deg2rad(60.0),
) -> np.ndarray:
    """(N, T) bool: tag t (edge sizes[t] [m], pose T_camera_tag (N, T, 4, 4)) lies fully inside the image with a
    margin, appears at least `min_size_px` large and faces the camera (normal within `max_angle_rad` of the ray)."""
    corners = np.stack([tag_corners(s) for s in sizes])  # (T, 4, 3)
    p = np.einsum("ntij,tcj->ntci", T_camera_tag[..., :3, :3], corners) + T_camera_tag[:, :, None, :3, 3]
    uv = camera.project(p)  # (N, T, 4, 2)
    inside = np.all(camera.in_image(uv, margin_px), axis=-1)
    edges = np.linalg.norm(uv - np.roll(uv, 1, axis=2), axis=-1)
    big = np.nan_to_num(np.min(edges, axis=-1), nan=0.0) >= min_size_px
    normal = T_camera_tag[..., :3, 2]
    to_camera = -T_camera_tag[..., :3, 3]
    cos = np.sum(normal * to_camera, axis=-1) / np.linalg.norm(to_camera, axis=-1)
    return inside & big & (cos > np.cos(max_angle_rad))
