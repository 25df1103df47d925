"""`wolfcal venue --field` against the bus emulator (real dynamixel-sdk on a pty, in its own process) and the
simulated camera, which renders the robot's feet on its stand, then the field from the robot standing at the truth
file's `field_pose`.

Known truth: the demo's camera mount (turned by about 5.6 deg) and the robot's true place on the field, 0.2 m and
6 deg away from `field.robot_at` (and as far from `field.check_at` where the held-out field views are taken).
Checks: one command from start to the deploy files, the camera within 0.1 deg (the field fit's tolerance) and 2 mm
of the truth, the place within 5 cm, the ground error measured on the held-out field views within 2 cm + 2 sigma of
the true one, before and after; without `field.check_at` no held-out field views and the ground error from field
views "n/a"; a config without a field refused before the bus opens.
"""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import wolfgang_on_a_field

from wolfcal.errors import WolfcalError
from wolfcal.evaluate.accuracy import camera_pose_errors
from wolfcal.evaluate.deploy import DEPLOY_FILES
from wolfcal.fit.result import load_result
from wolfcal.hardware.emulator import EmulatorProcess, load_truth, spec_from_config
from wolfcal.robot.floor import standing_pose
from wolfcal.robot.robot import load_robot
from wolfcal.venue.options import VenueOptions
from wolfcal.venue.report import report_lines
from wolfcal.venue.session import field_phases, run_venue

ROOT = Path(__file__).resolve().parents[2]
DEMO_TRUTH = ROOT / "captures" / "floor_demo.truth.yaml"
PLACE = {"x": -3.2, "y": 0.1, "yaw": float(np.deg2rad(-6.0))}  # field.robot_at is (-3, 0, 0)
CHECK_AT = {"x": -1.5, "y": 1.0, "yaw": 0.5}
WAIT_S = 900.0  # generous: a whole session with its fits on a busy machine


@pytest.mark.slow
def test_one_field_session_from_start_to_deploy_files(tmp_path):
    config = wolfgang_on_a_field(tmp_path)
    data = yaml.safe_load(config.read_text())
    data["field"]["sweep"] = {"pan": [-0.4, 0.1, 0.6, 1.1], "tilt": [-0.5, -0.22]}
    data["field"]["check_at"] = CHECK_AT
    config.write_text(yaml.safe_dump(data))
    robot = load_robot(config)
    truth_data = yaml.safe_load(DEMO_TRUTH.read_text())
    truth_data.pop("floor_tags", None)
    truth_data["field_pose"] = PLACE
    truth_file = tmp_path / "truth.yaml"
    truth_file.write_text(yaml.safe_dump(truth_data))
    truth = load_truth(truth_file)
    out = tmp_path / "session"
    with EmulatorProcess(spec_from_config(robot.config, truth, truth_path=str(truth_file))) as emu:
        run = subprocess.run([sys.executable, "-m", "wolfcal.cli", "venue", "--robot", str(config), "--port", emu.port,
                              "--camera", "sim", "--yes", "--field", "--out", str(out)], cwd=ROOT, capture_output=True,
                             text=True, timeout=WAIT_S)  # fmt: skip
    assert run.returncode == 0, run.stderr
    for line in ("field views instead of the floor views", "Stand the robot on the field at field.robot_at",
                 "field view 1 of 8", "Stand the robot on the field at field.check_at", "held-out field view 1 of 8",
                 "held-out field views (8 at field.check_at", "robot time"):  # fmt: skip
        assert line in run.stderr, line
    assert "n/a" not in run.stderr
    metrics = json.loads((out / "metrics.json").read_text())
    assert metrics["field_views"] == metrics["samples"]["field"] == 8 and metrics["samples"]["floor"] == 0
    assert metrics["samples"]["field_check"] == metrics["held_out_field"]["views"] == 8
    assert metrics["held_out_floor"] is None and (out / "field_check-1.mcap").is_file()
    at = [r["distance_m"] for r in metrics["held_out_field"]["models"]["after"]["rows"]].index(4.5)
    for name in ("before", "after"):
        measured = metrics["held_out_field"]["models"][name]["rows"][at]
        true = metrics["truth"]["ground_error_m"][name]
        assert abs(measured["error_m"] - true) <= 0.02 + 2 * measured["std_m"], (name, measured, true)
    assert metrics["truth"]["ground_error_m"]["before"] > 0.5  # the nominal camera's error is seen, not read as 0
    assert metrics["verdict"]["ground_distance_m"] == 4.5 and "measured ground error at 4.5 m" in run.stderr
    rotation, translation = camera_pose_errors(robot, load_result(out / "fit").corrections, truth)
    assert np.rad2deg(rotation.max()) < 0.1 and translation.max() < 0.002, (rotation.max(), translation.max())
    params = {p["name"]: p["value"] for p in yaml.safe_load((out / "fit" / "result.yaml").read_text())["parameters"]}
    place_error = np.hypot(params["field_pose.x"] - PLACE["x"], params["field_pose.y"] - PLACE["y"])
    yaw_error = abs(np.rad2deg(params["field_pose.yaw"] - PLACE["yaw"]))
    assert place_error < 0.05 and yaw_error < 0.5, (place_error, yaw_error)
    assert metrics["truth"]["place_mm"] == pytest.approx(1000 * place_error)  # the report against the truth
    assert metrics["truth"]["place_yaw_deg"] == pytest.approx(yaw_error)
    assert all((out / name).is_file() for name in DEPLOY_FILES) and metrics["deploy"]["written"]


def test_a_field_session_without_a_field_is_refused_before_the_bus_opens(tmp_path):
    config = wolfgang_on_a_field(tmp_path)
    data = yaml.safe_load(config.read_text())
    data.pop("field")
    config.write_text(yaml.safe_dump(data))
    options = VenueOptions(robot=config, out=tmp_path / "session", camera="sim", port="/dev/null", yes=True,
                           field_views=True)  # fmt: skip
    with pytest.raises(WolfcalError, match=r"has no 'field:'; field views need the field's dimensions"):
        run_venue(options, say=lambda line: None)
    assert not (tmp_path / "session").exists()


def test_the_held_out_field_views_stand_at_check_at_when_the_config_gives_it(tmp_path):
    """With field.check_at: after the field views, the same sweep's views with the robot at check_at; without it:
    the field views alone, and a note that the ground error from field views is not measured."""
    config = wolfgang_on_a_field(tmp_path)
    robot = load_robot(config)
    options = VenueOptions(robot=config, out=tmp_path / "session", camera="sim", field_views=True)
    start = dict(zip(robot.joint_names, standing_pose(robot)))
    said: list[str] = []
    phases = field_phases(robot, options, start, said.append)
    assert [p.name for p in phases] == ["field"] and "field.robot_at" in phases[0].stand
    assert any("gives no 'field.check_at': no held-out field views" in line for line in said), said
    data = yaml.safe_load(config.read_text())
    data["field"]["check_at"] = CHECK_AT
    config.write_text(yaml.safe_dump(data))
    robot = load_robot(config)
    fitted, held_out = field_phases(robot, options, start, lambda line: None)
    assert held_out.name == "field_check" and "field.check_at (x -1.50 m, y +1.00 m, facing +29 deg" in held_out.stand
    assert sorted(p.name for p in held_out.script.poses) == sorted(p.name for p in fitted.script.poses)
    assert len(fitted.script.poses) >= 8


def test_without_held_out_field_views_the_ground_error_from_field_views_reads_na_with_the_reason():
    cv = {"folds": 4, "samples": 8, "outlier_samples": 0, "before": {"rms_px": 20.0}, "after": {"rms_px": 0.2},
          "fold_spread": {"rotation_deg": 0.01, "translation_mm": 0.05}}  # fmt: skip
    figures = {"robot": "robot.yaml", "robot_time_s": 30.0, "wall_time_s": 40.0, "runs": 1, "plan": "cached",
               "samples": {"feet": 8, "field": 8, "field_check": 0}, "cross_validation": cv, "held_out_floor": None,
               "held_out_field": None, "field_views": 8, "field_check_at": None, "fit": "session/fit",
               "verdict": {"message": "Deploy the files below.", "refusals": [], "notes": []},
               "deploy": {"written": False, "reason": "not written"}}  # fmt: skip
    na = "ground error from field views: n/a (it needs held-out field views, the robot placed elsewhere: "
    assert na + "the config gives no field.check_at)" in "\n".join(report_lines(figures))
    figures["field_check_at"] = [-1.5, 1.0, 0.5]
    assert na + "none taken)" in "\n".join(report_lines(figures))
