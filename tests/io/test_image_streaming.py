"""Streaming reads: a read capture holds image locations, not bytes; the bytes are read back in any order, in one
pass per file; detection streams them; a file changed after reading is a clear error."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from mcap_ros2.writer import Writer as Ros2Writer

from wolfcal.config import load_robot_config
from wolfcal.errors import WolfcalError
from wolfcal.io.msgdefs import COMPRESSED_IMAGE, JOINT_STATE, MSGDEFS, stamp_dict
from wolfcal.io.reader import read_capture
from wolfcal.io.recording import JointLog, JointStates
from wolfcal.io.samples import SampleImage, encoded_images
from wolfcal.io.stream import stream_images
from wolfcal.observations import HEAD_CAMERA

CONFIG = Path(__file__).resolve().parents[2] / "configs" / "wolfgang" / "robot.yaml"
T0 = 1_700_000_000_000_000_000  # [ns]
JOINTS = ["HeadPan", "HeadTilt"]


def frame(i: int) -> bytes:
    image = np.random.default_rng(i).integers(0, 256, (48, 64), np.uint8)
    return cv2.imencode(".png", image)[1].tobytes()


def write_still_recording(path: Path, n_images: int, reverse_stamps: bool = False) -> list[bytes]:
    """A recording of a robot holding still: joint states at 100 Hz, an image every 0.5 s; returns the images in
    stamp order. `reverse_stamps`: images logged in the opposite order of their header stamps."""
    config = load_robot_config(CONFIG)
    images = [frame(i) for i in range(n_images)]
    with path.open("wb") as handle:
        writer = Ros2Writer(handle, chunk_size=4096)  # many chunks: the index is used
        schemas = {name: writer.register_msgdef(name, text) for name, text in MSGDEFS.items()}
        duration = 0.5 * (n_images + 1)
        events = [(k / 100, "joints", k) for k in range(int(duration * 100))]
        events += [(0.5 * (i + 1) + 0.003, "image", i) for i in range(n_images)]
        for t, kind, i in sorted(events):
            log_time = T0 + int(round(t * 1e9))
            if kind == "joints":
                message = {"header": {"stamp": stamp_dict(log_time), "frame_id": ""}, "name": JOINTS,
                           "position": [0.1, -0.2], "velocity": [0.0, 0.0], "effort": []}  # fmt: skip
                writer.write_message(config.joint_states_topic, schemas[JOINT_STATE], message, log_time=log_time)
                continue
            k = n_images - 1 - i if reverse_stamps else i
            stamp = T0 + int(round((0.5 * (k + 1) + 0.003) * 1e9))
            message = {"header": {"stamp": stamp_dict(stamp), "frame_id": ""}, "format": "png", "data": images[k]}
            writer.write_message(config.camera.topic, schemas[COMPRESSED_IMAGE], message, log_time=log_time)
        writer.finish()
    return images


def test_read_capture_keeps_locations_not_bytes_and_reads_them_back(tmp_path):
    path = tmp_path / "rec.mcap"
    images = write_still_recording(path, 6)
    capture = read_capture(path, load_robot_config(CONFIG))
    kept = [s.images[HEAD_CAMERA] for s in capture.samples]
    assert len(kept) == 6 and all(image.data == b"" and image.location.path == path for image in kept)
    assert list(stream_images(i.location for i in kept)) == images
    assert list(stream_images(i.location for i in kept[::-1])) == images[::-1]  # waits for its turn
    assert list(stream_images(i.location for i in [kept[2], kept[2], kept[0]])) == [images[2], images[2], images[0]]
    assert kept[4].encoded() == images[4] and kept[4].decode().shape == (48, 64)


def test_images_read_back_in_windows_of_a_few(tmp_path, monkeypatch):
    """Locations are looked up WINDOW at a time (each window one pass over its span of the file): with windows of 2,
    every order (the file's, reversed, repeats, a window spanning the file) gives the images of one window."""
    from wolfcal.io import stream

    path = tmp_path / "rec.mcap"
    images = write_still_recording(path, 7)
    kept = [s.images[HEAD_CAMERA].location for s in read_capture(path, load_robot_config(CONFIG)).samples]
    monkeypatch.setattr(stream, "WINDOW", 2)
    for order in ([0, 1, 2, 3, 4, 5, 6], [6, 5, 4, 3, 2, 1, 0], [0, 6, 6, 3, 1], [2, 2, 2]):
        assert list(stream_images(kept[i] for i in order)) == [images[i] for i in order]


def test_header_stamps_against_file_order_and_images_made_in_memory(tmp_path):
    path = tmp_path / "rec.mcap"
    images = write_still_recording(path, 5, reverse_stamps=True)
    capture = read_capture(path, load_robot_config(CONFIG))
    kept = [s.images[HEAD_CAMERA] for s in capture.samples]  # stamp order: the file's reverse
    memory = SampleImage(frame(99), "png", kept[0].camera)
    assert list(encoded_images([kept[0], memory, *kept[1:]])) == [images[0], frame(99), *images[1:]]


def test_changed_file_is_a_clear_error(tmp_path):
    path = tmp_path / "rec.mcap"
    write_still_recording(path, 4)
    kept = [s.images[HEAD_CAMERA] for s in read_capture(path, load_robot_config(CONFIG)).samples]
    write_still_recording(path, 2)  # re-recorded under the same name
    with pytest.raises(WolfcalError, match=r"rec.mcap: the image on .* no longer in the file"):
        list(stream_images(i.location for i in kept))
    path.unlink()
    with pytest.raises(WolfcalError, match=r"rec.mcap: cannot read its images again"):
        kept[0].encoded()


def test_joint_log_matches_per_message_reading():
    log = JointLog()
    log.add(30, ["a", "b"], [0.3, 3.0], [])
    log.add(10, ["a", "b"], [0.1, 1.0], [0.5, 0.6])
    log.add(20, ["c", "a"], [2.0], [])  # positions shorter than names: the rest is absent
    states = JointStates.from_log(log)
    assert log.count == 3 and states.names == ["a", "b", "c"]
    np.testing.assert_array_equal(states.series["a"].times, [10, 30])
    np.testing.assert_array_equal(states.series["a"].positions, [0.1, 0.3])
    np.testing.assert_array_equal(states.series["a"].velocities, [0.5, np.nan])
    np.testing.assert_array_equal(states.series["c"].positions, [2.0])
    masked = JointStates.from_log(log, [np.array([False, True]), np.array([False])])
    assert masked.names == ["a", "b"] and masked.series["b"].positions.tolist() == [1.0]


def _objects_reachable(root: object) -> int:
    """Distinct objects reachable from `root` (through gc's referents), modules and classes not followed."""
    import gc
    import types

    seen: set[int] = set()
    stack = [root]
    while stack:
        obj = stack.pop()
        if id(obj) in seen or isinstance(obj, (type, types.ModuleType)):
            continue
        seen.add(id(obj))
        stack.extend(gc.get_referents(obj))
    return len(seen)


def test_samples_of_a_recording_hold_a_fixed_number_of_objects_each(tmp_path):
    """A long recording's samples: per sample the Sample, its image dict, image and location, its two rows of
    readings and its two stamps (header, log time); the joint names, source strings, file path and camera model
    are one object each for all samples (thousands of samples in a ten-minute recording)."""
    config = load_robot_config(CONFIG)
    counts = {}
    for n in (10, 30):
        write_still_recording(tmp_path / f"rec{n}.mcap", n)
        samples = read_capture(tmp_path / f"rec{n}.mcap", config).samples
        assert len(samples) == n
        counts[n] = _objects_reachable(samples)
    per_sample = (counts[30] - counts[10]) / 20
    assert per_sample <= 8, per_sample
    first, last = samples[0], samples[-1]
    assert first.joint_names is last.joint_names and first.source is last.source
    assert first.images[HEAD_CAMERA].source is last.images[HEAD_CAMERA].source
