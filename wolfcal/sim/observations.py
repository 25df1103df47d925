"""Observations without images: tag corners projected at the true kinematics plus Gaussian pixel noise.

For testing and benchmarking the estimator apart from detection.
"""

from __future__ import annotations

import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.encoders import encoder_readings
from wolfcal.observations import HEAD_CAMERA, Observations
from wolfcal.projection import tag_corner_pixels, tag_corner_table
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import Robot


def observations_from_poses(
    robot: Robot, camera: CameraModel, truth: Corrections, q_true: np.ndarray, T_camera_tag: np.ndarray,
    visible: np.ndarray, noise_px: float, rng: np.random.Generator, camera_name: str = HEAD_CAMERA,
    sources: list[str] | None = None,
) -> Observations:
    """Corners of the visible tags (visible: (N, T) over robot.config.tag_ids, poses T_camera_tag (N, T, 4, 4))
    with Gaussian pixel noise [px], and the encoder readings a real robot would report."""
    tag_ids = robot.config.tag_ids
    s_idx, t_idx = np.nonzero(visible)
    corners = tag_corner_table(robot.config, tag_ids)[t_idx]  # (V, 4, 3)
    uv = tag_corner_pixels(camera, T_camera_tag[s_idx, t_idx], corners)
    uv = uv + rng.normal(0.0, noise_px, size=uv.shape)
    n = len(q_true)
    return Observations(
        joint_names=list(robot.joint_names),
        q_measured=encoder_readings(q_true, truth.offset_vector(robot.joint_names)),
        stamps_ns=np.arange(n, dtype=np.int64),
        sources=sources or ["synthetic"] * n,
        camera=camera,
        sample_index=np.repeat(s_idx, 4),
        tag_ids=np.repeat(np.array(tag_ids)[t_idx], 4),
        corner_index=np.tile(np.arange(4), len(s_idx)),
        uv=uv.reshape(-1, 2),
        camera_name=camera_name,
    )


def synthetic_observations(
    robot: Robot, camera: CameraModel, truth: Corrections, q_true: np.ndarray, visible: np.ndarray,
    noise_px: float, rng: np.random.Generator,
) -> Observations:
    """Corners of the visible tags (visible: (N, T) over robot.config.tag_ids) seen by the head camera."""
    frames = Corrections(frames=truth.frames, tags=truth.tags)
    _, T_camera_tag = robot.camera_and_tag_poses(q_true, robot.config.tag_ids, frames)
    return observations_from_poses(robot, camera, truth, q_true, T_camera_tag, visible, noise_px, rng)

