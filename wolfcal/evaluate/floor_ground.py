"""The measured ground error: held-out views of the floor tags, without truth.

Each view (one floor tag in one sample) gives the rays through its four corner pixels, in the model's floor frame
(`ground.camera_in_floor`, at the sample's joint readings). The real floor is the model's floor tilted and lifted:
T_model_real = Trans(0, 0, dz) @ Rx(rx) @ Ry(ry) about the model floor's origin (midway between the soles). The
three plane unknowns and each tag's place (x, y, yaw) are fitted by least squares so that the rays meet the real
floor (at the tag's thickness) in the tag's printed corners: a model whose floor is tilted against the camera
stretches far tags and bends their rows, which the printed size and the views from several head angles reveal.
The ground error at distance D (1, 2, 4.5, 9 m) is then the ground error of `evaluate.ground` against that real
floor: the ball at D on the real floor, the ray from the standing camera (head aimed at it) through it, met with
the model's floor; the worst of the bearings -30, 0, +30 deg [m], with its 1-sigma uncertainty from the plane
unknowns' covariance (residual scatter). Distances beyond the views' are extrapolated by the plane (said in the
report). A turn or shift of the floor within its plane is not seen (the tags' places are unknown), nor errors that
change with the head angle (the plane is one for all samples).
"""

from __future__ import annotations

import numpy as np
from scipy.optimize import least_squares

from wolfcal.evaluate.ground import BEARINGS_RAD, DISTANCES_M, aim_head, ball_position, camera_in_floor
from wolfcal.geometry import exp_so3, invert_transform
from wolfcal.observations import Observations
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import Robot
from wolfcal.vision.tags import tag_corners

MIN_VIEWS = 6  # fewer floor-tag views than this measure no ground error


def floor_view_rays(robot: Robot, obs: Observations, model: Corrections) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Views with all 4 corners: their tag ids (V,), the model's T_floor_camera (V, 4, 4) and the corner rays
    (V, 4, 3) in the camera frame."""
    order = np.lexsort((obs.corner_index, obs.tag_ids, obs.sample_index))
    s, t, uv = obs.sample_index[order], obs.tag_ids[order], obs.uv[order]
    key = s.astype(np.int64) * 1_000_000 + t
    _, start, count = np.unique(key, return_index=True, return_counts=True)
    start = start[count == 4]
    rows = start[:, None] + np.arange(4)
    T_floor_camera, _ = camera_in_floor(robot, obs.q_measured, model)
    T = T_floor_camera[s[start]]  # (V, 4, 4)
    return t[start], T, obs.camera.unproject(uv[rows])


def _plane(values: np.ndarray) -> np.ndarray:
    """T_model_real (4, 4) of plane unknowns (rx, ry, dz) [rad, m]."""
    T = np.eye(4)
    T[:3, :3] = exp_so3(np.array([values[0], values[1], 0.0]))
    T[2, 3] = values[2]
    return T


def _real_camera(unknowns: np.ndarray, T_floor_camera: np.ndarray) -> np.ndarray:
    """T_real_camera (..., 4, 4): the model's camera turned by the camera rotation unknowns[3:6], in the real floor
    (plane unknowns[:3])."""
    C = np.eye(4)
    C[:3, :3] = exp_so3(unknowns[3:6])
    return invert_transform(_plane(unknowns[:3])) @ T_floor_camera @ C


def _meet(T_real_model: np.ndarray, origins: np.ndarray, rays: np.ndarray, height: np.ndarray) -> np.ndarray:
    """(..., 2) where rays (..., 3) from origins (..., 3), model floor frame, meet the real floor's plane z = height
    (...,), in real floor coordinates [m]; NaN above the horizon."""
    o = origins @ T_real_model[:3, :3].T + T_real_model[:3, 3]
    r = rays @ T_real_model[:3, :3].T
    with np.errstate(divide="ignore", invalid="ignore"):
        s = (height - o[..., 2]) / r[..., 2]
    s = np.where(s > 0, s, np.nan)
    return o[..., :2] + s[..., None] * r[..., :2]


def real_floor(robot: Robot, obs: Observations, model: Corrections) -> dict | None:
    """The plane unknowns (3,) [rad, rad, m], their covariance (3, 3) and the views' count; None with fewer
    than MIN_VIEWS views or a floor tag seen only once."""
    tags, T_floor_camera, camera_rays = floor_view_rays(robot, obs, model)
    ids, inverse, counts = np.unique(tags, return_inverse=True, return_counts=True)
    if len(tags) < MIN_VIEWS or counts.min() < 2:
        return None
    printed = np.stack([tag_corners(robot.config.floor_config().tag(int(i)).size)[:, :2] for i in ids])  # (T, 4, 2)
    height = np.array([robot.config.floor_config().tag(int(i)).thickness for i in ids])[inverse][:, None]

    def meet(x: np.ndarray) -> np.ndarray:
        T = _real_camera(x, T_floor_camera)
        rays = np.einsum("vij,vcj->vci", T[:, :3, :3], camera_rays)
        return _meet(np.eye(4), np.repeat(T[:, None, :3, 3], 4, axis=1), rays, height)

    start_corners = meet(np.zeros(6))
    start = np.zeros((len(ids), 3))
    for k in range(len(ids)):  # tag places under the model's floor: centre and yaw of the first view
        first = start_corners[inverse == k][0]
        edge = first[1] - first[0]
        start[k] = [*first.mean(axis=0), np.arctan2(edge[1], edge[0])]

    def residuals(x: np.ndarray) -> np.ndarray:
        seen = meet(x)
        place = x[6:].reshape(-1, 3)[inverse]
        c, s = np.cos(place[:, 2]), np.sin(place[:, 2])
        p = printed[inverse]
        expected = np.stack([place[:, None, 0] + c[:, None] * p[..., 0] - s[:, None] * p[..., 1],
                             place[:, None, 1] + s[:, None] * p[..., 0] + c[:, None] * p[..., 1]], axis=-1)
        return np.nan_to_num((seen - expected).ravel(), nan=1.0)

    fit = least_squares(residuals, np.concatenate([np.zeros(6), start.ravel()]), x_scale="jac")
    J, r = fit.jac, fit.fun
    dof = max(len(r) - len(fit.x), 1)
    covariance = np.linalg.pinv(J.T @ J) * float(r @ r) / dof
    return {"unknowns": fit.x[:6], "covariance": covariance[:6, :6], "views": len(tags)}


def _aimed(robot: Robot, model: Corrections, distance: float, bearing: float) -> tuple[np.ndarray, np.ndarray]:
    """The model's T_floor_camera and T_floor_base (1, 4, 4) with the head aimed at the ball."""
    q = aim_head(robot, model, ball_position(robot, model, distance, bearing))
    return camera_in_floor(robot, q[None], model)


def _landing_error(unknowns: np.ndarray, aimed: tuple[np.ndarray, np.ndarray], distance: float,
                   bearing: float) -> float:  # fmt: skip
    """Ground error [m] of the model (camera aimed: `_aimed`) against the real floor and camera (`unknowns`) for
    a ball `distance` m away at `bearing`; NaN above the model's horizon."""
    T_model_real = _plane(unknowns[:3])
    T_floor_camera, T_floor_base = aimed
    below = (invert_transform(T_model_real) @ T_floor_base[0, :, 3])[:2]  # point below base, real floor coordinates
    ball = np.array([*(below + distance * np.array([np.cos(bearing), np.sin(bearing)])), 0.0, 1.0])
    ray_camera = (invert_transform(_real_camera(unknowns, T_floor_camera[0])) @ ball)[:3]
    landed = _meet(np.eye(4), T_floor_camera[0, :3, 3], T_floor_camera[0, :3, :3] @ ray_camera, np.array(0.0))
    return float(np.linalg.norm(landed - ball[:2]))


def measured_ground_errors(
    robot: Robot, obs: Observations, models: dict[str, Corrections], distances: tuple[float, ...] = DISTANCES_M
) -> dict | None:
    """Per model: per distance the measured ground error [m] (worst bearing; None: the ball lies above the model's
    horizon) and its 1-sigma [m]; the views' count. None when the floor views cannot measure it (too few views,
    or a tag seen once)."""
    out: dict = {"models": {}}
    for name, model in models.items():
        floor = real_floor(robot, obs, model)
        if floor is None:
            return None
        rows = []
        for distance in distances:
            worst = (-1.0, 0.0)
            for bearing in BEARINGS_RAD:
                x, aimed = floor["unknowns"], _aimed(robot, model, distance, bearing)
                error = _landing_error(x, aimed, distance, bearing)
                grad = np.zeros(6)
                for i in range(6):
                    step = np.zeros(6)
                    step[i] = 1e-6
                    grad[i] = (_landing_error(x + step, aimed, distance, bearing)
                               - _landing_error(x - step, aimed, distance, bearing)) / 2e-6
                if not np.isfinite(error):  # the ball lies above the model's horizon
                    worst = (np.inf, np.nan)
                    break
                worst = max(worst, (error, float(np.sqrt(grad @ floor["covariance"] @ grad))))
            finite = bool(np.isfinite(worst[0]))
            rows.append({"distance_m": distance, "error_m": worst[0] if finite else None,
                         "std_m": worst[1] if finite else None})
        out["models"][name] = {"rows": rows, "unknowns": [float(v) for v in floor["unknowns"]]}
        out["views"] = floor["views"]
    return out
