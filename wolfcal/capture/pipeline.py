"""`wolfcal capture`: still poses of the robot -> samples (joint angles, image, camera info) in an MCAP file.

Scripted mode drives the robot through a poses file (torque on, profile velocity limited, waits for arrival);
manual mode switches torque off on the chosen chains and takes a sample whenever the operator has moved the
robot and it has become still with a tag in view (or on Enter). A sample is one still moment: bus reading,
frame, frame, bus reading, all within a tick of each other; the image is the second frame.

The file is written through `CaptureWriter` (each sample durable on return); Ctrl-C, a bus or camera failure
finish the file with every sample taken so far before the error is reported.
"""

from __future__ import annotations

import sys
import threading
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np
from rich.console import Console

from wolfcal.camera.camera_info import load_camera_info
from wolfcal.camera.model import CameraModel
from wolfcal.capture.gating import GateSettings, StillnessWindow, why_not_sharp
from wolfcal.capture.poses import PoseScript, load_poses
from wolfcal.capture.view import Coverage, LiveView, Status
from wolfcal.errors import WolfcalError
from wolfcal.hardware.bus import BusError, DynamixelBus, JointState, rad_to_ticks
from wolfcal.hardware.camera import CameraError, CameraSource, open_camera
from wolfcal.io.writer import CaptureWriter
from wolfcal.robot.robot import Robot, load_robot
from wolfcal.sim.truth import leg_and_head_joints
from wolfcal.vision.tags import detect_tags

EXIT_TORQUE = ("restore", "on", "off")
ARRIVAL_TICKS = 8  # a joint within this many ticks of its goal has arrived (servos under load stop short)
HARDWARE_POLL_S = 1.0
POLL_S = 0.005  # pause between bus reads while waiting


@dataclass
class CaptureOptions:
    robot: Path
    out: Path
    camera: str
    port: str | None = None
    poses: Path | None = None
    manual: bool = False
    samples: int | None = None
    limp: str = "head,legs"  # manual mode: joints or groups (head, legs, arms, all) to switch torque off
    yes: bool = False  # manual mode: switch torque off without asking
    exit_torque: str = "restore"  # restore (as found) | on (hold the last pose) | off
    binning: int | None = None  # default 4 for the sim camera (fast rendering), else 1
    intrinsics: Path | None = None
    velocity: float | None = None  # overrides the poses file [rad/s]
    pose_timeout_s: float = 5.0  # scripted: give up a pose that gives no sample within this time after arrival
    image_format: str = "png"
    gates: GateSettings = field(default_factory=GateSettings)


@dataclass
class CaptureSummary:
    path: Path | None
    samples: int
    rest_to_sample_s: list[float] = field(
        default_factory=list
    )  # from the robot at rest to the sample on disk
    skipped: list[str] = field(default_factory=list)


def joint_groups(robot: Robot) -> dict[str, list[str]]:
    """Groups of the servo joints: head (base -> camera), legs (base -> foot tags), arms (the rest), all."""
    servo_joints = list(robot.config.servos.ids)
    head = [j for j in leg_and_head_joints(robot, sides=()) if j in servo_joints]
    legs = [j for j in leg_and_head_joints(robot) if j in servo_joints and j not in head]
    arms = [j for j in servo_joints if j not in head and j not in legs]
    return {"head": head, "legs": legs, "arms": arms, "all": servo_joints}


def parse_limp(text: str, robot: Robot) -> list[str]:
    groups = joint_groups(robot)
    joints: list[str] = []
    for item in (t.strip() for t in text.split(",") if t.strip()):
        names = groups.get(item, [item] if item in groups["all"] else None)
        if names is None:
            raise WolfcalError(
                f"--limp {text!r}: {item!r} is neither a group ({', '.join(groups)}) nor a servo joint of "
                f"{robot.config.path}"
            )
        joints += [n for n in names if n not in joints]
    if not joints:
        raise WolfcalError("--limp names no joint; give e.g. head,legs")
    return joints


def _confirm_limp(joints: list[str], yes: bool, ask: Callable[[str], bool] | None) -> None:
    if yes:
        return
    question = (
        f"Torque goes OFF on {len(joints)} joint(s): {', '.join(joints)}. A standing robot will fall: hold "
        "it, hang it up or sit it down. Continue?"
    )
    if ask is None or not ask(question):
        raise WolfcalError(
            "manual capture needs torque off on "
            + ", ".join(joints)
            + (
                "; not confirmed"
                if ask is not None
                else "; no terminal to ask on: pass --yes once the robot is supported (hanging or sitting)"
            )
        )


class _EnterKey:
    """Sets `pressed` when the operator presses Enter (only when stdin is a terminal)."""

    def __init__(self) -> None:
        self.pressed = threading.Event()
        if sys.stdin is not None and sys.stdin.isatty():
            threading.Thread(target=self._run, daemon=True).start()

    def _run(self) -> None:
        for _ in sys.stdin:
            self.pressed.set()


class Capture:
    """One capture session over an open bus, camera and writer."""

    def __init__(
        self,
        robot: Robot,
        bus: DynamixelBus,
        camera: CameraSource,
        writer: CaptureWriter,
        options: CaptureOptions,
        view: LiveView,
        coverage: Coverage,
        status: Status,
    ):
        self.robot, self.bus, self.camera, self.writer = robot, bus, camera, writer
        self.options, self.view, self.coverage, self.status = options, view, coverage, status
        self.gates = options.gates
        self.window = StillnessWindow(bus.joints, self.gates)
        self.tag_ids = set(robot.config.tag_ids)
        self.families = sorted({t.family for t in robot.config.tags})
        self.summary = CaptureSummary(None, 0)
        self.last_hw_poll = 0.0
        self.rest_since: float | None = None

    # --- bus and camera -------------------------------------------------------------------------------------
    def read(self) -> JointState:
        now = time.monotonic()
        if now - self.last_hw_poll > HARDWARE_POLL_S:
            self.bus.check_hardware()
            self.last_hw_poll = now
        state = self.bus.read_state()
        self.window.add(time.monotonic(), state)
        if np.any(self.window.spread() > self.gates.tolerance_ticks):
            self.rest_since = None
        elif self.rest_since is None:
            self.rest_since = self.window.readings[0][0]
        return state

    def detect(self, image: np.ndarray) -> dict[int, np.ndarray]:
        corners: dict[int, np.ndarray] = {}
        for family in self.families:
            corners.update(detect_tags(image, family, self.tag_ids))
        return corners

    def done(self) -> bool:
        return self.options.samples is not None and self.summary.samples >= self.options.samples

    # --- one still moment -----------------------------------------------------------------------------------
    def try_sample(self) -> str | None:
        """Take a sample if this moment is still and sharp; returns None on success, else why not."""
        reason = self.window.why_not_still(time.monotonic())
        if reason:
            self.status.still = "no"
            return reason
        before = self.read()
        frame_a = self.camera.grab()
        corners_a = self.detect(frame_a)
        frame_b = self.camera.grab()
        stamp_ns = time.time_ns()
        after = self.read()
        corners_b = self.detect(frame_b)
        self.status.tags = sorted(corners_b)
        moved = np.abs(after.ticks - before.ticks)
        reason = self.window.why_not_still(time.monotonic())
        if reason is None and moved.max() > self.gates.tolerance_ticks:
            k = int(np.argmax(moved))
            reason = f"joints moved during the frames: {self.bus.joints[k]} by {int(moved[k])} ticks"
        if reason:
            self.status.still = "no"
            return reason
        self.status.still = "yes"
        reason, self.status.sharpness = why_not_sharp(frame_b, corners_a, corners_b, self.gates)
        if reason:
            return reason
        self.bus.check_hardware()
        self.writer.add_sample(stamp_ns, self.bus.joints, after.positions, after.velocities, frame_b)
        self.summary.samples += 1
        if self.rest_since is not None:
            self.summary.rest_to_sample_s.append(time.monotonic() - self.rest_since)
        self.status.taken = self.summary.samples
        self.coverage.add(self.bus.joints, after.positions)
        target = f"/{self.options.samples}" if self.options.samples else ""
        pose = f" ({self.status.pose})" if self.status.pose else ""
        tags = ", ".join(map(str, sorted(corners_b)))
        self.view.event(
            f"sample {self.summary.samples}{target}{pose}: tags {tags}, sharpness {self.status.sharpness:.0f}"
        )
        self.view.refresh()
        return None

    # --- scripted -------------------------------------------------------------------------------------------
    def run_scripted(self, script: PoseScript) -> None:
        joints = script.joints
        state = self.read()
        index = {j: k for k, j in enumerate(self.bus.joints)}
        goals = {j: float(state.positions[index[j]]) for j in joints}
        velocity = self.options.velocity or script.velocity
        self.bus.set_goal_positions(goals)  # torque on must not jump to a stale goal
        self.bus.set_profile_velocity(joints, velocity)
        self.bus.set_torque(joints, True)
        for pose in script.poses:
            if self.done():
                return
            self.status.pose = pose.name
            goals.update(pose.joints)
            self.bus.set_goal_positions(goals)
            reason = self.wait_arrival(goals, index, velocity)
            if reason is None:
                reason = self.sample_until(time.monotonic() + self.options.pose_timeout_s)
            if reason is not None:
                self.summary.skipped.append(f"{pose.name}: {reason}")
                self.view.event(f"pose {pose.name} skipped: {reason}")
            self.status.waiting = ""

    def sample_until(self, deadline: float) -> str | None:
        """Try for a sample until one is taken (None) or the deadline passes (the last reason)."""
        while True:
            reason = self.try_sample()
            if reason is None or time.monotonic() > deadline:
                return reason
            self.status.waiting = reason
            self.view.refresh()
            time.sleep(POLL_S)
            self.read()

    def wait_arrival(self, goals: dict[str, float], index: dict[str, int], velocity: float) -> str | None:
        goal_ticks = {j: int(rad_to_ticks(q)) for j, q in goals.items()}
        state = self.read()
        distance = max(abs(state.positions[index[j]] - q) for j, q in goals.items())
        deadline = time.monotonic() + distance / velocity + 3.0
        while True:
            off = {j: abs(int(state.ticks[index[j]]) - t) for j, t in goal_ticks.items()}
            worst = max(off, key=off.get)
            if off[worst] <= ARRIVAL_TICKS:  # then the stillness gate waits for it to settle
                return None
            if time.monotonic() > deadline:
                return f"did not arrive: {worst} is {off[worst]} ticks from its goal"
            self.status.waiting = f"moving ({worst} {off[worst]} ticks to go)"
            self.status.still = "no"
            self.view.refresh()
            time.sleep(POLL_S)
            state = self.read()

    # --- manual ---------------------------------------------------------------------------------------------
    def run_manual(self, limp: list[str]) -> None:
        self.bus.set_torque(limp, False)
        enter = _EnterKey()
        reference = self.read().ticks
        moved = False
        threshold = self.gates.moved_rad / (2 * np.pi / 4096)
        while not self.done():
            state = self.read()
            moved = moved or bool(np.max(np.abs(state.ticks - reference)) >= threshold)
            forced = enter.pressed.is_set()
            if moved or forced:
                reason = self.try_sample()
                if reason is None:
                    moved = False
                    enter.pressed.clear()
                    reference = self.window.readings[-1][1]
                self.status.waiting = reason or ""
            else:
                self.status.still = "yes" if self.window.why_not_still(time.monotonic()) is None else "no"
                self.status.waiting = "pose the robot (a sample is taken when it is still), or press Enter"
            self.view.refresh()
            time.sleep(POLL_S)


def _image_camera(options: CaptureOptions, robot: Robot) -> tuple[CameraModel, int]:
    """(full-resolution intrinsics, binning)."""
    path = options.intrinsics or robot.config.camera.intrinsics
    if path is None:
        raise WolfcalError(f"{robot.config.path}: no 'camera.intrinsics'; pass --intrinsics camera_info.yaml")
    camera = load_camera_info(path)
    binning = options.binning or (4 if options.camera == "sim" else 1)
    if binning < 1 or camera.width % binning or camera.height % binning:
        raise WolfcalError(f"--binning {binning}: must divide the camera size {camera.width}x{camera.height}")
    return camera, binning


def _restore_torque(bus: DynamixelBus, initial: dict[str, bool], touched: list[str], mode: str) -> list[str]:
    """Leave the torque of the touched joints as `mode` says, best effort; returns the joints that failed."""
    wanted = {j: (initial[j] if mode == "restore" else mode == "on") for j in touched}
    turn_on = [j for j, on in wanted.items() if on]
    failed = []
    if turn_on:
        try:  # hold where it stands: no jump to an old goal
            state = bus.read_state()
            bus.set_goal_positions({j: float(state.positions[bus.joints.index(j)]) for j in turn_on})
        except BusError:
            failed, turn_on = turn_on, []
    for joint in touched:
        if joint in failed:
            continue
        try:
            bus.set_torque([joint], wanted[joint])
        except BusError:
            failed.append(joint)
    return failed


def run_capture(
    options: CaptureOptions, console: Console | None = None, ask: Callable[[str], bool] | None = None
) -> CaptureSummary:
    """Run a capture; the summary says how many samples the file holds. Errors are WolfcalError subclasses."""
    console = console or Console(stderr=True)
    if options.manual == (options.poses is not None):
        raise WolfcalError("give exactly one of --poses POSES.yaml (scripted) or --manual")
    if options.out.suffix != ".mcap":
        raise WolfcalError(f"{options.out}: the capture file name must end in .mcap")
    if options.out.exists():
        raise WolfcalError(f"{options.out}: exists; give another --out or delete it first")
    if options.samples is not None and options.samples < 1:
        raise WolfcalError("--samples must be at least 1")
    if options.exit_torque not in EXIT_TORQUE:
        raise WolfcalError(f"--exit-torque {options.exit_torque!r}: use one of {', '.join(EXIT_TORQUE)}")
    robot = load_robot(options.robot)
    if robot.config.servos is None:
        raise WolfcalError(
            f"{robot.config.path}: no 'servos' section (port, ids): capture needs the servo bus"
        )
    limits = {j: (robot.model.joints[j].lower, robot.model.joints[j].upper) for j in robot.config.servos.ids}
    script = load_poses(options.poses, limits) if options.poses else None  # refused before anything moves
    limp = parse_limp(options.limp, robot) if options.manual else []
    camera_model, binning = _image_camera(options, robot)
    image_camera = (
        camera_model
        if binning == 1
        else camera_model.scaled(
            1 / binning, 1 / binning, camera_model.width // binning, camera_model.height // binning
        )
    )
    touched = script.joints if script else limp
    status = Status(
        "scripted" if script else "manual", options.samples or (len(script.poses) if script else None)
    )
    coverage = Coverage({j: limits[j] for j in touched})
    with DynamixelBus(robot.config.servos, options.port) as bus:
        bus.ping_all()
        bus.check_hardware()
        initial = bus.torque_enabled()
        if limp and any(initial[j] for j in limp):
            _confirm_limp([j for j in limp if initial[j]], options.yes, ask)
        camera = open_camera(options.camera, image_camera, robot, bus.port_name)
        try:
            writer = CaptureWriter(options.out, robot.config, camera_model, (binning, binning), options.image_format)
        except WolfcalError:
            camera.close()
            raise
        view = LiveView(status, coverage, console)
        session = Capture(robot, bus, camera, writer, options, view, coverage, status)
        failure: BaseException | None = None
        try:
            with view:
                if script:
                    session.run_scripted(script)
                else:
                    session.run_manual(limp)
        except (BusError, CameraError, KeyboardInterrupt) as exc:
            failure = exc
        finally:
            session.summary.path = writer.close()
            camera.close()
        bus.recover_port()
        failed = _restore_torque(bus, initial, touched, options.exit_torque)
    summary = session.summary
    saved = f"{summary.samples} sample(s) saved in {summary.path}" if summary.path else "no sample taken, no file"
    if failed:
        saved += (f"\ntorque could not be left as chosen (--exit-torque {options.exit_torque}) on {', '.join(failed)}: "
                  "check these joints before touching the robot")
        failure = failure if isinstance(failure, WolfcalError) else BusError(f"{bus.port_name}: bus failure at exit")
    if isinstance(failure, WolfcalError):
        raise type(failure)(f"{failure}\n{saved}") from None
    console.print(saved)
    if isinstance(failure, KeyboardInterrupt):
        raise failure
    return summary
