"""Which pictures the evaluation report shows, with their captions: the data behind each picture (errors, predicted
corners and the kinematic skeleton projected into the camera image, the parameter correlation). Drawing is `figures`.

Pixels [px] follow OpenCV (centre of the top-left pixel at (0, 0)) at the captured image's resolution. A sample that
is a still span of a recording (`wolfcal.spans`) is drawn on the span's first frame with a tag seen (the sample's
stamp), its detected corners the means over the span's frames; the captions say so.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.evaluate import figures as fig
from wolfcal.evaluate.metrics import HeldOutErrors, ModelErrors
from wolfcal.io.samples import Sample
from wolfcal.observations import HEAD_CAMERA, Observations
from wolfcal.projection import tag_corner_pixels, tag_corner_table
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import Robot

OVERLAYS = 4  # camera images with overlays in the report
SKELETON_STEPS = 12  # points per link segment, so that lens distortion bends the drawn skeleton as it should

Figures = tuple[dict[str, bytes], list[tuple[str, str]]]  # PNG bytes by file name, (file name, caption) in order


def skeleton_px(robot: Robot, q: np.ndarray, corrections: Corrections, camera: CameraModel) -> list[np.ndarray]:
    """Every joint as a segment parent origin -> child origin, projected into the image [px] (NaN off-image).

    q: (J,) encoder readings [rad]; each segment is (SKELETON_STEPS, 2).
    """
    joints = list(robot.model.joints.values())
    links = sorted({j.parent for j in joints} | {j.child for j in joints})
    poses = robot.model.link_poses(q[None], links, corrections, base=robot.config.head_camera().frame)
    t = np.linspace(0.0, 1.0, SKELETON_STEPS)[:, None]
    lines = []
    for joint in joints:
        a, b = poses[joint.parent][0, :3, 3], poses[joint.child][0, :3, 3]
        uv = camera.project(a + t * (b - a))
        uv[~camera.in_image(uv, margin=-camera.width / 2)] = np.nan
        lines.append(uv)
    return lines


def predicted_corners_px(robot: Robot, obs: Observations, s: int, corrections: Corrections) -> np.ndarray:
    """(4T, 2) predicted corners [px] of the T tags detected in sample s, tags in ascending id, aruco corner order."""
    rows = np.flatnonzero(obs.sample_index == s)
    tags = sorted({int(t) for t in obs.tag_ids[rows]})
    _, T_camera_tag = robot.camera_and_tag_poses(obs.q_measured[s : s + 1], tags, corrections)
    return tag_corner_pixels(obs.camera, T_camera_tag[0], tag_corner_table(robot.config, tags)).reshape(-1, 2)


def overlay_samples(outliers: np.ndarray, after: ModelErrors) -> list[int]:
    """Which samples to show: inliers spread from best to worst after calibration, plus the worst outlier."""
    inliers = np.flatnonzero(~outliers)
    ranked = inliers[np.argsort(after.sample_rms[inliers])]
    picks = [int(ranked[i]) for i in np.unique(np.linspace(0, len(ranked) - 1, OVERLAYS - 1).round().astype(int))]
    if outliers.any():
        bad = np.flatnonzero(outliers)
        picks.append(int(bad[np.argmax(after.sample_rms[bad])]))
    return picks


def report_figures(
    robot: Robot,
    obs: Observations,
    samples: dict[tuple[str, int], Sample],
    errors: HeldOutErrors,
    covariance: dict | None,
) -> Figures:
    """All pictures of the report: PNG bytes by file name, and (file name, caption) in report order.

    samples: the captured samples (frames) by (source, stamp_ns), for their images (a still span's: its first
    frame's, the span's stamp); errors: before and after on the held-out samples (with the calibrated model that
    judges each); covariance: the fit's {"names", "matrix"} (SI units), or None.
    """
    pngs: dict[str, bytes] = {}
    captions: list[tuple[str, str]] = []
    for part in (
        _error_charts(obs, errors),
        _overlays(robot, obs, samples, errors),
        _correlation(covariance),
    ):
        pngs.update(part[0])
        captions += part[1]
    return pngs, captions


def _error_charts(obs: Observations, errors: HeldOutErrors) -> Figures:
    """Histogram of the inlier corner errors and the per-sample RMS bars [px]."""
    before, after, outliers = errors.before, errors.after, errors.outliers
    spans = "" if obs.span_frames is None else " Each sample is a still span of a recording: its frames' mean corners."
    inlier_corners = ~outliers[obs.sample_index]
    pngs = {
        "corner_histogram.png": fig.histogram_png(
            before.corner_distance[inlier_corners],
            after.corner_distance[inlier_corners],
            "distance between predicted and detected tag corner [px] (log scale)",
            "Held-out corner errors",
        ),
        "per_sample.png": fig.per_sample_png(
            before.sample_rms,
            after.sample_rms,
            outliers,
            "RMS per axis [px] (log scale)",
            "Reprojection error per sample",
        ),
    }
    captions = [
        (
            "corner_histogram.png",
            "Distance between where each tag corner was detected and where the "
            "model predicts it, inlier samples: red with the input URDF, blue calibrated. Further left is "
            "better." + spans,
        ),
        (
            "per_sample.png",
            "Each held-out sample's reprojection RMS before (red) and after (blue); grey "
            "columns marked x are outlier samples (blurred image or a joint reading that does not match "
            "the image), left out of the headline numbers." + spans,
        ),
    ]
    return pngs, captions


def _overlays(
    robot: Robot, obs: Observations, samples: dict[tuple[str, int], Sample], errors: HeldOutErrors
) -> Figures:
    """Camera images of the `overlay_samples` with detected corners and both models' corners and skeleton."""
    before, after, outliers = errors.before, errors.after, errors.outliers
    pngs: dict[str, bytes] = {}
    captions: list[tuple[str, str]] = []
    for k, s in enumerate(overlay_samples(outliers, after)):
        sample = samples.get((obs.sources[s], int(obs.stamps_ns[s])))
        if sample is None:
            continue
        name = f"overlay_{k + 1}.png"
        models = {"before": Corrections(), "after": errors.after_of_sample[s]}
        pngs[name] = fig.overlay_png(
            sample.images[HEAD_CAMERA].decode(),
            obs.uv[obs.sample_index == s],
            {key: predicted_corners_px(robot, obs, s, c) for key, c in models.items()},
            {key: skeleton_px(robot, obs.q_measured[s], c, obs.camera) for key, c in models.items()},
            f"sample {s}: RMS {before.sample_rms[s]:.2f} px before, {after.sample_rms[s]:.2f} px after"
            + (" (outlier)" if outliers[s] else ""),
        )
        span = "" if obs.span_frames is None else (
            f"; a still span of {int(obs.span_frames.frames_of_sample[s])} frames drawn on its first frame with a tag "
            "seen, the green rings its frames' mean corners")  # fmt: skip
        captions.append(
            (
                name,
                f"Sample {s} ({Path(obs.sources[s]).name}{span}): detected tag corners (green rings), "
                "corners and the robot's kinematic skeleton (lines between joint origins) as each model "
                "predicts them from the joint readings: red input URDF, blue calibrated.",
            )
        )
    return pngs, captions


def _correlation(covariance: dict | None) -> Figures:
    """Heat map of the fitted parameters' correlation, from the fit's covariance (nothing without parameters)."""
    covariance = covariance or {"names": [], "matrix": []}
    names = covariance["names"]
    if not names:
        return {}, []
    cov = np.asarray(covariance["matrix"], dtype=float)
    d = np.sqrt(np.clip(np.diag(cov), 1e-300, None))
    pngs = {"correlation.png": fig.correlation_png(names, cov / np.outer(d, d), "Parameter correlation")}
    captions = [
        (
            "correlation.png",
            "Correlation between the fitted parameters (from the fit's "
            "covariance). Near +1 or -1 (dark) means the data cannot tell the two apart: only their "
            "combination is determined.",
        )
    ]
    return pngs, captions
