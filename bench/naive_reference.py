"""The naive reference solver of bench/bench_table.py: the same unknowns and detections as a wolfcal fit, solved
the textbook way. Forward kinematics per observation (one tag view: a sample and a tag) in a Python loop over the
joints with 4x4 numpy matrices, cv2.projectPoints per view, and scipy.optimize.least_squares with numeric
(2-point) differentiation. Residuals: pixel errors over the pixel noise, and the unknowns over their prior sigma
(the same priors as wolfcal's problem). No outlier rounds, no robust loss.
"""

from __future__ import annotations

import cv2
import numpy as np
from scipy.optimize import least_squares

from wolfcal.geometry import axis_angle_matrix, invert_transform, tag_corners, transform_from_twist_params
from wolfcal.observations import Observations
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.parameters import ParameterSet
from wolfcal.robot.robot import Robot


def link_pose(robot: Robot, q: dict[str, float], link: str, corrections: Corrections) -> np.ndarray:
    """T_root_link (4, 4) for one sample: origin @ frame correction @ motion, joint by joint from the root."""
    T = np.eye(4)
    for joint in robot.model.path_from_root(link):
        T = T @ joint.T_parent_origin
        if joint.name in corrections.frames:
            T = T @ transform_from_twist_params(corrections.frames[joint.name])
        if joint.type != "fixed":
            if joint.mimic is not None:
                master, multiplier, offset = joint.mimic
                angle = multiplier * (q[master] + corrections.offsets.get(master, 0.0)) + offset
            else:
                angle = q[joint.name] + corrections.offsets.get(joint.name, 0.0)
            motion = np.eye(4)
            if joint.type == "prismatic":
                motion[:3, 3] = joint.axis * angle
            else:
                motion[:3, :3] = axis_angle_matrix(joint.axis, np.array([angle]))[0]
            T = T @ motion
    return T


def predicted(robot: Robot, obs: Observations, corrections: Corrections) -> np.ndarray:
    """Pixels (M, 2) of every observed corner, one tag view at a time."""
    uv = np.zeros((len(obs.uv), 2))
    views: dict[tuple[int, int], list[int]] = {}
    for row, (s, t) in enumerate(zip(obs.sample_index.tolist(), obs.tag_ids.tolist())):
        views.setdefault((s, t), []).append(row)
    camera_frame = robot.config.head_camera().frame
    K, D = obs.camera.K, obs.camera.D
    for (s, t), rows in views.items():
        q = dict(zip(obs.joint_names, obs.q_measured[s]))
        T_root_base = link_pose(robot, q, robot.config.base_link, corrections)
        T_base_camera = invert_transform(T_root_base) @ link_pose(robot, q, camera_frame, corrections)
        tag = robot.config.tag(t)
        T_base_tag = (invert_transform(T_root_base) @ link_pose(robot, q, tag.link, corrections)
                      @ robot.T_link_tag(t, corrections))  # fmt: skip
        T_camera_tag = invert_transform(T_base_camera) @ T_base_tag
        points = tag_corners(tag.size)[obs.corner_index[rows]]
        rvec = cv2.Rodrigues(T_camera_tag[:3, :3])[0]
        uv[rows] = cv2.projectPoints(points, rvec, T_camera_tag[:3, 3], K, D)[0].reshape(-1, 2)
    return uv


def naive_solve(robot: Robot, obs: Observations, chain: ParameterSet, pixel_noise: float) -> np.ndarray:
    """Parameter values [SI] that minimise the pixel and prior residuals (see the module docstring)."""

    def residuals(z: np.ndarray) -> np.ndarray:
        corrections = chain.corrections(chain.values(z))
        pixels = (predicted(robot, obs, corrections) - obs.uv).ravel() / pixel_noise
        return np.concatenate([pixels, z])

    solution = least_squares(residuals, np.zeros(len(chain)), jac="2-point", method="trf")
    return chain.values(solution.x)
