"""The team's calibration files (bit-bots/bitbots_main layouts), written and read back; `--current` inputs; the
verdict's ground check from the robot config.

Expected values come from the layouts of the real files and the extrinsic node's convention (rot_conv's
QuatFromEuler(offset_z, offset_y, offset_x) = Rz Ry Rx), computed with scipy, not with wolfcal's geometry."""

from pathlib import Path

import numpy as np
import pytest
import yaml
from scipy.spatial.transform import Rotation

from wolfcal.config import GroundCheck, load_robot_config
from wolfcal.errors import WolfcalError
from wolfcal.evaluate.deploy import DEPLOY_FILES, deploy_warnings, write_deploy_files
from wolfcal.evaluate.verdict import VerdictLimits, deploy_verdict
from wolfcal.io.current import CurrentCalibration, load_current
from wolfcal.robot.corrections import Corrections

WOLFGANG = Path(__file__).resolve().parents[2] / "configs" / "wolfgang"

# A per-robot file in the layout of bitbots_misc/bitbots_extrinsic_calibration/config/<robot>.yaml
TEAM_FILE = """/bitbots_extrinsic_camera_calibration:
  ros__parameters:
    offset_x: -0.065
    offset_y: 0.02
    offset_z: 0.01

/bitbots_extrinsic_imu_calibration:
  ros__parameters:
    offset_x: -0.03
    offset_y: 0.03
    offset_z: 0.0
"""

# The servo table in the layout of bitbots_lowlevel/bitbots_ros_control/config/wolfgang.yaml (shortened)
HARDWARE_FILE = """wolfgang_hardware_interface:
  ros__parameters:
    control_loop_hz: 500.0
    device_info:
      IMU_torso:
        id: 241
        topic: imu/data
        frame: imu_frame
        model_number: 0xBAFF
        interface_type: IMU
      RKnee:
        id: 13
        model_number: 1100
        mounting_offset: 0.0
        joint_offset: 0.012
        group: KNEES
      HeadTilt:
        id: 20
        model_number: 311
        mounting_offset: 0.1
        joint_offset: -0.004
"""


def node_rotation(params: dict) -> Rotation:
    """The rotation the extrinsic node publishes for its parameters: QuatFromEuler(z, y, x) = Rz(z) Ry(y) Rx(x)."""
    return Rotation.from_euler("ZYX", [params["offset_z"], params["offset_y"], params["offset_x"]])


def test_team_file_holds_the_camera_rotation_in_the_nodes_convention(robot, tmp_path):
    rotvec = np.array([-0.07, 0.05, -0.02])
    model = Corrections(frames={robot.camera_joint: np.array([0.0004, -0.0002, 0.0003, *rotvec])})
    write_deploy_files(robot, model, tmp_path)
    data = yaml.safe_load((tmp_path / "bitbots_extrinsic_calibration.yaml").read_text())
    assert set(data) == {"/bitbots_extrinsic_camera_calibration", "/bitbots_extrinsic_imu_calibration"}
    camera = data["/bitbots_extrinsic_camera_calibration"]["ros__parameters"]
    assert set(camera) == {"offset_x", "offset_y", "offset_z"}
    assert all(type(v) is float for v in camera.values()), "ROS 2 double parameters must be written as floats"
    turn = node_rotation(camera).inv() * Rotation.from_rotvec(rotvec)
    assert turn.magnitude() < 1e-9, f"published rotation off by {turn.magnitude():.2e} rad"
    assert data["/bitbots_extrinsic_imu_calibration"]["ros__parameters"] == {"offset_x": 0.0, "offset_y": 0.0,
                                                                             "offset_z": 0.0}  # fmt: skip
    assert set(DEPLOY_FILES) <= {p.name for p in tmp_path.iterdir()}
    assert "static_transform_publisher" not in (tmp_path / "camera_correction.yaml").read_text()


def test_translation_the_team_file_cannot_hold_is_warned(robot):
    small = Corrections(frames={robot.camera_joint: np.array([0.0005, 0.0005, 0.0, 0.01, 0.0, 0.0])})
    large = Corrections(frames={robot.camera_joint: np.array([0.0, 0.002, 0.0, 0.01, 0.0, 0.0])})
    present = CurrentCalibration(imu=(0.0, 0.0, 0.0), sources=["x.yaml"])
    assert deploy_warnings(robot, small, present) == []
    (warning,) = deploy_warnings(robot, large, present)
    assert "2.0 mm" in warning and "rotation only" in warning


def test_present_calibration_of_the_teams_files(robot, tmp_path):
    (tmp_path / "rory.yaml").write_text(TEAM_FILE)
    (tmp_path / "wolfgang.yaml").write_text(HARDWARE_FILE)
    present = load_current([tmp_path / "rory.yaml", tmp_path / "wolfgang.yaml"], robot)
    expected = node_rotation({"offset_x": -0.065, "offset_y": 0.02, "offset_z": 0.01})
    vec = present.corrections.frames[robot.camera_joint]
    assert np.allclose(vec[:3], 0.0) and (Rotation.from_rotvec(vec[3:]).inv() * expected).magnitude() < 1e-12
    assert present.corrections.offsets == pytest.approx({"RKnee": 0.012, "HeadTilt": 0.096})  # mounting + joint
    assert present.mounting == {"HeadTilt": 0.1}
    assert present.imu == (-0.03, 0.03, 0.0)


def test_deploy_files_hold_the_new_total_and_keep_the_imu_block(robot, tmp_path):
    """A folder written with a present calibration reads back as the model deployed; the IMU block is the
    present one, unchanged; the hardware snippet merges into the servo table's layout."""
    (tmp_path / "rory.yaml").write_text(TEAM_FILE)
    (tmp_path / "wolfgang.yaml").write_text(HARDWARE_FILE)
    present = load_current([tmp_path / "rory.yaml", tmp_path / "wolfgang.yaml"], robot)
    new = present.corrections.overridden_by(
        Corrections(offsets={"RKnee": 0.02}, frames={robot.camera_joint: np.array([0.0, 0.0, 0.0, -0.08, 0.01, 0.0])})
    )
    out = tmp_path / "deploy"
    out.mkdir()
    write_deploy_files(robot, new, out, present)
    again = load_current([out], robot)
    assert again.imu == present.imu
    assert again.corrections.offsets == pytest.approx({"RKnee": 0.02, "HeadTilt": 0.096}, abs=1e-10)
    assert np.allclose(again.corrections.frames[robot.camera_joint], [0, 0, 0, -0.08, 0.01, 0.0], atol=1e-9)
    snippet = yaml.safe_load((out / "wolfgang_hardware_interface_offsets.yaml").read_text())
    table = yaml.safe_load(HARDWARE_FILE)
    for joint, entry in snippet["wolfgang_hardware_interface"]["ros__parameters"]["device_info"].items():
        table["wolfgang_hardware_interface"]["ros__parameters"]["device_info"][joint].update(entry)
    devices = table["wolfgang_hardware_interface"]["ros__parameters"]["device_info"]
    assert devices["RKnee"]["joint_offset"] == pytest.approx(0.02) and devices["RKnee"]["id"] == 13
    assert devices["HeadTilt"]["joint_offset"] == pytest.approx(-0.004)  # the mounting offset stays apart
    assert devices["HeadTilt"]["mounting_offset"] == pytest.approx(0.1)


@pytest.mark.parametrize("text, words", [
    ("image_width: 640\nimage_height: 480\ncamera_matrix: {rows: 3}\n", "'image_width' is not of a calibration"),
    ("/bitbots_extrinsic_camera_calibration:\n  ros__parameters:\n    offset_q: 0.1\n",
     "'/bitbots_extrinsic_camera_calibration.ros__parameters.offset_q' is not a parameter"),
    ("/bitbots_extrinsic_camera_calibration:\n  ros__parameters:\n    offset_x: high\n", "must be a number [rad]"),
    ("op3_manager:\n  ros__parameters:\n    device_info:\n      r_knee:\n        joint_offset: 0.1\n",
     "'r_knee' is not a movable joint"),
    ("parent_frame: cam_uncalibrated\nchild_frame: cam\ntranslation: {x: 0, y: 0, z: 0}\n"
     "rpy: [0, 0, 0]\n", "'child_frame' is 'cam'"),
])  # fmt: skip
def test_current_of_another_robot_or_format_is_refused(robot, tmp_path, text, words):
    path = tmp_path / "present.yaml"
    path.write_text(text)
    with pytest.raises(WolfcalError) as err:
        load_current([path], robot)
    assert str(path) in str(err.value) and words in str(err.value)


def test_current_folder_without_calibration_files_is_refused(robot, tmp_path):
    with pytest.raises(WolfcalError, match="holds none of"):
        load_current([tmp_path], robot)


def test_ground_check_from_the_robot_config(tmp_path):
    data = yaml.safe_load((WOLFGANG / "robot.yaml").read_text())
    data["urdf"] = str(WOLFGANG / data["urdf"])
    data["camera"]["intrinsics"] = str(WOLFGANG / data["camera"]["intrinsics"])
    data["external_cameras"][0]["intrinsics"] = str(WOLFGANG / data["external_cameras"][0]["intrinsics"])
    assert load_robot_config(WOLFGANG / "robot.yaml").floor.ground_check == GroundCheck(4.5, 0.05)
    data["floor"]["ground_check"] = {"distance": 7.0, "limit": 0.1}  # AdultSize: half of a 14 m field
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(data))
    assert load_robot_config(tmp_path / "robot.yaml").floor.ground_check == GroundCheck(7.0, 0.1)
    data["floor"]["ground_check"] = {"distance": -1.0}
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(data))
    with pytest.raises(WolfcalError, match="'floor.ground_check.distance' must be positive"):
        load_robot_config(tmp_path / "robot.yaml")


def test_verdict_judges_at_the_configured_distance():
    structure = {"unexplained": False, "view_shift_rms_px": 0.1, "scale": 1.0, "corner_noise_px": 0.1}
    ground = {"before_m": 0.5, "after_m": 0.08, "after_std_m": 0.005}
    adult = VerdictLimits(ground_limit_m=0.1, ground_distance_m=7.0)
    assert deploy_verdict("leg", 2.0, 0.3, structure, ground, None, 0.0, adult)["deploy"]
    refused = deploy_verdict("leg", 2.0, 0.3, structure, ground, None, 0.0)
    assert not refused["deploy"] and "at 4.5 m stays above the limit" in " ".join(refused["refusals"])
    assert "at 7 m 8.0 +- 0.5 cm" in deploy_verdict("leg", 2.0, 0.3, structure, ground, None, 0.0, adult)["message"]
