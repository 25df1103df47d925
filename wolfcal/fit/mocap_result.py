"""The motion-capture block's part of result.yaml: residuals in mm, noise per marker (the level the fit weighted it
with), each left-out marker with its sample, the base pose in the motion-capture frame and the clock offsets of
motion-capture files."""

from __future__ import annotations

from pathlib import Path
from typing import TYPE_CHECKING

import numpy as np

from wolfcal.geometry import matrix_to_rpy, transform_from_twist_params

if TYPE_CHECKING:
    from wolfcal.fit.blocks import BlockResult
    from wolfcal.markers import MarkerObservations


def mocap_block_dict(
    obs: MarkerObservations,
    placement_names: list[str],
    view_labels: list[tuple[int, int]],
    b: BlockResult,
    values: np.ndarray,
    residual: np.ndarray,
) -> dict:
    """result.yaml entry of a motion-capture block: its markers `obs`, the names of its base-pose placements, the
    (sample, marker) of each view, the solver's figures `b`; `values` are its own unknowns (6 per placement) [SI],
    `residual` (U, 3) [m] its residuals at the solution."""
    left_out = {(s, k) for s, k in b.outlier_views}
    inlier = np.array([(s, k) not in left_out for s, k in view_labels], dtype=bool)
    samples = [{
        "index": i,
        "source": Path(obs.sources[i]).name,
        "stamp_ns": int(obs.stamps_ns[i]),
        "markers": obs.markers_in_sample(i),
        "rms_before_mm": round(float(b.sample_rms_before[i]) * 1000, 4),
        "rms_after_mm": round(float(b.sample_rms_after[i]) * 1000, 4),
        "outlier": bool(b.outlier_samples[i]),
        "left_out_markers": sorted(obs.marker_names[k] for s, k in b.outlier_views if s == i),
    } for i in range(obs.n_samples)]  # fmt: skip
    per_marker = {}
    for k, name in enumerate(obs.marker_names):
        rows = inlier & (obs.marker_index == k)
        rms = float(np.sqrt(np.mean(residual[rows] ** 2))) if rows.any() else float("nan")
        per_marker[name] = {"n_used": int(rows.sum()), "rms_after_mm": round(rms * 1000, 4),
                            "noise_sigma_mm": round(float(b.class_sigma[k]) * 1000, 4)}  # fmt: skip
    poses = {}
    for p, name in enumerate(placement_names):
        T = transform_from_twist_params(values[6 * p : 6 * p + 6])
        poses[name] = {"xyz": [float(v) for v in T[:3, 3]], "rpy": [float(v) for v in matrix_to_rpy(T[:3, :3])],
                       "T_mocap_base": np.round(T, 12).tolist()}  # fmt: skip
    return {
        "name": b.name,
        "system": b.system,
        "unit": "mm",  # of the figures below (the fit works in metres)
        "markers_used": obs.marker_names,
        "rms_meaning": "per-axis RMS of marker residuals (predicted minus measured, motion-capture frame) in mm, "
        "inlier markers",
        "rms_before_mm": round(b.rms_before * 1000, 4),
        "rms_after_mm": round(b.rms_after * 1000, 4),
        "max_after_mm": round(b.max_after * 1000, 4),
        "noise_sigma_mm": round(b.sigma * 1000, 4),
        "per_marker": per_marker,
        "n_samples": obs.n_samples,
        "n_outlier_samples": int(np.sum(b.outlier_samples)),
        "n_outlier_views": len(b.outlier_views),
        "n_units_used": b.n_units,
        "left_out_markers": [
            {
                "sample": int(s),
                "marker": obs.marker_names[k],
                "source": Path(obs.sources[s]).name,
                "stamp_ns": int(obs.stamps_ns[s]),
                "distance_mm": round(float(np.linalg.norm(residual[u])) * 1000, 3),
            }
            for u, (s, k) in enumerate(view_labels)
            if (s, k) in left_out
        ],  # fmt: skip
        "unknown_marker_names": obs.unknown_names,
        "base_poses": poses,
        "base_pose_meaning": "T_mocap_base: the base link in the motion-capture frame, p_mocap = T @ p_base [m]",
        "mocap_clock_offset_s": {Path(k).name: round(v, 6) for k, v in obs.clock_offsets_s.items()},
        "samples": samples,
    }
