"""`wolfcal evaluate`: a fit + held-out captures (or k-fold cross-validation) -> report and files to deploy.

Before = the input URDF (no corrections); after = the fit's corrections. Every error is measured on samples the
judged model was not fitted on. The deploy files are written only when the verdict (`verdict`: pixels, whether the
model explains the data, ground error) allows it, or with deploy_worse=True. This module only runs the steps;
errors are `metrics` / `ground` / `crossval` / `structure`, the report's words `report_content`, its pictures
`report_figures`, the files to deploy `deploy`.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from datetime import datetime, timezone
from pathlib import Path

import numpy as np

import wolfcal
from wolfcal.atomic import output_set, write_bytes_atomic, write_text_atomic
from wolfcal.camera.model import CameraModel
from wolfcal.errors import WolfcalError
from wolfcal.evaluate.crossval import cross_validate
from wolfcal.evaluate.deploy import DEPLOY_FILES, camera_correction, write_or_withhold_deploy_files
from wolfcal.evaluate.external import external_metrics
from wolfcal.evaluate.floor_ground import measured_ground_errors
from wolfcal.evaluate.ground import DISTANCES_M, VERDICT_DISTANCE_M, ground_errors, predicted_ground_std
from wolfcal.evaluate.metrics import (
    HeldOutErrors,
    ModelErrors,
    TagViews,
    measure_tag_views,
    merge_folds,
    model_errors,
    outlier_samples,
    summary,
)
from wolfcal.evaluate.report import before_after_table, render_html, render_markdown
from wolfcal.evaluate.report_content import (
    MEANINGS,
    cross_validation_note,
    held_out_note,
    report_blocks,
    sample_rows,
)
from wolfcal.evaluate.report_figures import Figures, report_figures
from wolfcal.evaluate.structure import unexplained
from wolfcal.evaluate.verdict import VerdictLimits, deploy_verdict
from wolfcal.fit.pipeline import FIT_OUTPUTS, load_captures, samples_of
from wolfcal.fit.result import FitResult, load_result
from wolfcal.fit.systems import evaluating_systems
from wolfcal.io.samples import Capture, Sample
from wolfcal.io.truth import truth_paths
from wolfcal.leftout import check_left_out
from wolfcal.observations import HEAD_CAMERA, Observations
from wolfcal.outputs import check_output_folder
from wolfcal.progress import Progress
from wolfcal.robot.corrections import Corrections, load_corrections
from wolfcal.robot.parameters import ParameterSet, build_parameter_set
from wolfcal.robot.robot import Robot, load_robot
from wolfcal.vision.corner_bias import CORNER_INSET
from wolfcal.vision.observe import detect_observations, observations_of


def load_fit(fit_dir: Path) -> tuple[FitResult, Robot]:
    """The fit's result.yaml, its robot and its fitted corrections."""
    if not Path(fit_dir).exists():
        raise WolfcalError(f"{fit_dir}: fit folder not found (run `wolfcal fit ... --out {fit_dir}` first)")
    folder = Path(fit_dir) if Path(fit_dir).is_dir() else Path(fit_dir).parent
    missing = [name for name in FIT_OUTPUTS if not (folder / name).is_file()]
    if missing:
        raise WolfcalError(
            f"{folder}: not a complete fit folder ({', '.join(missing)} missing); give the --out folder of a "
            f"`wolfcal fit` run, or run the fit again"
        )
    result = load_result(fit_dir)
    robot_path = Path(result.robot)
    if not robot_path.exists():
        raise WolfcalError(f"{fit_dir}: the fit's robot config {robot_path} no longer exists")
    return result, load_robot(robot_path)


def refuse_fitted_captures(captures: list[Path], fit_captures: list[str]) -> None:
    """A held-out capture must not be one the fit used."""
    fitted_on = {Path(c).resolve() for c in fit_captures}
    reused = [str(c) for c in captures if Path(c).resolve() in fitted_on]
    if reused:
        raise WolfcalError(
            f"{', '.join(reused)}: the fit used this capture, so it is not held out; give a capture the fit did not "
            "use, or leave out --capture for cross-validation over the fit's samples"
        )


def _observe(
    robot: Robot, result: FitResult, loaded: list[Capture], sources: list[Path], say: Callable[[str], None]
) -> tuple[list[Sample], Observations, list[int], list[str], Observations | None]:
    """Samples of the read sources, their corners of the fit's tags, those tags, detection warnings, and the views
    of floor tags (None without)."""
    samples, _ = samples_of(loaded, robot)
    say(f"read {len(samples)} sample(s) from {len(sources)} capture file(s); detecting tags ...")
    observations, warnings = detect_observations(
        samples, robot, progress=Progress(say, "detecting tags", "samples"), cameras=[HEAD_CAMERA]
    )
    obs = observations_of(observations, HEAD_CAMERA, sources)
    floor_ids = [t for t in obs.observed_tag_ids if robot.config.floor is not None and t in robot.config.floor.tag_ids]
    floor = obs.only_tags(floor_ids) if floor_ids else None
    tags = [t for t in result.tags_used if t in obs.observed_tag_ids]
    if not tags:
        raise WolfcalError(
            f"none of the fit's tags ({', '.join(map(str, result.tags_used))}) was detected in "
            f"{', '.join(str(s) for s in sources)}"
        )
    return samples, obs.only_tags(tags), tags, warnings, floor


def _measured_ground(robot: Robot, floor: Observations | None, fitted: Corrections, held_out: bool,
                     say: Callable[[str], None], corner_inset: tuple[float, float]) -> dict | None:  # fmt: skip
    """`floor_ground.measured_ground_errors` of the held-out floor views, before and after (None: not measured)."""
    if floor is None or not held_out:
        return None
    say("measuring the ground error on the held-out floor views ...")
    return measured_ground_errors(robot, floor, {"before": Corrections(), "after": fitted}, DISTANCES_M, corner_inset)


def _verdict_ground(measured: dict | None) -> dict | None:
    """The verdict's {'before_m', 'after_m', 'after_std_m'} at 4.5 m (inf: the ball lies above the horizon)."""
    if measured is None:
        return None
    k = DISTANCES_M.index(VERDICT_DISTANCE_M)
    before, after = (measured["models"][m]["rows"][k] for m in ("before", "after"))
    inf = float("inf")
    return {"before_m": inf if before["error_m"] is None else before["error_m"],
            "after_m": inf if after["error_m"] is None else after["error_m"], "after_std_m": after["std_m"],
            "before_std_m": before["std_m"] or 0.0, "capture": measured.get("capture"),
            "check": measured.get("check")}


def _run_external_evaluate(
    robot: Robot, result: FitResult, fitted: Corrections, fit_dir: Path, loaded: list[Capture], captures: list[Path],
    out_dir: Path, deploy_worse: bool, say: Callable[[str], None],
) -> dict:
    """Held-out external-camera captures (read: `loaded`): `external_metrics` before/after, metrics.json,
    report.md, deploy files unless the reprojection error of any camera got worse."""
    samples, warnings = samples_of(loaded, robot, cameras=())
    names = [c.name for c in robot.config.external_cameras]
    observations, detect_warnings = detect_observations(samples, robot, cameras=names)
    tags = set(result.tags_used)
    observations = {n: o.only_tags(sorted(tags & set(o.observed_tag_ids))) for n, o in observations.items()
                    if tags & set(o.observed_tag_ids)}  # fmt: skip
    truth = _truth_reference(captures)
    figures = external_metrics(robot, observations, fitted, truth, say)
    worse = any(c["after"]["rms_px"] > c["before"]["rms_px"] for c in figures["cameras"].values())
    out_dir.mkdir(parents=True, exist_ok=True)
    refused = "The calibration makes the held-out reprojection error worse." if worse else None
    deploy = write_or_withhold_deploy_files(robot, fitted, out_dir, refused, deploy_worse)
    lines = [f"# wolfcal evaluation {robot.config.name}: held-out external-camera captures", "",
             f"fit: {fit_dir.resolve()}; captures: {', '.join(str(c) for c in captures)}", "",
             figures["meaning"], "", "| camera | model | RMS [px] | max [px] | tag grid [mm] mean +- std |",
             "|---|---|---|---|---|"]  # fmt: skip
    for name, c in figures["cameras"].items():
        for label in ("before", "after"):
            r = c[label]
            mean, std = r["tag_grid_mm_mean"], r["tag_grid_mm_std"]
            grid = "-" if mean is None else f"{mean:.2f} +- {std:.2f}"
            lines.append(f"| {name} | {label} | {r['rms_px']:.3f} | {r['max_px']:.2f} | {grid} |")
    if "sole_error_mm" in figures:
        lines += ["", "Sole position error relative to the torso against the simulator's truth, max over 300 random "
                  "leg configurations [mm]: " + "; ".join(
                      f"{label}: " + ", ".join(f"{s} {v:.2f}" for s, v in e.items())
                      for label, e in figures["sole_error_mm"].items())]  # fmt: skip
    verdict = ("the calibration makes the held-out reprojection error worse: deploy files withheld" if worse else
               "the calibration improves the held-out external-camera views")  # fmt: skip
    lines += ["", f"**{verdict}**"]
    metrics = {
        "wolfcal_version": wolfcal.__version__, "fit_dir": str(fit_dir.resolve()), "robot": str(robot.config.path),
        "robot_name": robot.config.name, "free": result.free, "mode": "held-out",
        "captures": [str(Path(c).resolve()) for c in captures], "external": figures,
        "verdict": {"worse": worse, "message": verdict}, "deploy": deploy, "warnings": warnings + detect_warnings,
    }  # fmt: skip
    write_text_atomic(out_dir / "report.md", "\n".join(lines) + "\n")
    write_text_atomic(out_dir / "metrics.json", json.dumps(metrics, indent=2, allow_nan=False) + "\n")
    for line in lines[6:]:
        say(line)
    say(f"report: {out_dir / 'report.md'}")
    return metrics


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


def _ground_rows(
    robot: Robot, camera: CameraModel, reference: Corrections, fitted: Corrections, say: Callable[[str], None]
) -> tuple[list[dict], str | None]:
    """`ground_errors` rows of the input URDF and the calibration [m], or none and why (no `floor:` config)."""
    if robot.config.floor is None:
        return [], (f"{robot.config.path} has no 'floor:' (standing soles and pose): the ground error was not "
                    "computed")
    say("computing the ground error ...")
    models = {"before": Corrections(), "after": fitted}
    return ground_errors(robot, camera, reference, models, DISTANCES_M), None


def _predicted_ground(
    robot: Robot, camera: CameraModel, result: FitResult, tags: list[int], fitted: Corrections
) -> float | None:
    """1-sigma ground error at 4.5 m [m] from the fit's covariance of its chain parameters (None without floor)."""
    covariance = result.covariance
    if robot.config.floor is None or not covariance:
        return None
    chain = build_parameter_set(robot, result.free, {HEAD_CAMERA: tags}, result.side, result.fix_tags)
    index = {name: i for i, name in enumerate(covariance["names"])}
    keep = [k for k, name in enumerate(chain.names) if name in index]
    cols = [index[chain.names[k]] for k in keep]
    sub = ParameterSet([chain.parameters[k] for k in keep])
    matrix = np.asarray(covariance["matrix"], dtype=float)[np.ix_(cols, cols)]
    return predicted_ground_std(robot, camera, sub, sub.values_from(fitted), matrix)


def camera_turn(robot: Robot, fitted: Corrections) -> float:
    """Rotation angle of the fitted camera frame correction [rad] (0 without a head camera)."""
    if robot.config.camera is None:
        return 0.0
    return float(np.linalg.norm(fitted.frames.get(robot.camera_joint, np.zeros(6))[3:]))


REPORT_FILES = ("report.html", "report.md", "metrics.json")


def _write_report(out_dir: Path, metrics: dict, figures: Figures) -> None:
    """figures/*.png, report.html, report.md and metrics.json in out_dir."""
    pngs, captions = figures
    blocks = report_blocks(metrics, captions)
    for name, data in pngs.items():
        write_bytes_atomic(out_dir / "figures" / name, data)
    write_text_atomic(
        out_dir / "report.html", render_html(blocks, pngs, f"wolfcal evaluation {metrics['robot_name']}")
    )
    write_text_atomic(out_dir / "report.md", render_markdown(blocks, "figures"))
    write_text_atomic(out_dir / "metrics.json", json.dumps(metrics, indent=2, allow_nan=False) + "\n")


PARAMETER_KEYS = ("name", "value", "std", "unit", "data_share", "display")  # of each fitted parameter in metrics


def _after(
    robot: Robot, obs: Observations, views: TagViews, result: FitResult, held_out: list[Path] | None, folds: int,
    say: Callable[[str], None],
) -> tuple[ModelErrors, list[Corrections], np.ndarray | None, str]:
    """Errors of the calibrated model: on held-out captures (`held_out`) the fitted one, otherwise each sample under
    the model of the cross-validation fold that left it out. Also the model per sample, the fold of each sample
    (None when held out) and the sentence saying which."""
    fitted = result.corrections
    if held_out is not None:
        note = held_out_note(held_out, result.captures)
        return model_errors(robot, obs, views, fitted), [fitted] * obs.n_samples, None, note
    fold_of, models = cross_validate(robot, obs, result.options, folds, say)
    after = merge_folds(obs, views, fold_of, [model_errors(robot, obs, views, c) for c in models])
    return after, [models[k] for k in fold_of], fold_of, cross_validation_note(len(models), obs.n_samples)


def _judge(
    robot: Robot, obs: Observations, result: FitResult, sources: list[Path], held_out: bool, folds: int,
    say: Callable[[str], None],
) -> HeldOutErrors:
    """Errors before and after (see `_after`), the outlier samples and the summaries; more than MAX_LEFT_OUT of the
    samples left out is refused (WolfcalError)."""
    views = measure_tag_views(robot, obs)
    before = model_errors(robot, obs, views, Corrections())
    after, after_of_sample, fold_of, mode_note = _after(robot, obs, views, result, sources if held_out else None,
                                                       folds, say)  # fmt: skip
    outliers = outlier_samples(before, after)
    check_left_out(
        {"samples": (int(outliers.sum()), obs.n_samples)},
        ", ".join(map(str, sources)),
        "the evaluation refuses to judge on what is left: check these captures' joint readings and images, and "
        "that they are of this robot and camera",
    )
    return HeldOutErrors(before, after, after_of_sample, fold_of, mode_note, outliers,
                         summary(obs, views, before, outliers), summary(obs, views, after, outliers))  # fmt: skip


def _ground_section(robot: Robot, from_truth: bool, rows: list[dict], measured: dict | None) -> dict:
    """metrics['ground']: the ground error rows of the standing robot and the one measured on floor views."""
    floor = robot.config.floor
    return {
        "reference": "simulator truth" if from_truth else "calibrated model",
        "standing_pose_rad": dict(floor.standing) if floor else {},
        "soles": list(floor.soles) if floor else [],
        "rows": rows,
        "measured": measured,
    }


@output_set()  # all outputs written as one set: nothing of a failed run replaces an earlier one
def run_evaluate(
    fit_dir: Path,
    captures: list[Path],
    out_dir: Path,
    deploy_worse: bool = False,
    folds: int = 5,
    say: Callable[[str], None] = print,
    force: bool = False,
    limits: VerdictLimits = VerdictLimits(),
) -> dict:
    """The whole `wolfcal evaluate` job; returns the metrics written to out_dir/metrics.json.

    With `captures` empty, k-fold cross-validation over the fit's own captures. The deploy files are written only
    when the deploy verdict allows it (`verdict.deploy_verdict`: held-out reprojection RMS, whether the free
    parameters explain the held-out data, the measured ground error; held-out external-camera captures alone: each
    camera's reprojection RMS), or with `deploy_worse`; check `metrics['deploy']['written']`.
    `before_after_table(metrics)` gives the terminal table. Outputs of an earlier run in out_dir are replaced only
    with `force`; all are written as one set (`output_set`). More than MAX_LEFT_OUT of the samples left out as
    outliers is refused (WolfcalError).
    """
    fit_dir, out_dir = Path(fit_dir), Path(out_dir)
    result, robot = load_fit(fit_dir)
    fitted = result.corrections
    held_out = bool(captures)
    refuse_fitted_captures(captures, result.captures)
    sources = [Path(c) for c in captures] if held_out else [Path(c) for c in result.captures]
    fit_folder = fit_dir if fit_dir.is_dir() else fit_dir.parent
    inputs = [*sources, *(fit_folder / name for name in FIT_OUTPUTS), robot.config.path, robot.config.urdf]
    check_output_folder(out_dir, REPORT_FILES + DEPLOY_FILES, force, inputs)
    for system in evaluating_systems():  # recordings a system judges alone (held out, or its refusal)
        own = system.load("evaluator")(fit_dir, result, robot, sources, out_dir, deploy_worse, say)
        if own is not None:
            return own
    intrinsics = Path(result.intrinsics) if result.intrinsics else None
    loaded = load_captures(robot, sources, intrinsics, say)  # read once, for whichever camera holds the views
    if held_out and not any(HEAD_CAMERA in c.cameras for c in loaded):
        return _run_external_evaluate(robot, result, fitted, fit_dir, loaded, captures, out_dir, deploy_worse, say)
    samples, obs, tags, warnings, floor = _observe(robot, result, loaded, sources, say)
    errors = _judge(robot, obs, result, sources, held_out, folds, say)
    truth = _truth_reference(sources)
    ground_rows, no_ground = _ground_rows(robot, obs.camera, truth if truth is not None else fitted, fitted, say)
    if no_ground:
        warnings.append(no_ground)
    structure = unexplained(robot, obs, fitted, errors.after.residuals, ~errors.outliers)
    predicted = _predicted_ground(robot, obs.camera, result, tags, fitted)
    measured = _measured_ground(robot, floor, fitted, held_out, say, result.estimate(CORNER_INSET) or (0.0, 0.0))
    verdict = deploy_verdict(result.free, errors.summary_before["rms_px"], errors.summary_after["rms_px"], structure,
                             _verdict_ground(measured), predicted, camera_turn(robot, fitted), limits)  # fmt: skip
    say("drawing the pictures ...")
    sample_by_key = {(s.source, int(s.stamp_ns)): s for s in samples}
    figures = report_figures(robot, obs, sample_by_key, errors, result.covariance)
    out_dir.mkdir(parents=True, exist_ok=True)
    deploy = write_or_withhold_deploy_files(robot, fitted, out_dir, None if verdict["deploy"] else verdict["message"],
                                            deploy_worse)  # fmt: skip
    metrics = {
        "wolfcal_version": wolfcal.__version__,
        "created": datetime.now(timezone.utc).isoformat(timespec="seconds"),
        "fit_dir": str(fit_dir.resolve()),
        "robot": str(robot.config.path),
        "robot_name": robot.config.name,
        "free": result.free,
        "mode": "held-out" if held_out else "cross-validation",
        "mode_note": errors.mode_note,
        "captures": [str(p.resolve()) for p in sources],
        "folds": errors.folds,
        "tags_used": tags,
        "n_samples": obs.n_samples,
        "n_outliers": int(errors.outliers.sum()),
        "meanings": dict(MEANINGS),
        "before": errors.summary_before,
        "after": errors.summary_after,
        "ground": _ground_section(robot, truth is not None, ground_rows, measured),
        "verdict": verdict,
        "structure": structure,
        "deploy": deploy,
        "camera_correction": camera_correction(robot, fitted),
        "parameters": [{k: getattr(p, k) for k in PARAMETER_KEYS} for p in result.parameters],
        "correlated_pairs": result.correlated_pairs,
        "samples": sample_rows(obs, errors),
        "figures": [{"file": f"figures/{name}", "caption": caption} for name, caption in figures[1]],
        "warnings": warnings,
    }
    _write_report(out_dir, metrics, figures)
    for line in before_after_table(metrics).splitlines():
        say(line)
    for line in [verdict["message"], *verdict["refusals"][1:], *verdict["notes"]]:
        say(line)
    say(f"report: {out_dir / 'report.html'}")
    return metrics
