"""Where the robot stands on the field, before the fit: a search around the configured place.

The line points of a placement's views are put on the floor through the nominal model with the camera pitched
(`pitched`) by each of `pitches` (a camera several degrees off moves far points by metres: the grid spans
PITCH_REACH standard deviations of the config's camera rotation prior); each candidate pose (x, y, yaw) of the
floor frame on the field is scored by the mean distance of those points from the nearest line, truncated at
`TRUNCATE_M` (points on no line count alike, and so do points whose rays miss the floor at that pitch: a pitch
that lifts the far points above the horizon is not scored on the near ones alone), looked up in a distance map of
the field at `RASTER_M`. A coarse
grid around `field.robot_at` for every pitch, then a finer one around the best. The field is point-symmetric: the
mirrored pose scores the same, so the search stays on the configured half. The fit starts at the place found and
with the camera at the pitch found (`wolfcal.fit.field_fit`).
"""

from __future__ import annotations

from dataclasses import dataclass

import cv2
import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.field.ground import ground_points
from wolfcal.field.model import FieldLines
from wolfcal.field.observations import FieldObservations
from wolfcal.field.scene import BORDER_STRIP
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.floor import camera_in_floor
from wolfcal.robot.robot import Robot

FAR_FROM_CONFIGURED = (0.45, np.deg2rad(15.0))  # [m, rad]: a place further from the config's is said

RASTER_M = 0.02  # distance map resolution [m]
TRUNCATE_M = 0.25  # a point further from every line than this counts as this far [m]
SEARCH_M = 0.6  # the coarse grid reaches this far from the configured place [m]
SEARCH_YAW = np.deg2rad(20.0)
PITCH_STEP = np.deg2rad(1.0)  # between the camera pitch corrections tried [rad]
PITCH_REACH = 3.0  # the pitches tried reach this many of the camera rotation prior's std either way
COARSE_POINTS = 400  # points the coarse grid scores
OFF_FIELD = 1e6  # where a point whose ray misses the floor is put: beyond every line [m]


@dataclass(frozen=True)
class PlaceSearch:
    """The search's outcome for one placement."""

    pose: np.ndarray  # (3,) best x, y [m], yaw [rad]
    pitch: float  # the camera pitch correction that placed the points best [rad]
    score_m: float  # mean truncated distance of the points at the best pose [m]
    configured_score_m: float  # the same at the configured place [m]


class DistanceMap:
    """Distance [m] from the nearest line of a field, on a raster covering the carpet."""

    def __init__(self, lines: FieldLines) -> None:
        extent = np.abs(lines.segments).max(axis=(0, 1)) + BORDER_STRIP
        self.origin = -extent
        size = np.ceil(2 * extent / RASTER_M).astype(int) + 1
        canvas = np.full((size[1], size[0]), 255, np.uint8)
        for start, end in lines.segments:
            a, b = self._pixel(start), self._pixel(end)
            cv2.line(canvas, (int(a[0]), int(a[1])), (int(b[0]), int(b[1])), 0, 1)
        centre = self._pixel(np.zeros(2))
        cv2.circle(canvas, (int(centre[0]), int(centre[1])), int(round(lines.circle_radius / RASTER_M)), 0, 1)
        self.distance = cv2.distanceTransform(canvas, cv2.DIST_L2, 5) * RASTER_M

    def _pixel(self, points: np.ndarray) -> np.ndarray:
        return np.round((np.asarray(points) - self.origin) / RASTER_M).astype(int)

    def truncated_mean(self, points: np.ndarray) -> np.ndarray:
        """Mean over the last-but-one axis of each point set's truncated distance; points (..., N, 2) [m]."""
        pixel = np.floor((points - self.origin) / RASTER_M + 0.5).astype(int)
        h, w = self.distance.shape
        inside = (pixel[..., 0] >= 0) & (pixel[..., 0] < w) & (pixel[..., 1] >= 0) & (pixel[..., 1] < h)
        d = self.distance[np.clip(pixel[..., 1], 0, h - 1), np.clip(pixel[..., 0], 0, w - 1)]
        return np.where(inside, np.minimum(d, TRUNCATE_M), TRUNCATE_M).mean(axis=-1)


def pitches(robot: Robot) -> np.ndarray:
    """(K,) the camera pitch corrections the search tries [rad]: 0 and every PITCH_STEP out to PITCH_REACH times
    the config's camera rotation prior either way."""
    steps = int(PITCH_REACH * robot.config.priors.camera_rotation / PITCH_STEP)
    return PITCH_STEP * np.arange(-steps, steps + 1)


def pitched(robot: Robot, pitch: float) -> Corrections:
    """The nominal model with the head camera pitched by `pitch` [rad]: turned about its optical x axis (right),
    positive up."""
    return Corrections(frames={robot.camera_joint: np.array([0.0, 0.0, 0.0, pitch, 0.0, 0.0])})


def _placed(ground: np.ndarray, poses: np.ndarray) -> np.ndarray:
    """(K, N, 2) field points of floor points (N, 2) for floor-frame poses (K, 3) on the field."""
    c, s = np.cos(poses[:, 2])[:, None], np.sin(poses[:, 2])[:, None]
    x = poses[:, 0:1] + c * ground[None, :, 0] - s * ground[None, :, 1]
    y = poses[:, 1:2] + s * ground[None, :, 0] + c * ground[None, :, 1]
    return np.stack([x, y], axis=-1)


def _grid(centre: np.ndarray, reach: float, yaw_reach: float, steps: int) -> np.ndarray:
    axes = (np.linspace(-r, r, steps) for r in (reach, reach, yaw_reach))
    return centre + np.stack(np.meshgrid(*axes, indexing="ij"), axis=-1).reshape(-1, 3)


def _best(field: DistanceMap, ground: np.ndarray, candidates: np.ndarray) -> tuple[np.ndarray, float]:
    scores = np.concatenate([field.truncated_mean(_placed(ground, chunk))
                             for chunk in np.array_split(candidates, max(1, len(candidates) // 256))])  # fmt: skip
    k = int(np.argmin(scores))
    return candidates[k], float(scores[k])


def search_place(field: DistanceMap, robot: Robot, q: np.ndarray, view_of_point: np.ndarray, uv: np.ndarray,
                 camera: CameraModel, configured: np.ndarray) -> PlaceSearch:  # fmt: skip
    """The best pose of the floor frame near `configured` (x, y, yaw) for line points uv (N, 2) [px] of views
    `view_of_point` (N,) taken at readings q (S, J) (module docstring)."""
    configured = np.asarray(configured, float)
    coarse = np.unique(np.linspace(0, len(uv) - 1, min(len(uv), COARSE_POINTS)).astype(int))
    best: tuple[float, np.ndarray, float] | None = None  # score, pose, pitch
    grounds = {}
    for pitch in pitches(robot):
        ground = ground_points(camera, camera_in_floor(robot, q, pitched(robot, pitch))[0][view_of_point], uv)
        ground = np.where(np.isfinite(ground), ground, OFF_FIELD)  # a ray that misses the floor: on no line
        grounds[float(pitch)] = ground
        pose, score = _best(field, ground[coarse], _grid(configured, SEARCH_M, SEARCH_YAW, 13))
        if best is None or score < best[0]:
            best = (score, pose, float(pitch))
    assert best is not None
    _, pose, pitch = best
    ground = grounds[pitch]
    pose, score = _best(field, ground, _grid(pose, 0.1, np.deg2rad(3.0), 11))
    configured_score = float(field.truncated_mean(_placed(ground, configured[None]))[0])
    return PlaceSearch(pose, pitch, score, configured_score)


def place_offset(found: np.ndarray, configured: np.ndarray) -> tuple[float, float]:
    """How far a field pose (x, y, yaw) lies from the configured one: distance [m] and turn [rad], both >= 0."""
    turn = abs(float(np.remainder(found[2] - configured[2] + np.pi, 2 * np.pi)) - np.pi)
    return float(np.linalg.norm(np.asarray(found[:2]) - np.asarray(configured[:2]))), turn


def far_from_configured(off: tuple[float, float]) -> bool:
    """Whether a place `place_offset` away is further from the config's than a robot is placed (FAR_FROM_CONFIGURED)."""
    return off[0] > FAR_FROM_CONFIGURED[0] or off[1] > FAR_FROM_CONFIGURED[1]


def far_places(obs: FieldObservations, names: list[str], poses: np.ndarray) -> list[str]:
    """A note for each fitted place (P, 3: x, y [m], yaw [rad], named `names`) further from where the config puts
    the robot (`obs.configured`) than a robot is placed: the lines may then be matched to other lines than the ones
    the robot saw (a confident fit, but not of the robot's place)."""
    if obs.configured is None:
        return []
    notes = []
    for name, pose, at in zip(names, poses, obs.configured):
        off = place_offset(pose, at)
        if far_from_configured(off):
            notes.append(f"{name} lies {off[0]:.2f} m and {np.rad2deg(off[1]):.0f} deg from where the config places "
                         f"the robot ({at[0]:+.2f}, {at[1]:+.2f}, {np.rad2deg(at[2]):+.0f} deg): check where it stood; "
                         "the lines may be matched to others than it saw")  # fmt: skip
    return notes
