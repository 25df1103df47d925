"""`wolfcal capture` against the bus emulator (real dynamixel-sdk on a pty) and the simulated camera.

Known truth: the emulator's true offsets and the simulator's frame and tag corrections. Checks: joint angles
exact to the tick, image and joints from the same still moment (tag corners where the true model puts them),
`wolfcal fit` recovering the offsets, faults reported with every sample kept, a killed capture recoverable.
"""

from __future__ import annotations

import io
import math
import os
import re
import signal
import subprocess
import sys
import threading
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from conftest import stop_after_sample
from rich.console import Console

from wolfcal.camera.camera_info import load_camera_info, save_camera_info
from wolfcal.capture.gating import GateSettings, StillnessWindow, sharpness, why_not_sharp
from wolfcal.capture.pipeline import CaptureOptions, run_capture
from wolfcal.capture.poses import load_poses
from wolfcal.errors import WolfcalError
from wolfcal.geometry import tag_corners
from wolfcal.hardware.bus import BusError, DynamixelBus, JointState, rad_to_ticks, ticks_to_rad
from wolfcal.hardware.camera import CameraError
from wolfcal.hardware.emulator import EmulatorProcess, Fault, read_true_angles, spec_from_config, state_paths
from wolfcal.io.reader import read_capture
from wolfcal.io.recover import recover_capture
from wolfcal.io.writer import CaptureWriter
from wolfcal.observations import HEAD_CAMERA
from wolfcal.robot.corrections import Corrections
from wolfcal.vision.observe import detect_observations
from wolfcal.vision.tags import detect_tags, tag_texture

WAIT_S = 60.0  # generous: tests must pass on a busy machine
ROOT = Path(__file__).resolve().parents[2]
ROBOT = ROOT / "configs" / "wolfgang"
POSES = ROBOT / "poses.yaml"
BINNING = 4
TRUTH = Corrections(
    # head offsets for the fit; arm offsets (outside the camera-to-foot chains) to check ids and ticks
    offsets={"HeadPan": 0.0326, "HeadTilt": 0.0237, "RElbow": -0.021, "LShoulderRoll": 0.017},
    frames={"camera_optical_frame_uncalibrated_frame": np.array([0.0004, -0.0004, 0.0019, -0.0619, -0.0161, 0.0108])},
    tags={
        43: np.array([-0.0007, -0.0013, -0.0006, 0.0004, -0.0233, -0.0022]),
        44: np.array([-0.0012, -0.0007, -0.0005, -0.003, 0.0046, 0.0102]),
    },
)


@pytest.fixture(scope="module")
def truth_file(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("truth") / "truth.yaml"
    path.write_text(yaml.safe_dump({"truth": TRUTH.to_dict()}))
    return path


def emulator(robot, truth_file, **kwargs) -> EmulatorProcess:
    return EmulatorProcess(spec_from_config(robot.config, TRUTH, truth_path=str(truth_file), **kwargs))


def options(out: Path, port: str, **kwargs) -> CaptureOptions:
    return CaptureOptions(robot=ROBOT, out=out, camera=kwargs.pop("camera", "sim"), port=port, **kwargs)


def quiet() -> Console:
    return Console(file=io.StringIO(), force_terminal=False)


def fit(capture: Path, out: Path) -> dict:
    subprocess.run(
        [
            sys.executable,
            "-m",
            "wolfcal.cli",
            "fit",
            str(capture),
            "--robot",
            str(ROBOT),
            "--free",
            "head_camera",
            "--out",
            str(out),
        ],
        check=True,
        cwd=ROOT,
        capture_output=True,
    )
    return yaml.safe_load((out / "result.yaml").read_text())


def assert_recovers_truth(result: dict) -> None:
    """HeadPan offset recovered; HeadTilt offset and camera pitch only as a sum (parallel axes, DESIGN)."""
    fitted = result["corrections"]
    assert fitted["offsets"]["HeadPan"] == pytest.approx(TRUTH.offsets["HeadPan"], abs=2e-3)
    camera = "camera_optical_frame_uncalibrated_frame"
    together = fitted["offsets"]["HeadTilt"] + fitted["frames"][camera][3]
    assert together == pytest.approx(TRUTH.offsets["HeadTilt"] + TRUTH.frames[camera][3], abs=3e-3)


def assert_same_still_moment(robot, capture) -> None:
    """The tags in each image lie where the true model puts them at the recorded joint angles + true offsets.

    Detection noise on these small binned tags is up to ~1.5 px a corner, a few px on the oblique views near the
    image edge that planned poses reach (configs/wolfgang/poses.yaml is a `wolfcal plan`); joints from another
    moment would be off by tens of pixels, so the limits (2 px RMS, 6 px per corner) still tell the two apart.
    """
    camera = capture.samples[0].images[HEAD_CAMERA].camera
    for sample in capture.samples:
        errors = []
        q = sample.joint_positions(robot.joint_names) + TRUTH.offset_vector(robot.joint_names)
        found = detect_tags(sample.images[HEAD_CAMERA].decode(), "tag36h11", {43, 44})
        assert found, sample.stamp_ns
        ids = sorted(found)
        _, T_camera_tag = robot.camera_and_tag_poses(q[None], ids, Corrections(frames=TRUTH.frames, tags=TRUTH.tags))
        for k, tag_id in enumerate(ids):
            p = tag_corners(robot.config.tag(tag_id).size) @ T_camera_tag[0, k, :3, :3].T + T_camera_tag[0, k, :3, 3]
            errors += list(np.linalg.norm(camera.project(p) - found[tag_id], axis=1))
        assert np.sqrt(np.mean(np.square(errors))) < 2.0 and max(errors) < 6.0, sample.stamp_ns


# --- scripted -----------------------------------------------------------------------------------------------
@pytest.fixture(scope="module")
def scripted(robot, truth_file, tmp_path_factory):
    out = tmp_path_factory.mktemp("scripted") / "scripted.mcap"
    with emulator(robot, truth_file) as emu:
        before, _ = read_true_angles(emu.port)
        summary = run_capture(options(out, emu.port, poses=POSES, velocity=5.0), quiet())
    return out, summary, before


@pytest.mark.slow
def test_scripted_capture_is_exact_to_the_tick_and_from_one_still_moment(robot, scripted):
    out, summary, before = scripted
    capture = read_capture(out, robot.config)
    poses = load_poses(POSES, {j: (-9, 9) for j in robot.joint_names}).poses
    assert summary.samples == len(capture.samples) == len(poses) and not summary.skipped
    for sample, pose in zip(capture.samples, poses, strict=True):
        assert sample.images[HEAD_CAMERA].camera.width == 2048 // BINNING
        for joint, value in zip(sample.joint_names, sample.positions, strict=True):
            # pose joints at their goal tick; the others where they stood: true angle - true offset, quantised
            start = round((before[joint] - TRUTH.offsets.get(joint, 0.0)) / (2 * math.pi / 4096)) + 2048
            expected = rad_to_ticks(pose.joints[joint]) if joint in pose.joints else start
            assert value == ticks_to_rad(expected), (pose.name, joint)
        assert np.all(sample.velocities == 0)
    assert_same_still_moment(robot, capture)
    assert len(summary.rest_to_sample_s) == summary.samples  # how long each took: the bench harness's `capture` part


@pytest.mark.slow
def test_scripted_capture_then_fit_recovers_the_offsets(scripted, tmp_path):
    assert_recovers_truth(fit(scripted[0], tmp_path / "fit"))


def test_targets_outside_the_urdf_limits_are_refused_before_anything_moves(robot, truth_file, tmp_path):
    poses = tmp_path / "bad.yaml"
    poses.write_text(
        "poses:\n  - {name: up, joints: {HeadTilt: 2.0, HeadPan: 0.1}}\n  - {name: typo, joints: {HeadTlt: 0.0}}\n"
    )
    with emulator(robot, truth_file) as emu:
        before, _ = read_true_angles(emu.port)
        with pytest.raises(WolfcalError) as info:
            run_capture(options(tmp_path / "x.mcap", emu.port, poses=poses), quiet())
        with DynamixelBus(robot.config.servos, emu.port) as bus:  # a reply: earlier bytes were handled too
            assert not any(bus.torque_enabled().values())
        assert read_true_angles(emu.port)[0] == before
    message = str(info.value)
    assert "2 problem(s), nothing was moved" in message
    assert "HeadTilt = 2.0000 rad is outside the URDF limits [-1.9230, 1.2400]" in message
    assert "unknown joint 'HeadTlt'" in message
    assert not (tmp_path / "x.mcap").exists()


# --- manual -------------------------------------------------------------------------------------------------
@pytest.mark.slow
def test_manual_capture_with_an_emulated_operator_then_fit(robot, truth_file, tmp_path):
    operator = [p.joints for p in load_poses(POSES, {j: (-9, 9) for j in robot.joint_names}).poses]
    out = tmp_path / "manual.mcap"
    with emulator(robot, truth_file, operator_poses=operator, hold_s=0.9, operator_speed=5.0) as emu:
        summary = run_capture(options(out, emu.port, manual=True, samples=14, yes=True), quiet())
    capture = read_capture(out, robot.config)
    assert summary.samples == len(capture.samples) == 14
    readings = [{j: ticks_to_rad(rad_to_ticks(q)) for j, q in pose.items()} for pose in operator]
    for sample in capture.samples:  # each sample is one held pose of the operator, to the tick
        values = dict(zip(sample.joint_names, sample.positions, strict=True))
        assert any(all(values[j] == q for j, q in pose.items()) for pose in readings)
    assert_same_still_moment(robot, capture)
    assert_recovers_truth(fit(out, tmp_path / "fit"))


def test_manual_mode_never_switches_torque_off_silently(robot, truth_file, tmp_path):
    with emulator(robot, truth_file) as emu:
        run_capture(
            options(tmp_path / "a.mcap", emu.port, poses=POSES, samples=1, velocity=5.0, exit_torque="on"),
            quiet(),
        )
        for ask, expected in ((None, "pass --yes"), (lambda question: False, "not confirmed")):
            with pytest.raises(WolfcalError, match=expected):
                run_capture(options(tmp_path / "b.mcap", emu.port, manual=True, samples=1), quiet(), ask)
        with DynamixelBus(robot.config.servos, emu.port) as bus:
            torque = bus.torque_enabled()
    assert torque["HeadTilt"] and torque["RKnee"] and not torque["RElbow"]  # as the scripted capture left it


# --- faults -------------------------------------------------------------------------------------------------
class WatchedText(io.StringIO):
    """A text file that sets `seen` once `pattern` has been written to it."""

    def __init__(self, pattern: str) -> None:
        super().__init__()
        self.pattern, self.seen = pattern, threading.Event()

    def write(self, text: str) -> int:
        count = super().write(text)
        if self.pattern in self.getvalue():
            self.seen.set()
        return count


def run_with_fault(opts: CaptureOptions, inject, after_samples: int = 2) -> tuple[BaseException | None, str]:
    """Run a capture in a thread; call `inject()` once it has taken `after_samples` samples."""
    text = WatchedText(f"sample {after_samples}")
    result: list[BaseException | None] = [None]

    def target() -> None:
        try:
            run_capture(opts, Console(file=text, force_terminal=False))
        except BaseException as exc:  # noqa: BLE001 - handed to the test
            result[0] = exc
        finally:
            text.seen.set()  # also when it ended early: the test then sees why

    thread = threading.Thread(target=target)
    thread.start()
    assert text.seen.wait(WAIT_S), f"no sample {after_samples} within {WAIT_S:.0f} s"
    inject()
    thread.join(WAIT_S)
    assert not thread.is_alive(), f"the capture did not end within {WAIT_S:.0f} s of the fault"
    return result[0], text.getvalue()


@pytest.mark.parametrize(
    "fault, message",
    [
        (Fault("no-answer", 13), r"failed at RKnee \(id 13\): There is no status packet"),
        (Fault("crc", 20), r"failed at HeadTilt \(id 20\): Incorrect status packet"),
        (Fault("hw-error", 15, 32), r"hardware error: RAnklePitch \(id 15\): overload"),
    ],
)
def test_bus_faults_are_reported_and_lose_no_sample(robot, truth_file, tmp_path, fault, message):
    out = tmp_path / "f.mcap"
    with emulator(robot, truth_file) as emu:
        error, _ = run_with_fault(options(out, emu.port, poses=POSES, velocity=5.0), lambda: emu.inject(fault))
    assert isinstance(error, BusError)
    assert re.search(message, str(error))
    kept = len(read_capture(out, robot.config).samples)
    assert kept >= 2 and f"{kept} sample(s) saved in {out}" in str(error)
    if fault.kind == "no-answer":  # the other servos are left as chosen, the silent one is named
        assert "torque could not be left as chosen (--exit-torque restore) on RKnee:" in str(error)


@pytest.mark.slow
def test_camera_failure_is_reported_and_loses_no_sample(robot, truth_file, scripted, tmp_path):
    folder = tmp_path / "frames"
    folder.mkdir()
    image = folder / "0.png"  # one image: consecutive frames agree
    cv2.imwrite(str(image), read_capture(scripted[0], robot.config).samples[0].images[HEAD_CAMERA].decode())
    intrinsics = tmp_path / "camera.yaml"  # the images' own resolution: no binning for a folder source
    full = load_camera_info(robot.config.camera.intrinsics)
    save_camera_info(full.scaled(1 / BINNING, 1 / BINNING, full.width // BINNING, full.height // BINNING), intrinsics)
    out = tmp_path / "c.mcap"

    def unplug() -> None:
        image.write_bytes(b"")

    with emulator(robot, truth_file) as emu:
        opts = options(out, emu.port, poses=POSES, velocity=5.0, camera=str(folder), intrinsics=intrinsics)
        error, _ = run_with_fault(opts, unplug)
    assert isinstance(error, CameraError) and "cannot read this image" in str(error)
    kept = len(read_capture(out, robot.config).samples)
    assert kept >= 2 and f"{kept} sample(s) saved" in str(error)


TRIPOD_POSES = """velocity: 5.0
poses:
  - name: stand
    joints: {RKnee: -0.26, LKnee: 0.26}
  - name: feet_up
    joints: {RHipPitch: -0.6, RKnee: -1.0, RAnklePitch: 0.2, LHipPitch: 0.6, LKnee: 1.0, LAnklePitch: -0.2}
  - name: feet_forward
    joints: {RHipPitch: -0.4, RKnee: -0.6, RAnklePitch: -0.2, LHipPitch: 0.4, LKnee: 0.6, LAnklePitch: 0.2}
"""


def test_external_camera_alone_records_the_tripod_view(robot, truth_file, tmp_path):
    poses = tmp_path / "legs.yaml"
    poses.write_text(TRIPOD_POSES)
    out = tmp_path / "tripod.mcap"
    with emulator(robot, truth_file) as emu:
        opts = options(out, emu.port, poses=poses, camera=None, external=["tripod=sim"])
        summary = run_capture(opts, quiet())
    capture = read_capture(out, robot.config)
    assert capture.cameras == ["tripod"] and summary.samples == len(capture.samples) == 3
    assert all(set(s.images) == {"tripod"} for s in capture.samples)
    assert capture.samples[0].images["tripod"].camera.width == 1920 // 2  # sim external default binning 2
    observations, warnings = detect_observations(capture.samples, robot)
    assert set(observations) == {"tripod"} and not warnings
    tripod = observations["tripod"]
    assert tripod.n_samples == 3 and all(tripod.tags_in_sample(i) == [42, 43, 44] for i in range(3))


def test_capture_needs_a_camera_and_known_external_names(robot, tmp_path):
    with pytest.raises(WolfcalError, match="at least one camera"):
        run_capture(options(tmp_path / "a.mcap", "/dev/null", poses=POSES, camera=None), quiet())
    with pytest.raises(WolfcalError, match=r"no external camera named 'crane' \(configured: tripod\)"):
        run_capture(options(tmp_path / "a.mcap", "/dev/null", poses=POSES, external=["crane=sim"]), quiet())
    with pytest.raises(WolfcalError, match="NAME=SOURCE"):
        run_capture(options(tmp_path / "a.mcap", "/dev/null", poses=POSES, external=["tripod"]), quiet())


def test_missing_servo_stops_the_capture_before_it_starts(robot, truth_file, tmp_path):
    with emulator(robot, truth_file, faults=[Fault("missing", 18)]) as emu:
        with pytest.raises(BusError, match=r"LAnkleRoll \(id 18\): no answer"):
            run_capture(options(tmp_path / "m.mcap", emu.port, poses=POSES), quiet())
    assert not list(tmp_path.glob("m.mcap*"))


def test_killed_capture_leaves_a_recoverable_file(robot, truth_file, tmp_path):
    out = tmp_path / "killed.mcap"
    with emulator(robot, truth_file) as emu:
        process = subprocess.Popen(
            [
                sys.executable,
                "-m",
                "wolfcal.cli",
                "capture",
                "--robot",
                str(ROBOT),
                "--port",
                emu.port,
                "--camera",
                "sim",
                "--poses",
                str(POSES),
                "--velocity",
                "5",
                "--out",
                str(out),
            ],
            cwd=ROOT,
            stderr=subprocess.PIPE,
            stdout=subprocess.DEVNULL,
            text=True,
        )
        try:
            for line in process.stderr:
                if line.startswith("sample 3"):
                    break
            os.kill(process.pid, signal.SIGKILL)
        finally:
            process.wait(10)
    assert not out.exists()
    partial = out.with_name(out.name + ".partial")
    rescued = tmp_path / "rescued.mcap"
    count = recover_capture(partial, rescued)
    assert count >= 3
    assert len(read_capture(rescued, robot.config).samples) == count


def capture_command(port: str, out: Path) -> list[str]:
    return [sys.executable, "-m", "wolfcal.cli", "capture", "--robot", str(ROBOT), "--port", port, "--camera", "sim",
            "--poses", str(POSES), "--velocity", "5", "--out", str(out)]  # fmt: skip


@pytest.mark.parametrize("signum", [signal.SIGTERM, signal.SIGHUP], ids=["SIGTERM", "SIGHUP"])
def test_sigterm_and_sighup_leave_the_torque_as_found_and_the_file_finished(robot, truth_file, tmp_path, signum):
    out = tmp_path / "stopped.mcap"
    with emulator(robot, truth_file) as emu:
        with DynamixelBus(robot.config.servos, emu.port) as bus:
            bus.set_torque(["HeadPan"], True)  # found on: restored on; every other joint found off
            initial = bus.torque_enabled()
        returncode, stderr = stop_after_sample(capture_command(emu.port, out), ROOT, signum, wait_s=WAIT_S)
        with DynamixelBus(robot.config.servos, emu.port) as bus:
            torque = bus.torque_enabled()
    assert returncode == 128 + signum, stderr
    assert "Traceback" not in stderr and f"stopped by {signal.Signals(signum).name}" in stderr
    assert torque == initial and sum(initial.values()) == 1
    kept = len(read_capture(out, robot.config).samples)  # finished, not left as .partial
    assert kept >= 2 and f"{kept} sample(s) saved in" in stderr and out.name in stderr


def test_an_unexpected_error_still_leaves_the_torque_as_found(robot, truth_file, tmp_path, monkeypatch):
    write = CaptureWriter.add_sample

    def failing_on_the_third(self, *args, **kwargs):  # a bug, not a bus or camera failure
        if self.count == 2:
            raise RuntimeError("a bug in the capture loop")
        return write(self, *args, **kwargs)

    monkeypatch.setattr(CaptureWriter, "add_sample", failing_on_the_third)
    out = tmp_path / "bug.mcap"
    with emulator(robot, truth_file) as emu:
        with pytest.raises(RuntimeError, match="a bug in the capture loop"):
            run_capture(options(out, emu.port, poses=POSES, velocity=5.0), quiet())
        with DynamixelBus(robot.config.servos, emu.port) as bus:
            torque = bus.torque_enabled()
    assert not any(torque.values())
    assert len(read_capture(out, robot.config).samples) == 2


# --- gates and the command line --------------------------------------------------------------------------------
def tag_image(shift_px: float = 0.0, blur_sigma: float = 0.0) -> np.ndarray:
    """A 320x240 image with tag 43 (12 px per cell), optionally shifted right and blurred."""
    texture = np.kron(tag_texture("tag36h11", 43), np.ones((12, 12), np.uint8))
    image = np.full((240, 320), 128, np.uint8)
    image[60 : 60 + texture.shape[0], 100 : 100 + texture.shape[1]] = texture
    image = cv2.warpAffine(
        image, np.float32([[1, 0, shift_px], [0, 1, 0]]), (320, 240), flags=cv2.INTER_LINEAR, borderValue=128
    )
    return cv2.GaussianBlur(image, (0, 0), blur_sigma) if blur_sigma else image


def test_gates_say_why_a_moment_is_rejected():
    settings = GateSettings(settle_s=0.3)
    window = StillnessWindow(["HeadPan", "HeadTilt"], settings)
    for k, t in enumerate(np.arange(0.0, 0.5, 0.01)):
        window.add(t, JointState(np.array([2048, 1500 + (k > 40) * 3]), np.zeros(2, int)))
    assert window.why_not_still(0.5) == "joints not still: HeadTilt moved 3 ticks in the last 0.3 s"
    window.clear()
    window.add(0.0, JointState(np.array([2048, 1500]), np.zeros(2, int)))
    assert window.why_not_still(0.1).startswith("settling")
    window.add(0.35, JointState(np.array([2049, 1500]), np.zeros(2, int)))
    assert window.why_not_still(0.35) is None  # within a tick

    sharp = tag_image()
    corners = detect_tags(sharp, "tag36h11", {43})
    assert why_not_sharp(sharp, corners, corners, settings)[0] is None
    blurred = tag_image(blur_sigma=3.0)
    reason, value = why_not_sharp(blurred, corners, detect_tags(blurred, "tag36h11", {43}), settings)
    assert reason == f"image blurred: sharpness {value:.0f} < 100" and value < sharpness(sharp, corners) / 5
    moved = detect_tags(tag_image(shift_px=1.5), "tag36h11", {43})
    reason, _ = why_not_sharp(tag_image(shift_px=1.5), corners, moved, settings)
    assert reason.startswith("tag corners moved 1.5") and "between consecutive frames" in reason
    assert why_not_sharp(np.full((240, 320), 128, np.uint8), {}, {}, settings)[0] == "no tag in view"


def test_command_line_emulate_and_capture_report_bus_problems_without_traceback(tmp_path):
    emulate = subprocess.Popen(
        [
            sys.executable,
            "-m",
            "wolfcal.cli",
            "emulate",
            "--robot",
            str(ROBOT),
            "--fault",
            "model:20=1020",
            "--fault",
            "missing:7",
        ],
        cwd=ROOT,
        stdout=subprocess.PIPE,
        stderr=subprocess.PIPE,
        text=True,
    )
    try:
        port = emulate.stdout.readline().strip()
        capture = subprocess.run(
            [
                sys.executable,
                "-m",
                "wolfcal.cli",
                "capture",
                "--robot",
                str(ROBOT),
                "--port",
                port,
                "--camera",
                "sim",
                "--poses",
                str(POSES),
                "--out",
                str(tmp_path / "x.mcap"),
            ],
            cwd=ROOT,
            capture_output=True,
            text=True,
            timeout=60,
        )
    finally:
        emulate.send_signal(signal.SIGTERM)
        emulate.wait(10)
    assert capture.returncode == 3 and "Traceback" not in capture.stderr
    assert f"error: {port}: 2 servo problem(s):" in capture.stderr
    assert "RHipYaw (id 7): no answer" in capture.stderr
    assert "HeadTilt (id 20): model number 1020, expected 311" in capture.stderr
    assert emulate.returncode == 0 and not state_paths(port)[1].exists()  # cleaned up on SIGTERM
