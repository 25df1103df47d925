"""Ground error: where a ball on the field lands when the robot localises it through a kinematic model.

The robot stands in the pose of its config (`floor.standing`: encoder readings, other joints 0). The floor is the
plane of the standing soles (`floor.soles`): origin midway between the soles' origins, z along their mean z axis,
x along their mean x axis made level (`T_base_floor`). A ball lies on the floor at distance d from the point below
base_link, at a bearing of -30, 0 or +30 deg from the floor's x axis. The robot aims its head (the last two movable
joints before the camera: pan and tilt) so that the reference model's optical axis points at the ball; the pixel
where the reference model sees it is turned back through the evaluated model (same encoder readings) into a point
on that model's floor. The ground error at d is the largest over the bearings of the distance between the two floor
points, each in its own model's floor frame [m]. The ball is a point on the floor (its radius moves both models'
answers alike).
"""

from __future__ import annotations

import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.geometry import invert_transform
from wolfcal.robot.aim import aim_head, ball_position
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.floor import FLOOR_NEEDED, camera_in_floor
from wolfcal.robot.parameters import ParameterSet
from wolfcal.robot.robot import Robot

DISTANCES_M = (1.0, 2.0, 4.5, 9.0)
BEARINGS_RAD = tuple(np.deg2rad((-30.0, 0.0, 30.0)))


def ground_point(
    robot: Robot, q: np.ndarray, corrections: Corrections, uv: np.ndarray, camera: CameraModel
) -> np.ndarray:
    """(3,) where the ray through pixel uv meets the model's floor, floor frame [m]; NaN above the horizon."""
    T_floor_camera, _ = camera_in_floor(robot, q[None], corrections)
    ray = T_floor_camera[0, :3, :3] @ camera.unproject(uv)
    origin = T_floor_camera[0, :3, 3]
    if ray[2] >= -1e-12:
        return np.full(3, np.nan)
    return origin + (-origin[2] / ray[2]) * ray


def ball_views(robot: Robot, camera: CameraModel, reference: Corrections, distance: float) -> list[dict]:
    """Per bearing: the head readings q (J,), the ball on the floor (3,) and its pixel (2,) under the reference."""
    views = []
    for bearing in BEARINGS_RAD:
        ball = ball_position(robot, reference, distance, bearing)
        q = aim_head(robot, reference, ball)
        T_floor_camera, _ = camera_in_floor(robot, q[None], reference)
        p_camera = invert_transform(T_floor_camera[0]) @ np.append(ball, 1.0)
        views.append({"bearing": bearing, "q": q, "ball": ball, "uv": camera.project(p_camera[:3])})
    return views


def landing_error(robot: Robot, camera: CameraModel, view: dict, corrections: Corrections) -> tuple[float, float]:
    """(where the model puts the ball: distance from the robot [m], error on the floor [m]); NaN above horizon."""
    point = ground_point(robot, view["q"], corrections, view["uv"], camera)
    if not np.isfinite(point).all():
        return float("nan"), float("nan")
    _, T_floor_base = camera_in_floor(robot, view["q"][None], corrections)
    landed = float(np.linalg.norm(point[:2] - T_floor_base[0, :2, 3]))
    return landed, float(np.linalg.norm(point[:2] - view["ball"][:2]))


def ground_errors(
    robot: Robot,
    camera: CameraModel,
    reference: Corrections,
    models: dict[str, Corrections],
    distances: tuple[float, ...] = DISTANCES_M,
) -> list[dict]:
    """Per distance: per model, where the ball lands (distance from the robot) and the error [m], the worst of
    the bearings. An error of None means the model puts the ball's pixel above its horizon."""
    robot.config.floor_config(FLOOR_NEEDED)  # before any work
    rows = []
    for d in distances:
        views = ball_views(robot, camera, reference, d)
        models_out: dict[str, dict] = {}
        row = {"distance_m": d, "pixel": [float(v) for v in views[len(views) // 2]["uv"]], "models": models_out}
        for name, corrections in models.items():
            results = [landing_error(robot, camera, v, corrections) for v in views]
            worst = max(range(len(results)), key=lambda k: -1.0 if np.isnan(results[k][1]) else results[k][1])
            landed, error = results[worst]
            above = any(np.isnan(e) for _, e in results)
            models_out[name] = {
                "landed_at_m": None if above else landed,
                "error_m": None if above else error,
                "worst_bearing_deg": float(np.rad2deg(views[worst]["bearing"])),
            }
        rows.append(row)
    return rows


def predicted_ground_std(
    robot: Robot,
    camera: CameraModel,
    chain: ParameterSet,
    values: np.ndarray,
    covariance: np.ndarray,
    distance: float,
) -> float:
    """1-sigma ground error at `distance` [m] that the fit's covariance (P, P) of the chain parameter `values` (P,)
    [SI] implies: sqrt(trace(J C J^T)) of the landing point on the floor, worst bearing (J by central differences)."""
    model = chain.corrections(values)
    worst = 0.0
    for view in ball_views(robot, camera, model, distance):
        J = np.zeros((2, len(values)))
        for i in range(len(values)):
            step = np.zeros(len(values))
            step[i] = 1e-6
            plus = ground_point(robot, view["q"], chain.corrections(values + step), view["uv"], camera)
            minus = ground_point(robot, view["q"], chain.corrections(values - step), view["uv"], camera)
            J[:, i] = (plus[:2] - minus[:2]) / 2e-6
        if not np.all(np.isfinite(J)):
            return float("inf")
        worst = max(worst, float(np.sqrt(np.trace(J @ covariance @ J.T))))
    return worst
