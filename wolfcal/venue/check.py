"""The end of a venue session: fit the camera, check it on views the fit did not use, verdict, deploy files.

- Fit: `--free camera` on the feet views and the floor views of the fit (`fit.pipeline.fit_observations`), or the
  feet views and the field views (the field block of `wolfcal fit --system field`, `fit.field_fit.field_blocks`,
  with the robot's place on the field as its unknowns), written as `wolfcal fit` writes it (`fit/`: result.yaml,
  calibrated.urdf, calibrated_robot.yaml).
- Cross-validation over the session's own views (`evaluate.crossval`): each sample's tags on the feet judged by the
  model fitted without its fold; the spread of the folds' camera poses around the full fit says how far one view
  more or less moves the answer.
- Held-out floor views (the check phase's stances, none of the fit's): the measured ground error before and after
  at the robot config's `floor.ground_check` distance (`evaluate.floor_ground`). Or held-out field views (the
  robot moved to `field.check_at`): the ground error measured from their lines, with its 1 sigma, by the held-out
  field check of `wolfcal evaluate` (`evaluate.field_check.held_out_field_ground`). Without held-out views it
  reads "n/a", never a number the data did not measure.
- The deploy verdict of `wolfcal evaluate` (`evaluate.verdict.deploy_verdict`) on these, and the deploy files of the
  model to deploy (`evaluate.undetermined.deployable_model`) through `write_deploy`, the one place that writes them.
"Before" is the robot's present calibration (`--current`, `io.current.load_current`), else the input URDF; the fit
starts from it and the deploy files hold the new totals.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from dataclasses import replace
from pathlib import Path

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.evaluate.accuracy import camera_pose_errors
from wolfcal.evaluate.crossval import fold_assignment
from wolfcal.evaluate.deploy import DEPLOY_FILES, camera_correction, write_or_withhold_deploy_files
from wolfcal.evaluate.field_check import held_out_field_ground
from wolfcal.evaluate.floor_ground import measured_ground_errors
from wolfcal.evaluate.ground_figures import (
    camera_turn,
    ground_distances,
    predicted_ground,
    verdict_ground,
    verdict_limits,
)
from wolfcal.evaluate.metrics import measure_tag_views, merge_folds, model_errors, outlier_samples, summary
from wolfcal.evaluate.structure import unexplained
from wolfcal.evaluate.undetermined import deployable_model
from wolfcal.evaluate.verdict import MOUNT_LIMIT_RAD, deploy_verdict
from wolfcal.fit.blocks import Block
from wolfcal.fit.field_fit import field_blocks
from wolfcal.fit.options import FitOptions
from wolfcal.fit.pipeline import check_solution_left_out, detect_captures, fit_observations, write_fit
from wolfcal.fit.result import fit_result
from wolfcal.io.current import CurrentCalibration, load_current
from wolfcal.observations import HEAD_CAMERA, Observations
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import Robot
from wolfcal.vision.corner_bias import CORNER_INSET

FOLDS = 5
FIT_FOLDER = "fit"
CHECK_FILES = ("metrics.json", "report.md", *DEPLOY_FILES)


def write_deploy(robot: Robot, fitted: Corrections, out_dir: Path, refused: str | None,
                 present: CurrentCalibration) -> dict:  # fmt: skip
    """The deploy files of a session (or their refusal): metrics.json's 'deploy' record, with the present
    calibration's files ('current'); the files hold the model to deploy `fitted` (totals)."""
    record = write_or_withhold_deploy_files(robot, fitted, out_dir, refused, False, present)
    record["current"] = ", ".join(present.sources) or None
    return record


def session_views(robot: Robot, feet_parts: list[Path], floor_parts: list[Path], options: FitOptions,
                  say: Callable[[str], None]) -> tuple[Observations, list[str]]:  # fmt: skip
    """The head camera's views of a session: the robot's tags in the feet views (floor tags seen while the robot
    hangs on its stand are not floor samples), every tag in the floor views; samples of the feet parts first."""
    link_tags = robot.config.tag_ids
    found: list[Observations] = []
    warnings: list[str] = []
    for captures, tags in ((feet_parts, link_tags), (floor_parts, None)):
        if not captures:
            continue
        observations, notes = detect_captures(robot, captures, None, options, say)
        warnings += notes
        head = observations.get(HEAD_CAMERA)
        if head is not None and tags is not None:
            head = head.only_tags([t for t in head.observed_tag_ids if t in tags])
        if head is not None and head.n_samples:
            found.append(head)
    if not found:
        raise WolfcalError(f"{', '.join(map(str, feet_parts + floor_parts))}: no head-camera image shows a tag; "
                           "nothing to fit")  # fmt: skip
    return (found[0] if len(found) == 1 else concatenated(found[0], found[1])), warnings


def concatenated(a: Observations, b: Observations) -> Observations:
    """The samples of `a`, then those of `b` (one camera, the same joints)."""
    return Observations(
        list(a.joint_names),
        np.vstack([a.q_measured, b.q_measured]),
        np.concatenate([a.stamps_ns, b.stamps_ns]),
        [*a.sources, *b.sources],
        a.camera,
        np.concatenate([a.sample_index, b.sample_index + a.n_samples]),
        np.concatenate([a.tag_ids, b.tag_ids]),
        np.concatenate([a.corner_index, b.corner_index]),
        np.vstack([a.uv, b.uv]),
        a.camera_name,
    )


def without_single_floor_views(robot: Robot, head: Observations, say: Callable[[str], None]) -> Observations:
    """The head camera's views less those of floor tags seen in one sample only (their place on the floor is an
    unknown of the fit, which one view cannot tell), with a note naming them."""
    floor_ids = set(robot.config.floor.tag_ids) if robot.config.floor is not None else set()
    labels, _ = head.views()
    once = [t for t in sorted(floor_ids) if 0 < int(np.sum(labels[:, 1] == t)) < 2]
    if not once:
        return head
    say(f"note: floor tag(s) {', '.join(map(str, once))} seen in one view only: left out of the fit")
    return head.only_tags([t for t in head.observed_tag_ids if t not in once])


def cross_validation(robot: Robot, head: Observations, link_tags: list[int], current: Corrections,
                     options: FitOptions, fitted: Corrections, say: Callable[[str], None],
                     own_blocks: Sequence[Block] = ()) -> dict:  # fmt: skip
    """Held-out pixel errors of the feet tags before (`current`) and after (each sample by the fold model that did
    not see it), the structure test and the folds' camera spread around the full fit [deg, mm]; `own_blocks` (the
    field views) are in every fold's fit, as in the full one."""
    folds = min(FOLDS, head.n_samples // 2)
    if folds < 2:
        raise WolfcalError(f"only {head.n_samples} view(s) with tags: too few to check the fit by cross-validation")
    fold_of = fold_assignment(head.n_samples, folds)
    models = []
    for k in range(folds):
        say(f"fold {k + 1}/{folds}: fitting without {int(np.sum(fold_of == k))} of the {head.n_samples} views")
        train = without_single_floor_views(robot, head.subset(np.flatnonzero(fold_of != k)), lambda line: None)
        models.append(fit_observations(robot, {HEAD_CAMERA: train}, options, own_blocks=own_blocks).corrections)
    seen = np.unique(head.sample_index[np.isin(head.tag_ids, link_tags)])
    feet = head.subset(seen, link_tags)
    fold_feet = fold_of[seen]
    views = measure_tag_views(robot, feet)
    before = model_errors(robot, feet, views, current)
    after = merge_folds(feet, views, fold_feet, [model_errors(robot, feet, views, c) for c in models])
    outliers = outlier_samples(before, after)
    spread = [camera_pose_errors(robot, m, fitted) for m in models]
    return {
        "folds": len(models), "samples": feet.n_samples, "outlier_samples": int(outliers.sum()),
        "before": summary(feet, views, before, outliers), "after": summary(feet, views, after, outliers),
        "structure": unexplained(robot, feet, fitted, after.residuals, ~outliers),
        "fold_spread": {"rotation_deg": float(np.rad2deg(max(r.max() for r, _ in spread))),
                        "translation_mm": float(1000 * max(t.max() for _, t in spread))},
    }  # fmt: skip


def check_session(robot: Robot, feet_parts: list[Path], floor_parts: list[Path], check_parts: list[Path],
                  field_parts: list[Path], field_check_parts: list[Path], out_dir: Path, current: Path | None,
                  say: Callable[[str], None]) -> dict:  # fmt: skip
    """Fit, cross-validation, held-out floor or field check, verdict and deploy files of a session in `out_dir`;
    returns the figures for metrics.json (the caller adds the session's times and writes it)."""
    present = load_current([current], robot) if current is not None else CurrentCalibration()
    options = FitOptions(free="camera", current=present.corrections if current is not None else None)
    limits = verdict_limits(robot, None, MOUNT_LIMIT_RAD)
    distances = ground_distances(limits)
    fit_parts = feet_parts + floor_parts + field_parts
    head, warnings = session_views(robot, feet_parts, floor_parts, options, say)
    head = without_single_floor_views(robot, head, say)
    observations = {HEAD_CAMERA: head}
    field: list[Block] = []
    if field_parts:
        say("finding the field's lines in the field views ...")
        field, _ = field_blocks(robot, field_parts, replace(options, system="field"), say)
    say(f"fitting the camera on {head.n_samples} views" + (f" and {len(field[0].q_measured)} field views"
                                                           if field else "") + " ...")  # fmt: skip
    fit = fit_observations(robot, observations, options, own_blocks=field)
    check_solution_left_out(fit, fit_parts)
    result = fit_result(fit, options, fit_parts, None, warnings, present if current is not None else None)
    write_fit(out_dir / FIT_FOLDER, fit, result)
    fitted, held_notes = deployable_model(result, present, robot)
    warnings += held_notes
    before = present.corrections
    say("checking it on views the fit did not use: cross-validation over the session's views ...")
    crossval = cross_validation(robot, head, fit.tag_ids, before, options, fitted, say, field)
    measured = None
    if check_parts:
        say("measuring the ground error on the held-out floor views ...")
        held, _ = detect_captures(robot, check_parts, None, options, say)
        floor_ids = robot.config.floor_config().tag_ids
        if HEAD_CAMERA in held and set(held[HEAD_CAMERA].observed_tag_ids) & set(floor_ids):
            floor = held[HEAD_CAMERA].only_tags(floor_ids)
            inset = result.estimate(CORNER_INSET) or (0.0, 0.0)
            measured = measured_ground_errors(robot, floor, {"before": before, "after": fitted}, distances,
                                              inset)  # fmt: skip
    judged = verdict_ground(measured, distances, limits.ground_distance_m)
    held_out_field = None
    if field_check_parts:
        say("measuring the ground error on the held-out field views ...")
        checked = held_out_field_ground(robot, field_check_parts, {"before": before, "after": fitted}, limits, say)
        held_out_field, judged = checked.measured, checked.judged
    predicted = predicted_ground(robot, head.camera, result, fit.tag_ids, fitted, limits.ground_distance_m)
    verdict = deploy_verdict("camera", crossval["before"]["rms_px"], crossval["after"]["rms_px"],
                             crossval["structure"], judged, predicted, camera_turn(robot, fitted, before),
                             limits)  # fmt: skip
    deploy = write_deploy(robot, fitted, out_dir, None if verdict["deploy"] else verdict["message"], present)
    return {"fit": str(out_dir / FIT_FOLDER), "samples_fitted": head.n_samples, "cross_validation": crossval,
            "held_out_floor": measured, "field_views": len(field[0].q_measured) if field else 0,
            "held_out_field": held_out_field, "field_check_at": _check_at(robot),
            "ground_distance_m": limits.ground_distance_m, "verdict": verdict, "deploy": deploy,
            "camera_correction": camera_correction(robot, fitted), "warnings": warnings}  # fmt: skip


def _check_at(robot: Robot) -> list[float] | None:
    """`field.check_at` [m, m, rad] of the robot config, None without it (or without a field)."""
    field = robot.config.playing_field
    return None if field is None or field.check_at is None else list(field.check_at)
