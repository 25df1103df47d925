"""Which detected line points a field block uses, and how they group: the nearest field line of each point, the points
on lines a view sees well enough (spread over the view), and the stretches of a line that share one detection
error."""

from __future__ import annotations

import numpy as np

from wolfcal.field.ground import ground_points
from wolfcal.field.model import FieldLines, nearest_line
from wolfcal.field.observations import FieldObservations, spread

MIN_LINE_POINTS = 5  # points of a line in one view the block needs to use them
POINTS_PER_VIEW = 35  # and the most it uses of one view
STRETCH_POINTS = 3  # points in a row along a line that share one detection error


def line_stretches(sample_index: np.ndarray, line: np.ndarray, uv: np.ndarray) -> np.ndarray:
    """(M,) the stretch of its line each point lies on: a line's points in one view, in their order along it, in
    runs of STRETCH_POINTS (the last run takes the rest)."""
    _, group = np.unique(np.stack([sample_index, line], axis=1), axis=0, return_inverse=True)
    group = group.ravel()
    stretch = np.zeros(len(group), dtype=int)
    for g in np.unique(group):
        members = np.flatnonzero(group == g)
        centred = uv[members] - uv[members].mean(axis=0)
        along = centred @ np.linalg.svd(centred, full_matrices=False)[2][0] if len(members) > 1 else np.zeros(1)
        rank = np.empty(len(members), dtype=int)
        rank[np.argsort(along)] = np.arange(len(members))
        stretch[members] = np.minimum(rank // STRETCH_POINTS, max(len(members) // STRETCH_POINTS - 1, 0))
    return stretch


def points_used(sample_index: np.ndarray, line: np.ndarray) -> np.ndarray:
    """(M,) the points the block uses: those on lines seen by at least MIN_LINE_POINTS points of their view, at
    most POINTS_PER_VIEW of them per view, spread over it (`spread`). A lone point near a line (a robot's foot, a
    post's base, the far end of a short marking) has no others to share the line's error with; and the detector's
    error along a line drifts slowly (the line's sub-pixel phase against the scan lines), so many points of one
    line would count one error many times."""
    _, group, counts = np.unique(np.stack([sample_index, line], axis=1), axis=0, return_inverse=True,
                                 return_counts=True)  # fmt: skip
    on_lines = np.flatnonzero(counts[group.ravel()] >= MIN_LINE_POINTS)
    keep = np.zeros(len(line), bool)
    for view in np.unique(sample_index[on_lines]):
        members = on_lines[sample_index[on_lines] == view]
        keep[members[spread(members, POINTS_PER_VIEW)]] = True
    return keep


def lines_seen(obs: FieldObservations, lines: FieldLines, T_floor_camera: np.ndarray) -> np.ndarray:
    """(M,) the nearest line (`nearest_line`) of each point seen from cameras T_floor_camera (M, 4, 4) of a robot
    standing at its placement's start."""
    g = ground_points(obs.camera, T_floor_camera, obs.uv)
    x, y, yaw = obs.starts[obs.placement[obs.sample_index]].T
    c, s = np.cos(yaw), np.sin(yaw)
    field = np.stack([x + c * g[:, 0] - s * g[:, 1], y + s * g[:, 0] + c * g[:, 1]], axis=1)
    return nearest_line(lines, np.nan_to_num(field))
