"""What a venue session prints and writes at the end (report.md): times, the check's figures, the verdict, the
deploy files; and, with the simulated camera, the camera's error against the simulator's truth (with held-out
field views, also the true ground error of the model to deploy, beside the measured one)."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from wolfcal.camera.camera_info import load_camera_info
from wolfcal.evaluate.accuracy import camera_pose_errors
from wolfcal.evaluate.ground import ground_errors
from wolfcal.evaluate.undetermined import deployable_model
from wolfcal.fit.result import load_result
from wolfcal.hardware.buses import port_paths
from wolfcal.hardware.emulator import load_truth, truth_file_of
from wolfcal.io.current import CurrentCalibration, load_current
from wolfcal.io.truth import load_field_pose
from wolfcal.observations import HEAD_CAMERA
from wolfcal.robot.robot import Robot
from wolfcal.venue.check import FIT_FOLDER
from wolfcal.venue.options import VenueOptions


def truth_errors(robot: Robot, options: VenueOptions, figures: dict) -> dict | None:
    """Largest camera pose error of the fit against the emulator's truth over the head joints' range [deg, mm]
    (`evaluate.accuracy.camera_pose_errors`), when the camera is the simulated one and the emulator has a truth;
    with field views, also the error of the robot's place on the field [mm, deg] (the truth's `field_pose`); with
    held-out field views (`figures['held_out_field']`), also the true ground errors [m] before (the present
    calibration) and after (the model to deploy) at `figures['ground_distance_m']` (`evaluate.ground.ground_errors`,
    the truth as the reference; None above the horizon)."""
    if options.camera != "sim" or robot.config.servos is None:
        return None
    servos = robot.config.servos
    paths = port_paths(options.port, list(servos.buses)) or {device: device for device in servos.buses}
    truth_path = truth_file_of(paths.values())
    if not truth_path:
        return None
    result = load_result(options.out / FIT_FOLDER)
    rotation, translation = camera_pose_errors(robot, result.corrections, load_truth(Path(truth_path)))
    errors: dict = {
        "rotation_deg": float(np.rad2deg(rotation.max())),
        "translation_mm": float(translation.max() * 1000),
    }
    place = load_field_pose(Path(truth_path))
    fitted = [result.estimate(f"field_pose.{c}") for c in ("x", "y", "yaw")]
    if place is not None and all(v is not None for v in fitted):
        x, y, yaw = (v[0] for v in fitted if v is not None)
        errors["place_mm"] = float(1000 * np.hypot(x - place[0], y - place[1]))
        errors["place_yaw_deg"] = float(np.rad2deg(abs(np.remainder(yaw - place[2] + np.pi, 2 * np.pi) - np.pi)))
    if figures.get("held_out_field") is not None:
        present = load_current([options.current], robot) if options.current is not None else CurrentCalibration()
        deployed, _ = deployable_model(result, present, robot)
        camera = load_camera_info(options.intrinsics or robot.config.intrinsics_file(HEAD_CAMERA, "the ground error"))
        models = {"before": present.corrections, "after": deployed}
        row = ground_errors(robot, camera, load_truth(Path(truth_path)), models, (figures["ground_distance_m"],))[0]
        errors["ground_error_m"] = {name: row["models"][name]["error_m"] for name in models}
    return errors


def _px(value: float | None) -> str:
    return "n/a" if value is None else f"{value:.3f} px"


def report_lines(figures: dict) -> list[str]:
    """The session's end in a few lines (also report.md)."""
    cv, verdict, deploy = figures["cross_validation"], figures["verdict"], figures["deploy"]
    samples = ", ".join(f"{k} {v}" for k, v in figures["samples"].items())
    lines = [
        f"# wolfcal venue: {figures['robot']}",
        "",
        f"robot time {figures['robot_time_s']:.1f} s, wall time {figures['wall_time_s']:.1f} s "
        f"({figures['runs']} run(s)); samples: {samples}; poses: {figures['plan']}",
        f"cross-validation over the session's views ({cv['folds']} folds, {cv['samples']} feet views, "
        f"{cv['outlier_samples']} left out): reprojection RMS per axis {_px(cv['before']['rms_px'])} (input URDF) "
        f"-> {_px(cv['after']['rms_px'])} (calibrated); the folds' camera poses lie within "
        f"{cv['fold_spread']['rotation_deg']:.3f} deg and {cv['fold_spread']['translation_mm']:.2f} mm of the fit",
    ]
    floor, field = figures["held_out_floor"], figures.get("held_out_field")
    if field is not None:
        lines.append(_field_check_line(figures, field))
    elif floor is not None:
        distance = figures["ground_distance_m"]
        k = [r["distance_m"] for r in floor["models"]["after"]["rows"]].index(distance)
        before, after = (floor["models"][m]["rows"][k] for m in ("before", "after"))
        lines.append(f"held-out floor views ({floor['capture']['samples']} in {floor['capture']['stances']} stances): "
                     f"ground error at {distance:g} m {_cm(before)} -> {_cm(after)} (1 sigma)")  # fmt: skip
    elif figures.get("field_views"):
        why = "none taken" if figures.get("field_check_at") else "the config gives no field.check_at"
        lines.append(f"field views: {figures['field_views']} fitted with the feet views; ground error from field "
                     f"views: n/a (it needs held-out field views, the robot placed elsewhere: {why})")  # fmt: skip
    else:
        lines.append("held-out floor views: none measured (no floor tags, or too few held-out views of them)")
    truth = figures.get("truth")
    if truth is not None:
        place = (f"; the robot's place on the field within {truth['place_mm']:.1f} mm and "
                 f"{truth['place_yaw_deg']:.3f} deg" if "place_mm" in truth else "")  # fmt: skip
        true = [_cm({"error_m": e, "std_m": None}) for e in truth.get("ground_error_m", {}).values()]
        ground = f"; ground error at {figures['ground_distance_m']:g} m {' -> '.join(true)}" if true else ""
        lines.append(f"against the simulator's truth: camera within {truth['rotation_deg']:.4f} deg and "
                     f"{truth['translation_mm']:.3f} mm (largest over the head joints' range){place}"
                     f"{ground}")  # fmt: skip
    lines += ["", verdict["message"], *[f"- {r}" for r in verdict["refusals"]], *[f"- {n}" for n in verdict["notes"]]]
    if deploy["written"]:
        lines.append(f"deploy files: {', '.join(deploy['files'])} in {Path(figures['fit']).parent}")
    else:
        lines.append(deploy["reason"])
    if deploy.get("current"):
        lines.append(
            f"--current {deploy['current']}: recorded; the deploy files hold the calibration on the input URDF"
        )
    return lines


def _field_check_line(figures: dict, field: dict) -> str:
    """The held-out field views' measured ground error at the check distance, before -> after, and the smallest
    error they can see."""
    distance = figures["ground_distance_m"]
    k = [r["distance_m"] for r in field["models"]["after"]["rows"]].index(distance)
    before, after = (field["models"][m]["rows"][k] for m in ("before", "after"))
    resolution = field["resolution_m"]
    seen = "" if resolution is None else f"; they cannot see an error below {resolution * 100:.1f} cm (2 sigma)"
    return (f"held-out field views ({field['views']} at field.check_at, {field['line_points']} line points): "
            f"ground error at {distance:g} m {_cm(before)} -> {_cm(after)} (1 sigma){seen}")  # fmt: skip


def _cm(row: dict) -> str:
    """A ground error row as 'X +- Y cm' (1 sigma; 'X cm' without one), or why there is none."""
    if row["error_m"] is None:
        return "above the horizon"
    return f"{row['error_m'] * 100:.1f}" + ("" if row["std_m"] is None else f" +- {row['std_m'] * 100:.1f}") + " cm"
