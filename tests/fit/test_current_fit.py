"""Fits that start from the robot's present calibration, and figures and causes that say what they are: a camera fit
with `--current`, 'after' without a truth, the free set a refusal names, a parameter the data cannot determine."""

import json
import shutil
from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation
from typer.testing import CliRunner

from wolfcal.cli import app
from wolfcal.evaluate.pipeline import run_evaluate
from wolfcal.evaluate.undetermined import deployable_model
from wolfcal.fit.pipeline import FitOptions, run_fit
from wolfcal.fit.result import load_result
from wolfcal.io.current import CurrentCalibration
from wolfcal.io.reader import read_capture
from wolfcal.robot.corrections import Corrections, load_corrections
from wolfcal.sim.simulate import SimOptions, simulate_capture

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "configs" / "wolfgang"
CAPTURES = ROOT / "captures"

# the robot's present calibration in the team's layout: a hand-tuned camera rotation and an IMU block
PRESENT = """/bitbots_extrinsic_camera_calibration:
  ros__parameters:
    offset_x: -0.06
    offset_y: 0.03
    offset_z: 0.0

/bitbots_extrinsic_imu_calibration:
  ros__parameters:
    offset_x: -0.03
    offset_y: 0.03
    offset_z: 0.0
"""


def quiet(_text: str) -> None:
    pass


def node_rotation(params: dict) -> Rotation:
    """The extrinsic node's rotation: rot_conv QuatFromEuler(offset_z, offset_y, offset_x) = Rz Ry Rx."""
    return Rotation.from_euler("ZYX", [params["offset_z"], params["offset_y"], params["offset_x"]])


@pytest.fixture(scope="module")
def camera_fits(tmp_path_factory, robot):
    """The demo's camera fit with and without the present calibration, each evaluated on the held-out capture."""
    root = tmp_path_factory.mktemp("current")
    (root / "rory.yaml").write_text(PRESENT)
    runner = CliRunner()
    for name, extra in (("plain", []), ("current", ["--current", str(root / "rory.yaml")])):
        fit = runner.invoke(app, ["fit", str(CAPTURES / "demo.mcap"), "--robot", str(CONFIG), "--free", "camera",
                                  "--out", str(root / f"fit_{name}"), *extra])  # fmt: skip
        assert fit.exit_code == 0, fit.output
        run_evaluate(root / f"fit_{name}", [CAPTURES / "demo_heldout.mcap"], root / f"eval_{name}", say=quiet)
    return root


def test_camera_fit_from_the_present_calibration(camera_fits, robot):
    root = camera_fits
    plain = json.loads((root / "eval_plain" / "metrics.json").read_text())
    current = json.loads((root / "eval_current" / "metrics.json").read_text())
    # before = the present calibration: the hand-tuned rotation explains part of the camera error
    assert current["before_model"] == "present calibration (rory.yaml)"
    assert current["before"]["rms_px"] < 0.7 * plain["before"]["rms_px"]
    assert current["after"]["rms_px"] == pytest.approx(plain["after"]["rms_px"], abs=0.01)
    result = load_result(root / "fit_current")
    assert result.current["sources"] == [str(root / "rory.yaml")]
    # the team file holds the new total: the truth's rotation, not the change from the present one
    truth = load_corrections(CAPTURES / "demo.truth.yaml", key="truth").frames[robot.camera_joint]
    team = yaml.safe_load((root / "eval_current" / "bitbots_extrinsic_calibration.yaml").read_text())
    camera = team["/bitbots_extrinsic_camera_calibration"]["ros__parameters"]
    error = (node_rotation(camera).inv() * Rotation.from_rotvec(truth[3:])).magnitude()
    assert np.rad2deg(error) < 0.1, f"deployed camera rotation {np.rad2deg(error):.3f} deg from the truth"
    assert team["/bitbots_extrinsic_imu_calibration"]["ros__parameters"] == {"offset_x": -0.03, "offset_y": 0.03,
                                                                             "offset_z": 0.0}  # fmt: skip


def test_bad_current_is_a_clear_error(tmp_path):
    (tmp_path / "info.yaml").write_text("image_width: 640\nimage_height: 480\n")
    result = CliRunner().invoke(app, ["fit", str(CAPTURES / "demo.mcap"), "--robot", str(CONFIG), "--out",
                                      str(tmp_path / "fit"), "--current", str(tmp_path / "info.yaml")])  # fmt: skip
    assert result.exit_code == 2 and "Traceback" not in result.output
    assert f"{tmp_path / 'info.yaml'}: key 'image_width' is not of a calibration file" in result.output
    assert not (tmp_path / "fit").exists()


def test_after_without_truth_is_not_a_measurement(camera_fits, tmp_path):
    held = tmp_path / "held.mcap"
    shutil.copy(CAPTURES / "demo_heldout.mcap", held)  # no .truth.yaml beside it: a real capture
    result = CliRunner().invoke(app, ["evaluate", str(camera_fits / "fit_plain"), "--capture", str(held), "--out",
                                      str(tmp_path / "eval")])  # fmt: skip
    assert result.exit_code == 0, result.output
    metrics = json.loads((tmp_path / "eval" / "metrics.json").read_text())
    assert all(row["models"]["after"]["error_m"] is None for row in metrics["ground"]["rows"])
    assert all(row["models"]["before"]["error_m"] > 0 for row in metrics["ground"]["rows"][:2])
    assert "ground error, ball at 4.5 m [cm]" in result.output and "n/a (no truth)" in result.output
    lines = [line for line in result.output.splitlines() if line.startswith("ground error")]
    assert lines and all(line.endswith("n/a (no truth)") for line in lines)


@pytest.mark.slow
def test_refusal_names_the_head_joints_when_they_explain_the_residuals(tmp_path):
    """Head servos off, legs calibrated: a camera fit is refused with the head joints named, not the legs."""
    simulate_capture(CONFIG, tmp_path / "head.mcap", SimOptions(samples=24, seed=3, binning=4, offsets="head"),
                     say=quiet)  # fmt: skip
    run_fit([tmp_path / "head.mcap"], CONFIG, tmp_path / "fit", FitOptions(free="camera"), say=quiet)
    metrics = run_evaluate(tmp_path / "fit", [], tmp_path / "eval", folds=3, say=quiet)
    assert not metrics["deploy"]["written"]
    assert metrics["structure"]["explained_by"] == "head_camera"
    assert "the head joints need calibration" in metrics["verdict"]["message"]
    assert "legs" not in metrics["verdict"]["message"]


def camera_rotation_error_deg(robot, q: np.ndarray, a, b) -> float:
    """Largest angle between the camera frames of corrections a and b at readings q (S, J) [deg]."""
    frame = robot.config.head_camera().frame
    Ta, Tb = (robot.model.link_poses(q, [frame], c, base=robot.config.base_link)[frame] for c in (a, b))
    return max(np.rad2deg(Rotation.from_matrix(x[:3, :3].T @ y[:3, :3]).magnitude()) for x, y in zip(Ta, Tb))


def test_undetermined_offset_is_held_and_the_model_kept(robot, tmp_path):
    """A leg fit's HeadTilt offset (30 % from data, trades against the camera's pitch) is deployed at its present
    value; the camera carries its share, so the camera poses of the fitted views stay where the fit put them."""
    capture = CAPTURES / "legs_demo.mcap"
    result = run_fit([capture], CONFIG, tmp_path / "fit", FitOptions(free="leg"), say=quiet)
    share = {p.name: p.data_share for p in result.parameters}
    assert share["HeadTilt.offset"] < 0.5 < min(share["RKnee.offset"], share["camera.ry"])
    deployed, notes = deployable_model(result, CurrentCalibration(), robot)
    assert deployed.offsets["HeadTilt"] == 0.0
    assert deployed.offsets["RKnee"] == pytest.approx(result.corrections.offsets["RKnee"], abs=1e-4)
    assert any(n.startswith("HeadTilt.offset: only 30%") and "camera.rx" in n for n in notes), notes
    samples = read_capture(capture, robot.config).samples
    q = np.array([[dict(zip(s.joint_names, s.positions)).get(j, 0.0) for j in robot.joint_names] for s in samples])
    naive = result.corrections.overridden_by(Corrections(offsets={"HeadTilt": 0.0}))
    assert camera_rotation_error_deg(robot, q, result.corrections, naive) > 0.1  # the offset alone moves it
    assert camera_rotation_error_deg(robot, q, result.corrections, deployed) < 0.005
    present = CurrentCalibration(Corrections(offsets={"HeadTilt": 0.01}), None, ["wolfgang.yaml"])
    held, _ = deployable_model(result, present, robot)
    assert held.offsets["HeadTilt"] == 0.01  # held at the present value, not at 0


def test_evaluate_refuses_a_present_calibration_other_than_the_fits(camera_fits, tmp_path):
    other = tmp_path / "other.yaml"
    other.write_text(PRESENT.replace("offset_x: -0.06", "offset_x: -0.07"))
    result = CliRunner().invoke(app, ["evaluate", str(camera_fits / "fit_current"), "--capture",
                                      str(CAPTURES / "demo_heldout.mcap"), "--out", str(tmp_path / "eval"),
                                      "--current", str(other)])  # fmt: skip
    assert result.exit_code == 2 and "the fit started from another present calibration" in result.output
    assert str(camera_fits / "rory.yaml") in result.output and not (tmp_path / "eval").exists()


def test_present_calibration_files_are_never_overwritten(camera_fits):
    folder = camera_fits / "eval_plain"
    before = (folder / "bitbots_extrinsic_calibration.yaml").read_bytes()
    result = CliRunner().invoke(app, ["evaluate", str(camera_fits / "fit_plain"), "--capture",
                                      str(CAPTURES / "demo_heldout.mcap"), "--out", str(folder), "--current",
                                      str(folder), "--force"])  # fmt: skip
    assert result.exit_code == 2 and "this is an input of the command" in result.output
    assert (folder / "bitbots_extrinsic_calibration.yaml").read_bytes() == before
