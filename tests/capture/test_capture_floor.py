"""`wolfcal capture --floor` against the bus emulator (real dynamixel-sdk on a pty) and the simulated camera, which
renders the floor tags at the true places of the truth file.

Known truth: the emulator's true offsets, the camera's true mount and each floor tag's true place. Checks: the legs
held at the config's standing readings to the tick, the head at the planned pan/tilt, floor tag corners where the true
model puts them (one still moment), the samples recognised as floor samples, a fit finding the tags' places, torque
left as chosen when stopped, bad input refused before anything moves.
"""

from __future__ import annotations

import io
import math
import signal
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import WOLFGANG, stop_after_sample, wolfgang_with_other_tags
from rich.console import Console

from wolfcal.capture.floor import floor_script
from wolfcal.capture.manual import joint_groups
from wolfcal.capture.pipeline import CaptureOptions, run_capture
from wolfcal.errors import WolfcalError
from wolfcal.fit.pipeline import FitOptions, run_fit, split_floor
from wolfcal.hardware.bus import DynamixelBus, rad_to_ticks, ticks_to_rad
from wolfcal.hardware.emulator import EmulatorProcess, spec_from_config
from wolfcal.io.reader import read_capture
from wolfcal.observations import HEAD_CAMERA
from wolfcal.robot.aim import AIM_BEARINGS_DEG, AIM_DISTANCES_M, aim_joints, ball_position
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.floor import camera_in_floor, standing_pose
from wolfcal.robot.robot import load_robot
from wolfcal.sim.floor import floor_corners
from wolfcal.sim.simulate import SimOptions, simulate_capture
from wolfcal.vision.observe import detect_observations
from wolfcal.vision.tags import detect_tags

ROOT = Path(__file__).resolve().parents[2]
WAIT_S = 60.0  # generous: tests must pass on a busy machine
TRUTH = Corrections(
    offsets={"HeadPan": 0.0326, "HeadTilt": 0.0237},
    frames={"camera_optical_frame_uncalibrated_frame": np.array([0.0004, -0.0004, 0.0019, -0.0619, -0.0161, 0.0108])},
)
PLACES = {50: (1.2, 0.0, 0.3), 51: (1.5, 0.7, 1.0), 52: (1.6, -0.8, -0.5), 53: (2.2, 0.3, 2.0),
          54: (2.5, -1.2, 0.1), 55: (1.0, -0.5, -2.0)}  # fmt: skip  # x, y [m], yaw [rad] in the true floor frame


@pytest.fixture(scope="module")
def truth_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("floor-truth") / "truth.yaml"
    floor_tags = {t: {"x": x, "y": y, "yaw": yaw} for t, (x, y, yaw) in PLACES.items()}
    path.write_text(yaml.safe_dump({"truth": TRUTH.to_dict(), "floor_tags": floor_tags}))
    return path


def emulator(robot, truth_file: Path) -> EmulatorProcess:
    return EmulatorProcess(spec_from_config(robot.config, TRUTH, truth_path=str(truth_file)))


def options(out: Path, port: str, **kwargs) -> CaptureOptions:
    """Floor capture options; 1024x768 images by default (floor tags 2.5 m away detected)."""
    settings = {"camera": "sim", "velocity": 5.0, "binning": 2, **kwargs}
    return CaptureOptions(robot=WOLFGANG, out=out, port=port, floor=True, **settings)


def quiet() -> Console:
    return Console(file=io.StringIO(), force_terminal=False)


def assert_standing_and_seeing_the_floor(robot, path: Path, head_poses: list[dict[str, float]]) -> None:
    """Every sample: legs at the standing readings to the tick, the head at one of `head_poses` (readings [rad]),
    the floor tags where the true model at the true angles puts them (detection noise only), floor samples."""
    capture = read_capture(path, robot.config)
    standing = standing_pose(robot)
    pan_tilt = aim_joints(robot)
    ticks = [{j: rad_to_ticks(pose[j]) for j in pan_tilt} for pose in head_poses]
    for sample in capture.samples:
        values = dict(zip(sample.joint_names, sample.positions, strict=True))
        for joint in ("RHipPitch", "RKnee", "RAnklePitch", "LHipPitch", "LKnee", "LAnklePitch", "LAnkleRoll"):
            assert values[joint] == ticks_to_rad(rad_to_ticks(standing[robot.model.column(joint)])), joint
        assert {j: rad_to_ticks(values[j]) for j in pan_tilt} in ticks
        q_true = sample.joint_positions(robot.joint_names) + TRUTH.offset_vector(robot.joint_names)
        T_floor_camera, _ = camera_in_floor(robot, q_true[None], Corrections(frames=TRUTH.frames))
        image = sample.images[HEAD_CAMERA]
        found = detect_tags(image.decode(), "tag36h11", set(PLACES))
        assert len(found) >= 2, sample.stamp_ns
        corners = floor_corners(robot, {t: np.array(PLACES[t]) for t in found})
        T_camera_floor = np.linalg.inv(T_floor_camera[0])
        errors = [np.linalg.norm(image.camera.project(corners[t] @ T_camera_floor[:3, :3].T + T_camera_floor[:3, 3])
                                 - found[t], axis=1) for t in found]  # fmt: skip
        assert np.sqrt(np.mean(np.square(errors))) < 1.0, sample.stamp_ns
    observations, _ = detect_observations(capture.samples, robot)
    rest, floor = split_floor(robot, observations)  # as the fit and evaluation tell floor samples
    assert floor is not None and HEAD_CAMERA not in rest
    assert len(np.unique(floor.sample_index)) == len(capture.samples)


def test_the_floor_views_follow_the_config(tmp_path):
    """Legs at the config's `floor.standing` (not the Wolfgang's values: here deeper knees), the optical axis of
    each view on its aim point of the floor, within the URDF limits."""
    data = wolfgang_with_other_tags()
    data["floor"]["standing"] = {"RKnee": -0.5, "LKnee": 0.5, "RHipPitch": 0.25, "LHipPitch": -0.25,
                                 "RAnklePitch": -0.25, "LAnklePitch": 0.25}  # fmt: skip
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(data))
    robot = load_robot(tmp_path / "robot.yaml")
    script = floor_script(robot, 0.5)
    assert len(script.poses) == len(AIM_DISTANCES_M) * len(AIM_BEARINGS_DEG)
    aims = {(d, b) for d in AIM_DISTANCES_M for b in AIM_BEARINGS_DEG}
    for pose in script.poses:
        assert {j: pose.joints[j] for j in data["floor"]["standing"]} == data["floor"]["standing"]
        distance, bearing = (float(x.split()[0]) for x in pose.name.removeprefix("floor ").split(", "))
        aims.discard((distance, bearing))
        q = standing_pose(robot)
        for joint, value in pose.joints.items():
            q[robot.model.column(joint)] = value
            assert robot.model.joints[joint].lower <= value <= robot.model.joints[joint].upper
        T_floor_camera, _ = camera_in_floor(robot, q[None], Corrections())
        origin, axis = T_floor_camera[0, :3, 3], T_floor_camera[0, :3, 2]
        hit = origin - origin[2] / axis[2] * axis
        aim = ball_position(robot, Corrections(), distance, math.radians(bearing))
        assert np.linalg.norm(hit[:2] - aim[:2]) < 0.01 * distance, pose.name
    assert not aims


def test_floor_capture_holds_the_legs_standing_and_sees_the_floor_tags(robot, truth_file, tmp_path):
    out = tmp_path / "floor.mcap"
    console = Console(file=io.StringIO(), force_terminal=False)
    with emulator(robot, truth_file) as emu:
        summary = run_capture(options(out, emu.port, samples=2, binning=4), console)
        with DynamixelBus(robot.config.servos, emu.port) as bus:
            torque = bus.torque_enabled()
    assert summary.samples == 2 and not summary.skipped
    assert_standing_and_seeing_the_floor(robot, out, [p.joints for p in floor_script(robot, 5.0).poses])
    assert not any(torque.values())  # --exit-torque restore: as found (off)
    text = console.file.getvalue()
    assert "view(s) left out" in text and "would touch" in text  # the capsule model's head against the shoulder


@pytest.mark.slow
def test_floor_capture_then_fit_finds_the_tags_places(robot, truth_file, tmp_path):
    out, feet = tmp_path / "floor.mcap", tmp_path / "feet.mcap"
    with emulator(robot, truth_file) as emu:
        summary = run_capture(options(out, emu.port), quiet())
    assert summary.samples >= 5
    simulate_capture(WOLFGANG, feet, SimOptions(samples=12, seed=5, binning=2, truth_file=truth_file),
                     say=lambda s: None)  # fmt: skip
    result = run_fit([feet, out], WOLFGANG, tmp_path / "fit", FitOptions(free="head_camera"), say=lambda s: None)
    values = {p.name: p.value for p in result.parameters}
    for tag_id, (x, y, yaw) in PLACES.items():  # measured: within 13 mm (tag 54, 2.7 m away) and 0.2 deg
        assert math.hypot(values[f"floor.tag{tag_id}.x"] - x, values[f"floor.tag{tag_id}.y"] - y) < 0.02, tag_id
        assert abs(values[f"floor.tag{tag_id}.yaw"] - yaw) < math.radians(1.0), tag_id
    assert values["HeadPan.offset"] == pytest.approx(TRUTH.offsets["HeadPan"], abs=2e-3)


@pytest.mark.slow
def test_manual_floor_capture_keeps_the_legs_standing(robot, truth_file, tmp_path):
    head_poses = [{"HeadPan": 0.3, "HeadTilt": -0.6}, {"HeadPan": 0.0, "HeadTilt": -0.4},
                  {"HeadPan": 0.4, "HeadTilt": -0.3}]  # fmt: skip
    spec = spec_from_config(robot.config, TRUTH, operator_poses=head_poses, hold_s=0.9, truth_path=str(truth_file),
                            operator_speed=5.0)  # fmt: skip
    out = tmp_path / "manual_floor.mcap"
    with EmulatorProcess(spec) as emu:
        summary = run_capture(options(out, emu.port, manual=True, samples=3, yes=True, exit_torque="on"), quiet())
        with DynamixelBus(robot.config.servos, emu.port) as bus:
            torque = bus.torque_enabled()
    assert summary.samples == 3
    assert_standing_and_seeing_the_floor(robot, out, head_poses)
    assert torque["RKnee"] and torque["HeadPan"] and not torque["RElbow"]  # --exit-torque on: the touched joints


def test_stopped_floor_capture_keeps_its_samples_and_leaves_the_torque_as_chosen(robot, truth_file, tmp_path):
    out = tmp_path / "stopped.mcap"
    command = [sys.executable, "-m", "wolfcal.cli", "capture", "--floor", "--robot", str(WOLFGANG), "--camera", "sim",
               "--binning", "2", "--velocity", "5", "--exit-torque", "on", "--out", str(out)]  # fmt: skip
    with emulator(robot, truth_file) as emu:
        returncode, stderr = stop_after_sample([*command, "--port", emu.port], ROOT, signal.SIGTERM, wait_s=WAIT_S)
        with DynamixelBus(robot.config.servos, emu.port) as bus:
            torque = bus.torque_enabled()
    assert returncode == 128 + signal.SIGTERM, stderr
    assert "Traceback" not in stderr and "stopped by SIGTERM" in stderr
    groups = joint_groups(robot)  # --exit-torque on: the joints the capture touched, legs and head; no arm
    assert all(torque[j] for j in groups["legs"] + groups["head"]) and not any(torque[j] for j in groups["arms"])
    kept = len(read_capture(out, robot.config).samples)
    assert kept >= 2 and f"{kept} sample(s) saved in" in stderr


def test_floor_capture_refuses_bad_input_before_anything_moves(tmp_path):
    out = tmp_path / "x.mcap"
    with pytest.raises(WolfcalError, match="--floor moves the head through its own grid"):
        run_capture(options(out, "/dev/null", poses=WOLFGANG / "poses.yaml"), quiet())
    with pytest.raises(WolfcalError, match="--floor records the head camera's views"):
        run_capture(options(out, "/dev/null", camera=None, external=["tripod=sim"]), quiet())
    with pytest.raises(WolfcalError, match=r"--floor keeps the legs standing with torque on; --limp names RHipYaw"):
        run_capture(options(out, "/dev/null", manual=True, limp="head,legs"), quiet())
    data = wolfgang_with_other_tags()
    data.pop("floor")
    (tmp_path / "robot.yaml").write_text(yaml.safe_dump(data))
    with pytest.raises(WolfcalError, match=r"robot.yaml has no 'floor:'; capture --floor needs the standing soles"):
        run_capture(CaptureOptions(robot=tmp_path / "robot.yaml", out=out, camera="sim", port="/dev/null",
                                   floor=True), quiet())  # fmt: skip
    assert not list(tmp_path.glob("x.mcap*"))


def test_the_check_capture_moves_the_legs_through_the_check_stances(robot, truth_file, tmp_path):
    """`capture --floor --check`: one sample in each of `floor.check_stances` in turn, the legs at its readings to
    the tick, a floor sample each."""
    out = tmp_path / "check.mcap"
    with emulator(robot, truth_file) as emu:
        summary = run_capture(options(out, emu.port, samples=3, binning=4, floor_check=True), quiet())
    assert summary.samples == 3
    capture = read_capture(out, robot.config)
    for sample, stance in zip(capture.samples, robot.config.floor_config().check_stances):
        values = dict(zip(sample.joint_names, sample.positions, strict=True))
        for joint, reading in stance.items():
            assert values[joint] == ticks_to_rad(rad_to_ticks(reading)), joint
    observations, _ = detect_observations(capture.samples, robot)
    assert split_floor(robot, observations)[1] is not None
