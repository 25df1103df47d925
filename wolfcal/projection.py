"""Where a kinematic model puts tag corners in a camera image: the one projection of fit, evaluation, simulation and
pose planning.

Frames: T_camera_tag (..., 4, 4) maps points in a tag's frame (aruco convention, `tag_corners`) to the camera's optical
frame (z forward, x right, y down) [m]; pixels follow OpenCV (centre of the top-left pixel at (0, 0)).
"""

from __future__ import annotations

import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.config import RobotConfig
from wolfcal.encoders import encoder_readings
from wolfcal.geometry import tag_corners, transform_points
from wolfcal.observations import HEAD_CAMERA, Observations
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import Robot

BEHIND_CAMERA_PX = 1e4  # residual given to a corner that a model puts behind the camera [px]


def tag_corner_table(config: RobotConfig, tag_ids: list[int]) -> np.ndarray:
    """(T, 4, 3) the four corners of each tag in its own frame (aruco order) [m]."""
    return np.stack([tag_corners(config.tag(t).size) for t in tag_ids])


def tag_corner_pixels(camera: CameraModel, T_camera_tag: np.ndarray, corners: np.ndarray) -> np.ndarray:
    """(..., 4, 2) pixels of tag corners `corners` (..., 4, 3) [m] under the poses T_camera_tag (..., 4, 4)
    (broadcast); NaN behind the camera."""
    return camera.project(transform_points(T_camera_tag, corners))


def visible_in_view(
    camera: CameraModel,
    T_camera_tag: np.ndarray,
    sizes: np.ndarray,
    margin_px: float,
    min_size_px: float,
    max_angle_rad: float = np.deg2rad(60.0),
) -> np.ndarray:
    """(N, T) bool: tag t (edge `sizes[t]` [m], pose T_camera_tag (N, T, 4, 4)) lies fully inside the image with a
    margin, appears at least `min_size_px` per edge and faces the camera (less than `max_angle_rad` off the ray)."""
    corners = np.stack([tag_corners(s) for s in sizes])  # (T, 4, 3)
    uv = tag_corner_pixels(camera, T_camera_tag, corners)  # (N, T, 4, 2)
    inside = np.all(camera.in_image(uv, margin_px), axis=-1)
    edges = np.linalg.norm(uv - np.roll(uv, 1, axis=2), axis=-1)
    big = np.nan_to_num(np.min(edges, axis=-1), nan=0.0) >= min_size_px
    normal = T_camera_tag[..., :3, 2]
    to_camera = -T_camera_tag[..., :3, 3]
    cos = np.sum(normal * to_camera, axis=-1) / np.linalg.norm(to_camera, axis=-1)
    return inside & big & (cos > np.cos(max_angle_rad))


def observations_from_poses(
    robot: Robot,
    camera: CameraModel,
    truth: Corrections,
    q_true: np.ndarray,
    T_camera_tag: np.ndarray,
    visible: np.ndarray,
    noise_px: float,
    rng: np.random.Generator,
    camera_name: str = HEAD_CAMERA,
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
    return Observations.of_views(
        list(robot.joint_names),
        encoder_readings(q_true, truth.offset_vector(robot.joint_names)),
        np.arange(n, dtype=np.int64),
        sources or ["synthetic"] * n,
        camera,
        s_idx,
        np.array(tag_ids)[t_idx],
        uv,
        camera_name,
    )


def pixel_jacobian(camera: CameraModel, p_camera: np.ndarray) -> np.ndarray:
    """(M, 2, 3) d(pixel)/d(point in the optical frame) by central differences [px/m] (the six shifted copies of
    the points projected in one call)."""
    h = 1e-6 * np.maximum(np.abs(p_camera[:, 2]), 1e-3)
    steps = np.einsum("m,ks->kms", h, np.concatenate([np.eye(3), -np.eye(3)]))  # (6, M, 3): +h, then -h per axis
    uv = camera.project(p_camera[None] + steps)  # (6, M, 2)
    return np.moveaxis((uv[:3] - uv[3:]) / (2 * h[None, :, None]), 0, 2)


def tag_pose_from_pixels(camera: CameraModel, uv: np.ndarray, size: float) -> np.ndarray | None:
    """T_camera_tag (4, 4) measured from the four detected corners (4, 2) [px] of one tag of edge `size` [m] alone
    (cv2.solvePnP, SOLVEPNP_IPPE_SQUARE, on undistorted normalised points), or None when PnP fails."""
    import cv2  # here, not at the top: a fit from cached detections does not load OpenCV

    xy = camera.undistort_normalized(camera.pixels_to_normalized(uv))
    ok, rvec, tvec = cv2.solvePnP(
        tag_corners(size), xy.reshape(4, 1, 2), np.eye(3), None, flags=cv2.SOLVEPNP_IPPE_SQUARE
    )
    if not ok:
        return None
    T = np.eye(4)
    T[:3, :3] = cv2.Rodrigues(rvec)[0]
    T[:3, 3] = tvec.ravel()
    return T


def tag_pose_from_corners(robot: Robot, obs: Observations, sample: int, tag_id: int) -> np.ndarray | None:
    """T_camera_tag (4, 4) of one tag in one sample from its four detected corners (`tag_pose_from_pixels`), or
    None when the tag was not fully detected or PnP failed."""
    rows = np.flatnonzero((obs.sample_index == sample) & (obs.tag_ids == tag_id))
    if len(rows) != 4:
        return None
    rows = rows[np.argsort(obs.corner_index[rows])]
    return tag_pose_from_pixels(obs.camera, obs.uv[rows], robot.config.tag(tag_id).size)


def corner_points(robot: Robot, obs: Observations, tag_ids: list[int]) -> tuple[np.ndarray, np.ndarray]:
    """Per observed corner: its column in `tag_ids` (M,) and its position in its tag frame (M, 3) [m]."""
    column = {t: i for i, t in enumerate(tag_ids)}
    tag_col = np.array([column[int(t)] for t in obs.tag_ids], dtype=int)
    return tag_col, tag_corner_table(robot.config, tag_ids)[tag_col, obs.corner_index]


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
