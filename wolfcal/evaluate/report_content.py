"""What the evaluation report says: its texts, tables and per-sample records, as report blocks (see `report`).

Everything here turns numbers already measured into words and rows; nothing is computed from the model. Units as
displayed: pixels [px] of the captured images, millimetres [mm] for the tag-grid distance, metres [m] and
centimetres [cm] on the field.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wolfcal.evaluate.deploy import DEPLOY_TABLE
from wolfcal.evaluate.metrics import HeldOutErrors
from wolfcal.evaluate.report import NO_TRUTH, Block, column_headers, headline_rows
from wolfcal.observations import Observations

INTRO = (
    "What this is: the robot computes where its camera is, and so where things it sees are on the field, from its "
    "joint readings and its kinematic model (the URDF). A calibration corrects that model (the camera's mounting, "
    "the joints' zero positions). This report checks whether the corrected model predicts what the camera really "
    "sees better than the model in use today, on images the calibration was not computed from, and gives the files "
    "to load on the robot if it does."
)
MEANINGS = {
    "rms_px": "per-axis RMS of corner residuals sqrt(mean(du^2 + dv^2) / 2) [px], inlier samples",
    "max_px": "largest distance between a predicted and a detected corner [px], inlier samples",
    "median_corner_px": "median distance between predicted and detected corner [px], inlier samples",
    "tag_grid_mean_mm": "mean distance between a 5x4 grid on each tag placed by PnP of its detected corners "
    "and by the model [mm] (the 2019 study's metric), inlier samples",
    "ground": "distance on the field between where the ball is and where the model puts it [m]",
}
# metrics['meanings']['samples'] of observations summarised by still span (a plain recording, `wolfcal.spans`)
SPAN_MEANING = (
    "each sample is one still span of a plain recording, as the fit takes it: per tag corner the mean of the span's "
    "frames that saw it, the span's median joint readings, the stamp of its first frame with a tag seen; every "
    "pixel and tag-grid figure is of these means (a mean of n frames carries about 1/sqrt(n) of one frame's random "
    "detection noise, but all of a model error and of a detection error that repeats at one pose)"
)


def span_counts(obs: Observations) -> dict:
    """{'n_frames': frames behind the samples} of observations summarised by still span; {} otherwise (capture
    files: one frame per sample)."""
    return {} if obs.span_frames is None else {"n_frames": int(obs.span_frames.frames_of_sample.sum())}


def spans_of(obs: Observations) -> str:
    """' (N still spans of M frames, each span's mean)' for pixel figures of span means; '' otherwise."""
    counts = span_counts(obs)
    if not counts:
        return ""
    return f" (of still-span means: {obs.n_samples} spans of {counts['n_frames']} frames)"


def held_out_note(sources: list[Path], fit_captures: list[str], obs: Observations) -> str:
    """How a held-out evaluation was made: which captures were judged, which the fit used (and `span_note`)."""
    return (
        f"Held-out evaluation on {', '.join(p.name for p in sources)}: samples the fit "
        f"({', '.join(Path(c).name for c in fit_captures)}) did not use." + span_note(obs)
    )


def cross_validation_note(n_folds: int, obs: Observations) -> str:
    """How a k-fold cross-validation was made, and why a held-out capture is the stronger test (and `span_note`)."""
    return (
        f"No held-out capture was given: {n_folds}-fold cross-validation over the fit's own "
        f"{obs.n_samples} sample(s). Each sample is judged by a calibration fitted on the other folds "
        "(sample i in fold i mod k), so no number here comes from a sample its model was fitted on. "
        "The deploy files hold the calibration fitted on all samples. A capture taken apart from the "
        "fit's (wolfcal evaluate FIT_DIR --capture HELDOUT.mcap) is the stronger test." + span_note(obs)
    )


def span_note(obs: Observations) -> str:
    """' Each sample is a still span ...' for observations summarised by still span; '' otherwise."""
    counts = span_counts(obs)
    if not counts:
        return ""
    return (
        f" Each sample is one still span of a recording ({obs.n_samples} spans of {counts['n_frames']} frames), "
        "its frames' tag corners averaged, as the fit takes it: the pixel figures are of these means."
    )


def sample_rows(obs: Observations, errors: HeldOutErrors) -> list[dict]:
    """One record per sample for metrics.json: errors in px (4 decimals) and tag-grid distance in mm (3 decimals,
    None without a fully seen tag); of a still span (a recording) also its frame count, its stamp its first
    frame's."""
    before, after, outliers, fold_of = errors.before, errors.after, errors.outliers, errors.fold_of

    def mm(v: float) -> float | None:
        return round(float(v) * 1000, 3) if np.isfinite(v) else None

    rows = []
    tags = obs.tags_by_sample()
    frames = None if obs.span_frames is None else obs.span_frames.frames_of_sample
    for s in range(obs.n_samples):
        rows.append(
            {
                "index": s,
                "source": Path(obs.sources[s]).name,
                "stamp_ns": int(obs.stamps_ns[s]),
                **({} if frames is None else {"frames": int(frames[s])}),
                "tags": tags[s],
                "fold": None if fold_of is None else int(fold_of[s]),
                "rms_before_px": round(float(before.sample_rms[s]), 4),
                "rms_after_px": round(float(after.sample_rms[s]), 4),
                "max_before_px": round(float(before.sample_max[s]), 4),
                "max_after_px": round(float(after.sample_max[s]), 4),
                "tag_grid_before_mm": mm(before.sample_grid[s]),
                "tag_grid_after_mm": mm(after.sample_grid[s]),
                "outlier": bool(outliers[s]),
            }
        )
    return rows


def ground_text(reference_is_truth: bool, standing: dict[str, float], soles: list[str]) -> str:
    """What the ground-error table means, and what it is measured against."""
    pose = ", ".join(f"{k} = {v:+.4f} rad" for k, v in standing.items()) or "every joint 0"
    common = (
        f"A standing robot (the config's standing pose: {pose}, all other joints 0 as read by the encoders) turns "
        "its head to look at a ball on the ground at -30, 0 and +30 deg; the worst of the three is shown. The "
        "pixel where the ball appears is turned back into a spot on the field through each model (the ground is "
        f"the plane of the model's standing soles {', '.join(soles)}); the error is the distance on the field "
        "between that spot and where the ball really is. 'Lands at' is the distance from the robot where the "
        "model puts the ball."
    )
    if reference_is_truth:
        return (
            common + " Reference: the simulator's truth (the held-out capture has a .truth.yaml beside it), so "
            "both columns are true errors."
        )
    return (
        common + " Reference: the calibrated model (no ground truth is known for a real robot), so 'before' "
        f"is how far the calibration moves the ball, and 'after' is {NO_TRUTH}: it cannot be measured against "
        "itself (the ground error measured on held-out floor views, where there are any, is the measurement)."
    )


def ground_blocks(ground: dict) -> list[Block]:
    """The ground-error section from metrics['ground'] (nothing when the robot has no sole frame to stand on)."""
    if not ground["rows"]:
        return []
    rows = []
    for row in ground["rows"]:
        cells = [f"{row['distance_m']:g} m"]
        for model in ("before", "after"):
            g = row["models"][model]
            cells += [
                "above horizon" if g["landed_at_m"] is None else f"{g['landed_at_m']:.3f} m",
                NO_TRUTH if g.get("no_truth") else "n/a" if g["error_m"] is None else f"{g['error_m'] * 100:.1f} cm",
            ]
        rows.append(cells)
    headers = ["ball at", "lands at, before", "error before", "lands at, after", "error after"]
    return [
        ("h2", "Where a ball lands on the field"),
        ("p", ground_text(ground["reference"] == "simulator truth", ground["standing_pose_rad"], ground["soles"])),
        ("table", (headers, rows, set())),
    ]


def measured_ground_blocks(measured: dict | None) -> list[Block]:
    """The measured ground error of the held-out floor views (`evaluate.floor_ground`), before and after."""
    if measured is None:
        return []

    def cell(row: dict) -> str:
        if row["error_m"] is None:
            return "above horizon"
        return f"{row['error_m'] * 100:.1f} +- {row['std_m'] * 100:.1f} cm"

    before, after = measured["models"]["before"]["rows"], measured["models"]["after"]["rows"]
    rows = [[f"{b['distance_m']:g} m", cell(b), cell(a)] for b, a in zip(before, after)]
    size = measured.get("capture")
    of = (f" ({size['samples']} samples in {size['stances']} stances, {size['layouts']} tag layout(s))" if size
          else "")  # fmt: skip
    text = (
        f"Measured without truth on {measured['views']} held-out views of the floor tags{of}: the floor tags' "
        "places, the real floor's tilt and height and the camera's turn are fitted so that every view shows "
        "each tag at its printed size; the ball is then placed through each model as above (worst of -30, 0, "
        "+30 deg; 1 sigma). A turn or shift of the whole floor is not seen."
    )
    return [
        ("h2", "Measured ground error (held-out floor views)"),
        ("p", text),
        ("table", (["ball at", "error before", "error after"], rows, set())),
    ]


def report_blocks(metrics: dict, captions: list[tuple[str, str]]) -> list[Block]:
    """The whole report, in order, from metrics.json's content and the figures' (file name, caption)."""
    m = metrics
    blocks: list[Block] = [("h1", f"wolfcal evaluation: {m['robot_name']}, --free {m['free']}")]
    blocks.append(("banner", (m["verdict"]["deploy"], m["verdict"]["message"])))
    blocks += [("p", line) for line in m["verdict"]["refusals"] + m["verdict"]["notes"]]
    blocks.append(("p", INTRO))
    blocks.append(("p", m["mode_note"]))
    blocks += _headline_blocks(m)
    blocks += ground_blocks(m["ground"])
    blocks += measured_ground_blocks(m["ground"].get("measured"))
    blocks.append(("h2", "Pictures"))
    blocks += [("figure", c) for c in captions]
    blocks += _parameter_blocks(m["parameters"])
    blocks += _per_sample_blocks(m["samples"], m["folds"] is not None, "n_frames" in m)
    blocks += _deploy_blocks(m)
    if m["warnings"]:
        blocks.append(("h2", "Notes"))
        blocks += [("p", w) for w in m["warnings"]]
    blocks.append(
        (
            "p",
            f"wolfcal {m['wolfcal_version']}, {m['created']}; fit: {m['fit_dir']}. Every number of "
            "this report is in metrics.json.",
        )
    )
    return blocks


def _headline_blocks(m: dict) -> list[Block]:
    """The before/after table and what its numbers mean."""
    return [
        ("h2", "Before and after"),
        (
            "p",
            f"Before: {m.get('before_model', 'input URDF')} as it is. After: with the calibration. Every number "
            f"comes from samples the calibration was not fitted on ({m['n_samples']} sample(s)"
            + (f", still spans of {m['n_frames']} frames, each the mean of its frames" if "n_frames" in m else "")
            + f", {m['n_outliers']} outlier sample(s) left out of these numbers and marked in the table below).",
        ),
        ("table", (column_headers(m), headline_rows(m), set())),
        (
            "p",
            "Reprojection RMS per axis: sqrt(mean(du^2 + dv^2) / 2) over all tag corners, in pixels "
            "of the captured images; how far, on average, the model's prediction of a tag corner is from "
            "where the camera saw it. Largest corner error: the worst single corner (distance). Tag-grid "
            "mean distance: the 2019 study's metric, for comparison with its 38.2 mm -> 18.4 mm: the tag's "
            "pose measured from its four corners alone (PnP) versus predicted by the model, mean distance of "
            "a 5 x 4 grid of points on the tag; a single tag's depth is poorly measured, so it is noisier.",
        ),
    ]


def _parameter_blocks(parameters: list[dict]) -> list[Block]:
    """The fitted parameters with their uncertainty and how much of them the data determined."""
    rows = [[p["name"], p["display"], f"{p['data_share']:.0%}"] for p in parameters]
    return [
        ("h2", "Fitted parameters"),
        ("table", (["parameter", "value +- std", "information from data"], rows, set())),
    ]


def _per_sample_blocks(samples: list[dict], folds: bool, spans: bool) -> list[Block]:
    """The per-sample table from `sample_rows` (with each still span's frame count when `spans`); outlier rows are
    marked."""
    headers = ["sample", "capture"] + (["frames"] if spans else []) + ["tags"] + (["fold"] if folds else [])
    headers += ["RMS before", "RMS after", "max after", "grid before", "grid after", ""]
    rows, marked = [], set()
    for i, s in enumerate(samples):
        row = [str(s["index"]), s["source"]] + ([str(s["frames"])] if spans else []) + [" ".join(map(str, s["tags"]))]
        row += [str(s["fold"] + 1)] if folds else []
        row += [f"{s['rms_before_px']:.3f}", f"{s['rms_after_px']:.3f}", f"{s['max_after_px']:.2f}"]
        row += [
            _fmt_mm(s["tag_grid_before_mm"]),
            _fmt_mm(s["tag_grid_after_mm"]),
            "OUTLIER" if s["outlier"] else "",
        ]
        rows.append(row)
        if s["outlier"]:
            marked.add(i)
    return [
        ("h2", "Per sample"),
        (
            "p",
            "RMS per axis and largest corner error in pixels, tag-grid distance in millimetres; "
            "outlier samples are marked (highlighted) and left out of the numbers above."
            + (" Each sample is a still span: its frames' mean corners, 'frames' how many." if spans else ""),
        ),
        ("table", (headers, rows, marked)),
    ]


def _deploy_blocks(m: dict) -> list[Block]:
    """The deploy files (what each holds, where it goes on a Wolfgang), or why they were not written."""
    blocks: list[Block] = [("h2", "Files to deploy")]
    if m["deploy"]["written"]:
        blocks.append(("p", "Written beside this report; each holds the new total calibration, not the change:"))
        rows = [[name, holds, where] for name, holds, where in DEPLOY_TABLE if name in m["deploy"]["files"]]
        blocks.append(("table", (["file", "holds", "where it goes on a Wolfgang (bitbots_main)"], rows, set())))
        blocks += [("p", w) for w in m["deploy"].get("warnings", [])]
    else:
        blocks.append(("banner", (False, m["deploy"]["reason"])))
    return blocks


def _fmt_mm(value: float | None) -> str:
    """A tag-grid distance [mm] with one decimal; empty when unknown."""
    return "" if value is None else f"{value:.1f}"
