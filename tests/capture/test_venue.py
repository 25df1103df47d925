"""`wolfcal venue` against the bus emulator (real dynamixel-sdk on a pty, in its own process) and the simulated camera.

Known truth: the demo's floor truth (a camera turned by about 5.6 deg, tag mounts off by a few mm, floor tags lying
1.6-3 m away), served by the emulator and rendered by the simulated camera. Checks: one command from start to the
deploy files with the camera within 0.05 deg and 2 mm of the truth; an interrupted session resumed without losing a
sample, the torque as found; a port where nothing answers, a camera that shows no tag, a config without floor tags
or plannable poses.
"""

from __future__ import annotations

import json
import os
import pty
import signal
import subprocess
import sys
import tty
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from conftest import default_sigint

from wolfcal.encoders import RAD_PER_TICK
from wolfcal.errors import WolfcalError
from wolfcal.evaluate.accuracy import camera_pose_errors
from wolfcal.evaluate.deploy import DEPLOY_FILES
from wolfcal.fit.result import load_result
from wolfcal.hardware import protocol as P
from wolfcal.hardware.bus import DynamixelBus
from wolfcal.hardware.emulator import EmulatorProcess, load_truth, read_true_angles, spec_from_config
from wolfcal.hardware.emulator.servo import EmulatedServo, ServoSpec
from wolfcal.io.reader import read_capture
from wolfcal.venue.motion import move_time
from wolfcal.venue.options import VenueOptions
from wolfcal.venue.session import run_venue

ROOT = Path(__file__).resolve().parents[2]
ROBOT = ROOT / "configs" / "wolfgang"
TRUTH = ROOT / "captures" / "floor_demo.truth.yaml"
WAIT_S = 600.0  # generous: a whole session with its fit on a busy machine


def emulator(robot, truth: Path = TRUTH) -> EmulatorProcess:
    return EmulatorProcess(spec_from_config(robot.config, load_truth(truth), truth_path=str(truth)))


def truth_without_floor(tmp_path: Path) -> Path:
    """The truth without its floor tags, for a robot config that has none."""
    data = yaml.safe_load(TRUTH.read_text())
    data.pop("floor_tags")
    path = tmp_path / "truth.yaml"
    path.write_text(yaml.safe_dump(data))
    return path


def venue_command(port: str, *args: str, robot: Path = ROBOT) -> list[str]:
    return [sys.executable, "-m", "wolfcal.cli", "venue", "--robot", str(robot), "--port", port, "--camera", "sim",
            "--yes", *args]  # fmt: skip


def torque(robot, port: str) -> dict[str, bool]:
    with DynamixelBus(robot.config.servos, port) as bus:
        return bus.torque_enabled()


def samples_in(robot, paths: list[Path]) -> int:
    return sum(len(read_capture(p, robot.config).samples) for p in paths)


def robot_without(tmp_path: Path, *keys: str, poses: bool = False) -> Path:
    """A copy of the Wolfgang config without the given top-level keys (absolute paths), optionally with the first
    six poses of the shipped poses file beside it."""
    data = yaml.safe_load((ROBOT / "robot.yaml").read_text())
    data["urdf"] = str(ROBOT / data["urdf"])
    data["camera"]["intrinsics"] = str(ROBOT / data["camera"]["intrinsics"])
    data.pop("external_cameras")
    for key in keys:
        data.pop(key)
    folder = tmp_path / "robot"
    folder.mkdir()
    (folder / "robot.yaml").write_text(yaml.safe_dump(data))
    if poses:
        script = yaml.safe_load((ROBOT / "poses.yaml").read_text())
        script["poses"] = script["poses"][:6]
        (folder / "poses.yaml").write_text(yaml.safe_dump(script))
    return folder


def test_emulated_servo_follows_the_velocity_based_profile():
    """Trapezoid of the Dynamixel documentation: d / v + v / a for a long move, 2 sqrt(d / a) for a short one."""
    for distance, velocity, acceleration in ((1.0, 1.5, 6.0), (0.05, 1.5, 6.0), (2.0, 3.0, 20.0)):
        servo = EmulatedServo(1, ServoSpec("j", 311))
        servo.write(P.TORQUE_ENABLE, 1)
        servo.write(P.PROFILE_VELOCITY, round(velocity / P.RAD_S_PER_UNIT))
        servo.write(P.PROFILE_ACCELERATION, round(acceleration / P.RAD_S2_PER_UNIT))
        goal = round(distance / RAD_PER_TICK)
        servo.write(P.GOAL_POSITION, P.CENTRE_TICK + goal)
        steps, fastest = 0, 0.0
        while servo.angle != goal * RAD_PER_TICK and steps < 10_000:
            servo.step(0.002, None, 0.0)
            steps, fastest = steps + 1, max(fastest, servo.speed)
        assert steps * 0.002 == pytest.approx(move_time(goal * RAD_PER_TICK, velocity, acceleration), rel=0.04)
        assert fastest <= velocity * 1.01


@pytest.mark.slow
def test_one_command_from_start_to_deploy_files_pins_the_camera(robot, tmp_path):
    out = tmp_path / "session"
    with emulator(robot) as emu:
        found = torque(robot, emu.port)
        run = subprocess.run(venue_command(emu.port, "--out", str(out)), cwd=ROOT, capture_output=True, text=True,
                             timeout=WAIT_S)  # fmt: skip
        after = torque(robot, emu.port)
    assert run.returncode == 0, run.stderr
    assert "Traceback" not in run.stderr and after == found
    for line in ("feet view 1 of 8", "s left", "Deploy the files below", "robot time", "wall time"):
        assert line in run.stderr, line
    metrics = json.loads((out / "metrics.json").read_text())
    print(f"robot time {metrics['robot_time_s']:.1f} s, wall time {metrics['wall_time_s']:.1f} s")
    rotation, translation = camera_pose_errors(robot, load_result(out / "fit").corrections, load_truth(TRUTH))
    assert np.rad2deg(rotation.max()) < 0.05 and translation.max() < 0.002, (rotation.max(), translation.max())
    assert all((out / name).is_file() for name in DEPLOY_FILES) and metrics["deploy"]["written"]
    assert metrics["held_out_floor"] is not None and metrics["samples"]["check"] >= 8
    assert metrics["cross_validation"]["after"]["rms_px"] < 0.5 < 10 < metrics["cross_validation"]["before"]["rms_px"]


def run_until(command: list[str], marker: str, count: int, signum: int) -> tuple[int, str]:
    """Run a command, send it `signum` once its stderr has shown `count` lines starting with `marker` (an event,
    no sleeping); its exit code and everything it wrote to stderr."""
    process = subprocess.Popen(
        command, cwd=ROOT, stderr=subprocess.PIPE, stdout=subprocess.DEVNULL, text=True, preexec_fn=default_sigint
    )
    seen, lines = 0, []
    try:
        for line in process.stderr:
            lines.append(line)
            seen += line.startswith(marker)
            if seen >= count:
                process.send_signal(signum)
                break
        lines.append(process.stderr.read())
        process.wait(WAIT_S)
    finally:
        if process.poll() is None:
            process.kill()
    return process.returncode, "".join(lines)


@pytest.mark.slow
def test_interrupted_session_resumes_without_losing_a_sample(robot, tmp_path):
    """Ctrl-C after three feet views: torque as found, the three samples kept; --resume takes the rest and fits.
    The config has no floor tags: the session says so and checks by cross-validation alone."""
    config = robot_without(tmp_path, "floor")
    out = tmp_path / "session"
    with emulator(robot, truth_without_floor(tmp_path)) as emu:
        with DynamixelBus(robot.config.servos, emu.port) as bus:
            bus.set_torque(["HeadPan"], True)  # found on: restored on; every other joint found off
        found = torque(robot, emu.port)
        code, stderr = run_until(venue_command(emu.port, "--out", str(out), robot=config), "  sample:", 3,
                                 signal.SIGINT)  # fmt: skip
        stopped = torque(robot, emu.port)
        state = json.loads((out / "session.json").read_text())
        kept = samples_in(robot, [out / "feet-1.mcap"])
        resumed = subprocess.run(venue_command(emu.port, "--resume", str(out), robot=config), cwd=ROOT,
                                 capture_output=True, text=True, timeout=WAIT_S)  # fmt: skip
        after = torque(robot, emu.port)
    assert code == 130 and "Traceback" not in stderr, stderr
    assert "lists no floor tags" in stderr and f"continue with `wolfcal venue --resume {out}`" in stderr
    assert stopped == found == after and sum(found.values()) == 1
    assert kept == len(state["done"]["feet"]) >= 3
    assert resumed.returncode == 0, resumed.stderr
    assert samples_in(robot, [out / "feet-1.mcap"]) == kept  # nothing of the first run lost or rewritten
    done = json.loads((out / "session.json").read_text())["done"]["feet"]
    assert done[:kept] == state["done"]["feet"] and len(done) == len(set(done)) >= 7
    assert samples_in(robot, [out / "feet-1.mcap", out / "feet-2.mcap"]) == len(done)
    assert json.loads((out / "metrics.json").read_text())["runs"] == 2


def test_a_port_where_nothing_answers_is_named(tmp_path):
    master, slave = pty.openpty()  # a serial line with nothing on the other end
    tty.setraw(slave)
    try:
        run = subprocess.run(venue_command(os.ttyname(slave), "--out", str(tmp_path / "s")), cwd=ROOT,
                             capture_output=True, text=True, timeout=WAIT_S)  # fmt: skip
    finally:
        os.close(master)
        os.close(slave)
    assert run.returncode == 3 and "Traceback" not in run.stderr, run.stderr
    assert "no servo answers on this port" in run.stderr and "--port names its servo bus" in run.stderr
    missing = subprocess.run(venue_command(str(tmp_path / "ttyUSB9"), "--out", str(tmp_path / "t")), cwd=ROOT,
                             capture_output=True, text=True, timeout=WAIT_S)  # fmt: skip
    assert missing.returncode == 3 and "cannot open the servo bus" in missing.stderr, missing.stderr


def test_a_camera_that_shows_no_tag_stops_after_a_few_poses(robot, tmp_path):
    frames = tmp_path / "frames"
    frames.mkdir()
    cv2.imwrite(str(frames / "0.png"), np.full((1536, 2048), 128, np.uint8))  # the config's full resolution
    out, said = tmp_path / "session", []
    with emulator(robot) as emu:
        found = torque(robot, emu.port)
        options = VenueOptions(robot=ROBOT, out=out, camera=str(frames), port=emu.port, yes=True)
        with pytest.raises(WolfcalError) as info:
            run_venue(options, say=said.append)
        after = torque(robot, emu.port)
    message = str(info.value)
    assert "showed none of the robot's tags (42, 43, 44) in the first 3 poses" in message
    assert "it sees a flat image (grey 128" in message and "0 sample(s) kept" in message
    assert after == found
    assert [line for line in said if line.startswith("feet view")][-1].startswith("feet view 3 of")


@pytest.mark.slow
def test_a_config_whose_poses_cannot_be_planned_falls_back_to_its_poses_file(robot, tmp_path):
    """No collision geometry: the planner refuses, the session says so and takes the config's poses file."""
    config = robot_without(tmp_path, "floor", "collision_radii", poses=True)
    out, said = tmp_path / "session", []
    with emulator(robot, truth_without_floor(tmp_path)) as emu:
        figures = run_venue(VenueOptions(robot=config, out=out, camera="sim", port=emu.port, yes=True),
                            say=said.append)  # fmt: skip
    text = "\n".join(said)
    assert "the feet views cannot be planned" in text and f"using {config / 'poses.yaml'} instead" in text
    assert "poses not checked for self-collision" in text and "lists no floor tags" in text
    assert figures["samples"]["feet"] == 6 and figures["held_out_floor"] is None


def test_nothing_moves_without_the_operator_saying_so(robot, tmp_path):
    with emulator(robot) as emu:
        found, angles = torque(robot, emu.port), read_true_angles(emu.port)[0]
        for ask, expected in ((None, "pass --yes to confirm without a terminal"), (lambda question: False,
                                                                                    "not confirmed")):  # fmt: skip
            options = VenueOptions(robot=ROBOT, out=tmp_path / expected.split()[0], camera="sim", port=emu.port)
            with pytest.raises(WolfcalError, match=expected):
                run_venue(options, say=lambda line: None, ask=ask)
        after = torque(robot, emu.port)
        assert read_true_angles(emu.port)[0] == angles
    assert after == found and not any(after.values())


@pytest.mark.slow
def test_a_killed_session_is_rescued_and_resumed(robot, tmp_path):
    """SIGKILL leaves an unfinished capture part: --resume rescues its complete samples, then takes the rest."""
    config = robot_without(tmp_path, "floor")
    out = tmp_path / "session"
    with emulator(robot, truth_without_floor(tmp_path)) as emu:
        code, _ = run_until(venue_command(emu.port, "--out", str(out), robot=config), "  sample:", 2, signal.SIGKILL)
        done = json.loads((out / "session.json").read_text())["done"]["feet"]
        resumed = subprocess.run(venue_command(emu.port, "--resume", str(out), robot=config), cwd=ROOT,
                                 capture_output=True, text=True, timeout=WAIT_S)  # fmt: skip
    assert code == -signal.SIGKILL and len(done) >= 2
    assert resumed.returncode == 0, resumed.stderr
    rescued = int(resumed.stderr.split("rescued ")[1].split()[0])
    assert rescued >= len(done) and "of an unfinished part into feet-1.mcap" in resumed.stderr
    assert samples_in(robot, [out / "feet-1.mcap"]) == rescued and not list(out.glob("*.partial"))
    final = json.loads((out / "session.json").read_text())["done"]["feet"]
    assert final[: len(done)] == done and samples_in(robot, [out / "feet-1.mcap", out / "feet-2.mcap"]) >= len(final)
