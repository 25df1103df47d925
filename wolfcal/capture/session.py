"""One capture session over an open bus, cameras and writer: reads the bus, tracks stillness and takes a sample
from a still moment; the scripted and manual modes decide when to try.

A sample is one still moment: bus reading, a frame of every camera, another frame of every camera, bus reading, all
within a tick of each other; each camera's image is its second frame, and the sample is written only when every
camera's frames pass the gates (tags in view, sharp, corners still; field views: the field's lines in view, sharp).
Joint angles in rad, the robot's joint convention; times on the monotonic clock [s].
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wolfcal.capture.gating import StillnessWindow, why_not_field_view, why_not_sharp
from wolfcal.capture.options import CaptureOptions
from wolfcal.capture.view import Coverage, LiveView, Status
from wolfcal.hardware.bus import JointState
from wolfcal.hardware.buses import ServoBuses
from wolfcal.hardware.camera import CameraSource
from wolfcal.io.writer import CaptureWriter
from wolfcal.observations import HEAD_CAMERA
from wolfcal.robot.robot import Robot
from wolfcal.vision.tags import detect_tags

POLL_S = 0.005  # pause between bus reads while waiting


@dataclass
class CaptureSummary:
    path: Path | None
    samples: int
    rest_to_sample_s: list[float] = field(default_factory=list)  # from the robot at rest to the sample on disk
    skipped: list[str] = field(default_factory=list)


class CaptureSession:
    """The bus, camera, writer and live view of one capture, and what it has taken so far (`summary`)."""

    def __init__(
        self,
        robot: Robot,
        bus: ServoBuses,
        cameras: dict[str, CameraSource],
        writer: CaptureWriter,
        options: CaptureOptions,
        view: LiveView,
        coverage: Coverage,
        status: Status,
    ):
        self.bus, self.cameras, self.writer = bus, cameras, writer
        self.options, self.view, self.coverage, self.status = options, view, coverage, status
        self.gates = options.gates
        self.window = StillnessWindow(bus.joints, self.gates)
        self.field = options.field_views  # field views: the gates look for the field's lines, not for tags
        tags = list(robot.config.tags) + (list(robot.config.floor_config().tags) if options.floor else [])
        self.tag_ids = {t.id for t in tags}  # floor capture: the floor tags too
        self.families = sorted({t.family for t in tags})
        self.summary = CaptureSummary(None, 0)
        self.rest_since: float | None = None  # when every joint last became still

    def read(self) -> JointState:
        """Read the bus into the stillness window (hardware errors checked now and then: `read_state_polled`)."""
        state = self.bus.read_state_polled()
        self.window.add(time.monotonic(), state)
        if np.any(self.window.spread() > self.gates.tolerance_ticks):
            self.rest_since = None
        elif self.rest_since is None:
            self.rest_since = self.window.readings[0][0]
        return state

    def detect(self, image: np.ndarray) -> dict[int, np.ndarray]:
        """Corners [px] of the robot's tags in view, per tag id."""
        corners: dict[int, np.ndarray] = {}
        for family in self.families:
            corners.update(detect_tags(image, family, self.tag_ids))
        return corners

    def done(self) -> bool:
        """True once the requested number of samples is taken."""
        return self.options.samples is not None and self.summary.samples >= self.options.samples

    def try_sample(self) -> str | None:
        """Take a sample if this moment is still and sharp; returns None on success, else why not."""
        reason = self.window.why_not_still(time.monotonic())
        if reason:
            self.status.still = "no"
            return reason
        before = self.read()
        frames_a = {name: camera.grab() for name, camera in self.cameras.items()}
        frames_b = {name: camera.grab() for name, camera in self.cameras.items()}
        stamp_ns = time.time_ns()
        after = self.read()
        if self.field:
            return self._try_field_sample(before, after, frames_b, stamp_ns)
        corners_a = {name: self.detect(frame) for name, frame in frames_a.items()}
        corners_b = {name: self.detect(frame) for name, frame in frames_b.items()}
        self.status.tags = sorted({t for corners in corners_b.values() for t in corners})
        reason = self._moved(before, after)
        if reason:
            self.status.still = "no"
            return reason
        self.status.still = "yes"
        values = []
        for name, frame in frames_b.items():
            reason, value = why_not_sharp(frame, corners_a[name], corners_b[name], self.gates)
            values.append(value)
            if reason:
                self.status.sharpness = min(values)
                return f"{name}: {reason}" if len(frames_b) > 1 else reason
        self.status.sharpness = min(values)
        self.bus.check_hardware()
        self.writer.add_sample(stamp_ns, self.bus.joints, after.positions, after.velocities, frames_b)
        self._record(after, {name: sorted(corners) for name, corners in corners_b.items()})
        return None

    def _try_field_sample(self, before: JointState, after: JointState, frames: dict[str, np.ndarray],
                          stamp_ns: int) -> str | None:  # fmt: skip
        """The field views' end of `try_sample` (the head camera alone): still between the two bus readings, the
        field's lines in the frame (`why_not_field_view`), then written; None on success, else why not."""
        reason = self._moved(before, after)
        if reason:
            self.status.still = "no"
            return reason
        self.status.still = "yes"
        reason, self.status.sharpness, points = why_not_field_view(frames[HEAD_CAMERA], self.gates)
        self.status.line_points = points
        if reason:
            return reason
        self.bus.check_hardware()
        self.writer.add_sample(stamp_ns, self.bus.joints, after.positions, after.velocities, frames)
        self._record(after, {}, f"{points} field-line points")
        return None

    def _moved(self, before: JointState, after: JointState) -> str | None:
        """Why the robot was not still between two bus readings around the frames (stillness gate again), or None."""
        reason = self.window.why_not_still(time.monotonic())
        moved = np.abs(after.ticks - before.ticks)
        if reason is None and moved.max() > self.gates.tolerance_ticks:
            k = int(np.argmax(moved))
            reason = f"joints moved during the frames: {self.bus.joints[k]} by {int(moved[k])} ticks"
        return reason

    def _record(self, state: JointState, tags: dict[str, list[int]], seen_text: str = "") -> None:
        """Count a sample written to the file, in the summary and the live view; `seen_text` says what the images
        show when it is not tags."""
        self.summary.samples += 1
        if self.rest_since is not None:
            self.summary.rest_to_sample_s.append(time.monotonic() - self.rest_since)
        self.status.taken = self.summary.samples
        self.coverage.add(self.bus.joints, state.positions)
        target = f"/{self.options.samples}" if self.options.samples else ""
        pose = f" ({self.status.pose})" if self.status.pose else ""
        seen = seen_text or "tags " + "; ".join(
            ", ".join(map(str, ids)) + (f" ({name})" if len(tags) > 1 else "") for name, ids in tags.items()
        )
        self.view.event(f"sample {self.summary.samples}{target}{pose}: {seen}, sharpness {self.status.sharpness:.0f}")
        self.view.refresh()
