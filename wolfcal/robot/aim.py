"""Where the standing robot aims its head: at a point on the floor (a ball), through a model.

The robot stands in the pose of its config (`floor.standing`, `robot.floor.standing_pose`); the head aims with the
joints of `floor.aim`, by default the last two movable joints before the camera (pan and tilt). The scripted floor
capture and the floor plan aim at the floor points `AIM_DISTANCES_M` from the point below base_link at bearings
`AIM_BEARINGS_DEG`.
"""

from __future__ import annotations

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.floor import camera_in_floor, standing_pose
from wolfcal.robot.robot import Robot

AIM_REFINEMENTS = 12  # of the head aim after the coarse grid (see aim_head)
AIM_DISTANCES_M = (1.0, 2.0, 3.5)  # floor points the head aims at, from the point below base_link [m] ...
AIM_BEARINGS_DEG = (-30.0, 0.0, 30.0)  # ... at these bearings from the floor's x axis (left positive) [deg]


def aim_joints(robot: Robot) -> list[str]:
    """The joints that aim the camera: the config's `floor.aim`, else the last two movable joints between base and
    camera (pan, tilt), or one."""
    if robot.config.floor is not None and robot.config.floor.aim:
        return list(robot.config.floor.aim)
    joints = [
        j.name
        for j in robot.model.joints_between(robot.config.base_link, robot.config.head_camera().frame)
        if j.actuated
    ]
    if not joints:
        raise WolfcalError(f"{robot.config.path}: no movable joint between base and camera; cannot aim the head")
    return joints[-2:]


def ball_position(robot: Robot, reference: Corrections, distance: float, bearing: float) -> np.ndarray:
    """(3,) ball on the floor `distance` m from the point below base_link at `bearing` rad, floor frame [m]."""
    _, T_floor_base = camera_in_floor(robot, standing_pose(robot)[None], reference)
    origin = T_floor_base[0, :3, 3]
    return np.array([origin[0] + distance * np.cos(bearing), origin[1] + distance * np.sin(bearing), 0.0])


def aim_head(robot: Robot, reference: Corrections, ball: np.ndarray, stance: np.ndarray | None = None) -> np.ndarray:
    """(J,) standing readings (`stance` (J,), default `floor.standing`) with pan/tilt set so that the reference
    model's optical axis points at the ball."""
    q0 = standing_pose(robot) if stance is None else stance.copy()
    joints = [robot.model.joints[name] for name in aim_joints(robot)]
    columns = [robot.model.column(j.name) for j in joints]
    lo = np.array([max(j.lower, -np.pi) for j in joints])
    hi = np.array([min(j.upper, np.pi) for j in joints])

    def off_axis(values: np.ndarray) -> np.ndarray:
        q = np.repeat(q0[None], len(values), axis=0)
        q[:, columns] = np.clip(values, lo, hi)
        T_floor_camera, _ = camera_in_floor(robot, q, reference)
        to_ball = ball - T_floor_camera[:, :3, 3]
        cos = np.einsum("ni,ni->n", T_floor_camera[:, :3, 2], to_ball) / np.linalg.norm(to_ball, axis=1)
        return np.arccos(np.clip(cos, -1.0, 1.0))

    points = 41 if len(joints) == 2 else 721
    axes = [np.linspace(a, b, points) for a, b in zip(lo, hi)]
    grid = np.stack([g.ravel() for g in np.meshgrid(*axes, indexing="ij")], axis=1)
    best = grid[int(np.argmin(off_axis(grid)))]
    step = (hi - lo) / (points - 1)
    ticks = np.linspace(-1.0, 1.0, 11)  # each refinement: 11 values per joint over +-1 step around the best
    local = np.stack([g.ravel() for g in np.meshgrid(*[ticks] * len(joints), indexing="ij")], axis=1)
    for _ in range(AIM_REFINEMENTS):  # the step shrinks 5-fold each time: 1e-9 rad in the end
        candidates = np.clip(best + local * step, lo, hi)
        best = candidates[int(np.argmin(off_axis(candidates)))]
        step = step / 5
    q0[columns] = best
    return q0
