"""The field system's held-out check: a field fit judged on field views the fit did not use (the robot placed
elsewhere on the field, `field.check_at`).

Before = the robot's present calibration (`--current`, else the fit's), after = the model to deploy. The ground
error at `floor.ground_check.distance` and the other distances is measured from the held-out views' lines
(`field_ground`), with its 1 sigma; the deploy verdict judges it as it judges the floor tags' (`verdict`), and
refuses when the views cannot see an error of the limit's size. `held_out_field_ground` is that measurement and
the verdict's input, shared by `wolfcal evaluate` and the venue session's held-out field step. With the
simulator's truth beside the captures the true ground errors are given too. `evaluate_held_out` is the registry's
evaluator (`wolfcal.fit.systems`): a fit of field views (`--system field`) given held-out captures is judged here;
metrics.json and report.md are written, and the deploy files when the verdict allows.
"""

from __future__ import annotations

import json
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

from wolfcal.atomic import make_folder, write_text_atomic
from wolfcal.camera.model import CameraModel
from wolfcal.errors import WolfcalError
from wolfcal.evaluate.deploy import camera_correction, deploy_lines, write_or_withhold_deploy_files
from wolfcal.evaluate.field_ground import measured_field_ground
from wolfcal.evaluate.ground_figures import camera_turn, ground_distances, ground_rows, ground_section, verdict_ground
from wolfcal.evaluate.pipeline import before_label, truth_reference
from wolfcal.evaluate.provenance import provenance
from wolfcal.evaluate.undetermined import deployable_model
from wolfcal.evaluate.verdict import GROUND_SIGMAS, VerdictLimits, deploy_verdict
from wolfcal.field.observe import field_observations
from wolfcal.fit.result import FitResult
from wolfcal.io.current import CurrentCalibration
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import Robot

MEANING = (
    "ground error [m]: where the model puts a ball seen d m away on the floor (head aimed at it, worst of -30, 0, "
    "+30 deg) against where the camera the held-out field views ask for puts it; 1 sigma from that camera's "
    "covariance. The robot's place on the field is fitted too, so an error that turns or shifts every view alike "
    "(a HeadPan offset, the body turned on its soles) is not measured"
)


@dataclass(frozen=True)
class FieldGroundCheck:
    """The held-out field views' measurement: `measured` (`field_ground.measured_field_ground`'s per model and
    distance, with 'resolution_m': the smallest ground error at the check distance the views can tell from none,
    GROUND_SIGMAS of the model after's 1 sigma [m], None above its horizon; and 'meaning'), `judged` (the deploy
    verdict's measured ground at the check distance, `verdict.deploy_verdict`) and the head camera's model of the
    views' images."""

    measured: dict
    judged: dict
    camera: CameraModel


def held_out_field_ground(robot: Robot, captures: list[Path], models: dict[str, Corrections], limits: VerdictLimits,
                          say: Callable[[str], None]) -> FieldGroundCheck:  # fmt: skip
    """The ground error of `models` ('before' and 'after' [, others]) measured on the held-out field `captures`
    (taken at `field.check_at`) at every distance of `limits`, and the verdict's input on it; WolfcalError naming
    the file when a capture holds too few line points."""
    distances = ground_distances(limits)
    obs = field_observations(robot, captures, say, check=True)
    measured = measured_field_ground(robot, obs, models, distances, say)
    at = distances.index(limits.ground_distance_m)
    after_std = measured["models"]["after"]["rows"][at]["std_m"]
    measured["resolution_m"] = None if after_std is None else GROUND_SIGMAS * after_std
    measured["meaning"] = MEANING
    judged = verdict_ground(measured, distances, limits.ground_distance_m)
    assert judged is not None  # measured is
    if judged["after_std_m"] is None:  # the ball lies above the horizon: nothing seen
        judged["after_std_m"] = float("inf")
    advice = (f"to measure it more precisely, take more held-out field views at field.check_at, the head swept over "
              f"lines from near the robot to beyond {limits.ground_distance_m:g} m")  # fmt: skip
    return FieldGroundCheck(measured, {**judged, "views": "the held-out field views", "advice": advice}, obs.camera)


def evaluate_held_out(fit_dir: Path, result: FitResult, robot: Robot, captures: list[Path], out_dir: Path,
                      deploy_worse: bool, say: Callable[[str], None], present: CurrentCalibration,
                      limits: VerdictLimits) -> dict | None:  # fmt: skip
    """The check when the fit is of field views (`result.system` 'field'); None otherwise. Returns metrics.json's
    content; a WolfcalError when the captures are the fit's own (the check needs held-out field views)."""
    if result.system != "field":
        return None
    if {str(Path(c).resolve()) for c in captures} <= {str(Path(c).resolve()) for c in result.captures}:
        raise WolfcalError(
            f"{', '.join(map(str, captures))}: a field fit is checked on field views it did not use, the robot "
            "placed elsewhere (field.check_at): give them with --capture (simulated: `wolfcal simulate --system "
            "field --check`)"
        )
    fitted, held_notes = deployable_model(result, present, robot)
    models = {"before": present.corrections, "after": fitted}
    distances = ground_distances(limits)
    check = held_out_field_ground(robot, captures, models, limits, say)
    truth = truth_reference(captures)
    rows, _ = ground_rows(robot, check.camera, truth, models, say, distances) if truth is not None else ([], None)
    verdict = deploy_verdict(result.free, None, None, None, check.judged, None,
                             camera_turn(robot, fitted, present.corrections), limits)  # fmt: skip
    verdict["notes"] += held_notes
    make_folder(out_dir)
    deploy = write_or_withhold_deploy_files(robot, fitted, out_dir, None if verdict["deploy"] else verdict["message"],
                                            deploy_worse, present)  # fmt: skip
    metrics = {
        **provenance(robot, fit_dir, result.free), "mode": "held-out", "system": "field",
        "captures": [str(Path(c).resolve()) for c in captures],
        "before_model": before_label(present), "current": present.to_dict() if present.sources else None,
        "ground": ground_section(robot, truth is not None, rows, check.measured),
        "verdict": verdict, "deploy": deploy, "camera_correction": camera_correction(robot, fitted),
    }  # fmt: skip
    lines = report_lines(metrics, distances)
    write_text_atomic(out_dir / "report.md", "\n".join(lines) + "\n")
    write_text_atomic(out_dir / "metrics.json", json.dumps(metrics, indent=2, allow_nan=False) + "\n")
    for line in lines[4:]:
        say(line)
    for line in deploy_lines(deploy, out_dir):
        say(line)
    say(f"report: {out_dir / 'report.md'}")
    return metrics


def _cm(error: float | None, std: float | None = None) -> str:
    if error is None:
        return "above the horizon"
    return f"{error * 100:.1f}" + ("" if std is None else f" +- {std * 100:.1f}")


def report_lines(metrics: dict, distances: tuple[float, ...]) -> list[str]:
    """report.md: the measured ground errors before and after (and the true ones with a simulator's truth), the
    robot's place the views put it at, the verdict."""
    measured, true_rows = metrics["ground"]["measured"], metrics["ground"]["rows"]
    before, after = (measured["models"][m] for m in ("before", "after"))
    places = "; ".join(f"{name} x {p['x']['value']:+.3f} m, y {p['y']['value']:+.3f} m, "
                       f"yaw {p['yaw']['value']:+.4f} rad" for name, p in measured["field_pose"].items())  # fmt: skip
    truth = " true before [cm] | true after [cm] |" if true_rows else ""
    head = "| distance [m] | before [cm] | after [cm] |" + truth
    lines = [f"# wolfcal evaluation {metrics['robot_name']}: held-out field views", "",
             f"fit: {metrics['fit_dir']}; captures: {', '.join(metrics['captures'])}", "",
             f"Ground error measured on {measured['views']} held-out field views ({measured['line_points']} line "
             f"points), 1 sigma; before = {metrics['before_model']}.", "", head,
             "|---|---|---|" + ("---|---|" if true_rows else "")]  # fmt: skip
    for k, d in enumerate(distances):
        b, a = before["rows"][k], after["rows"][k]
        row = f"| {d:g} | {_cm(b['error_m'], b['std_m'])} | {_cm(a['error_m'], a['std_m'])} |"
        if true_rows:
            row += "".join(f" {_cm(true_rows[k]['models'][m]['error_m'])} |" for m in ("before", "after"))
        lines.append(row)
    resolution = measured["resolution_m"]
    lines += ["", f"The views place the robot at {places} (with the camera they ask for). "
              + ("" if resolution is None else
                 f"They cannot see a ground error below {resolution * 100:.1f} cm (2 sigma) at "
                 f"{metrics['verdict']['ground_distance_m']:g} m. ")
              + "Not measured: a turn or shift of every view alike (a HeadPan offset, the body turned on its soles), "
              "which the robot's place takes.", ""]  # fmt: skip
    verdict = metrics["verdict"]
    lines += [f"**{verdict['message']}**", *verdict["refusals"], *verdict["notes"]]
    return lines
