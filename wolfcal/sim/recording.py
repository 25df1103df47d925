"""A simulated plain ROS 2 recording (as `ros2 bag record` writes it, not wolfcal's capture format): the robot moves
between still poses while joint states, images and camera info stream with their own stamps.

Per still pose: `move_s` of smooth motion from the previous pose, then `hold_s` still. Joint states at
`joint_rate_hz` (encoder readings: true angle minus the true offset, quantised to ticks; with `flicker` a reading
near a tick boundary flips between the two neighbouring ticks from message to message, as a servo's encoder does),
images of the head camera at `image_rate_hz` (rendered at the true angles of their own stamp, a held pose's view
once, each frame with image noise of its own), camera info at 1 Hz. Messages are written with mcap_ros2 directly.
`simulate_recording` draws a truth and still poses in which the head camera sees a tag and writes such a recording
of them.
"""

from __future__ import annotations

from dataclasses import dataclass
from pathlib import Path

import cv2
import numpy as np
from mcap_ros2.writer import Writer as Ros2Writer

from wolfcal.camera.camera_info import load_camera_info
from wolfcal.camera.model import CameraModel
from wolfcal.encoders import RAD_PER_TICK
from wolfcal.io.msgdefs import CAMERA_INFO, COMPRESSED_IMAGE, JOINT_STATE, MSGDEFS, stamp_dict
from wolfcal.io.writer import camera_info_message
from wolfcal.observations import HEAD_CAMERA
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import Robot
from wolfcal.sim.poses import random_visible_poses
from wolfcal.sim.scene import SimScene
from wolfcal.sim.simulate import offset_joints
from wolfcal.sim.truth import TruthSpec, random_truth

START_NS = 1_700_000_000_000_000_000


@dataclass(frozen=True)
class RecordingOptions:
    move_s: float = 1.0  # motion from one still pose to the next [s]
    hold_s: float = 2.5  # still time per pose [s]
    joint_rate_hz: float = 100.0
    image_rate_hz: float = 10.0
    noise_sigma: float = 2.0  # image noise [gray levels]
    flicker: float = 0.0  # std of the encoder's reading noise [ticks]; readings stay within one tick of each other
    seed: int = 0


def readings(q_true: np.ndarray, offsets: np.ndarray, flicker: float, rng: np.random.Generator) -> np.ndarray:
    """(N, J) encoder readings [rad] of true angles (N, J): (true - offset) in ticks plus reading noise of `flicker`
    ticks, rounded, and kept to the two ticks around the true value."""
    x = (q_true - offsets) / RAD_PER_TICK
    ticks = np.round(x + rng.normal(0.0, flicker, x.shape)) if flicker > 0 else np.round(x)
    return np.clip(ticks, np.floor(x), np.floor(x) + 1) * RAD_PER_TICK


def write_recording(
    path: Path, robot: Robot, truth: Corrections, camera: CameraModel, poses: np.ndarray, options: RecordingOptions
) -> None:
    """Write the recording of true still poses (P, J) [rad] seen by the head camera `camera` (the images' size)."""
    rng = np.random.default_rng(options.seed)
    scene = SimScene(robot, truth, camera, seed=options.seed + 1, noise_sigma=0.0)
    held: list = [None, None]  # the still pose being held (its readings' bytes) and its noise-free view

    def image_at(t: float) -> np.ndarray:
        """The gray image at time t: the noise-free view at the true angles (a held pose's rendered once) plus
        image noise of its own."""
        q = q_at(t)
        if held[0] != q.tobytes():
            held[:] = [q.tobytes(), scene.render_true(q).astype(np.float32)]
        noisy = held[1] + options.noise_sigma * rng.standard_normal(held[1].shape, dtype=np.float32)
        return np.clip(np.rint(noisy), 0, 255).astype(np.uint8)

    offsets = truth.offset_vector(robot.joint_names)
    period = options.move_s + options.hold_s

    def q_at(t: float) -> np.ndarray:
        k = min(int(t // period), len(poses) - 1)
        phase = min((t - k * period) / options.move_s, 1.0)
        previous = poses[max(k - 1, 0)]
        return previous + (poses[k] - previous) * 0.5 * (1.0 - np.cos(np.pi * phase))

    total = period * len(poses)
    events = [(t, "joints") for t in np.arange(0.0, total, 1.0 / options.joint_rate_hz)]
    events += [(t + 0.003, "image") for t in np.arange(0.0, total, 1.0 / options.image_rate_hz)]
    events += [(t + 0.001, "info") for t in np.arange(0.0, total, 1.0)]
    config = robot.config
    head = config.head_camera("the simulated recording is of the head camera")
    with path.open("wb") as handle:
        writer = Ros2Writer(handle)
        schemas = {name: writer.register_msgdef(name, text) for name, text in MSGDEFS.items()}
        for t, kind in sorted(events):
            stamp = START_NS + int(round(t * 1e9))
            header = {"stamp": stamp_dict(stamp), "frame_id": head.frame}
            if kind == "joints":
                q = readings(q_at(t)[None], offsets, options.flicker, rng)[0]
                message = {"header": header, "name": robot.joint_names, "position": q.tolist(), "velocity": [],
                           "effort": []}  # fmt: skip
                writer.write_message(config.joint_states_topic, schemas[JOINT_STATE], message, log_time=stamp)
            elif kind == "image":
                png = cv2.imencode(".png", image_at(t))[1].tobytes()
                message = {"header": header, "format": "png", "data": png}
                writer.write_message(head.topic, schemas[COMPRESSED_IMAGE], message, log_time=stamp)
            else:
                message = camera_info_message(camera, (0, 0), stamp, head.frame)
                writer.write_message(head.info_topic, schemas[CAMERA_INFO], message, log_time=stamp)
        writer.finish()


def simulate_recording(
    robot: Robot,
    path: Path,
    poses: int,
    offsets: str = "none",
    binning: int = 4,
    options: RecordingOptions = RecordingOptions(),
) -> Corrections:
    """Write a recording of `poses` random still poses of the head camera (its config intrinsics, images binned by
    `binning`) with true encoder offsets on the joints of `offsets` (see `offset_joints`); returns the truth.
    Everything random follows `options.seed`."""
    rng = np.random.default_rng(options.seed)
    camera = load_camera_info(robot.config.intrinsics_file(HEAD_CAMERA, "simulating")).binned(binning, HEAD_CAMERA)
    truth = random_truth(robot, TruthSpec(offset_joints=offset_joints(robot, offsets)), rng)
    q_still = random_visible_poses(robot, camera, truth, poses, rng)[0]
    write_recording(path, robot, truth, camera, q_still, options)
    return truth
