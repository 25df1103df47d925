"""`wolfcal simulate` + `wolfcal fit` end to end with images, and bad input that must give a clear message."""

from pathlib import Path

import numpy as np
import pytest
import yaml
from typer.testing import CliRunner

from wolfcal.camera.camera_info import load_camera_info
from wolfcal.cli import app
from wolfcal.evaluate.accuracy import camera_pose_errors
from wolfcal.io.reader import read_capture
from wolfcal.io.writer import CaptureWriter
from wolfcal.observations import HEAD_CAMERA
from wolfcal.robot.corrections import Corrections, load_corrections
from wolfcal.robot.robot import load_robot

ROOT = Path(__file__).resolve().parents[2]
ROBOT = ROOT / "configs" / "wolfgang"


def run(*args):
    result = CliRunner().invoke(app, [str(a) for a in args])
    assert "Traceback" not in result.output
    return result


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    """16 samples, 512x384 images binned 4x from the 2048x1536 camera, image noise, encoder quantisation."""
    path = tmp_path_factory.mktemp("sim") / "sim.mcap"
    result = run("simulate", "--out", path, "--samples", 16, "--seed", 4, "--binning", 4)
    assert result.exit_code == 0, result.output
    return path


def test_fit_recovers_simulated_camera_pose(capture, tmp_path):
    result = run("fit", capture, "--robot", ROBOT, "--free", "camera", "--out", tmp_path)
    assert result.exit_code == 0, result.output
    assert "reprojection RMS" in result.output
    data = yaml.safe_load((tmp_path / "result.yaml").read_text())
    truth = load_corrections(capture.with_suffix(".truth.yaml"), key="truth")
    robot = load_robot(ROBOT)
    rot, trans = camera_pose_errors(robot, Corrections.from_dict(data["corrections"]), truth)
    assert np.rad2deg(rot.max()) < 0.1 and trans.max() < 0.002
    assert data["rms_after_px"] < 0.1 * data["rms_before_px"]
    # The calibrated URDF carries the camera correction folded into the camera joint's origin.
    urdf = (tmp_path / "calibrated.urdf").read_text()
    assert 'joint name="camera_optical_frame_uncalibrated_frame"' in urdf and "<link" in urdf
    calibrated = load_robot(ROBOT).model.__class__.from_urdf(tmp_path / "calibrated.urdf")
    q = np.zeros((1, len(robot.joint_names)))
    expected = robot.model.link_poses(q, ["camera_optical_frame"], Corrections.from_dict(data["corrections"]))
    np.testing.assert_allclose(
        calibrated.link_poses(q, ["camera_optical_frame"])["camera_optical_frame"],
        expected["camera_optical_frame"],
        atol=1e-8,
    )


def test_torn_capture_says_how_to_recover(capture, tmp_path):
    torn = tmp_path / "torn.mcap"
    data = capture.read_bytes()
    torn.write_bytes(data[: len(data) // 2])
    result = run("fit", torn, "--out", tmp_path / "fit")
    assert result.exit_code != 0
    assert "torn.mcap" in result.output and "wolfcal recover" in result.output


def test_missing_topics_name_the_topics(capture, tmp_path):
    config = yaml.safe_load((ROBOT / "robot.yaml").read_text())
    config["urdf"] = str(ROBOT / "wolfgang.urdf")
    config["camera"]["intrinsics"] = str(ROBOT / "basler_acA2040.yaml")
    config["external_cameras"][0]["intrinsics"] = str(ROBOT / "tripod_webcam.yaml")
    config["joint_states_topic"] = "/other/joint_states"
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(config))
    result = run("fit", capture, "--robot", tmp_path / "robot.yaml", "--out", tmp_path / "fit")
    assert result.exit_code != 0
    assert "/other/joint_states" in result.output


def write_capture(path, joint_names, image):
    robot = load_robot(ROBOT)
    camera = load_camera_info(ROBOT / "basler_acA2040.yaml")
    with CaptureWriter(path, robot.config, {HEAD_CAMERA: (camera, (4, 4))}) as writer:
        for i in range(4):
            writer.add_sample(10**9 * (i + 1), joint_names, np.zeros(len(joint_names)), None, {HEAD_CAMERA: image})


def test_joints_missing_from_joint_states(tmp_path):
    names = load_robot(ROBOT).joint_names[:-2]
    write_capture(tmp_path / "c.mcap", names, np.full((384, 512), 128, np.uint8))
    result = run("fit", tmp_path / "c.mcap", "--out", tmp_path / "fit")
    assert result.exit_code != 0
    assert "LShoulderRoll" in result.output or "LElbow" in result.output


def test_no_tags_detected(tmp_path):
    write_capture(tmp_path / "c.mcap", load_robot(ROBOT).joint_names, np.full((384, 512), 128, np.uint8))
    result = run("fit", tmp_path / "c.mcap", "--out", tmp_path / "fit")
    assert result.exit_code != 0
    assert "no configured tag" in result.output and "c.mcap" in result.output


def test_too_few_samples(capture, tmp_path):
    small = tmp_path / "small.mcap"
    robot = load_robot(ROBOT)
    samples = read_capture(capture, robot.config).samples[:3]
    head = {HEAD_CAMERA: (load_camera_info(ROBOT / "basler_acA2040.yaml"), (4, 4))}
    with CaptureWriter(small, robot.config, head) as writer:
        for s in samples:
            image = s.images[HEAD_CAMERA].decode()
            writer.add_sample(s.stamp_ns, s.joint_names, s.positions, None, {HEAD_CAMERA: image})
    result = run("fit", small, "--free", "leg", "--out", tmp_path / "fit")
    assert result.exit_code != 0
    assert "too few samples" in result.output


def test_unknown_preset_and_missing_file(tmp_path):
    result = run("fit", tmp_path / "nope.mcap", "--out", tmp_path / "fit")
    assert result.exit_code != 0 and "nope.mcap" in result.output
    result = run("fit", tmp_path / "nope.mcap", "--free", "arms", "--out", tmp_path / "fit")
    assert result.exit_code != 0 and "'arms' is not a preset" in result.output


def test_capture_of_another_robot_is_refused(capture, tmp_path):
    config = yaml.safe_load((ROBOT / "robot.yaml").read_text())
    config.update(name="other_robot", urdf=str(ROBOT / "wolfgang.urdf"))
    config["camera"]["intrinsics"] = str(ROBOT / "basler_acA2040.yaml")
    config["external_cameras"][0]["intrinsics"] = str(ROBOT / "tripod_webcam.yaml")
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(config))
    result = run("fit", capture, "--robot", tmp_path / "robot.yaml", "--out", tmp_path / "fit")
    assert result.exit_code != 0
    assert "captured with robot 'wolfgang'" in result.output and "other_robot" in result.output
