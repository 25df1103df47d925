"""Rendered board views of a known camera (ground truth for tests, benchmarks and the detector choice)."""

from __future__ import annotations

import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.geometry import exp_so3
from wolfcal.vision.board import Board
from wolfcal.vision.render import PlanarTarget, motion_blur, render_targets

PX_PER_SQUARE = 64  # texture resolution: square edges fall on texel edges


def random_board_poses(
    camera: CameraModel,
    board: Board,
    n: int,
    rng: np.random.Generator,
    max_tilt_deg: float = 45.0,
    fill: tuple[float, float] = (0.35, 0.8),
) -> list[np.ndarray]:
    """`n` poses T_camera_board (4, 4) with every corner in view, varied in place, tilt and distance."""
    obj = board.object_points()
    centre = obj.mean(axis=0)
    extent = np.ptp(obj[:, :2], axis=0).max() + 2 * board.square
    poses: list[np.ndarray] = []
    while len(poses) < n:
        share = rng.uniform(*fill)  # board width as a share of the image width
        depth = camera.fx * extent / (share * camera.width)
        tilt = np.deg2rad(rng.uniform(-max_tilt_deg, max_tilt_deg, 2))
        R = exp_so3(np.array([tilt[0], tilt[1], 0.0])) @ exp_so3(np.array([0.0, 0.0, rng.uniform(-0.4, 0.4)]))
        target = rng.uniform([0.15 * camera.width, 0.15 * camera.height], [0.85 * camera.width, 0.85 * camera.height])
        ray = camera.unproject(target)
        T = np.eye(4)
        T[:3, :3] = R
        T[:3, 3] = ray * depth - R @ centre
        uv = camera.project((obj @ R.T) + T[:3, 3])
        if np.all(camera.in_image(uv, margin=0.03 * camera.width)):
            poses.append(T)
    return poses


def true_corners(camera: CameraModel, board: Board, T_camera_board: np.ndarray) -> np.ndarray:
    """(N, 2) true pixel positions of all board corners."""
    obj = board.object_points()
    return camera.project(obj @ T_camera_board[:3, :3].T + T_camera_board[:3, 3])


def render_view(
    camera: CameraModel,
    board: Board,
    T_camera_board: np.ndarray,
    rng: np.random.Generator,
    noise_sigma: float = 2.0,
    blur_px: float = 0.0,
    supersample: int = 3,
) -> np.ndarray:
    """uint8 gray image of the board (white margin of one square) at `T_camera_board`, with blur and noise."""
    texture = board.texture(PX_PER_SQUARE)
    width, height = board.texture_size(PX_PER_SQUARE)
    T_camera_target = T_camera_board @ np.linalg.inv(board.T_target_board(PX_PER_SQUARE))
    target = PlanarTarget(T_camera_target, texture, width, height)
    image = render_targets(camera, [target], background=90, supersample=supersample, rng=rng)
    if blur_px > 0:
        image = motion_blur(image, blur_px, rng.uniform(0, np.pi))
    if noise_sigma > 0:
        image = np.clip(image + rng.normal(0, noise_sigma, image.shape), 0, 255).astype(np.uint8)
    return image


def example_camera(width: int = 640, height: int = 480) -> CameraModel:
    """A plumb_bob camera with moderate distortion, ~70 degrees horizontal field of view."""
    f = 0.72 * width
    K = np.array([[f * 1.002, 0, width / 2 - 0.5 + 0.013 * width], [0, f, height / 2 - 0.5 - 0.01 * height], [0, 0, 1]])
    return CameraModel(width, height, K, np.array([-0.28, 0.09, 0.0006, -0.0004, -0.012]), "plumb_bob")
