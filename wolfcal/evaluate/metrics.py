"""Errors of a kinematic model on observed samples: corner reprojection [px] and the 2019 study's tag-grid metric [mm].

- Corner residual: predicted minus detected pixel of every tag corner (OpenCV pixel convention), predicted from the
  encoder readings through the model: project(K, D, T_camera_tag(q + offsets) @ p_corner).
- Per-sample RMS is per axis, as in the fit: sqrt(mean(du^2 + dv^2) / 2) over the sample's corners; the max is the
  largest corner distance sqrt(du^2 + dv^2).
- Tag-grid distance (the study's metric): the pose of each tag in the camera frame is measured from its four detected
  corners alone (cv2.solvePnP, SOLVEPNP_IPPE_SQUARE, on undistorted normalised points) and predicted by the model;
  the mean distance between the two placements of a 5 x 4 grid of points spanning the tag's black square [m].
  A single tag's depth is poorly measured by PnP, so this number is noisier than the pixel error; it is reported
  so results compare with the study (38.2 mm -> 18.4 mm for its camera pose).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wolfcal.observations import Observations
from wolfcal.outliers import HELD_OUT_SAMPLE_PX
from wolfcal.projection import BEHIND_CAMERA_PX, corner_points, project_corners, tag_pose_from_pixels
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import Robot

GRID_SHAPE = (5, 4)  # grid points across x and y of the tag's black square


def tag_grid(size: float) -> np.ndarray:
    """(20, 3) points of a 5 x 4 grid spanning a tag's black square of edge `size`, tag frame [m]."""
    h = size / 2.0
    x, y = np.meshgrid(np.linspace(-h, h, GRID_SHAPE[0]), np.linspace(-h, h, GRID_SHAPE[1]), indexing="ij")
    return np.stack([x.ravel(), y.ravel(), np.zeros(x.size)], axis=1)


@dataclass
class TagViews:
    """Tags seen with all four corners: one row per (sample, tag), with the pose measured from the image alone."""

    sample: np.ndarray  # (V,) sample index
    tag: np.ndarray  # (V,) tag id
    T_camera_tag: np.ndarray  # (V, 4, 4) measured by PnP; NaN where PnP failed


def measure_tag_views(robot: Robot, obs: Observations) -> TagViews:
    """Pose T_camera_tag [m] of every fully detected tag in the camera's optical frame from its corners alone (IPPE
    square on undistorted points)."""
    samples, tags, poses = [], [], []
    labels, view_of_corner = obs.views()
    for k, (sample, tag_id) in enumerate(labels):
        rows = np.flatnonzero(view_of_corner == k)
        if len(rows) != 4:
            continue
        rows = rows[np.argsort(obs.corner_index[rows])]
        T = tag_pose_from_pixels(obs.camera, obs.uv[rows], robot.config.tag(int(tag_id)).size)
        samples.append(int(sample))
        tags.append(int(tag_id))
        poses.append(np.full((4, 4), np.nan) if T is None else T)
    return TagViews(np.array(samples, dtype=int), np.array(tags, dtype=int), np.array(poses).reshape(-1, 4, 4))


@dataclass
class ModelErrors:
    """Errors of one model on the samples of an `Observations` (per corner and per sample)."""

    residuals: np.ndarray  # (M, 2) predicted - detected [px]
    sample_rms: np.ndarray  # (S,) per-axis RMS [px]
    sample_max: np.ndarray  # (S,) largest corner distance [px]
    view_grid: np.ndarray  # (V,) mean tag-grid distance per tag view [m]
    sample_grid: np.ndarray  # (S,) mean over the sample's tag views [m] (NaN without a view)

    @property
    def corner_distance(self) -> np.ndarray:
        """(M,) distance between predicted and detected corner [px]."""
        return np.linalg.norm(self.residuals, axis=1)


def model_errors(robot: Robot, obs: Observations, views: TagViews, corrections: Corrections) -> ModelErrors:
    """Corner [px] and tag-grid [m] errors of the model `corrections` (on top of the robot's URDF), predicted from
    the encoder readings."""
    tag_ids = obs.observed_tag_ids
    column = {t: i for i, t in enumerate(tag_ids)}
    _, T_camera_tag = robot.camera_and_tag_poses(obs.q_measured, tag_ids, corrections)
    residuals = project_corners(obs, T_camera_tag, corner_points(robot, obs, tag_ids)) - obs.uv
    residuals = np.where(np.isfinite(residuals), residuals, BEHIND_CAMERA_PX)
    n = obs.n_samples
    sample_rms = obs.per_sample_rms(residuals)
    distance = np.linalg.norm(residuals, axis=1)
    sample_max = np.full(n, np.nan)
    np.fmax.at(sample_max, obs.sample_index, distance)
    grid = np.full(len(views.sample), np.nan)
    for k, (s, t) in enumerate(zip(views.sample, views.tag)):
        g = tag_grid(robot.config.tag(int(t)).size)
        predicted = T_camera_tag[s, column[int(t)]]
        measured = views.T_camera_tag[k]
        diff = g @ (predicted[:3, :3] - measured[:3, :3]).T + (predicted[:3, 3] - measured[:3, 3])
        grid[k] = np.mean(np.linalg.norm(diff, axis=1))
    sample_grid = np.full(n, np.nan)
    for s in range(n):
        values = grid[(views.sample == s) & np.isfinite(grid)]
        if values.size:
            sample_grid[s] = float(values.mean())
    return ModelErrors(residuals, sample_rms, sample_max, grid, sample_grid)


@dataclass
class HeldOutErrors:
    """Errors of the input URDF (before) and the calibration (after) on samples the judged model was not fitted on."""

    before: ModelErrors
    after: ModelErrors
    after_of_sample: list[Corrections]  # (S,) the calibrated model that judged each sample
    fold_of: np.ndarray | None  # (S,) cross-validation fold that left each sample out; None on held-out captures
    mode_note: str  # the sentence saying which
    outliers: np.ndarray  # (S,) bool: samples the better model does not explain, left out of the summaries
    summary_before: dict  # `summary` of before over the inliers [px, mm]
    summary_after: dict  # the same of after

    @property
    def folds(self) -> int | None:
        """Number of cross-validation folds (None on held-out captures)."""
        return None if self.fold_of is None else int(self.fold_of.max()) + 1


def merge_folds(
    obs: Observations, views: TagViews, fold_of_sample: np.ndarray, folds: list[ModelErrors]
) -> ModelErrors:
    """Per-fold errors (each computed on all samples) -> each sample's error under the model it was held out of."""
    corner_fold = fold_of_sample[obs.sample_index]
    view_fold = fold_of_sample[views.sample]
    residuals = np.zeros_like(folds[0].residuals)
    view_grid = np.zeros_like(folds[0].view_grid)
    sample_rms, sample_max, sample_grid = (np.zeros(obs.n_samples) for _ in range(3))
    for k, errors in enumerate(folds):
        residuals[corner_fold == k] = errors.residuals[corner_fold == k]
        view_grid[view_fold == k] = errors.view_grid[view_fold == k]
        mine = fold_of_sample == k
        sample_rms[mine] = errors.sample_rms[mine]
        sample_max[mine] = errors.sample_max[mine]
        sample_grid[mine] = errors.sample_grid[mine]
    return ModelErrors(residuals, sample_rms, sample_max, view_grid, sample_grid)


def outlier_samples(before: ModelErrors, after: ModelErrors) -> np.ndarray:
    """(S,) samples that the better of the two models does not explain (blurred image, stale joint reading)."""
    better = after if np.nanmedian(after.sample_rms) <= np.nanmedian(before.sample_rms) else before
    return HELD_OUT_SAMPLE_PX.flags(better.sample_rms)


def summary(obs: Observations, views: TagViews, errors: ModelErrors, outliers: np.ndarray) -> dict:
    """Headline numbers of one model over the inlier samples, in display units (keys end in _px or _mm)."""
    corners = ~outliers[obs.sample_index]
    grid = errors.view_grid[~outliers[views.sample] & np.isfinite(errors.view_grid)]
    r = errors.residuals[corners]
    return {
        "rms_px": float(np.sqrt(np.mean(r**2))) if r.size else None,
        "max_px": float(np.max(np.linalg.norm(r, axis=1))) if r.size else None,
        "median_corner_px": float(np.median(np.linalg.norm(r, axis=1))) if r.size else None,
        "tag_grid_mean_mm": float(grid.mean() * 1000) if grid.size else None,
        "tag_grid_max_mm": float(grid.max() * 1000) if grid.size else None,
    }
