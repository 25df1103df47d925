"""Driving the servos through a list of poses fast and safely, one sample per pose.

Each pose: the goals are sent and the servos move along their profile (the session's velocity [rad/s] and
acceleration [rad/s^2]); while they move, the previous pose's sample is written (image encoding and fsync). Once
every joint is within ARRIVAL_TICKS of its goal, the stillness gate (`capture.gating.StillnessWindow`) decides when
the robot is still; two frames are grabbed at once between two bus readings that must agree, and checked while the
robot still holds the pose (tags in view, sharp, corners still: `capture.gating.why_not_sharp`; field views: the
field's lines in view, sharp: `capture.gating.why_not_field_view`), so that a failed
check costs another still moment (up to GRAB_TRIES) instead of a move back. A pose that still fails is taken again
once at the end. Poses reach this module already checked (URDF limits, self-collision): it sends nothing else.
Angles are joint readings [rad]; times are on the monotonic clock [s].
"""

from __future__ import annotations

import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field

import numpy as np

from wolfcal.capture.gating import GateSettings, StillnessWindow, why_not_field_view, why_not_sharp
from wolfcal.capture.poses import Pose
from wolfcal.errors import WolfcalError
from wolfcal.hardware.bus import JointState, rad_to_ticks
from wolfcal.hardware.buses import ServoBuses
from wolfcal.hardware.camera import CameraSource
from wolfcal.io.writer import CaptureWriter
from wolfcal.venue.seen import what_the_camera_sees
from wolfcal.vision.tags import detect_tags

ARRIVAL_TICKS = 8  # a joint within this many ticks of its goal has arrived (then the stillness gate waits)
ARRIVAL_MARGIN_S = 3.0  # time allowed for a move beyond its profile's duration
POSE_TIMEOUT_S = 5.0  # after arrival, a pose that is not still by then is given up
POLL_S = 0.002  # pause between bus reads while waiting
GRAB_TRIES = 4  # still moments tried at a pose before it is given up (the image gates may fail on noise)
NO_TAG_POSES = 3  # a session whose first poses all show no tag stops after this many


class VenueCameraError(WolfcalError):
    """The camera shows none of the robot's tags in the first poses."""


def move_time(distance: float, velocity: float, acceleration: float) -> float:
    """Duration [s] of a move of `distance` [rad] along the velocity-based profile (trapezoid or triangle)."""
    distance = abs(distance)
    if distance * acceleration >= velocity**2:
        return distance / velocity + velocity / acceleration
    return 2.0 * math.sqrt(distance / acceleration)


@dataclass
class Taken:
    """What happened to one pose: its name and the tags seen (a sample written), or why it was not taken."""

    name: str
    tags: list[int] = field(default_factory=list)
    reason: str | None = None


@dataclass
class Grabbed:
    """The frames of a still moment that passed the gates, the bus reading after them and the tags seen."""

    pose: Pose
    stamp_ns: int
    state: JointState
    frames: dict[str, np.ndarray]
    tags: list[int]


class PoseDriver:
    """The bus, cameras and capture writer of one phase; `drive` takes the poses in order."""

    def __init__(self, bus: ServoBuses, cameras: dict[str, CameraSource], tag_ids: set[int], families: list[str],
                 gates: GateSettings, velocity: float, acceleration: float, say: Callable[[str], None]):  # fmt: skip
        self.bus, self.cameras = bus, cameras
        self.writer: CaptureWriter | None = None  # the phase's capture part, set before `drive`
        self.tag_ids, self.families, self.gates = tag_ids, families, gates
        self.field = False  # field views: the gates look for the field's lines instead of tags
        self.velocity, self.acceleration, self.say = velocity, acceleration, say
        self.index = {j: k for k, j in enumerate(bus.joints)}
        self.window = StillnessWindow(bus.joints, gates)
        self.hold_s: list[float] = []  # per pose: from arrival to frames grabbed [s]

    # --- bus ------------------------------------------------------------------------------------------------
    def read(self) -> JointState:
        """Read the bus into the stillness window (hardware errors checked now and then: `read_state_polled`)."""
        state = self.bus.read_state_polled()
        self.window.add(time.monotonic(), state)
        return state

    def torque_on(self, joints: list[str]) -> dict[str, float]:
        """Torque on for `joints`, each holding where it stands, moves limited to the session's velocity and
        acceleration; returns the goals [rad] by joint."""
        state = self.read()
        goals = {j: float(state.positions[self.index[j]]) for j in joints}
        self.bus.set_goal_positions(goals)
        self.bus.set_profile_velocity(joints, self.velocity)
        self.bus.set_profile_acceleration(joints, self.acceleration)
        self.bus.set_torque(joints, True)
        return goals

    def _arrive(self, goals: dict[str, float]) -> str | None:
        """Wait until every joint is within ARRIVAL_TICKS of its goal (None), or say why it did not in time."""
        state = self.read()
        distance = max(abs(float(state.positions[self.index[j]]) - q) for j, q in goals.items())
        deadline = time.monotonic() + move_time(distance, self.velocity, self.acceleration) + ARRIVAL_MARGIN_S
        goal_ticks = {j: int(rad_to_ticks(q)) for j, q in goals.items()}
        while True:
            off = {j: abs(int(state.ticks[self.index[j]]) - t) for j, t in goal_ticks.items()}
            worst = max(off, key=lambda j: off[j])
            if off[worst] <= ARRIVAL_TICKS:
                return None
            if time.monotonic() > deadline:
                return f"did not arrive: {worst} is {off[worst]} ticks from its goal"
            time.sleep(POLL_S)
            state = self.read()

    def _grab_when_still(self, pose: Pose) -> Grabbed | tuple[str, np.ndarray | None]:
        """The frames of the first still moment after arrival whose images pass the gates, or why there was none
        within GRAB_TRIES moments or POSE_TIMEOUT_S (with the last head frame seen)."""
        arrived = time.monotonic()
        deadline = arrived + POSE_TIMEOUT_S
        tries, last = 0, None
        while True:
            reason = self.window.why_not_still(time.monotonic())
            if reason is None:
                before = self.read()
                frames_a = {name: camera.grab() for name, camera in self.cameras.items()}
                frames_b = {name: camera.grab() for name, camera in self.cameras.items()}
                stamp_ns = time.time_ns()
                after = self.read()
                moved = np.abs(after.ticks - before.ticks)
                k = int(np.argmax(moved))
                reason = (f"joints moved during the frames: {self.bus.joints[k]} by {int(moved[k])} ticks"
                          if moved[k] > self.gates.tolerance_ticks else None)  # fmt: skip
                if reason is None:
                    tries += 1
                    last = next(iter(frames_b.values()))
                    reason, tags = self._check(frames_a, frames_b)
                    if reason is None:
                        self.hold_s.append(time.monotonic() - arrived)
                        return Grabbed(pose, stamp_ns, after, frames_b, tags)
                    if tries >= GRAB_TRIES or reason == "no tag in view":
                        return reason, last
            if time.monotonic() > deadline:
                return reason, last
            time.sleep(POLL_S)
            self.read()

    # --- images ---------------------------------------------------------------------------------------------
    def _detect(self, image: np.ndarray) -> dict[int, np.ndarray]:
        corners: dict[int, np.ndarray] = {}
        for family in self.families:
            corners.update(detect_tags(image, family, self.tag_ids))
        return corners

    def _check(self, frames_a: dict[str, np.ndarray], frames_b: dict[str, np.ndarray]) -> tuple[str | None, list[int]]:
        """(why the frames of one still moment fail the gates or None, the tags seen in the second frames)."""
        seen: set[int] = set()
        for name, frame in frames_b.items():
            if self.field:
                reason = why_not_field_view(frame, self.gates)[0]
                if reason:
                    return (f"{name}: {reason}" if len(frames_b) > 1 else reason), []
                continue
            corners_b = self._detect(frame)
            reason, _ = why_not_sharp(frame, self._detect(frames_a[name]), corners_b, self.gates)
            if reason:
                return (f"{name}: {reason}" if len(frames_b) > 1 else reason), []
            seen |= set(corners_b)
        return None, sorted(seen)

    def _write(self, grabbed: Grabbed) -> Taken:
        """Write a grabbed pose's sample (its frames passed the gates)."""
        if self.writer is None:
            raise RuntimeError("PoseDriver.drive needs a writer")
        state = grabbed.state
        self.writer.add_sample(grabbed.stamp_ns, self.bus.joints, state.positions, state.velocities, grabbed.frames)
        return Taken(grabbed.pose.name, grabbed.tags)

    def move_only(self, goals: dict[str, float], targets: dict[str, float]) -> None:
        """Move `targets` (joint -> rad, a pose checked like the others) without a sample; WolfcalError when they
        do not arrive."""
        goals.update(targets)
        self.bus.set_goal_positions(goals)
        reason = self._arrive({j: goals[j] for j in targets})
        if reason is not None:
            raise WolfcalError(f"the legs did not reach the standing pose: {reason}")

    # --- the poses ------------------------------------------------------------------------------------------
    def seconds_left(self, goals: dict[str, float], poses: list[Pose]) -> float:
        """Estimated time [s] to take `poses` from `goals`: each move's profile plus the mean hold so far."""
        hold = float(np.mean(self.hold_s)) if self.hold_s else self.gates.settle_s + 0.2
        total, at = 0.0, dict(goals)
        for pose in poses:
            distance = max((abs(q - at.get(j, q)) for j, q in pose.joints.items()), default=0.0)
            total += move_time(distance, self.velocity, self.acceleration) + hold
            at.update(pose.joints)
        return total

    def drive(self, goals: dict[str, float], poses: list[Pose], label: str,
              taken: Callable[[Taken], None], check_first: bool = False) -> None:  # fmt: skip
        """Take `poses` in order from `goals` (updated in place); `taken` hears of each pose's outcome (a sample
        written, or the reason; a failed pose is tried once more at the end). With `check_first`, NO_TAG_POSES
        poses in a row at the start that show no tag stop the phase (VenueCameraError)."""
        queue = list(poses)
        retried: set[str] = set()
        pending: Grabbed | None = None
        no_tag: list[np.ndarray] = []
        written = number = 0
        while queue or pending is not None:
            pose = queue.pop(0) if queue else None
            if pose is not None:
                number += 1
                goals.update(pose.joints)
                self.bus.set_goal_positions(goals)  # moving from here on; the last pose's sample is written now
            if pending is not None:
                taken(self._write(pending))
                written += 1
                pending = None
            if pose is None:
                break
            self.say(f"{label} {number} of {len(poses) + len(retried)}: {pose.name}, about "
                     f"{self.seconds_left(goals, queue):.0f} s left")  # fmt: skip
            reason = self._arrive({j: goals[j] for j in pose.joints})
            grabbed = self._grab_when_still(pose) if reason is None else (reason, None)
            if isinstance(grabbed, Grabbed):
                pending = grabbed
                continue
            reason, frame = grabbed
            if reason == "no tag in view" and check_first and not written and frame is not None:
                no_tag.append(frame)
                if len(no_tag) >= NO_TAG_POSES:
                    raise VenueCameraError(what_the_camera_sees(no_tag, self.tag_ids))
            if pose.name not in retried:
                retried.add(pose.name)
                queue.append(pose)
                reason += " (tried again at the end)"
            taken(Taken(pose.name, reason=reason))
