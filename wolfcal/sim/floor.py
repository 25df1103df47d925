"""Synthetic floor samples without images: the robot stands, turns its head, and sees tags lying on the floor.

The robot stands at the true joint angles of its config's stances (`floor.stances`, default `floor.standing`; the
samples spread evenly over them, one stance after the other); in each the soles of the true model lie on one plane,
the floor, with the feet where they were; its encoders report those angles minus the true offsets. Floor tags lie
face up at random places `distance` m ahead (within +-35 deg of the floor's x axis) with random yaw. Head pan/tilt
(the two joints before the camera) are drawn so that each sample sees at least one floor tag whole, `margin_px`
inside the image, each edge at least `min_edge_px` long: the project's one rule of a view
(`wolfcal.projection.visible_in_view`) with no angle limit, as pose planning takes it (`wolfcal.plan.floor`), since
a tag on the floor is seen at a grazing angle.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.encoders import encoder_readings
from wolfcal.errors import WolfcalError
from wolfcal.geometry import tag_corners, transform_points
from wolfcal.observations import Observations
from wolfcal.projection import tag_corner_pixels, visible_in_view
from wolfcal.robot.aim import aim_joints
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.floor import camera_in_floor, floor_tag_poses, stance_poses
from wolfcal.robot.robot import Robot
from wolfcal.vision.render import PlanarTarget, render_targets
from wolfcal.vision.tags import tag_texture, tag_texture_width


@dataclass
class FloorScene:
    obs: Observations  # head-camera corners of the floor tags
    places: dict[int, np.ndarray]  # true (x, y, yaw) of each floor tag in the true floor frame [m, rad]
    q_true: np.ndarray  # (S, J) [rad]


def floor_corners(robot: Robot, places: dict[int, np.ndarray]) -> dict[int, np.ndarray]:
    """(4, 3) corners of each floor tag in the floor frame [m], aruco order."""
    return {t: transform_points(T_floor_tag, tag_corners(robot.config.floor_config().tag(t).size))
            for t, T_floor_tag in floor_tag_poses(robot, places).items()}  # fmt: skip


@dataclass
class FloorViews:
    places: dict[int, np.ndarray]  # true (x, y, yaw) of each floor tag in the true floor frame [m, rad]
    q_true: np.ndarray  # (S, J) [rad]
    visible: np.ndarray  # (S, T) bool over config floor.tag_ids: `visible_in_view` (module docstring)
    uv: np.ndarray  # (S, T, 4, 2) true corner pixels
    T_camera_floor: np.ndarray  # (S, 4, 4) true


def floor_views(
    robot: Robot,
    camera: CameraModel,
    truth: Corrections,
    n: int,
    rng: np.random.Generator,
    distance: tuple[float, float] = (1.0, 4.0),
    min_edge_px: float = 12.0,
    margin_px: float = 10.0,
    check: bool = False,
) -> FloorViews:
    """Places of the floor tags and n standing poses (the stances one after the other; `check`: the check's,
    `floor.check_stances`) with head pan/tilt that see at least one of them whole (module docstring); margin and
    edge in pixels."""
    floor = robot.config.floor_config()
    ids = floor.tag_ids
    r = rng.uniform(*distance, len(ids))
    bearing = rng.uniform(-0.6, 0.6, len(ids))
    places = {t: np.array([r[k] * np.cos(bearing[k]), r[k] * np.sin(bearing[k]), rng.uniform(-np.pi, np.pi)])
              for k, t in enumerate(ids)}  # fmt: skip
    joints = [robot.model.joints[j] for j in aim_joints(robot)]
    columns = [robot.model.column(j.name) for j in joints]
    stances = stance_poses(robot, check)
    stance_of = np.arange(4000) % len(stances)
    q = stances[stance_of]
    for j, col in zip(joints, columns):
        q[:, col] = rng.uniform(max(j.lower, -1.2), min(j.upper, 1.2), len(q))
    T_floor_camera, _ = camera_in_floor(robot, q, Corrections(frames=truth.frames, tags=truth.tags))  # true angles
    T_camera_floor = np.linalg.inv(T_floor_camera)
    tag_poses = floor_tag_poses(robot, places)
    T_camera_tag = T_camera_floor[:, None] @ np.stack([tag_poses[t] for t in ids])[None]  # (S, T, 4, 4)
    sizes = np.array([floor.tag(t).size for t in ids])
    visible = visible_in_view(camera, T_camera_tag, sizes, margin_px, min_edge_px, np.pi / 2)  # (S, T)
    uv = tag_corner_pixels(camera, T_camera_tag, np.stack([tag_corners(s) for s in sizes]))  # (S, T, 4, 2)
    picked = []
    for k, m in enumerate(np.diff(np.linspace(0, n, len(stances) + 1).round().astype(int))):  # n spread evenly
        candidates = np.flatnonzero(visible.any(axis=1) & (stance_of == k))
        if len(candidates) < m:
            raise WolfcalError(f"{robot.config.path}: only {len(candidates)} of {np.sum(stance_of == k)} head "
                               f"pan/tilt poses in stance {k} see a floor tag whole and at least {min_edge_px:.0f} "
                               f"px wide; asked for {m} floor samples in it")  # fmt: skip
        picked.append(rng.choice(candidates, size=m, replace=False))
    chosen = np.concatenate(picked)
    return FloorViews(places, q[chosen], visible[chosen], uv[chosen], T_camera_floor[chosen])


def simulate_floor(
    robot: Robot,
    camera: CameraModel,
    truth: Corrections,
    n: int,
    rng: np.random.Generator,
    distance: tuple[float, float] = (1.0, 4.0),
    noise_px: float = 0.15,
    min_edge_px: float = 12.0,
    margin_px: float = 10.0,
    source: str = "floor.mcap",
) -> FloorScene:
    """n floor samples (see the module docstring) with Gaussian corner noise [px]."""
    ids = robot.config.floor_config().tag_ids
    views = floor_views(robot, camera, truth, n, rng, distance, min_edge_px, margin_px)
    q_true, vis, uv = views.q_true, views.visible, views.uv
    s_idx, t_idx = np.nonzero(vis)
    detected = uv[s_idx, t_idx] + rng.normal(0.0, noise_px, (len(s_idx), 4, 2))
    obs = Observations.of_views(
        list(robot.joint_names),
        encoder_readings(q_true, truth.offset_vector(robot.joint_names)),
        np.arange(len(q_true), dtype=np.int64) + 10**6,
        [source] * len(q_true),
        camera,
        s_idx,
        np.array(ids)[t_idx],
        detected,
    )
    return FloorScene(obs, views.places, q_true)


def floor_targets(robot: Robot, places: dict[int, np.ndarray], T_camera_floor: np.ndarray) -> list[PlanarTarget]:
    """The floor tags in front of a camera at T_camera_floor (4, 4), each lying at its place (x, y, yaw) [m, rad]."""
    targets = []
    for tag_id, T_floor_tag in floor_tag_poses(robot, places).items():
        T_camera_tag = T_camera_floor @ T_floor_tag
        if T_camera_tag[2, 3] <= 0.05:
            continue
        tag = robot.config.floor_config().tag(tag_id)
        texture = tag_texture(tag.family, tag_id)
        width = tag_texture_width(tag.family, tag.size, texture)
        targets.append(PlanarTarget(T_camera_tag, texture, width, width))
    return targets


def render_floor(robot: Robot, camera: CameraModel, views: FloorViews, i: int, noise_sigma: float,
                 rng: np.random.Generator) -> np.ndarray:  # fmt: skip
    """Gray uint8 image of sample i: every floor tag in front of the camera, rendered at its true place."""
    targets = floor_targets(robot, views.places, views.T_camera_floor[i])
    return render_targets(camera, targets, noise_sigma=noise_sigma, rng=rng)
