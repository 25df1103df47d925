"""Random reachable robot poses in which the head camera sees at least one tag well.

Joint values are true angles [rad]. Candidates are drawn in batches (vectorised FK and projection) and kept when a
tag lies fully inside the image with a margin, faces the camera (less than 60 deg off the viewing ray) and
appears large enough to detect.
"""

from __future__ import annotations

import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.errors import WolfcalError
from wolfcal.projection import visible_in_view
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.ranges import sampling_bounds
from wolfcal.robot.robot import Robot


def tag_visibility(
    robot: Robot,
    camera: CameraModel,
    q_true: np.ndarray,
    truth: Corrections,
    tag_ids: list[int],
    margin_px: float,
    min_size_px: float,
    max_angle_rad: float = np.deg2rad(60.0),
) -> np.ndarray:
    """(N, T) bool: tag t is well visible to the head camera in pose n (q_true are true angles: no offsets)."""
    true_frames = Corrections(frames=truth.frames, tags=truth.tags)
    _, T_camera_tag = robot.camera_and_tag_poses(q_true, tag_ids, true_frames)
    sizes = np.array([robot.config.tag(t).size for t in tag_ids])
    return visible_in_view(camera, T_camera_tag, sizes, margin_px, min_size_px, max_angle_rad)


def random_visible_poses(
    robot: Robot,
    camera: CameraModel,
    truth: Corrections,
    n: int,
    rng: np.random.Generator,
    tag_ids: list[int] | None = None,
    margin_px: float | None = None,
    min_size_px: float | None = None,
) -> tuple[np.ndarray, np.ndarray]:
    """n true joint configurations (n, J) and their visibility (n, T) of `tag_ids` (default: all tags)."""
    tag_ids = tag_ids or robot.config.tag_ids
    margin_px = 0.03 * camera.width if margin_px is None else margin_px
    min_size_px = 0.02 * camera.width if min_size_px is None else min_size_px
    lo, hi = sampling_bounds(robot, "head")

    def visibility(q: np.ndarray) -> np.ndarray:
        return tag_visibility(robot, camera, q, truth, tag_ids, margin_px, min_size_px)

    q = draw_accepted(lo, hi, n, rng, lambda q: np.any(visibility(q), axis=1),
                      f"a tag is in view; check the tags and camera of {robot.config.path}")  # fmt: skip
    return q, visibility(q)


def draw_accepted(lo: np.ndarray, hi: np.ndarray, n: int, rng: np.random.Generator, accept, what: str) -> np.ndarray:
    """n configurations (n, J) drawn uniformly in [lo, hi] for which `accept` ((N, J) -> (N,) bool) holds."""
    kept: list[np.ndarray] = []
    for _ in range(200):
        q = rng.uniform(lo, hi, size=(4000, len(lo)))
        kept.append(q[accept(q)])
        if sum(len(k) for k in kept) >= n:
            break
    q = np.concatenate(kept)[:n]
    if len(q) < n:
        raise WolfcalError(f"the simulator found only {len(q)} of {n} poses in which {what}")
    return q
