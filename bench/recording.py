"""A long plain ROS 2 recording for the memory part: the head camera at CAMERA_HZ, joint states at JOINT_HZ.

The robot holds a pose for HOLD_S, then moves to the next in MOVE_S, cycling through POSES poses; about two
thirds of the frames are still (kept by the reader). The poses are simulated without encoder offsets (what
`--free camera` fits). Each pose is rendered once (`simulate_capture`, true geometry); each still frame is
that render plus image noise of its own (a crop of one large noise field at an offset not used before),
encoded as jpeg (quality 95) as a camera gives; frames in motion (never kept) reuse the render's jpeg. No
CameraInfo: the config's intrinsics.
"""

from __future__ import annotations

from pathlib import Path

import numpy as np
from common import CONFIG

POSES = 12
CAMERA_HZ, JOINT_HZ = 10, 100
HOLD_S, MOVE_S = 2.0, 1.0
T0 = 1_700_000_000_000_000_000  # [ns]
NOISE_SIGMA = 2.0  # [gray levels] per-frame image noise of the still frames
NOISE_MARGIN = 96  # [px] the noise field's margin: 9216 offsets of the per-frame crops


def _jpeg(image: np.ndarray) -> bytes:
    import cv2

    return cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, 95])[1].tobytes()


def _poses(folder: Path, binning: int) -> tuple[list[str], np.ndarray, list[np.ndarray]]:
    """Joint names, measured readings (POSES, J) [rad] and gray images of POSES simulated still poses."""
    from wolfcal.config import load_robot_config
    from wolfcal.io.reader import read_capture
    from wolfcal.observations import HEAD_CAMERA
    from wolfcal.sim.simulate import SimOptions, simulate_capture

    path = folder / f"poses_b{binning}.mcap"
    if not path.exists():
        simulate_capture(CONFIG, path, SimOptions(samples=POSES, seed=5, binning=binning), say=lambda _: None)
    capture = read_capture(path, load_robot_config(CONFIG))
    q = np.stack([s.positions for s in capture.samples])
    return capture.samples[0].joint_names, q, [s.images[HEAD_CAMERA].decode() for s in capture.samples]


def _joints_at(t: float, q: np.ndarray) -> tuple[np.ndarray, np.ndarray, int]:
    """Positions [rad], velocities [rad/s] at time t [s] and the pose whose image the camera sees."""
    k, phase = divmod(t, HOLD_S + MOVE_S)
    a, b = int(k) % len(q), (int(k) + 1) % len(q)
    if phase < HOLD_S:
        return q[a], np.zeros(q.shape[1]), a
    s = (phase - HOLD_S) / MOVE_S
    blend = (1 - np.cos(np.pi * s)) / 2
    velocity = (q[b] - q[a]) * np.pi / (2 * MOVE_S) * np.sin(np.pi * s)
    return q[a] + blend * (q[b] - q[a]), velocity, a


def recording(folder: Path, frames: int, binning: int) -> Path:
    """The recording of `frames` camera frames at 2048x1536 / `binning`, written once into `folder`."""
    from mcap_ros2.writer import Writer

    from wolfcal.config import load_robot_config
    from wolfcal.io.msgdefs import COMPRESSED_IMAGE, JOINT_STATE, MSGDEFS, stamp_dict

    path = folder / f"recording_{frames}_b{binning}.mcap"
    if path.exists():
        return path
    folder.mkdir(parents=True, exist_ok=True)
    names, q, images = _poses(folder, binning)
    renders = [_jpeg(image) for image in images]
    rng = np.random.default_rng(0)
    field = rng.normal(0.0, NOISE_SIGMA, (images[0].shape[0] + NOISE_MARGIN, images[0].shape[1] + NOISE_MARGIN))
    field = field.astype(np.float32)
    offsets = iter(rng.permutation(NOISE_MARGIN * NOISE_MARGIN).tolist())
    config = load_robot_config(CONFIG)
    partial = path.with_suffix(".partial")
    with partial.open("wb") as handle:
        writer = Writer(handle, compression=None)
        schemas = {name: writer.register_msgdef(name, text) for name, text in MSGDEFS.items()}
        events = [(i / JOINT_HZ, 0) for i in range(int(frames / CAMERA_HZ * JOINT_HZ))]
        events += [(0.003 + i / CAMERA_HZ, 1) for i in range(frames)]
        for t, kind in sorted(events):
            stamp = T0 + int(round(t * 1e9))
            header = {"stamp": stamp_dict(stamp), "frame_id": ""}
            position, velocity, pose = _joints_at(t, q)
            if kind == 0:
                message = {
                    "header": header,
                    "name": names,
                    "position": position.tolist(),
                    "velocity": velocity.tolist(),
                    "effort": [],
                }
                writer.write_message(config.joint_states_topic, schemas[JOINT_STATE], message, log_time=stamp)
                continue
            data = renders[pose]
            if not np.any(velocity):
                dy, dx = divmod(next(offsets) % (NOISE_MARGIN * NOISE_MARGIN), NOISE_MARGIN)
                noise = field[dy : dy + images[pose].shape[0], dx : dx + images[pose].shape[1]]
                data = _jpeg(np.clip(images[pose] + noise, 0, 255).astype(np.uint8))
            message = {"header": header, "format": "jpeg", "data": data}
            writer.write_message(config.camera.topic, schemas[COMPRESSED_IMAGE], message, log_time=stamp)
        writer.finish()
    partial.rename(path)
    return path
