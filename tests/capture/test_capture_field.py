"""`wolfcal capture --field` against the bus emulator (real dynamixel-sdk on a pty) and the simulated camera, which
renders the field from the emulator's true robot standing at the truth file's `field_pose`.

Checks: the sweep follows the config (or its defaults: pans within the limits, tilts aimed at the floor ahead), the
legs held at `floor.standing` and the head on the sweep's grid to the tick, views that show no field line not
taken, a stopped capture keeping its samples with the torque as chosen, bad input refused naming the key before
anything moves.
"""

from __future__ import annotations

import io
import signal
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest
import yaml
from conftest import WOLFGANG, stop_after_sample, wolfgang_on_a_field
from rich.console import Console

from wolfcal.camera.camera_info import load_camera_info
from wolfcal.capture.field import (
    DEFAULT_PAN_SPAN_RAD,
    DEFAULT_PANS,
    DEFAULT_TILT_AIM_M,
    field_script,
    one_sided_note,
)
from wolfcal.capture.floor import without_collisions
from wolfcal.capture.pipeline import CaptureOptions, run_capture
from wolfcal.capture.sim_camera import SimCamera
from wolfcal.errors import WolfcalError
from wolfcal.hardware.bus import DynamixelBus, rad_to_ticks
from wolfcal.hardware.emulator import EmulatorProcess, spec_from_config
from wolfcal.io.reader import read_capture
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.floor import camera_in_floor, standing_pose
from wolfcal.robot.robot import load_robot

ROOT = Path(__file__).resolve().parents[2]
WAIT_S = 120.0  # generous: tests must pass on a busy machine
TRUTH = Corrections(frames={"camera_optical_frame_uncalibrated_frame": np.array([0.001, -0.002, 0.002, -0.06, 0.02,
                                                                                 0.01])})  # fmt: skip
PLACE = {"x": -2.8, "y": 0.15, "yaw": 0.1}


def config_with(tmp_path: Path, sweep: dict | None = None, field: bool = True) -> Path:
    path = wolfgang_on_a_field(tmp_path)
    data = yaml.safe_load(path.read_text())
    if sweep is not None:
        data["field"]["sweep"] = sweep
    if not field:
        data.pop("field")
    path.write_text(yaml.safe_dump(data))
    return path


def emulator(robot, tmp_path: Path) -> EmulatorProcess:
    truth = tmp_path / "truth.yaml"
    truth.write_text(yaml.safe_dump({"truth": TRUTH.to_dict(), "field_pose": PLACE}))
    return EmulatorProcess(spec_from_config(robot.config, TRUTH, truth_path=str(truth)))


def options(config: Path, out: Path, port: str, **kwargs) -> CaptureOptions:
    settings = {"camera": "sim", "velocity": 5.0, **kwargs}
    return CaptureOptions(robot=config, out=out, port=port, field_views=True, **settings)


def quiet() -> Console:
    return Console(file=io.StringIO(), force_terminal=False, width=200)


def head_ticks(pose_joints: dict[str, float]) -> tuple[int, int]:
    return int(rad_to_ticks(pose_joints["HeadPan"])), int(rad_to_ticks(pose_joints["HeadTilt"]))


def test_the_default_sweep_stands_and_aims_at_the_floor_ahead(tmp_path):
    """Without `field.sweep`: DEFAULT_PANS pans over +-DEFAULT_PAN_SPAN_RAD, tilts whose optical axis (pan 0) meets
    the floor DEFAULT_TILT_AIM_M ahead; the legs at `floor.standing`; every reading within the URDF limits."""
    robot = load_robot(config_with(tmp_path))
    script = field_script(robot, 1.0)
    assert len(script.poses) == DEFAULT_PANS * len(DEFAULT_TILT_AIM_M)
    pans = sorted({p.joints["HeadPan"] for p in script.poses})
    assert pans == pytest.approx(list(np.linspace(-DEFAULT_PAN_SPAN_RAD, DEFAULT_PAN_SPAN_RAD, DEFAULT_PANS)))
    tilts = sorted({p.joints["HeadTilt"] for p in script.poses})  # the nearer aim: the head tilted down more
    for tilt, distance in zip(tilts, DEFAULT_TILT_AIM_M, strict=True):
        q = standing_pose(robot)
        q[robot.model.column("HeadTilt")] = tilt
        T_floor_camera, T_floor_base = camera_in_floor(robot, q[None], Corrections())
        origin, axis = T_floor_camera[0, :3, 3], T_floor_camera[0, :3, 2]
        hit = origin - origin[2] / axis[2] * axis
        assert hit[0] - T_floor_base[0, 0, 3] == pytest.approx(distance, abs=0.02)
    for pose in script.poses:
        assert pose.joints["RKnee"] == -0.2618 and pose.joints["LKnee"] == 0.2618 and pose.joints["RHipPitch"] == 0
        for joint, value in pose.joints.items():
            assert robot.model.joints[joint].lower <= value <= robot.model.joints[joint].upper
    kept, _ = without_collisions(robot, script, {}, "--field")
    assert one_sided_note(robot, kept) is None  # the Wolfgang's capsules leave out pans to the right, not all of them
    first_row = [p.joints["HeadPan"] for p in script.poses[:DEFAULT_PANS]]
    assert first_row == sorted(first_row) and [p.joints["HeadPan"] for p in script.poses[DEFAULT_PANS:]] == sorted(
        first_row, reverse=True
    )  # to and fro: short moves


def test_field_capture_stands_at_the_sweep_and_sees_the_lines(tmp_path):
    config = config_with(tmp_path, {"pan": [0.0, 0.5], "tilt": [-0.4]})
    robot = load_robot(config)
    out = tmp_path / "field.mcap"
    console = quiet()
    with emulator(robot, tmp_path) as emu:
        summary = run_capture(options(config, out, emu.port), console)
        with DynamixelBus(robot.config.servos, emu.port) as bus:
            torque = bus.torque_enabled()
    assert summary.samples == 2 and not summary.skipped, summary.skipped
    grid = {head_ticks(p.joints) for p in field_script(robot, 5.0).poses}
    samples = read_capture(out, robot.config).samples
    assert {head_ticks(dict(zip(s.joint_names, s.positions))) for s in samples} == grid
    for sample in samples:
        values = dict(zip(sample.joint_names, sample.positions, strict=True))
        assert rad_to_ticks(values["RKnee"]) == rad_to_ticks(-0.2618) and rad_to_ticks(values["LHipPitch"]) == 2048
        assert sample.images["head"].decode().ndim == 3  # colour: the lines are told from the turf by colour
    assert not any(torque.values())  # --exit-torque restore: as found (off)
    text = console.file.getvalue()
    assert "field-line points" in text
    assert "note: --field: every view turns HeadPan to one side (+0 to +29 deg)" in text  # pans 0 and 0.5 rad


def test_views_that_show_no_field_line_are_not_taken(tmp_path):
    config = config_with(tmp_path, {"pan": [0.0], "tilt": [0.8]})  # the head looks up, over the field
    robot = load_robot(config)
    console = quiet()
    with emulator(robot, tmp_path) as emu:
        summary = run_capture(options(config, tmp_path / "sky.mcap", emu.port, pose_timeout_s=1.0), console)
    assert summary.samples == 0 and len(summary.skipped) == 1
    assert "no field lines in view" in summary.skipped[0]
    assert not (tmp_path / "sky.mcap").exists()


@pytest.mark.slow
def test_manual_field_capture_keeps_the_legs_standing(tmp_path):
    """--manual: the legs hold floor.standing (torque on), the emulated operator turns the limp head."""
    config = config_with(tmp_path)
    robot = load_robot(config)
    head_poses = [{"HeadPan": 0.3, "HeadTilt": -0.4}, {"HeadPan": -0.3, "HeadTilt": -0.3}]
    truth = tmp_path / "truth.yaml"
    truth.write_text(yaml.safe_dump({"truth": TRUTH.to_dict(), "field_pose": PLACE}))
    spec = spec_from_config(robot.config, TRUTH, operator_poses=head_poses, hold_s=0.9, truth_path=str(truth),
                            operator_speed=5.0)  # fmt: skip
    out = tmp_path / "manual.mcap"
    with EmulatorProcess(spec) as emu:
        summary = run_capture(options(config, out, emu.port, manual=True, samples=2, yes=True, exit_torque="on"),
                              quiet())  # fmt: skip
        with DynamixelBus(robot.config.servos, emu.port) as bus:
            torque = bus.torque_enabled()
    assert summary.samples == 2
    for sample in read_capture(out, robot.config).samples:
        values = dict(zip(sample.joint_names, sample.positions, strict=True))
        assert rad_to_ticks(values["RKnee"]) == rad_to_ticks(-0.2618) and rad_to_ticks(values["LHipPitch"]) == 2048
        assert head_ticks(values) in {head_ticks(p) for p in head_poses}
    assert torque["RKnee"] and torque["HeadPan"] and not torque["RElbow"]  # --exit-torque on: the touched joints


def test_a_stopped_field_capture_keeps_its_samples_and_leaves_the_torque_as_chosen(tmp_path):
    config = config_with(tmp_path, {"pan": [-0.3, 0.0, 0.3, 0.6], "tilt": [-0.4]})
    robot = load_robot(config)
    out = tmp_path / "stopped.mcap"
    command = [sys.executable, "-m", "wolfcal.cli", "capture", "--field", "--robot", str(config), "--camera", "sim",
               "--velocity", "5", "--exit-torque", "on", "--out", str(out)]  # fmt: skip
    with emulator(robot, tmp_path) as emu:
        returncode, stderr = stop_after_sample([*command, "--port", emu.port], ROOT, signal.SIGTERM, wait_s=WAIT_S)
        with DynamixelBus(robot.config.servos, emu.port) as bus:
            torque = bus.torque_enabled()
    assert returncode == 128 + signal.SIGTERM, stderr
    assert "Traceback" not in stderr and "stopped by SIGTERM" in stderr
    assert torque["RKnee"] and torque["HeadPan"] and not torque["RElbow"]  # --exit-torque on: the joints it moved
    kept = len(read_capture(out, robot.config).samples)
    assert kept >= 2 and f"{kept} sample(s) saved in" in stderr


def test_field_capture_refuses_bad_input_before_anything_moves(tmp_path):
    out = tmp_path / "x.mcap"
    (tmp_path / "bare").mkdir()
    no_field = config_with(tmp_path / "bare", field=False)
    with pytest.raises(WolfcalError, match=r"has no 'field:'; field views need the field's dimensions"):
        run_capture(options(no_field, out, "/dev/null"), quiet())
    outside = config_with(tmp_path, {"pan": [0.0, 3.0], "tilt": [-0.4]})
    with pytest.raises(WolfcalError, match=r"'field.sweep.pan' has 3.0000 rad outside the URDF limits of HeadPan"):
        run_capture(options(outside, out, "/dev/null"), quiet())
    with pytest.raises(WolfcalError, match=r"'field.sweep' unknown key\(s\) roll"):
        run_capture(options(config_with(tmp_path, {"roll": [0.0]}), out, "/dev/null"), quiet())
    with pytest.raises(WolfcalError, match=r"'field.sweep.tilt' must be a non-empty list of angles \[rad\]"):
        run_capture(options(config_with(tmp_path, {"tilt": -0.4}), out, "/dev/null"), quiet())
    config = config_with(tmp_path)
    with pytest.raises(WolfcalError, match="give one of --field .* and --floor"):
        run_capture(options(config, out, "/dev/null", floor=True), quiet())
    with pytest.raises(WolfcalError, match="--field moves the head through its own sweep"):
        run_capture(options(config, out, "/dev/null", poses=WOLFGANG / "poses.yaml"), quiet())
    with pytest.raises(WolfcalError, match="--field records the head camera's views of the field"):
        run_capture(options(config, out, "/dev/null", camera=None, external=["tripod=sim"]), quiet())
    with pytest.raises(WolfcalError, match="--field keeps the legs standing with torque on; --limp names RHipYaw"):
        run_capture(options(config, out, "/dev/null", manual=True, limp="head,legs"), quiet())
    assert not out.exists()
    run = subprocess.run([sys.executable, "-m", "wolfcal.cli", "capture", "--field", "--robot", str(no_field),
                          "--camera", "sim", "--port", "/dev/null", "--out", str(out)], cwd=ROOT, capture_output=True,
                         text=True, timeout=WAIT_S)  # fmt: skip
    assert run.returncode == 2 and "Traceback" not in run.stderr, run.stderr
    assert "has no 'field:'" in run.stderr and not out.exists()


def test_held_out_field_views_stand_at_check_at_and_need_it(tmp_path):
    """--field --check: the robot stands at field.check_at (the emulated one off from it as its truth is off from
    robot_at); a config without check_at is refused before anything opens."""
    config = config_with(tmp_path)
    out = tmp_path / "check.mcap"
    with pytest.raises(WolfcalError, match=r"--field --check stands the robot at 'field.check_at'"):
        run_capture(options(config, out, "/dev/null", floor_check=True), quiet())
    data = yaml.safe_load(config.read_text())
    data["field"]["check_at"] = {"x": -1.5, "y": 1.0, "yaw": 0.5}
    config.write_text(yaml.safe_dump(data))
    robot = load_robot(config)
    with emulator(robot, tmp_path) as emu:
        camera = SimCamera(robot, [emu.port], load_camera_info(WOLFGANG / "basler_acA2040.yaml").binned(4, "head"),
                           field=True, field_check=True)  # fmt: skip
    robot_at = np.array([-3.0, 0.0, 0.0])  # wolfgang_on_a_field's
    offset = np.array([PLACE["x"], PLACE["y"], PLACE["yaw"]]) - robot_at
    assert np.allclose(camera.scene.pose, np.array([-1.5, 1.0, 0.5]) + offset)
