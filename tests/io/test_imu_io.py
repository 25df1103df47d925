"""Standing recordings: sensor_msgs/msg/Imu read from files written by an independent writer (mcap_ros2 with the
message definition as rosbag2 stores it), still periods found from the data, bad input named, and the whole
`wolfcal simulate --system imu` -> `wolfcal fit --free imu` round trip."""

from __future__ import annotations

import json
from pathlib import Path

import numpy as np
import pytest
import yaml
from imu_robot import robot_with_imu
from mcap_ros2.writer import Writer
from typer.testing import CliRunner

from wolfcal.cli import app
from wolfcal.errors import WolfcalError
from wolfcal.io.imu import read_standing
from wolfcal.robot.robot import Robot

# sensor_msgs/msg/Imu as rosbag2 (Humble) stores it: the .msg file's text, comments included, then its dependencies
IMU_DEFINITION = """# This is a message to hold data from an IMU (Inertial Measurement Unit)
#
# Accelerations should be in m/s^2 (not in g's), and rotational velocity should be in rad/sec
#
# If the covariance of the measurement is known, it should be filled in (if all you know is the
# variance of each measurement, e.g. from the datasheet, just put those along the diagonal)
# A covariance matrix of all zeros will be interpreted as "covariance unknown", and to use the
# data a covariance will have to be assumed or gotten from some other source
#
# If you have no estimate for one of the data elements (e.g. your IMU doesn't produce an
# orientation estimate), please set element 0 of the associated covariance matrix to -1

std_msgs/Header header

geometry_msgs/Quaternion orientation
float64[9] orientation_covariance # Row major about x, y, z axes

geometry_msgs/Vector3 angular_velocity
float64[9] angular_velocity_covariance # Row major about x, y, z axes

geometry_msgs/Vector3 linear_acceleration
float64[9] linear_acceleration_covariance # Row major x, y z
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
================================================================================
MSG: geometry_msgs/Quaternion
float64 x 0
float64 y 0
float64 z 0
float64 w 1
================================================================================
MSG: geometry_msgs/Vector3
float64 x
float64 y
float64 z
"""
JOINT_STATE_DEFINITION = """std_msgs/Header header
string[] name
float64[] position
float64[] velocity
float64[] effort
================================================================================
MSG: std_msgs/Header
builtin_interfaces/Time stamp
string frame_id
================================================================================
MSG: builtin_interfaces/Time
int32 sec
uint32 nanosec
"""
TICK = 2 * np.pi / 4096
T0 = 1_650_000_000_000_000_000


@pytest.fixture(scope="module")
def robot(tmp_path_factory) -> Robot:
    return robot_with_imu(tmp_path_factory.mktemp("imu_io"))


def write(path: Path, robot: Robot, segments: list[tuple[float, bool, np.ndarray]], scale: float = 1.0,
          gyro: bool = True, imu_topic: str = "/imu/data") -> None:  # fmt: skip
    """A recording: per segment (duration [s], still?, gravity direction in the IMU frame), joint states at 50 Hz
    (every joint 0.3 rad, one more tick per segment), the IMU at 100 Hz (moving: the direction swings and the gyro
    turns). `scale` multiplies the accelerometer (1 / 9.80665: a driver publishing g)."""
    rng = np.random.default_rng(1)
    with path.open("wb") as handle:
        writer = Writer(handle)
        joints = writer.register_msgdef("sensor_msgs/msg/JointState", JOINT_STATE_DEFINITION)
        imu = writer.register_msgdef("sensor_msgs/msg/Imu", IMU_DEFINITION)
        t = 0.0
        for k, (duration, still, direction) in enumerate(segments):
            for s in np.arange(0.0, duration, 0.01):
                stamp = T0 + int((t + s) * 1e9)
                header = {"stamp": {"sec": stamp // 10**9, "nanosec": stamp % 10**9}, "frame_id": "imu_frame"}
                swing = 0.0 if still else 0.3 * np.sin(2 * np.pi * s)
                a = 9.80665 * (np.asarray(direction) + [swing, 0.0, 0.0]) + rng.normal(0.0, 0.02, 3)
                w = rng.normal(0.0, 0.003, 3) + (0.0 if still else [0.0, 0.6 * np.cos(2 * np.pi * s), 0.0])
                writer.write_message(imu_topic, imu, {
                    "header": header, "orientation": {"x": 0.0, "y": 0.0, "z": 0.0, "w": 1.0},
                    "orientation_covariance": [-1.0] + [0.0] * 8,
                    "angular_velocity": dict(zip("xyz", map(float, w))),
                    "angular_velocity_covariance": [0.0] * 9 if gyro else [-1.0] + [0.0] * 8,
                    "linear_acceleration": dict(zip("xyz", map(float, scale * a))),
                    "linear_acceleration_covariance": [0.0] * 9}, log_time=stamp)  # fmt: skip
                if round(s * 100) % 2 == 0:
                    q = 0.3 + (k + (0.0 if still else s / duration)) * TICK * (1 if still else 20)
                    writer.write_message("/joint_states", joints, {
                        "header": header, "name": robot.joint_names, "position": [float(q)] * len(robot.joint_names),
                        "velocity": [], "effort": []}, log_time=stamp)  # fmt: skip
            t += duration
        writer.finish()


UP = np.array([0.0, 0.0, 1.0])
TILTED = np.array([0.1, 0.0, 1.0]) / np.linalg.norm([0.1, 0.0, 1.0])


@pytest.mark.parametrize("gyro", [True, False])
def test_still_periods_are_found_from_the_data(robot, tmp_path, gyro):
    path = tmp_path / "standing.mcap"
    write(
        path,
        robot,
        [(3.0, True, UP), (1.0, False, UP), (3.0, True, TILTED), (1.0, False, UP), (2.5, True, UP)],
        gyro=gyro,
    )
    samples = read_standing([path], "/joint_states", "/imu/data", robot.joint_names)
    assert samples.n_samples == 3
    directions = samples.accel / np.linalg.norm(samples.accel, axis=1, keepdims=True)
    assert np.allclose(directions, [UP, TILTED, UP], atol=0.002)
    assert np.all(samples.n_messages >= 150) and np.all(samples.scatter < 0.05)


def test_no_imu_messages_on_the_topic_names_file_and_topic(robot, tmp_path):
    path = tmp_path / "other_topic.mcap"
    write(path, robot, [(3.0, True, UP)], imu_topic="/imu/raw")
    with pytest.raises(WolfcalError, match=f"{path}: no sensor_msgs/msg/Imu messages on /imu/data .*'imu.topic'"):
        read_standing([path], "/joint_states", "/imu/data", robot.joint_names)


def test_accelerometer_in_g_is_refused(robot, tmp_path):
    path = tmp_path / "in_g.mcap"
    write(path, robot, [(3.0, True, UP)], scale=1 / 9.80665)
    with pytest.raises(WolfcalError, match=r"in_g.mcap: /imu/data: the accelerometer reads \|a\| = 1.000 .* in g"):
        read_standing([path], "/joint_states", "/imu/data", robot.joint_names)


def test_a_robot_that_never_stands_still_is_refused(robot, tmp_path):
    path = tmp_path / "walking.mcap"
    write(path, robot, [(4.0, False, UP), (4.0, False, TILTED)])
    with pytest.raises(WolfcalError, match="walking.mcap: the robot never stood still"):
        read_standing([path], "/joint_states", "/imu/data", robot.joint_names)


def run(*args: str):
    return CliRunner().invoke(app, list(args))


@pytest.mark.slow
def test_simulate_then_fit_the_mount_from_a_standing_recording(robot, tmp_path):
    config = str(robot.config.path)
    recording = tmp_path / "standing.mcap"
    done = run("simulate", "--robot", config, "--system", "imu", "--samples", "12", "--seed", "4",
               "--out", str(recording))  # fmt: skip
    assert done.exit_code == 0, done.output
    done = run("fit", str(recording), "--robot", config, "--free", "imu", "--system", "imu", "--out",
               str(tmp_path / "fit"))  # fmt: skip
    assert done.exit_code == 0, done.output
    assert "imu.rz (yaw of the mount) is not determined" in done.output
    result = yaml.safe_load((tmp_path / "fit" / "result.yaml").read_text())
    truth = yaml.safe_load((tmp_path / "standing.truth.yaml").read_text())["truth"]["frames"]["imu_board_joint"]
    fitted = {p["name"]: p for p in result["parameters"]}
    for name, true in (("imu.rx", truth[3]), ("imu.ry", truth[4])):
        assert abs(fitted[name]["value"] - true) < 3 * fitted[name]["std"], (name, fitted[name], true)
        assert fitted[name]["urdf_joint"] == "imu_board_joint"
    imu = next(b for b in result["blocks"] if b["system"] == "imu")
    assert imu["rms_after_deg"] < 0.1 < imu["rms_before_deg"] and imu["n_samples"] == 12
    urdf = (tmp_path / "fit" / "calibrated.urdf").read_text()
    assert 'rpy="0 0 1.5708"' not in urdf.split('name="imu_board_joint"')[1].split("</joint>")[0]


def test_fit_without_imu_messages_is_a_clear_error(robot, tmp_path):
    path = tmp_path / "other_topic.mcap"
    write(path, robot, [(3.0, True, UP)], imu_topic="/imu/raw")
    done = run("fit", str(path), "--robot", str(robot.config.path), "--free", "imu", "--out", str(tmp_path / "f"))
    assert done.exit_code == 2 and "no sensor_msgs/msg/Imu messages on /imu/data" in done.output, done.output
    assert str(path) in done.output and not (tmp_path / "f").exists()


@pytest.mark.slow
def test_evaluate_on_a_held_out_standing_recording(robot, tmp_path):
    config = str(robot.config.path)
    fit_on, held_out = tmp_path / "standing.mcap", tmp_path / "held_out.mcap"
    assert run("simulate", "--robot", config, "--system", "imu", "--samples", "12", "--seed", "5",
               "--out", str(fit_on)).exit_code == 0  # fmt: skip
    done = run("simulate", "--robot", config, "--system", "imu", "--samples", "8", "--seed", "6",
               "--truth", str(tmp_path / "standing.truth.yaml"), "--out", str(held_out))  # fmt: skip
    assert done.exit_code == 0, done.output
    assert run("fit", str(fit_on), "--robot", config, "--free", "imu", "--out", str(tmp_path / "fit")).exit_code == 0
    done = run("evaluate", str(tmp_path / "fit"), "--capture", str(held_out), "--out", str(tmp_path / "report"))
    assert done.exit_code == 0, done.output
    metrics = json.loads((tmp_path / "report" / "metrics.json").read_text())
    assert metrics["system"] == "imu" and metrics["n_samples"] == 8
    assert metrics["after"]["rms_deg"] < 0.1 < metrics["before"]["rms_deg"], metrics
    assert metrics["deploy"]["written"] and (tmp_path / "report" / "calibrated.urdf").is_file()


@pytest.mark.slow
def test_legs_and_imu_in_one_fit_from_a_feet_capture_and_a_standing_recording(robot, tmp_path):
    config = str(robot.config.path)
    standing, feet = tmp_path / "standing.mcap", tmp_path / "feet.mcap"
    assert run("simulate", "--robot", config, "--system", "imu", "--samples", "24", "--offsets", "legs", "--seed",
               "3", "--out", str(standing)).exit_code == 0  # fmt: skip
    done = run("simulate", "--robot", config, "--truth", str(tmp_path / "standing.truth.yaml"), "--binning", "4",
               "--samples", "25", "--seed", "3", "--out", str(feet))  # fmt: skip
    assert done.exit_code == 0, done.output
    done = run("fit", str(feet), str(standing), "--robot", config, "--free", "leg,imu", "--out", str(tmp_path / "fit"))
    assert done.exit_code == 0, done.output
    result = yaml.safe_load((tmp_path / "fit" / "result.yaml").read_text())
    assert [b["system"] for b in result["blocks"]] == ["head", "imu"]
    truth = yaml.safe_load((tmp_path / "standing.truth.yaml").read_text())["truth"]
    fitted = {p["name"]: p for p in result["parameters"]}
    expected = {
        "imu.rx": truth["frames"]["imu_board_joint"][3],
        "imu.ry": truth["frames"]["imu_board_joint"][4],
        **{f"{j}.offset": v for j, v in truth["offsets"].items()},
    }
    for name, true in expected.items():
        if fitted[name]["data_share"] > 0.5:  # offsets the data inform (an ankle roll against its tag's mount not)
            assert abs(fitted[name]["value"] - true) < 3 * fitted[name]["std"], (name, fitted[name], true)
    assert abs(fitted["imu.rx"]["value"] - expected["imu.rx"]) < np.deg2rad(0.25)
    assert abs(fitted["imu.ry"]["value"] - expected["imu.ry"]) < np.deg2rad(0.25)
    assert any(c["a"].startswith("imu.") or c["b"].startswith("imu.") for c in result["correlated_pairs"])


def test_a_standing_recording_without_the_imu_preset_is_refused_with_the_preset_to_add(robot, tmp_path):
    path = tmp_path / "standing.mcap"
    write(path, robot, [(3.0, True, UP)])
    done = run("fit", str(path), "--robot", str(robot.config.path), "--free", "leg", "--out", str(tmp_path / "f"))
    assert done.exit_code == 2 and "IMU data without images" in done.output and "--free leg,imu" in done.output
    done = run("fit", str(path), "--robot", str(robot.config.path), "--system", "imu", "--out", str(tmp_path / "f"))
    assert done.exit_code == 2 and "gravity cannot inform the camera" in done.output, done.output


@pytest.mark.slow
def test_evaluate_without_a_held_out_recording_asks_for_one(robot, tmp_path):
    config = str(robot.config.path)
    recording = tmp_path / "standing.mcap"
    done = run("simulate", "--robot", config, "--system", "imu", "--samples", "8", "--out", str(recording))
    assert done.exit_code == 0, done.output
    done = run("fit", str(recording), "--robot", config, "--free", "imu", "--out", str(tmp_path / "fit"))
    assert done.exit_code == 0, done.output
    done = run("evaluate", str(tmp_path / "fit"), "--out", str(tmp_path / "report"))
    assert done.exit_code == 2 and "standing recordings the fit did not use" in done.output, done.output


def test_configured_stances_are_simulated_and_checked(tmp_path):
    floor = yaml.safe_load((Path(__file__).resolve().parents[2] / "configs" / "wolfgang" / "robot.yaml").read_text())
    stances = floor["floor"]["check_stances"][:3]
    robot = robot_with_imu(tmp_path, imu={"frame": "imu_board", "stances": stances})
    recording = tmp_path / "standing.mcap"
    done = run("simulate", "--robot", str(robot.config.path), "--system", "imu", "--samples", "3", "--out",
               str(recording))  # fmt: skip
    assert done.exit_code == 0, done.output
    samples = read_standing([recording], "/joint_states", "/imu/data", robot.joint_names)
    assert samples.n_samples == 3
    column = robot.model.column("LHipYaw")
    assert np.allclose(samples.q_measured[:, column], [s["LHipYaw"] for s in stances], atol=0.002)
    bent = dict(stances[0], LAnkleRoll=0.3)
    robot_with_imu(tmp_path, imu={"frame": "imu_board", "stances": [bent]})
    done = run("simulate", "--robot", str(robot.config.path), "--system", "imu", "--out", str(tmp_path / "x.mcap"))
    assert done.exit_code == 2 and "'imu.stances[0]' is not a standing pose" in done.output, done.output
