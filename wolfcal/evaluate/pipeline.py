"""`wolfcal evaluate`: a fit + held-out captures (or k-fold cross-validation) -> report and files to deploy.

Before = the robot's present calibration (`--current` of the evaluation, else the one the fit started from, else the
input URDF with no corrections); after = the model to deploy (`undetermined.deployable_model`: the present
calibration with the fitted parameters' new totals, a parameter the data cannot determine held at its present value).
Every error is measured on samples the judged model was not fitted on. The deploy files are written only when the
verdict (`verdict`: pixels, whether the model explains the data, ground error) allows it, or with
deploy_worse=True. This module only runs the steps;
errors are `metrics` / `ground` / `crossval` / `structure`, the report's words `report_content`, its pictures
`report_figures`, the files to deploy `deploy`.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from pathlib import Path

import numpy as np

from wolfcal.atomic import make_folder, output_set, write_bytes_atomic, write_text_atomic
from wolfcal.errors import WolfcalError
from wolfcal.evaluate.crossval import cross_validate
from wolfcal.evaluate.deploy import DEPLOY_FILES, camera_correction, deploy_lines, write_or_withhold_deploy_files
from wolfcal.evaluate.explaining import explaining_preset
from wolfcal.evaluate.external import external_metrics
from wolfcal.evaluate.ground_figures import (
    camera_turn,
    ground_distances,
    ground_rows,
    ground_section,
    measured_ground,
    predicted_ground,
    verdict_ground,
    verdict_limits,
)
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
from wolfcal.evaluate.provenance import provenance
from wolfcal.evaluate.report import before_after_table, render_html, render_markdown
from wolfcal.evaluate.report_content import (
    MEANINGS,
    SPAN_MEANING,
    cross_validation_note,
    held_out_note,
    report_blocks,
    sample_rows,
    span_counts,
    spans_of,
)
from wolfcal.evaluate.report_figures import Figures, report_figures
from wolfcal.evaluate.structure import unexplained
from wolfcal.evaluate.undetermined import deployable_model
from wolfcal.evaluate.verdict import MOUNT_LIMIT_RAD, deploy_verdict
from wolfcal.fit.pipeline import FIT_OUTPUTS, load_captures, samples_of
from wolfcal.fit.result import FitResult, load_result
from wolfcal.fit.systems import evaluating_systems
from wolfcal.io.current import CurrentCalibration, current_files, load_current
from wolfcal.io.samples import Capture, Sample
from wolfcal.io.truth import truth_paths
from wolfcal.leftout import check_left_out
from wolfcal.observations import HEAD_CAMERA, Observations
from wolfcal.outputs import check_output_folder
from wolfcal.progress import Progress
from wolfcal.robot.corrections import Corrections, load_corrections
from wolfcal.robot.robot import Robot, load_robot
from wolfcal.spans import sample_count, still_span_observations
from wolfcal.vision.corner_bias import CORNER_INSET
from wolfcal.vision.observe import detect_observations, observations_of


def load_fit(fit_dir: Path) -> tuple[FitResult, Robot]:
    """The fit's result.yaml, its robot and its fitted corrections."""
    if not Path(fit_dir).exists():
        raise WolfcalError(f"{fit_dir}: fit folder not found (run `wolfcal fit ... --out {fit_dir}` first)")
    if Path(fit_dir).is_file() and Path(fit_dir).name not in FIT_OUTPUTS:
        what = "a capture file" if Path(fit_dir).suffix == ".mcap" else "a file"
        raise WolfcalError(
            f"{fit_dir}: {what}, not a fit folder; evaluate takes the --out folder of `wolfcal fit` (it holds "
            f"result.yaml): fit first (`wolfcal fit CAPTURE.mcap --out FIT`), then `wolfcal evaluate FIT --out "
            "REPORT`, with held-out captures as `--capture HELD_OUT.mcap`"
        )
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
    """Samples of the read sources, their corners of the fit's tags (a recording's frames averaged per still span,
    as the fit takes them: `still_span_observations`), those tags, detection warnings, and the views of floor tags
    (None without)."""
    samples, _ = samples_of(loaded, robot)
    say(f"read {len(samples)} sample(s) from {len(sources)} capture file(s); detecting tags ...")
    observations, warnings = detect_observations(
        samples, robot, progress=Progress(say, "detecting tags", "samples"), cameras=[HEAD_CAMERA]
    )
    observations = still_span_observations(robot.config, observations, result.external_moving)
    obs = observations_of(observations, HEAD_CAMERA, sources)
    if obs.span_frames is not None:
        say(f"head camera: {sample_count(obs)}, one sample each as in the fit")
    floor_ids = [t for t in obs.observed_tag_ids if robot.config.floor is not None and t in robot.config.floor.tag_ids]
    floor = obs.only_tags(floor_ids) if floor_ids else None
    tags = [t for t in result.tags_used if t in obs.observed_tag_ids]
    if not tags:
        raise WolfcalError(
            f"none of the fit's tags ({', '.join(map(str, result.tags_used))}) was detected in "
            f"{', '.join(str(s) for s in sources)}"
        )
    return samples, obs.only_tags(tags), tags, warnings, floor


def _run_external_evaluate(
    robot: Robot,
    result: FitResult,
    fitted: Corrections,
    fit_dir: Path,
    loaded: list[Capture],
    captures: list[Path],
    out_dir: Path,
    deploy_worse: bool,
    say: Callable[[str], None],
    present: CurrentCalibration,
) -> dict:
    """Held-out external-camera captures (read: `loaded`): `external_metrics` before/after, metrics.json,
    report.md, deploy files (totals on `present`) unless the reprojection error of any camera got worse."""
    samples, warnings = samples_of(loaded, robot, cameras=())
    names = [c.name for c in robot.config.external_cameras]
    observations, detect_warnings = detect_observations(samples, robot, cameras=names)
    observations = still_span_observations(robot.config, observations, result.external_moving)
    tags = set(result.tags_used)
    observations = {n: o.only_tags(sorted(tags & set(o.observed_tag_ids))) for n, o in observations.items()
                    if tags & set(o.observed_tag_ids)}  # fmt: skip
    truth = truth_reference(captures)
    figures = external_metrics(robot, observations, fitted, truth, say, present.corrections)
    worse = any(c["after"]["rms_px"] > c["before"]["rms_px"] for c in figures["cameras"].values())
    make_folder(out_dir)
    refused = "The calibration makes the held-out reprojection error worse." if worse else None
    deploy = write_or_withhold_deploy_files(robot, fitted, out_dir, refused, deploy_worse, present)
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
        lines += ["", "Foot position error relative to the torso against the simulator's truth, max over 300 random "
                  "leg configurations [mm]: " + "; ".join(
                      f"{label}: " + ", ".join(f"{s} {v:.2f}" for s, v in e.items())
                      for label, e in figures["sole_error_mm"].items())]  # fmt: skip
    verdict = ("the calibration makes the held-out reprojection error worse: deploy files withheld" if worse else
               "the calibration improves the held-out external-camera views")  # fmt: skip
    lines += ["", f"**{verdict}**"]
    metrics = {
        **provenance(robot, fit_dir, result.free), "mode": "held-out",
        "captures": [str(Path(c).resolve()) for c in captures], "external": figures,
        "verdict": {"worse": worse, "message": verdict}, "deploy": deploy, "warnings": warnings + detect_warnings,
    }  # fmt: skip
    write_text_atomic(out_dir / "report.md", "\n".join(lines) + "\n")
    write_text_atomic(out_dir / "metrics.json", json.dumps(metrics, indent=2, allow_nan=False) + "\n")
    for line in lines[6:]:
        say(line)
    say(f"report: {out_dir / 'report.md'}")
    return metrics


def truth_reference(captures: list[Path]) -> Corrections | None:
    """The simulator's true corrections when every capture has the same `.truth.yaml` beside it."""
    truths = []
    for path in captures:
        truth_yaml = truth_paths(Path(path))[0]
        if not truth_yaml.is_file():
            return None
        truths.append(load_corrections(truth_yaml, key="truth"))
    first = truths[0].to_dict()
    return truths[0] if all(t.to_dict() == first for t in truths[1:]) else None


REPORT_FILES = ("report.html", "report.md", "metrics.json")


def _write_report(out_dir: Path, metrics: dict, figures: Figures) -> None:
    """figures/*.png, report.html, report.md and metrics.json in out_dir."""
    pngs, captions = figures
    blocks = report_blocks(metrics, captions)
    for name, data in pngs.items():
        write_bytes_atomic(out_dir / "figures" / name, data)
    write_text_atomic(out_dir / "report.html", render_html(blocks, pngs, f"wolfcal evaluation {metrics['robot_name']}"))
    write_text_atomic(out_dir / "report.md", render_markdown(blocks, "figures"))
    write_text_atomic(out_dir / "metrics.json", json.dumps(metrics, indent=2, allow_nan=False) + "\n")


PARAMETER_KEYS = ("name", "value", "std", "unit", "data_share", "display")  # of each fitted parameter in metrics


def _after(
    robot: Robot,
    obs: Observations,
    views: TagViews,
    result: FitResult,
    fitted: Corrections,
    present: CurrentCalibration,
    held_out: list[Path] | None,
    folds: int,
    say: Callable[[str], None],
) -> tuple[ModelErrors, list[Corrections], np.ndarray | None, str]:
    """Errors of the calibrated model: on held-out captures (`held_out`) the model to deploy (`fitted`), otherwise
    each sample under the model to deploy of the cross-validation fold that left it out.
    Also the model per sample, the fold of each sample (None when held out) and the sentence saying which."""
    if held_out is not None:
        note = held_out_note(held_out, result.captures, obs)
        return model_errors(robot, obs, views, fitted), [fitted] * obs.n_samples, None, note
    fold_of, models = cross_validate(robot, obs, result.options, folds, say, present)
    after = merge_folds(obs, views, fold_of, [model_errors(robot, obs, views, c) for c in models])
    return after, [models[k] for k in fold_of], fold_of, cross_validation_note(len(models), obs)


def _judge(
    robot: Robot,
    obs: Observations,
    views: TagViews,
    result: FitResult,
    fitted: Corrections,
    present: CurrentCalibration,
    sources: list[Path],
    held_out: bool,
    folds: int,
    say: Callable[[str], None],
) -> HeldOutErrors:
    """Errors before (the present calibration) and after (see `_after`), the outlier samples and the summaries;
    more than MAX_LEFT_OUT of the samples left out is refused (WolfcalError)."""
    before = model_errors(robot, obs, views, present.corrections)
    after, after_of_sample, fold_of, mode_note = _after(robot, obs, views, result, fitted, present,
                                                       sources if held_out else None, folds, say)  # fmt: skip
    outliers = outlier_samples(before, after)
    check_left_out(
        {"samples": (int(outliers.sum()), obs.n_samples)},
        ", ".join(map(str, sources)),
        "the evaluation refuses to judge on what is left: check these captures' joint readings and images, and "
        "that they are of this robot and camera",
    )
    return HeldOutErrors(before, after, after_of_sample, fold_of, mode_note, outliers,
                         summary(obs, views, before, outliers), summary(obs, views, after, outliers))  # fmt: skip


def present_calibration(robot: Robot, result: FitResult, current: list[Path]) -> CurrentCalibration:
    """The 'before' model: the evaluation's `--current` files, else the present calibration the fit started from
    (empty: the input URDF). Files other than the fit's own are refused when the fit started from one."""
    if not current:
        return result.current_calibration
    present = load_current(current, robot)
    started = result.current_calibration
    if result.current is not None and present.corrections.to_dict() != started.corrections.to_dict():
        raise WolfcalError(
            f"{', '.join(map(str, current))}: the fit started from another present calibration "
            f"({', '.join(started.sources)}); leave out --current, or fit again with it"
        )
    return present


@output_set()  # all outputs written as one set: nothing of a failed run replaces an earlier one
def run_evaluate(
    fit_dir: Path,
    captures: list[Path],
    out_dir: Path,
    deploy_worse: bool = False,
    folds: int = 5,
    say: Callable[[str], None] = print,
    force: bool = False,
    ground_limit_m: float | None = None,
    mount_limit_rad: float = MOUNT_LIMIT_RAD,
    current: list[Path] | tuple[Path, ...] = (),
) -> dict:
    """The whole `wolfcal evaluate` job; returns the metrics written to out_dir/metrics.json.

    With `captures` empty, k-fold cross-validation over the fit's own captures. Before = the present calibration
    (`present_calibration`: `current` files, else the fit's); after = the model to deploy (`deployable_model`). The
    deploy files (totals) are written only when the deploy verdict allows it (`verdict.deploy_verdict`: held-out
    reprojection RMS, whether the free parameters explain the held-out data, the measured ground error at the robot
    config's `floor.ground_check` distance and limit, the limit overridden by `ground_limit_m` [m]; held-out
    external-camera captures alone: each camera's reprojection RMS), or with `deploy_worse`; check
    `metrics['deploy']['written']`. `before_after_table(metrics)` gives the terminal table. Outputs of an earlier
    run in out_dir are replaced only with `force`; all are written as one set (`output_set`). More than
    MAX_LEFT_OUT of the samples left out as outliers is refused (WolfcalError).
    """
    fit_dir, out_dir = Path(fit_dir), Path(out_dir)
    result, robot = load_fit(fit_dir)
    present = present_calibration(robot, result, list(current))
    fitted, held_notes = deployable_model(result, present, robot)
    limits = verdict_limits(robot, ground_limit_m, mount_limit_rad)
    distances = ground_distances(limits)
    held_out = bool(captures)
    refuse_fitted_captures(captures, result.captures)
    sources = [Path(c) for c in captures] if held_out else [Path(c) for c in result.captures]
    fit_folder = fit_dir if fit_dir.is_dir() else fit_dir.parent
    inputs = [*sources, *(fit_folder / name for name in FIT_OUTPUTS), robot.config.path, robot.config.urdf,
              *current_files(list(current))]  # fmt: skip
    check_output_folder(out_dir, REPORT_FILES + DEPLOY_FILES, force, inputs)
    for system in evaluating_systems():  # recordings a system judges alone (held out, or its refusal)
        own = system.load("evaluator")(fit_dir, result, robot, sources, out_dir, deploy_worse, say, present, limits)
        if own is not None:
            return own
    intrinsics = Path(result.intrinsics) if result.intrinsics else None
    loaded = load_captures(robot, sources, intrinsics, say)  # read once, for whichever camera holds the views
    if held_out and not any(HEAD_CAMERA in c.cameras for c in loaded):
        return _run_external_evaluate(robot, result, fitted, fit_dir, loaded, captures, out_dir, deploy_worse, say,
                                      present)  # fmt: skip
    samples, obs, tags, warnings, floor = _observe(robot, result, loaded, sources, say)
    views = measure_tag_views(robot, obs)
    errors = _judge(robot, obs, views, result, fitted, present, sources, held_out, folds, say)
    truth = truth_reference(sources)
    models = {"before": present.corrections, "after": fitted}
    ground_table, no_ground = ground_rows(robot, obs.camera, truth, models, say, distances)
    if no_ground:
        warnings.append(no_ground)
    structure = unexplained(robot, obs, fitted, errors.after.residuals, ~errors.outliers)
    if structure["unexplained"]:
        say("testing which free parameters explain the residuals ...")
        structure.update(explaining_preset(robot, obs, views, result.options, present.corrections, ~errors.outliers))
    predicted = predicted_ground(robot, obs.camera, result, tags, fitted, limits.ground_distance_m)
    measured = measured_ground(robot, floor, models, held_out, say, result.estimate(CORNER_INSET) or (0.0, 0.0),
                                distances)  # fmt: skip
    verdict = deploy_verdict(result.free, errors.summary_before["rms_px"], errors.summary_after["rms_px"], structure,
                             verdict_ground(measured, distances, limits.ground_distance_m), predicted,
                             camera_turn(robot, fitted, present.corrections), limits, spans_of(obs))  # fmt: skip
    verdict["notes"] += held_notes
    say("drawing the pictures ...")
    sample_by_key = {(s.source, int(s.stamp_ns)): s for s in samples}
    figures = report_figures(robot, obs, sample_by_key, errors, result.covariance)
    make_folder(out_dir)
    deploy = write_or_withhold_deploy_files(robot, fitted, out_dir, None if verdict["deploy"] else verdict["message"],
                                            deploy_worse, present)  # fmt: skip
    metrics = {
        **provenance(robot, fit_dir, result.free),
        "mode": "held-out" if held_out else "cross-validation",
        "mode_note": errors.mode_note,
        "captures": [str(p.resolve()) for p in sources],
        "folds": errors.folds,
        "tags_used": tags,
        "n_samples": obs.n_samples,
        **span_counts(obs),
        "n_outliers": int(errors.outliers.sum()),
        "meanings": dict(MEANINGS) | ({"samples": SPAN_MEANING} if obs.span_frames is not None else {}),
        "before_model": before_label(present),
        "current": present.to_dict() if present.sources else None,
        "before": errors.summary_before,
        "after": errors.summary_after,
        "ground": ground_section(robot, truth is not None, ground_table, measured),
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
    for line in [verdict["message"], *verdict["refusals"][1:], *verdict["notes"], *deploy["warnings"]]:
        say(line)
    for line in deploy_lines(deploy, out_dir):
        say(line)
    say(f"report: {out_dir / 'report.html'}")
    return metrics


def before_label(present: CurrentCalibration) -> str:
    """What 'before' is: the present calibration's files, or the input URDF."""
    return (
        f"present calibration ({', '.join(Path(s).name for s in present.sources)})" if present.sources else "input URDF"
    )
