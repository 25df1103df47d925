"""Observations without images: tag corners projected at the true kinematics plus Gaussian pixel noise.

For testing and benchmarking the estimator apart from detection.
"""

from __future__ import annotations

from dataclasses import replace

import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.observations import Observations
from wolfcal.projection import observations_from_poses
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import Robot


def synthetic_observations(
    robot: Robot,
    camera: CameraModel,
    truth: Corrections,
    q_true: np.ndarray,
    visible: np.ndarray,
    noise_px: float,
    rng: np.random.Generator,
) -> Observations:
    """Corners of the visible tags (visible: (N, T) over robot.config.tag_ids) seen by the head camera."""
    frames = Corrections(frames=truth.frames, tags=truth.tags)
    _, T_camera_tag = robot.camera_and_tag_poses(q_true, robot.config.tag_ids, frames)
    return observations_from_poses(robot, camera, truth, q_true, T_camera_tag, visible, noise_px, rng)


def reordered(obs: Observations, seed: int) -> Observations:
    """The same observations with the samples in another order and the corner rows shuffled (seeded): what a fit
    must not depend on."""
    moved = obs.subset(np.random.default_rng(seed).permutation(obs.n_samples))
    rows = np.random.default_rng(seed + 1).permutation(len(moved.uv))
    return replace(moved, sample_index=moved.sample_index[rows], tag_ids=moved.tag_ids[rows],
                   corner_index=moved.corner_index[rows], uv=moved.uv[rows])  # fmt: skip
