"""Where a kinematic model puts the observed tag corners in the image."""

from __future__ import annotations

import numpy as np

from wolfcal.observations import Observations
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import Robot
from wolfcal.vision.tags import tag_corners

BEHIND_CAMERA_PX = 1e4  # residual given to a corner that a model puts behind the camera [px]


def corner_points(robot: Robot, obs: Observations, tag_ids: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """Per observed corner: its column in `tag_ids` (M,) and its position in its tag frame (M, 3) [m]."""
    column = {t: i for i, t in enumerate(tag_ids)}
    tag_col = np.array([column[int(t)] for t in obs.tag_ids], dtype=int)
    corners = np.stack([tag_corners(robot.config.tag(t).size) for t in tag_ids])
    return tag_col, corners[tag_col, obs.corner_index]


def project_corners(obs: Observations, T_camera_tag: np.ndarray, points: tuple[np.ndarray, np.ndarray]) -> np.ndarray:
    """Pixels (M, 2) of every observed corner, given the tag poses T_camera_tag (S, T, 4, 4) in the column order
    of `points` (from `corner_points`); NaN for corners behind the camera."""
    tag_col, p_tag = points
    T = T_camera_tag[obs.sample_index, tag_col]  # (M, 4, 4)
    p_camera = np.einsum("mij,mj->mi", T[:, :3, :3], p_tag) + T[:, :3, 3]
    return obs.camera.project(p_camera)


def predict_corners(
    robot: Robot,
    obs: Observations,
    corrections: Corrections,
    tag_ids: list[int] | None = None,
    q: np.ndarray | None = None,
    points: tuple[np.ndarray, np.ndarray] | None = None,
) -> np.ndarray:
    """Predicted pixels (M, 2) of every observed corner under `corrections`, from the encoder readings
    (`obs.q_measured`, or `q` (S, J)); NaN for corners behind the camera. `points` caches `corner_points`."""
    tag_ids = obs.observed_tag_ids if tag_ids is None else tag_ids
    points = points if points is not None else corner_points(robot, obs, tag_ids)
    _, T_camera_tag = robot.camera_and_tag_poses(obs.q_measured if q is None else q, tag_ids, corrections)
    return project_corners(obs, T_camera_tag, points)
