"""How far an estimated model is from a simulator's truth, in the terms of the requirements.

Both models are fed the same encoder readings (true angles minus true offsets), as on the robot.
"""

from __future__ import annotations

import numpy as np

from wolfcal.geometry import invert_transform, rotation_angle
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.ranges import range_grid, sampling_bounds
from wolfcal.robot.robot import Robot


def _pose_errors(
    robot: Robot, q_true: np.ndarray, link: str, estimate: Corrections, truth: Corrections
) -> tuple[np.ndarray, np.ndarray]:
    """Rotation [rad] and translation [m] error of `link` in the base frame per configuration."""
    q_measured = q_true - truth.offset_vector(robot.joint_names)
    base = robot.config.base_link
    T_true = robot.model.link_poses(q_measured, [link], truth, base=base)[link]
    T_est = robot.model.link_poses(q_measured, [link], estimate, base=base)[link]
    E = invert_transform(T_true) @ T_est
    return rotation_angle(E[:, :3, :3]), np.linalg.norm(T_est[:, :3, 3] - T_true[:, :3, 3], axis=1)


def camera_pose_errors(
    robot: Robot, estimate: Corrections, truth: Corrections, grid: int = 15
) -> tuple[np.ndarray, np.ndarray]:
    """Camera pose error (rad, m) over a grid spanning the whole range of every joint between base and camera."""
    frame = robot.config.head_camera().frame
    q = range_grid(robot, frame, grid)
    return _pose_errors(robot, q, frame, estimate, truth)


def link_position_errors(
    robot: Robot, link: str, estimate: Corrections, truth: Corrections, n: int, rng: np.random.Generator
) -> np.ndarray:
    """Position error [m] of `link` (e.g. a sole) in the base frame over n random calibration-range poses."""
    lo, hi = sampling_bounds(robot, "head")
    return _pose_errors(robot, rng.uniform(lo, hi, size=(n, len(lo))), link, estimate, truth)[1]


def link_pose_errors(
    robot: Robot, link: str, estimate: Corrections, truth: Corrections, n: int, rng: np.random.Generator
) -> tuple[np.ndarray, np.ndarray]:
    """Rotation [rad] and position [m] error of `link` (e.g. a sole) in the base frame over n random
    calibration-range poses."""
    lo, hi = sampling_bounds(robot, "head")
    return _pose_errors(robot, rng.uniform(lo, hi, size=(n, len(lo))), link, estimate, truth)
