"""`wolfcal evaluate`: a fit + held-out captures (or k-fold cross-validation) -> report and files to deploy.

Before = the input URDF (no corrections); after = the fit's corrections. Every error is measured on samples the
judged model was not fitted on. The deploy files are written only when the held-out reprojection RMS did not get
worse (or with force=True).
"""

from __future__ import annotations

import json
from collections.abc import Callable
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

import wolfcal
from wolfcal.atomic import write_bytes_atomic, write_text_atomic
from wolfcal.camera.model import CameraModel
from wolfcal.errors import WolfcalError
from wolfcal.evaluate import figures as fig
from wolfcal.evaluate.crossval import cross_validate
from wolfcal.evaluate.deploy import camera_correction, remove_deploy_files, write_deploy_files
from wolfcal.evaluate.ground import DISTANCES_M, GROUND_LINK, STANDING, ground_errors
from wolfcal.evaluate.metrics import (
    ModelErrors,
    TagViews,
    measure_tag_views,
    merge_folds,
    model_errors,
    outlier_samples,
    summary,
)
from wolfcal.evaluate.report import Block, before_after_table, headline_rows, render_html, render_markdown
from wolfcal.fit.pipeline import FitOptions, load_samples
from wolfcal.fit.result import load_result
from wolfcal.io.samples import Sample
from wolfcal.observations import Observations
from wolfcal.robot.corrections import Corrections, load_corrections
from wolfcal.robot.robot import Robot, load_robot
from wolfcal.sim.simulate import truth_paths
from wolfcal.vision.observe import detect_observations
from wolfcal.vision.tags import tag_corners

OVERLAYS = 4  # camera images with overlays in the report
SKELETON_STEPS = 12  # points per link segment, so that lens distortion bends the drawn skeleton as it should


def _load_fit(fit_dir: Path) -> tuple[dict, Robot, Corrections]:
    if not Path(fit_dir).exists():
        raise WolfcalError(f"{fit_dir}: fit folder not found (run `wolfcal fit ... --out {fit_dir}` first)")
    result = load_result(fit_dir)
    robot_path = Path(result["robot"])
    if not robot_path.exists():
        raise WolfcalError(f"{fit_dir}: the fit's robot config {robot_path} no longer exists")
    robot = load_robot(robot_path)
    corrections = Corrections.from_dict(result["corrections"], f"{fit_dir}/result.yaml: corrections")
    return result, robot, corrections


def _truth_reference(captures: list[Path]) -> Corrections | None:
    """The simulator's true corrections when every capture has the same `.truth.yaml` beside it."""
    truths = []
    for path in captures:
        truth_yaml = truth_paths(Path(path))[0]
        if not truth_yaml.is_file():
            return None
        truths.append(load_corrections(truth_yaml, key="truth"))
    first = truths[0].to_dict()
    return truths[0] if all(t.to_dict() == first for t in truths[1:]) else None


def _skeleton(robot: Robot, q: np.ndarray, corrections: Corrections, camera: CameraModel) -> list[np.ndarray]:
    """Every joint as a segment parent origin -> child origin, projected into the image [px] (NaN off-image)."""
    joints = list(robot.model.joints.values())
    links = sorted({j.parent for j in joints} | {j.child for j in joints})
    poses = robot.model.link_poses(q[None], links, corrections, base=robot.config.camera.frame)
    t = np.linspace(0.0, 1.0, SKELETON_STEPS)[:, None]
    lines = []
    for joint in joints:
        a, b = poses[joint.parent][0, :3, 3], poses[joint.child][0, :3, 3]
        uv = camera.project(a + t * (b - a))
        uv[~camera.in_image(uv, margin=-camera.width / 2)] = np.nan
        lines.append(uv)
    return lines


def _predicted_corners(robot: Robot, obs: Observations, s: int, corrections: Corrections) -> np.ndarray:
    """(4T, 2) predicted corners [px] of the tags detected in sample s, in observation order."""
    rows = np.flatnonzero(obs.sample_index == s)
    tags = sorted({int(t) for t in obs.tag_ids[rows]})
    _, T_camera_tag = robot.camera_and_tag_poses(obs.q_measured[s : s + 1], tags, corrections)
    out = []
    for k, tag in enumerate(tags):
        T = T_camera_tag[0, k]
        out.append(obs.camera.project(tag_corners(robot.config.tag(tag).size) @ T[:3, :3].T + T[:3, 3]))
    return np.concatenate(out)


def _overlay_samples(outliers: np.ndarray, after: ModelErrors) -> list[int]:
    """Which samples to show: inliers spread from best to worst after calibration, plus the worst outlier."""
    inliers = np.flatnonzero(~outliers)
    ranked = inliers[np.argsort(after.sample_rms[inliers])]
    picks = [
        int(ranked[i]) for i in np.unique(np.linspace(0, len(ranked) - 1, OVERLAYS - 1).round().astype(int))
    ]
    if outliers.any():
        bad = np.flatnonzero(outliers)
        picks.append(int(bad[np.argmax(after.sample_rms[bad])]))
    return picks


def _sample_rows(
    obs: Observations,
    before: ModelErrors,
    after: ModelErrors,
    outliers: np.ndarray,
    fold_of: np.ndarray | None,
) -> list[dict]:
    def mm(v: float) -> float | None:
        return round(float(v) * 1000, 3) if np.isfinite(v) else None

    rows = []
    for s in range(obs.n_samples):
        rows.append(
            {
                "index": s,
                "source": Path(obs.sources[s]).name,
                "stamp_ns": int(obs.stamps_ns[s]),
                "tags": sorted({int(t) for t in obs.tag_ids[obs.sample_index == s]}),
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


def _figures(
    robot: Robot,
    obs: Observations,
    samples: dict[tuple[str, int], Sample],
    before: ModelErrors,
    after: ModelErrors,
    outliers: np.ndarray,
    after_of_sample: list[Corrections],
    result: dict,
) -> tuple[dict[str, bytes], list[tuple[str, str]]]:
    """PNG pictures by file name, and (file name, caption) in report order."""
    pngs: dict[str, bytes] = {}
    captions: list[tuple[str, str]] = []
    inlier_corners = ~outliers[obs.sample_index]
    pngs["corner_histogram.png"] = fig.histogram_png(
        before.corner_distance[inlier_corners],
        after.corner_distance[inlier_corners],
        "distance between predicted and detected tag corner [px] (log scale)",
        "Held-out corner errors",
    )
    captions.append(
        (
            "corner_histogram.png",
            "Distance between where each tag corner was detected and where the "
            "model predicts it, inlier samples: red with the input URDF, blue calibrated. Further left is "
            "better.",
        )
    )
    pngs["per_sample.png"] = fig.per_sample_png(
        before.sample_rms,
        after.sample_rms,
        outliers,
        "RMS per axis [px] (log scale)",
        "Reprojection error per sample",
    )
    captions.append(
        (
            "per_sample.png",
            "Each held-out sample's reprojection RMS before (red) and after (blue); grey "
            "columns marked x are outlier samples (blurred image or a joint reading that does not match "
            "the image), left out of the headline numbers.",
        )
    )
    for k, s in enumerate(_overlay_samples(outliers, after)):
        sample = samples.get((obs.sources[s], int(obs.stamps_ns[s])))
        if sample is None:
            continue
        name = f"overlay_{k + 1}.png"
        rows = obs.sample_index == s
        pngs[name] = fig.overlay_png(
            sample.image(),
            obs.uv[rows],
            {
                "before": _predicted_corners(robot, obs, s, Corrections()),
                "after": _predicted_corners(robot, obs, s, after_of_sample[s]),
            },
            {
                "before": _skeleton(robot, obs.q_measured[s], Corrections(), obs.camera),
                "after": _skeleton(robot, obs.q_measured[s], after_of_sample[s], obs.camera),
            },
            f"sample {s}: RMS {before.sample_rms[s]:.2f} px before, {after.sample_rms[s]:.2f} px after"
            + (" (outlier)" if outliers[s] else ""),
        )
        captions.append(
            (
                name,
                f"Sample {s} ({Path(obs.sources[s]).name}): detected tag corners (green rings), "
                "corners and the robot's kinematic skeleton (lines between joint origins) as each model "
                "predicts them from the joint readings: red input URDF, blue calibrated.",
            )
        )
    covariance = result.get("covariance") or {"names": [], "matrix": []}
    names = covariance["names"]
    cov = np.asarray(covariance["matrix"], dtype=float)
    if names:
        d = np.sqrt(np.clip(np.diag(cov), 1e-300, None))
        pngs["correlation.png"] = fig.correlation_png(names, cov / np.outer(d, d), "Parameter correlation")
        captions.append(
            (
                "correlation.png",
                "Correlation between the fitted parameters (from the fit's "
                "covariance). Near +1 or -1 (dark) means the data cannot tell the two apart: only their "
                "combination is determined.",
            )
        )
    return pngs, captions


def _ground_text(reference_is_truth: bool) -> str:
    pose = ", ".join(f"{k} = {v:+.4f} rad" for k, v in STANDING.items())
    common = (
        f"A standing robot (straight legs: {pose}, all other joints 0 as read by the encoders) tilts its head to "
        "look at a ball on the ground straight ahead. The pixel where the ball appears is turned back into a spot "
        "on the field through each model (the ground is the model's sole plane); the error is the distance on the "
        "field between that spot and where the ball really is. 'Lands at' is the distance from the robot where "
        "the model puts the ball."
    )
    if reference_is_truth:
        return (
            common
            + " Reference: the simulator's truth (the held-out capture has a .truth.yaml beside it), so "
            "both columns are true errors."
        )
    return (
        common + " Reference: the calibrated model (no ground truth is known for a real robot), so 'before' "
        "is how far the calibration moves the ball, and 'after' is 0 by definition."
    )


def _ground_blocks(ground: dict) -> list[Block]:
    """The ground-error section (nothing when the robot has no sole frame to stand on)."""
    if not ground["rows"]:
        return []
    rows = []
    for row in ground["rows"]:
        cells = [f"{row['distance_m']:g} m"]
        for model in ("before", "after"):
            g = row["models"][model]
            cells += [
                "above horizon" if g["landed_at_m"] is None else f"{g['landed_at_m']:.3f} m",
                "n/a" if g["error_m"] is None else f"{g['error_m'] * 100:.1f} cm",
            ]
        rows.append(cells)
    headers = ["ball at", "lands at, before", "error before", "lands at, after", "error after"]
    return [
        ("h2", "Where a ball lands on the field"),
        ("p", _ground_text(ground["reference"] == "simulator truth")),
        ("table", (headers, rows, set())),
    ]


def _blocks(metrics: dict, captions: list[tuple[str, str]]) -> list[Block]:
    m = metrics
    blocks: list[Block] = [("h1", f"wolfcal evaluation: {m['robot_name']}, --free {m['free']}")]
    blocks.append(("banner", (not m["verdict"]["worse"], m["verdict"]["message"])))
    blocks.append(("p", INTRO))
    blocks.append(("p", m["mode_note"]))
    blocks.append(("h2", "Before and after"))
    blocks.append(
        (
            "p",
            "Before: the input URDF as it is. After: with the calibration. Every number comes from "
            f"samples the calibration was not fitted on ({m['n_samples']} sample(s), {m['n_outliers']} "
            "outlier sample(s) left out of these numbers and marked in the table below).",
        )
    )
    blocks.append(("table", (["", "before (input URDF)", "after (calibrated)"], headline_rows(m), set())))
    blocks.append(
        (
            "p",
            "Reprojection RMS per axis: sqrt(mean(du^2 + dv^2) / 2) over all tag corners, in pixels "
            "of the captured images; how far, on average, the model's prediction of a tag corner is from "
            "where the camera saw it. Largest corner error: the worst single corner (distance). Tag-grid "
            "mean distance: the 2019 study's metric, for comparison with its 38.2 mm -> 18.4 mm: the tag's "
            "pose measured from its four corners alone (PnP) versus predicted by the model, mean distance of "
            "a 5 x 4 grid of points on the tag; a single tag's depth is poorly measured, so it is noisier.",
        )
    )
    blocks += _ground_blocks(m["ground"])
    blocks.append(("h2", "Pictures"))
    blocks += [("figure", c) for c in captions]
    blocks.append(("h2", "Fitted parameters"))
    blocks.append(
        (
            "table",
            (
                ["parameter", "value +- std", "information from data"],
                [[p["name"], p["display"], f"{p['data_share']:.0%}"] for p in m["parameters"]],
                set(),
            ),
        )
    )
    blocks.append(("h2", "Per sample"))
    blocks.append(
        (
            "p",
            "RMS per axis and largest corner error in pixels, tag-grid distance in millimetres; "
            "outlier samples are marked (highlighted) and left out of the numbers above.",
        )
    )
    folds = m["folds"] is not None
    headers = ["sample", "capture", "tags"] + (["fold"] if folds else [])
    headers += ["RMS before", "RMS after", "max after", "grid before", "grid after", ""]
    rows, marked = [], set()
    for i, s in enumerate(m["samples"]):
        row = [str(s["index"]), s["source"], " ".join(map(str, s["tags"]))]
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
    blocks.append(("table", (headers, rows, marked)))
    blocks.append(("h2", "Files to deploy"))
    if m["deploy"]["written"]:
        blocks.append(("p", "Written beside this report:"))
        blocks.append(("pre", DEPLOY_TEXT))
        blocks.append(("p", "Camera correction as a static transform:"))
        blocks.append(("pre", m["camera_correction"]["static_transform_publisher"]))
    else:
        blocks.append(("banner", (False, m["deploy"]["reason"])))
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


def _fmt_mm(value: float | None) -> str:
    return "" if value is None else f"{value:.1f}"


INTRO = (
    "What this is: the robot computes where its camera is, and so where things it sees are on the field, from its "
    "joint readings and its kinematic model (the URDF). A calibration corrects that model (the camera's mounting, "
    "the joints' zero positions). This report checks whether the corrected model predicts what the camera really "
    "sees better than the model in use today, on images the calibration was not computed from, and gives the files "
    "to load on the robot if it does."
)
DEPLOY_TEXT = """calibrated.urdf          the URDF with the calibration: camera (and any other frame) corrections in
                         <origin>, encoder offsets as <calibration rising="offset"/> (ROS convention)
calibrated_folded.urdf   the same model with each offset folded into its joint's <origin>, for
                         robot_state_publisher and every tool that ignores <calibration>: publish it as
                         robot_description with the encoder readings as they are
joint_offsets.yaml       offset per joint [rad] for the hardware interface: add on read, subtract on write
                         (use it with calibrated.urdf, never together with calibrated_folded.urdf)
camera_correction.yaml   the camera correction alone: pose of the calibrated optical frame in the
                         uncalibrated one, for a static-transform node (command below)"""


def _deploy(robot: Robot, fitted: Corrections, out_dir: Path, worse: bool, force: bool) -> dict:
    """Write the deploy files, or (worse held-out error without force) remove any an earlier run left."""
    if worse and not force:
        removed = remove_deploy_files(out_dir)
        earlier = f" ({len(removed)} file(s) of an earlier run removed)" if removed else ""
        return {
            "written": False,
            "forced": False,
            "files": [],
            "reason": "The calibration makes held-out error worse, so the deploy files were not written"
            f"{earlier}. Pass --force to write them anyway.",
        }
    paths = write_deploy_files(robot, fitted, out_dir)
    return {
        "written": True,
        "forced": worse,
        "files": [p.name for p in paths],
        "reason": "written despite worse held-out error (--force)" if worse else None,
    }


def run_evaluate(
    fit_dir: Path,
    captures: list[Path],
    out_dir: Path,
    force: bool = False,
    folds: int = 5,
    say: Callable[[str], None] = print,
) -> dict:
    """The whole `wolfcal evaluate` job; returns the metrics written to out_dir/metrics.json.

    With `captures` empty, k-fold cross-validation over the fit's own captures. The deploy files are written only
    when the calibration does not make held-out reprojection RMS worse, or with `force`; check
    `metrics['deploy']['written']`. `before_after_table(metrics)` gives the terminal table.
    """
    fit_dir, out_dir = Path(fit_dir), Path(out_dir)
    result, robot, fitted = _load_fit(fit_dir)
    held_out = bool(captures)
    fitted_on = {Path(c).resolve() for c in result["captures"]}
    reused = [str(c) for c in captures if Path(c).resolve() in fitted_on]
    if reused:
        raise WolfcalError(
            f"{', '.join(reused)}: the fit used this capture, so it is not held out; give a capture the fit did not "
            "use, or leave out --capture for cross-validation over the fit's samples"
        )
    sources = [Path(c) for c in captures] if held_out else [Path(c) for c in result["captures"]]
    intrinsics = Path(result["intrinsics"]) if result.get("intrinsics") else None
    samples, _ = load_samples(robot, sources, intrinsics)
    say(f"read {len(samples)} sample(s) from {len(sources)} capture file(s); detecting tags ...")
    obs, warnings = detect_observations(samples, robot)
    tags = [t for t in result["tags_used"] if t in obs.observed_tag_ids]
    if not tags:
        raise WolfcalError(
            f"none of the fit's tags ({', '.join(map(str, result['tags_used']))}) was detected in "
            f"{', '.join(str(s) for s in sources)}"
        )
    obs = obs.only_tags(tags)
    views: TagViews = measure_tag_views(robot, obs)
    before = model_errors(robot, obs, views, Corrections())
    fold_of = None
    if held_out:
        after = model_errors(robot, obs, views, fitted)
        after_of_sample = [fitted] * obs.n_samples
        mode_note = (
            f"Held-out evaluation on {', '.join(p.name for p in sources)}: samples the fit "
            f"({', '.join(Path(c).name for c in result['captures'])}) did not use."
        )
    else:
        options = FitOptions(
            free=result["free"],
            side=result["side"],
            fix_tags=result["fix_tags"],
            huber_k=(result.get("robust_loss") or {}).get("threshold_sigma", 3.0),
        )
        fold_of, models = cross_validate(robot, obs, options, folds, say)
        after = merge_folds(obs, views, fold_of, [model_errors(robot, obs, views, c) for c in models])
        after_of_sample = [models[k] for k in fold_of]
        mode_note = (
            f"No held-out capture was given: {len(models)}-fold cross-validation over the fit's own "
            f"{obs.n_samples} sample(s). Each sample is judged by a calibration fitted on the other folds "
            "(sample i in fold i mod k), so no number here comes from a sample its model was fitted on. "
            "The deploy files hold the calibration fitted on all samples. A capture taken apart from the "
            "fit's (wolfcal evaluate FIT_DIR --capture HELDOUT.mcap) is the stronger test."
        )
    outliers = outlier_samples(before, after)
    s_before, s_after = summary(obs, views, before, outliers), summary(obs, views, after, outliers)
    worse = bool(s_after["rms_px"] > s_before["rms_px"])
    if worse:
        verdict = (
            f"The calibration makes held-out error worse: reprojection RMS {s_after['rms_px']:.3f} px "
            f"calibrated vs {s_before['rms_px']:.3f} px with the input URDF. Keep the input URDF; refit "
            "with more varied poses, fewer free parameters, or without the outlier samples."
        )
    else:
        verdict = (
            f"The calibration improves held-out error: reprojection RMS {s_before['rms_px']:.3f} px -> "
            f"{s_after['rms_px']:.3f} px."
        )
    truth = _truth_reference(sources)
    reference = truth if truth is not None else fitted
    ground_rows = []
    if GROUND_LINK in robot.model.links:
        say("computing the ground error ...")
        models = {"before": Corrections(), "after": fitted}
        ground_rows = ground_errors(robot, obs.camera, reference, models, DISTANCES_M)
    else:
        warnings.append(
            f"{robot.config.urdf} has no '{GROUND_LINK}' frame: the ground error was not computed"
        )
    say("drawing the pictures ...")
    sample_by_key = {(s.source, int(s.stamp_ns)): s for s in samples}
    pngs, captions = _figures(robot, obs, sample_by_key, before, after, outliers, after_of_sample, result)
    out_dir.mkdir(parents=True, exist_ok=True)
    deploy = _deploy(robot, fitted, out_dir, worse, force)
    metrics = {
        "wolfcal_version": wolfcal.__version__,
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "fit_dir": str(fit_dir.resolve()),
        "robot": str(robot.config.path),
        "robot_name": robot.config.name,
        "free": result["free"],
        "mode": "held-out" if held_out else "cross-validation",
        "mode_note": mode_note,
        "captures": [str(p.resolve()) for p in sources],
        "folds": None if held_out else int(fold_of.max() + 1),
        "tags_used": tags,
        "n_samples": obs.n_samples,
        "n_outliers": int(outliers.sum()),
        "meanings": {
            "rms_px": "per-axis RMS of corner residuals sqrt(mean(du^2 + dv^2) / 2) [px], inlier samples",
            "max_px": "largest distance between a predicted and a detected corner [px], inlier samples",
            "median_corner_px": "median distance between predicted and detected corner [px], inlier samples",
            "tag_grid_mean_mm": "mean distance between a 5x4 grid on each tag placed by PnP of its detected corners "
            "and by the model [mm] (the 2019 study's metric), inlier samples",
            "ground": "distance on the field between where the ball is and where the model puts it [m]",
        },
        "before": s_before,
        "after": s_after,
        "ground": {
            "reference": "simulator truth" if truth is not None else "calibrated model",
            "standing_pose_rad": STANDING,
            "rows": ground_rows,
        },
        "verdict": {"worse": bool(worse), "message": verdict},
        "deploy": deploy,
        "camera_correction": camera_correction(robot, fitted),
        "parameters": [
            {k: p[k] for k in ("name", "value", "std", "unit", "data_share", "display")}
            for p in result["parameters"]
        ],
        "correlated_pairs": result.get("correlated_pairs", []),
        "samples": _sample_rows(obs, before, after, outliers, fold_of),
        "figures": [{"file": f"figures/{name}", "caption": caption} for name, caption in captions],
        "warnings": warnings,
    }
    blocks = _blocks(metrics, captions)
    for name, data in pngs.items():
        write_bytes_atomic(out_dir / "figures" / name, data)
    write_text_atomic(
        out_dir / "report.html", render_html(blocks, pngs, f"wolfcal evaluation {robot.config.name}")
    )
    write_text_atomic(out_dir / "report.md", render_markdown(blocks, "figures"))
    write_text_atomic(out_dir / "metrics.json", json.dumps(metrics, indent=2, allow_nan=False) + "\n")
    for line in before_after_table(metrics).splitlines():
        say(line)
    say(verdict)
    say(f"report: {out_dir / 'report.html'}")
    return metrics
