"""result.yaml's entry of a block whose units are tag corners seen by one camera (camera, floor and sole-closure
blocks): per-axis RMS in pixels (metres for the sole closure), outlier views and single corners, per-sample rows."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wolfcal.fit.blocks import FittedBlock, TagViewBlock

CORNER_RULE_MEANING = (
    "a corner of a view kept is left out when its distance from where the fit puts it, less what the view's share of "
    "the joint-reading errors explains, exceeds max(floor_px, factor * the robust per-axis scale of the corners "
    "counted) [px]"
)


def tag_view_report(block: TagViewBlock, fitted: FittedBlock) -> dict:
    """The result of one tag-view block: residuals, noise, outliers, per-sample errors (`Block.report`)."""
    b = fitted.result
    obs = block.obs
    unit = b.unit
    tags = obs.tags_by_sample()  # once for all samples
    outlier_tags: dict[int, list[int]] = {}
    for s, t in sorted(b.outlier_views):
        outlier_tags.setdefault(s, []).append(t)
    rule = block.unit_rule  # single corners left out one by one (None: the block has no such rule)
    corners = outlier_corners(block, fitted) if rule is not None else None
    spans = obs.span_frames  # each sample a still span's frames averaged (`wolfcal.spans`), or None
    samples = []
    for i in range(obs.n_samples):
        samples.append({
            "index": i,
            "source": Path(obs.sources[i]).name,
            "stamp_ns": int(obs.stamps_ns[i]),
            **({"frames": int(spans.frames_of_sample[i])} if spans is not None else {}),
            "tags": tags[i],
            f"rms_before_{unit}": round(float(b.sample_rms_before[i]), 4),
            f"rms_after_{unit}": round(float(b.sample_rms_after[i]), 4),
            "outlier": bool(b.outlier_samples[i]),
            "outlier_tags": outlier_tags.get(i, []),
            **({"outlier_corners": corners.get(i, [])} if corners is not None else {}),
        })  # fmt: skip
    corner_keys = (
        {}
        if rule is None or corners is None
        else {
            # single corners of the views kept, far off while the view's others fit: left out, see corner_rule
            "n_outlier_corners": sum(len(c) for c in corners.values()),
            "corner_rule": {"factor": rule.factor, "floor_px": rule.floor, "meaning": CORNER_RULE_MEANING},
        }
    )
    return {
        "name": b.name,
        "system": b.system,
        "camera": block.camera_name,
        "unit": unit,
        "tags_used": block.tag_ids,
        "rms_meaning": f"per-axis RMS of corner residuals in {unit} (sqrt(mean(du^2 + dv^2) / 2)), inlier views"
        + (", single corners left out excluded" if rule is not None else "")
        + (", each corner the mean over its still span's frames" if spans is not None else ""),
        f"rms_before_{unit}": round(b.rms_before, 4),
        f"rms_after_{unit}": round(b.rms_after, 4),
        f"max_after_{unit}": round(b.max_after, 4),
        f"noise_sigma_{unit}": round(b.sigma, 4),
        "n_samples": obs.n_samples,
        **(
            {
                "samples_meaning": "each sample is one still span of a recording: its frames' corners averaged",
                "n_frames": int(spans.frames_of_sample.sum()),
                "n_frame_views_left_out": spans.left_out,  # far from their span's other frames, before averaging
            }
            if spans is not None
            else {}
        ),
        "n_outlier_samples": sum(s["outlier"] for s in samples),
        "n_outlier_views": len(b.outlier_views),
        **corner_keys,
        "n_units_used": b.n_units,
        "samples": samples,
    }


def outlier_corners(block: TagViewBlock, fitted: FittedBlock) -> dict[int, list[list[int]]]:
    """Sample -> [tag id, corner index] of each single corner the fit left out of the block's views kept
    (`Block.unit_rule`, e.g. `outliers.FLOOR_CORNER_PX`; the solver's final outlier sets). Only for a block with a
    unit rule: its units are the detected corners, one per row of its observations."""
    obs = block.obs
    out: dict[int, list[list[int]]] = {}
    for m in np.flatnonzero(fitted.excluded_units):
        out.setdefault(int(obs.sample_index[m]), []).append([int(obs.tag_ids[m]), int(obs.corner_index[m])])
    return out
