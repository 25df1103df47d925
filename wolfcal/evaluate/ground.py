"""Ground error: where a ball on the field lands when the robot localises it through a kinematic model.

A standing robot (straight legs: every joint 0 except the knees' built-in bend, RKnee = -0.2618, LKnee = +0.2618 rad,
as read by the encoders) tilts its head until a ball on the ground at distance d straight ahead (from the point
below base_link, along the right sole's x axis) lies on the camera's optical axis under the reference model. The
pixel where the reference model sees the ball is back-projected through the evaluated model (same encoder readings)
onto that model's ground plane (the right sole's plane, z = 0 of r_sole). The ground error is the distance between
the two ground points, each in its own model's sole frame [m]. The ball is a point on the ground (its radius is left
out: it moves both models' answers alike).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import minimize_scalar

from wolfcal.camera.model import CameraModel
from wolfcal.errors import WolfcalError
from wolfcal.geometry import invert_transform
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import Robot

DISTANCES_M = (1.0, 2.0, 4.5, 9.0)
STANDING = {"RKnee": -0.2618, "LKnee": 0.2618}  # encoder readings of straight Wolfgang legs [rad]
GROUND_LINK = "r_sole"


def standing_pose(robot: Robot) -> np.ndarray:
    """(J,) encoder readings of the standing robot: all joints 0 except the knees of STANDING [rad]."""
    q = np.zeros(len(robot.joint_names))
    for name, value in STANDING.items():
        if name in robot.joint_names:
            q[robot.model.column(name)] = value
    return q


def tilt_joint(robot: Robot) -> str:
    """The joint that pitches the camera: the last movable joint between base and camera (HeadTilt on Wolfgang)."""
    joints = [
        j.name
        for j in robot.model.joints_between(robot.config.base_link, robot.config.camera.frame)
        if j.actuated
    ]
    if not joints:
        raise WolfcalError(
            f"{robot.config.path}: no movable joint between base and camera; cannot aim the head"
        )
    return joints[-1]


def _poses(robot: Robot, q: np.ndarray, corrections: Corrections) -> tuple[np.ndarray, np.ndarray]:
    """T_sole_camera (N, 4, 4) and T_sole_base (N, 4, 4) for readings q (N, J)."""
    links = [robot.config.camera.frame, GROUND_LINK]
    poses = robot.model.link_poses(q, links, corrections, base=robot.config.base_link)
    T_sole_base = invert_transform(poses[GROUND_LINK])
    return T_sole_base @ poses[robot.config.camera.frame], T_sole_base


def ball_position(robot: Robot, q: np.ndarray, reference: Corrections, distance: float) -> np.ndarray:
    """(3,) ball on the ground d metres straight ahead of the point below base_link, right-sole frame [m]."""
    _, T_sole_base = _poses(robot, q[None], reference)
    origin = T_sole_base[0, :3, 3]
    return np.array([origin[0] + distance, origin[1], 0.0])


def aim_head(robot: Robot, reference: Corrections, distance: float) -> np.ndarray:
    """(J,) standing readings with the tilt joint set so the reference model's optical axis points at the ball."""
    q0 = standing_pose(robot)
    tilt = tilt_joint(robot)
    column = robot.model.column(tilt)
    joint = robot.model.joints[tilt]
    ball = ball_position(robot, q0, reference, distance)

    def off_axis(values: np.ndarray) -> np.ndarray:
        q = np.repeat(q0[None], len(values), axis=0)
        q[:, column] = values
        T_sole_camera, _ = _poses(robot, q, reference)
        to_ball = ball - T_sole_camera[:, :3, 3]
        cos = np.einsum("ni,ni->n", T_sole_camera[:, :3, 2], to_ball) / np.linalg.norm(to_ball, axis=1)
        return np.arccos(np.clip(cos, -1.0, 1.0))

    lo, hi = max(joint.lower, -np.pi), min(joint.upper, np.pi)
    grid = np.linspace(lo, hi, 721)
    best = grid[int(np.argmin(off_axis(grid)))]
    step = grid[1] - grid[0]
    found = minimize_scalar(
        lambda v: float(off_axis(np.array([v]))[0]),
        bounds=(max(lo, best - step), min(hi, best + step)),
        method="bounded",
        options={"xatol": 1e-10},
    )
    q0[column] = found.x
    return q0


def ground_point(
    robot: Robot, q: np.ndarray, corrections: Corrections, uv: np.ndarray, camera: CameraModel
) -> np.ndarray:
    """(3,) where the ray through pixel uv meets the ground plane of the model, right-sole frame [m]; NaN above
    the horizon."""
    T_sole_camera, _ = _poses(robot, q[None], corrections)
    ray = T_sole_camera[0, :3, :3] @ camera.unproject(uv)
    origin = T_sole_camera[0, :3, 3]
    if ray[2] >= -1e-12:
        return np.full(3, np.nan)
    return origin + (-origin[2] / ray[2]) * ray


def ground_errors(
    robot: Robot,
    camera: CameraModel,
    reference: Corrections,
    models: dict[str, Corrections],
    distances: tuple[float, ...] = DISTANCES_M,
) -> list[dict]:
    """Per distance: the ball's true spot and, per model, where it lands (distance from the robot) and the error [m].

    An error of None means the model puts the ball's pixel above its horizon (the ball would be "in the sky").
    """
    if GROUND_LINK not in robot.model.links:
        raise WolfcalError(
            f"{robot.config.urdf}: no '{GROUND_LINK}' frame; the ground error needs the sole plane"
        )
    rows = []
    for d in distances:
        q = aim_head(robot, reference, d)
        ball = ball_position(robot, q, reference, d)
        T_sole_camera, _ = _poses(robot, q[None], reference)
        p_camera = invert_transform(T_sole_camera[0]) @ np.append(ball, 1.0)
        uv = camera.project(p_camera[:3])
        row = {"distance_m": d, "pixel": [float(uv[0]), float(uv[1])], "models": {}}
        for name, corrections in models.items():
            point = ground_point(robot, q, corrections, uv, camera)
            _, T_sole_base_model = _poses(robot, q[None], corrections)
            below_robot = T_sole_base_model[0, :3, 3]
            landed = float(np.linalg.norm(point[:2] - below_robot[:2])) if np.isfinite(point).all() else None
            error = float(np.linalg.norm(point[:2] - ball[:2])) if np.isfinite(point).all() else None
            row["models"][name] = {"landed_at_m": landed, "error_m": error}
        rows.append(row)
    return rows
