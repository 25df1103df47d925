"""What an external camera at T_base_camera sees of a robot on its stand (base fixed): the rule the simulator draws
leg poses by and pose planning keeps its candidates by.

Joint values are true angles [rad] (readings under the nominal model for a plan). A pose is good when the external
camera sees the torso tag (every tag on a link the legs do not move) and at least one foot tag fully inside the
image (margin 2 % of the width), at least 1.5 % of the width per edge, facing it (less than `MAX_ANGLE_RAD` off the
viewing ray), and apart from every other tag in the image (bounding boxes grown by `SEPARATION` of their size must
not overlap: a foot tag lifted in front of the torso tag would hide it or break its white border). The Wolfgang's
foot tags lie face up on plates ahead of the feet, so a camera in front sees them well only when the feet are lifted
forward and tilted towards it (the simulator draws the legs from the config's `sampling_ranges.external`). Occlusion
by the robot's body is not modelled here (planning adds it: `wolfcal.plan.candidates`).
"""

from __future__ import annotations

import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.errors import WolfcalError
from wolfcal.geometry import invert_transform, tag_corners, transform_points
from wolfcal.projection import tag_corner_pixels, visible_in_view
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import Robot

MAX_ANGLE_RAD = np.deg2rad(55.0)
SEPARATION = 0.3  # share of a tag's image size kept free around it


def base_tag_ids(robot: Robot) -> list[int]:
    """The tags on links the legs do not move (`Robot.off_the_legs`): the torso tag, also behind waist joints."""
    return [t.id for t in robot.config.tags if robot.off_the_legs(t.link)]


def external_tag_poses(
    robot: Robot, T_base_camera: np.ndarray, q_true: np.ndarray, truth: Corrections, tag_ids: list[int]
) -> np.ndarray:
    """(N, T, 4, 4) T_camera_tag of the external camera for true angles q_true (N, J), true frames and tag mounts."""
    frames = Corrections(frames=truth.frames, tags=truth.tags)
    links = sorted({robot.config.tag(t).link for t in tag_ids})
    poses = robot.model.link_poses(np.atleast_2d(q_true), links, frames, base=robot.config.base_link)
    T_camera_base = invert_transform(T_base_camera)
    if not tag_ids:
        return np.zeros((len(np.atleast_2d(q_true)), 0, 4, 4))
    return np.stack(
        [T_camera_base @ poses[robot.config.tag(t).link] @ robot.T_link_tag(t, frames) for t in tag_ids], axis=1
    )


def external_visibility(
    robot: Robot, camera: CameraModel, T_base_camera: np.ndarray, q_true: np.ndarray, truth: Corrections
) -> np.ndarray:
    """(N, T) bool over robot.config.tag_ids: tag well visible to the external camera (see the module docstring)."""
    tag_ids = robot.config.tag_ids
    T_camera_tag = external_tag_poses(robot, T_base_camera, q_true, truth, tag_ids)
    sizes = np.array([robot.config.tag(t).size for t in tag_ids])
    visible = visible_in_view(camera, T_camera_tag, sizes, 0.02 * camera.width, 0.015 * camera.width, MAX_ANGLE_RAD)
    return visible & _apart(camera, T_camera_tag, sizes)


def _apart(camera: CameraModel, T_camera_tag: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """(N, T) bool: the tag's grown image box overlaps no other tag's in front of the camera."""
    corners = np.stack([tag_corners(s) for s in sizes])  # (T, 4, 3)
    in_front = np.all(transform_points(T_camera_tag, corners)[..., 2] > 0, axis=-1)  # (N, T)
    uv = tag_corner_pixels(camera, T_camera_tag, corners)  # NaN behind the camera
    uv = np.where(in_front[:, :, None, None], uv, 0.0)  # a tag behind the camera overlaps nothing (masked below)
    lo, hi = uv.min(axis=2), uv.max(axis=2)  # (N, T, 2)
    grow = SEPARATION * (hi - lo).max(axis=-1, keepdims=True)
    lo, hi = lo - grow, hi + grow
    overlap = np.all((lo[:, :, None] < hi[:, None, :]) & (lo[:, None, :] < hi[:, :, None]), axis=-1)  # (N, T, T)
    overlap &= in_front[:, :, None] & in_front[:, None, :]
    overlap[:, np.arange(len(sizes)), np.arange(len(sizes))] = False
    return ~np.any(overlap, axis=2)


def external_pose_ok(robot: Robot, visible: np.ndarray) -> np.ndarray:
    """(N,) bool: every tag off the legs and at least one other tag visible (visible: (N, T) over config.tag_ids)."""
    fixed = np.isin(robot.config.tag_ids, base_tag_ids(robot))
    if not fixed.any():
        raise WolfcalError(
            f"{robot.config.path}: no tag on a link the legs do not move (e.g. a torso tag); an external camera "
            "needs one to tell the robot's pose"
        )
    return np.all(visible[:, fixed], axis=1) & np.any(visible[:, ~fixed], axis=1)
