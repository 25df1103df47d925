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
from wolfcal.errors import WolfcalError
from wolfcal.geometry import invert_transform
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.floor import floor_frames
from wolfcal.robot.parameters import ParameterSet
from wolfcal.robot.robot import Robot

DISTANCES_M = (1.0, 2.0, 4.5, 9.0)
BEARINGS_RAD = tuple(np.deg2rad((-30.0, 0.0, 30.0)))
VERDICT_DISTANCE_M = 4.5  # half a field: the distance the deploy verdict judges
AIM_REFINEMENTS = 12  # of the head aim after the coarse grid (see aim_head)


# why `floor:` is needed, for the error that names the robot config when it is missing
FLOOR_NEEDED = "the ground error needs its soles and standing pose: add floor: {soles: [...], standing: {...}}"


def standing_pose(robot: Robot) -> np.ndarray:
    """(J,) encoder readings of the standing robot: the config's `floor.standing`, other joints 0 [rad]."""
    q = np.zeros(len(robot.joint_names))
    for name, value in robot.config.floor_config(FLOOR_NEEDED).standing.items():
        q[robot.model.column(name)] = value
    return q


def camera_in_floor(
    robot: Robot, q: np.ndarray, corrections: Corrections, camera_frame: str | None = None
) -> tuple[np.ndarray, np.ndarray]:
    """T_floor_camera (N, 4, 4) and T_floor_base (N, 4, 4) for readings q (N, J) under a model."""
    frame = camera_frame or robot.config.head_camera("the ground error needs the head camera").frame
    soles = list(robot.config.floor_config(FLOOR_NEEDED).soles)
    poses = robot.model.link_poses(q, [frame, *soles], corrections, base=robot.config.base_link)
    T_floor_base = invert_transform(floor_frames(np.stack([poses[s] for s in soles])))
    return T_floor_base @ poses[frame], T_floor_base


def aim_joints(robot: Robot) -> list[str]:
    """The joints that aim the camera: the last two movable joints between base and camera (pan, tilt), or one."""
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


def aim_head(robot: Robot, reference: Corrections, ball: np.ndarray) -> np.ndarray:
    """(J,) standing readings with pan/tilt set so that the reference model's optical axis points at the ball."""
    q0 = standing_pose(robot)
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
    robot: Robot, camera: CameraModel, chain: ParameterSet, values: np.ndarray, covariance: np.ndarray,
    distance: float = VERDICT_DISTANCE_M,
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
