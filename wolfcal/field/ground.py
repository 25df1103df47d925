"""Pixels to points on the ground plane, and the expected image width of a field line.

Frames: `T_ground_camera` maps points of the camera's optical frame (z forward, x right, y down) into a frame whose
plane z = 0 is the ground, z up [m]: the field frame (origin at the centre mark) or a standing robot's floor frame.
"""

from __future__ import annotations

import numpy as np

from wolfcal.camera.model import CameraModel


def ground_points(camera: CameraModel, T_ground_camera: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """Ground points (N, 2) [m] where the rays of pixels uv (N, 2) meet the ground, seen from one camera pose
    T_ground_camera (4, 4) or one per pixel (N, 4, 4); NaN for rays that do not go down."""
    T = np.asarray(T_ground_camera, float)
    rays = camera.unproject(np.asarray(uv, float).reshape(-1, 2))
    rays = rays @ T[:3, :3].T if T.ndim == 2 else np.einsum("nij,nj->ni", T[:, :3, :3], rays)
    origin = T[..., :3, 3]
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(rays[:, 2] < -1e-9, -origin[..., 2] / rays[:, 2], np.nan)
    return origin[..., :2] + s[:, None] * rays[:, :2]


def ground_gradient(camera: CameraModel, T_ground_camera: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """(N, 2, 2) d(ground point [m]) / d(pixel) at pixels uv (N, 2), columns u and v: the one-pixel steps
    (`ground_points` for the poses); NaN where a ray misses the ground."""
    uv = np.asarray(uv, float).reshape(-1, 2)
    here = ground_points(camera, T_ground_camera, uv)
    steps = [ground_points(camera, T_ground_camera, uv + step) - here for step in ([1.0, 0.0], [0.0, 1.0])]
    return np.stack(steps, axis=2)


def ground_step(camera: CameraModel, T_ground_camera: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """(N, 2) ground distance [m] covered by one pixel step along u (column 0) and along v (column 1) at pixels
    (N, 2); NaN where the ray misses the ground."""
    return np.linalg.norm(ground_gradient(camera, T_ground_camera, uv), axis=1)


def expected_line_width(
    camera: CameraModel, T_field_camera: np.ndarray, line_width: float, stride: int = 8
) -> np.ndarray:
    """(2, H, W) width [px] a field line of `line_width` [m] has at each pixel along rows and along columns, for a
    line crossing the scan at right angles; 0 above the horizon. Computed every `stride` pixels and spread to the
    pixels between (the width changes slowly across an image)."""
    h, w = camera.height, camera.width
    us, vs = np.arange(0, w + stride, stride, dtype=float), np.arange(0, h + stride, stride, dtype=float)
    grid = np.stack(np.meshgrid(us, vs), axis=-1).reshape(-1, 2)
    with np.errstate(divide="ignore", invalid="ignore"):
        widths = np.nan_to_num(line_width / ground_step(camera, T_field_camera, grid), nan=0.0, posinf=0.0)
    out = np.empty((2, h, w))
    for axis in range(2):
        coarse = widths[:, axis].reshape(len(vs), len(us)).astype(np.float32)
        out[axis] = _resize(coarse, w, h, stride)
    return out


def _resize(coarse: np.ndarray, w: int, h: int, stride: int) -> np.ndarray:
    """Spread a grid sampled every `stride` px (from pixel 0) to every pixel, nearest sample."""
    rows = np.minimum(np.round(np.arange(h) / stride).astype(int), coarse.shape[0] - 1)
    cols = np.minimum(np.round(np.arange(w) / stride).astype(int), coarse.shape[1] - 1)
    return coarse[np.ix_(rows, cols)]


def camera_on_field(T_floor_camera: np.ndarray, pose: np.ndarray) -> np.ndarray:
    """T_field_camera (..., 4, 4) of cameras T_floor_camera (..., 4, 4) on a robot whose floor frame stands at
    pose (x, y, yaw) [m, m, rad] on the field."""
    x, y, yaw = pose
    T = np.eye(4)
    T[:2, :2] = [[np.cos(yaw), -np.sin(yaw)], [np.sin(yaw), np.cos(yaw)]]
    T[:2, 3] = x, y
    return T @ T_floor_camera
