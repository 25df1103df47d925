"""Capture files: real MCAP files written, read back, torn by SIGKILL, recovered; plain ROS 2 recordings."""

from __future__ import annotations

import os
import shutil
import signal
import struct
import subprocess
import sys
import textwrap
import zlib
from pathlib import Path

import cv2
import numpy as np
import pytest
from mcap.reader import make_reader
from mcap_ros2.decoder import DecoderFactory
from mcap_ros2.writer import Writer as Ros2Writer
from typer.testing import CliRunner

from wolfcal.camera.camera_info import load_camera_info
from wolfcal.camera.model import CameraModel
from wolfcal.cli import app
from wolfcal.config import RobotConfig, load_robot_config
from wolfcal.errors import WolfcalError
from wolfcal.io.images import image_size
from wolfcal.io.msgdefs import CAMERA_INFO, COMPRESSED_IMAGE, JOINT_STATE, MSGDEFS, stamp_dict
from wolfcal.io.reader import read_capture, read_captures
from wolfcal.io.recording import ENCODER_TICK, JointStates, Paired, pair_frame
from wolfcal.io.recover import recover_capture
from wolfcal.io.standing_writer import StandingWriter
from wolfcal.io.writer import CaptureWriter, camera_info_message
from wolfcal.observations import HEAD_CAMERA

ROOT = Path(__file__).resolve().parents[2]
CONFIG = ROOT / "configs" / "wolfgang" / "robot.yaml"
T0 = 1_700_000_000_000_000_000  # [ns]
JOINTS = ["HeadPan", "HeadTilt", "RKnee", "LKnee"]


@pytest.fixture(scope="module")
def config() -> RobotConfig:
    return load_robot_config(CONFIG)


@pytest.fixture(scope="module")
def camera(config) -> CameraModel:
    """Full resolution 2048x1536."""
    return load_camera_info(config.camera.intrinsics)


def sample_data(i: int, shape=(384, 512)) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Deterministic positions, velocities and noisy image of sample i."""
    rng = np.random.default_rng(i)
    image = rng.integers(0, 256, shape, np.uint8)
    return rng.uniform(-1, 1, len(JOINTS)), rng.normal(0, 0.01, len(JOINTS)), image


def write_capture(path: Path, config: RobotConfig, camera: CameraModel, n: int, binning=(4, 4)) -> None:
    with CaptureWriter(path, config, {HEAD_CAMERA: (camera, binning)}) as writer:
        for i in range(n):
            q, v, image = sample_data(i, (camera.height // binning[1], camera.width // binning[0]))
            writer.add_sample(T0 + i * 1_000_000_000, JOINTS, q, v, {HEAD_CAMERA: image})


def assert_same_camera(a: CameraModel, b: CameraModel) -> None:
    assert (a.width, a.height, a.distortion_model) == (b.width, b.height, b.distortion_model)
    np.testing.assert_allclose(a.K, b.K, rtol=0, atol=1e-9)
    np.testing.assert_allclose(a.D, b.D, rtol=0, atol=1e-12)


# --- own capture files --------------------------------------------------------------------------------------


def test_round_trip_keeps_joints_images_camera_and_attachments(tmp_path, config, camera):
    path = tmp_path / "capture.mcap"
    write_capture(path, config, camera, 5)
    assert path.is_file() and not (tmp_path / "capture.mcap.partial").exists()
    capture = read_capture(path, config)
    assert len(capture.samples) == 5 and capture.skipped == []
    binned = camera.scaled(0.25, 0.25, 512, 384)
    for i, sample in enumerate(capture.samples):
        q, v, image = sample_data(i)
        assert sample.stamp_ns == T0 + i * 1_000_000_000
        assert sample.joint_names == JOINTS
        assert np.array_equal(sample.positions, q) and np.array_equal(sample.velocities, v)
        assert sample.images[HEAD_CAMERA].format == "png" and np.array_equal(sample.images[HEAD_CAMERA].decode(), image)
        assert_same_camera(sample.images[HEAD_CAMERA].camera, binned)
        assert sample.source == str(path)
    assert capture.urdf_text == config.urdf.read_text()
    assert capture.robot_config_text == config.path.read_text()


def test_colour_jpeg_and_no_velocities(tmp_path, config, camera):
    path = tmp_path / "colour.mcap"
    image = np.random.default_rng(0).integers(0, 256, (96, 128, 3), np.uint8)
    with CaptureWriter(path, config, {HEAD_CAMERA: (camera, (16, 16))}, image_format="jpeg") as writer:
        writer.add_sample(T0, JOINTS, np.zeros(4), None, {HEAD_CAMERA: image})
    (sample,) = read_capture(path, config).samples
    assert sample.images[HEAD_CAMERA].format == "jpeg" and sample.velocities is None
    assert sample.images[HEAD_CAMERA].decode().shape == (96, 128, 3)
    assert image_size(sample.images[HEAD_CAMERA].encoded()) == (128, 96)


def test_file_is_a_ros2_mcap_with_statistics_schemas_and_attachments(tmp_path, config, camera):
    path = tmp_path / "capture.mcap"
    write_capture(path, config, camera, 3)
    with path.open("rb") as handle:
        reader = make_reader(handle, decoder_factories=[DecoderFactory()])
        assert reader.get_header().profile == "ros2"
        summary = reader.get_summary()
        assert summary.statistics is not None and summary.statistics.message_count == 9
        topics = {}
        for channel in summary.channels.values():
            schema = summary.schemas[channel.schema_id]
            assert schema.encoding == "ros2msg" and channel.message_encoding == "cdr"
            topics[channel.topic] = schema.name
        assert topics == {
            config.joint_states_topic: JOINT_STATE,
            config.camera.topic: COMPRESSED_IMAGE,
            config.camera.info_topic: CAMERA_INFO,
        }
        assert {a.name for a in reader.iter_attachments()} == {"robot.urdf", "robot.yaml"}
        by_stamp: dict[int, dict[str, object]] = {}
        for _, channel, _, message in reader.iter_decoded_messages():
            stamp = message.header.stamp.sec * 1_000_000_000 + message.header.stamp.nanosec
            by_stamp.setdefault(stamp, {})[channel.topic] = message
    assert len(by_stamp) == 3 and all(len(messages) == 3 for messages in by_stamp.values())
    info = by_stamp[T0][config.camera.info_topic]
    assert (info.width, info.height, info.binning_x, info.binning_y) == (2048, 1536, 4, 4)
    assert np.allclose(info.k, camera.K.ravel())
    assert by_stamp[T0][config.camera.topic].format == "mono8; png compressed mono8"


def _png_layout(data: bytes) -> tuple[tuple[int, ...], list[bytes]]:
    """(IHDR fields: width, height, bit depth, colour type, compression, filter, interlace), the IDAT chunks' data."""
    assert data[:8] == b"\x89PNG\r\n\x1a\n"
    pos, header, idat = 8, (), []
    while pos < len(data):
        (length,) = struct.unpack(">I", data[pos : pos + 4])
        kind, payload = data[pos + 4 : pos + 8], data[pos + 8 : pos + 8 + length]
        header = struct.unpack(">IIBBBBB", payload) if kind == b"IHDR" else header
        idat += [payload] if kind == b"IDAT" else []
        pos += 12 + length
    return header, idat


@pytest.mark.parametrize("colour", [False, True])
def test_png_images_are_stored_unfiltered_and_decode_by_the_png_spec(tmp_path, config, camera, colour):
    """wolfcal's own captures store pngs uncompressed and unfiltered (fast to decode), still standard pngs: decoded
    here by the png specification alone (chunks, zlib, filter bytes), the pixels are the image's. A smooth image,
    which deflate would make ~100x smaller, is stored at its raw size."""
    height, width = 96, 128
    image = np.add.outer(np.arange(height), np.arange(width)).astype(np.uint8)
    if colour:
        image = np.stack([image, image[::-1], 255 - image], axis=2)
    path = tmp_path / "capture.mcap"
    with CaptureWriter(path, config, {HEAD_CAMERA: (camera, (16, 16))}) as writer:
        writer.add_sample(T0, JOINTS, np.zeros(4), None, {HEAD_CAMERA: image})
    with path.open("rb") as handle:
        reader = make_reader(handle, decoder_factories=[DecoderFactory()])
        (data,) = [m.data for _, _, _, m in reader.iter_decoded_messages(topics=[config.camera.topic])]
    header, chunks = _png_layout(data)
    channels = 3 if colour else 1
    assert header == (width, height, 8, 2 if colour else 0, 0, 0, 0)  # 8-bit gray / RGB, not interlaced
    idat = b"".join(chunks)
    rows = zlib.decompress(idat)
    stride = 1 + width * channels
    assert len(rows) == height * stride and len(idat) >= len(rows)  # stored, not deflated
    if hasattr(cv2, "IMWRITE_PNG_FILTER"):  # recent OpenCV (older ones let libpng filter the rows)
        assert set(rows[::stride]) == {0}  # filter type "none" on every row
        assert len(chunks) == 1  # one IDAT chunk (up to 1 MiB), few checksums for the reader's damage check
        pixels = np.frombuffer(rows, np.uint8).reshape(height, stride)[:, 1:].reshape(image.shape)
        assert np.array_equal(pixels, image[..., ::-1] if colour else image)  # png holds RGB, wolfcal's images BGR
    assert np.array_equal(read_capture(path, config).samples[0].images[HEAD_CAMERA].decode(), image)


def test_exception_inside_with_keeps_every_sample(tmp_path, config, camera):
    path = tmp_path / "capture.mcap"
    with pytest.raises(RuntimeError), CaptureWriter(path, config, {HEAD_CAMERA: (camera, (4, 4))}) as writer:
        for i in range(2):
            q, v, image = sample_data(i)
            writer.add_sample(T0 + i, JOINTS, q, v, {HEAD_CAMERA: image})
        raise RuntimeError("servo bus lost")
    assert len(read_capture(path, config).samples) == 2
    assert not (tmp_path / "capture.mcap.partial").exists()


def test_writer_refuses_wrong_image_size_and_a_leftover_partial(tmp_path, config, camera):
    path = tmp_path / "capture.mcap"
    with CaptureWriter(path, config, {HEAD_CAMERA: (camera, (4, 4))}) as writer:
        with pytest.raises(WolfcalError, match="512x384"):
            writer.add_sample(T0, JOINTS, np.zeros(4), None, {HEAD_CAMERA: np.zeros((100, 100), np.uint8)})
    assert not path.exists()  # no sample: no file, nothing replaced
    (tmp_path / "capture.mcap.partial").write_bytes(b"torn")
    with pytest.raises(WolfcalError, match="wolfcal recover"):
        CaptureWriter(path, config, {HEAD_CAMERA: (camera, (1, 1))})


def test_intrinsics_override_is_scaled_to_the_image(tmp_path, config, camera):
    path = tmp_path / "capture.mcap"
    write_capture(path, config, camera, 1)
    K = camera.K.copy()
    K[0, 0] += 10.0
    override = CameraModel(2048, 1536, K, camera.D)
    (sample,) = read_capture(path, config, intrinsics=override).samples
    assert_same_camera(sample.images[HEAD_CAMERA].camera, override.scaled(0.25, 0.25, 512, 384))
    wrong_aspect = CameraModel(1920, 1080, K, camera.D)
    with pytest.raises(WolfcalError, match="aspect ratio"):
        read_capture(path, config, intrinsics=wrong_aspect)


# --- torn files and recovery --------------------------------------------------------------------------------

WRITER_SCRIPT = textwrap.dedent(
    """
    import sys
    from pathlib import Path
    sys.path.insert(0, {tests!r})
    from test_capture_files import JOINTS, T0, sample_data
    from wolfcal.camera.camera_info import load_camera_info
    from wolfcal.config import load_robot_config
    from wolfcal.io.writer import CaptureWriter
    from wolfcal.observations import HEAD_CAMERA

    config = load_robot_config({config!r})
    camera = load_camera_info(config.camera.intrinsics)
    writer = CaptureWriter(Path({path!r}), config, {{HEAD_CAMERA: (camera, (4, 4))}})
    i = 0
    while True:
        q, v, image = sample_data(i)
        writer.add_sample(T0 + i * 1_000_000_000, JOINTS, q, v, {{HEAD_CAMERA: image}})
        print(i, flush=True)
        i += 1
    """
)


def test_sigkill_mid_capture_then_recover_rescues_every_confirmed_sample(tmp_path, config):
    path = tmp_path / "capture.mcap"
    script = WRITER_SCRIPT.format(tests=str(Path(__file__).resolve().parent), config=str(CONFIG), path=str(path))
    process = subprocess.Popen([sys.executable, "-c", script], stdout=subprocess.PIPE, text=True, cwd=ROOT)
    try:
        confirmed = [int(process.stdout.readline()) for _ in range(6)]
        os.kill(process.pid, signal.SIGKILL)
    finally:
        process.kill()
        process.wait()
        process.stdout.close()
    assert confirmed == list(range(6))
    partial = tmp_path / "capture.mcap.partial"
    assert partial.is_file() and not path.exists()
    with pytest.raises(WolfcalError, match=r"capture\.mcap\.partial: was not closed properly.*wolfcal recover"):
        read_capture(partial, config)
    with pytest.raises(WolfcalError, match="did not finish"):
        read_capture(path, config)

    rescued = tmp_path / "rescued.mcap"
    count = recover_capture(partial, rescued)
    samples = read_capture(rescued, config).samples
    assert count == len(samples) >= 6
    for i, sample in enumerate(samples[:6]):
        q, v, image = sample_data(i)
        assert sample.stamp_ns == T0 + i * 1_000_000_000
        assert np.array_equal(sample.positions, q) and np.array_equal(sample.images[HEAD_CAMERA].decode(), image)
    assert partial.is_file()  # the source is never touched


def torn_copy(tmp_path: Path, config: RobotConfig, camera: CameraModel, complete: int) -> Path:
    """A torn capture: `complete` samples, then half of the next sample's chunk."""
    path = tmp_path / "capture.mcap"
    torn = tmp_path / "torn.mcap"
    with CaptureWriter(path, config, {HEAD_CAMERA: (camera, (8, 8))}) as writer:
        for i in range(complete + 1):
            q, v, image = sample_data(i, (192, 256))
            writer.add_sample(T0 + i * 1_000_000_000, JOINTS, q, v, {HEAD_CAMERA: image})
            if i == complete - 1:
                shutil.copy(writer.partial, torn)
                size = torn.stat().st_size
        data = writer.partial.read_bytes()
    torn.write_bytes(data[: size + (len(data) - size) // 2])
    return torn


def test_a_torn_standing_capture_is_rescued_as_joint_states_and_imu_messages(tmp_path, config):
    """A standing capture has no images: the rescue counts its messages instead of saying 0 samples."""
    path = tmp_path / "standing.mcap"
    writer = StandingWriter(path, config, "/imu/data", "imu_frame")
    for i in range(10):
        writer.joint_state(T0 + i * 10_000_000, JOINTS, np.zeros(4), np.zeros(4))
        writer.imu(T0 + i * 10_000_000, np.array([0.0, 0.0, 9.81]), np.zeros(3))
    writer.flush()
    torn = tmp_path / "torn.mcap"
    shutil.copy(writer.partial, torn)  # as a killed capture leaves it: no summary, no footer
    writer.close()
    result = CliRunner().invoke(app, ["recover", str(torn)])
    assert result.exit_code == 0, result.output
    assert "rescued 10 joint state(s) and 10 IMU message(s)" in result.output


def test_recover_cli_and_default_output_name(tmp_path, config, camera):
    torn = torn_copy(tmp_path, config, camera, complete=3)
    result = CliRunner().invoke(app, ["recover", str(torn)])
    assert result.exit_code == 0, result.output
    assert "rescued 3 sample(s)" in result.output
    recovered = tmp_path / "torn.recovered.mcap"
    capture = read_capture(recovered, config)
    assert len(capture.samples) == 3 and capture.urdf_text == config.urdf.read_text()
    result = CliRunner().invoke(app, ["recover", str(torn), "--out", str(torn)])
    assert result.exit_code != 0 and "never overwrites" in result.output


def test_missing_and_non_mcap_files_name_the_file(tmp_path, config):
    missing = tmp_path / "nope.mcap"
    with pytest.raises(WolfcalError, match=r"nope\.mcap: capture file not found"):
        read_captures([missing], config)
    text = tmp_path / "notes.mcap"
    text.write_text("not a capture")
    with pytest.raises(WolfcalError, match=r"notes\.mcap: not an MCAP file"):
        read_capture(text, config)
    result = CliRunner().invoke(app, ["recover", str(missing)])
    assert result.exit_code != 0 and "nope.mcap" in result.output


# --- plain ROS 2 recordings ---------------------------------------------------------------------------------

RATE_HZ = 100
DURATION_S = 4.0
MOVES = ((1.0, 1.5), (2.5, 3.0))  # [s] motion phases; still elsewhere
DROPOUT = (3.65, 3.75)  # [s] no joint states (publisher hiccup)
IMAGE_TIMES = 0.103 + 0.2 * np.arange(20)  # [s] 5 Hz, own stamps 3 ms after a joint state


def joint_trajectory() -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Times [s], encoder-quantised positions (N, J) with 1-tick flicker when still, velocities (N, J)."""
    t = np.arange(int(DURATION_S * RATE_HZ)) / RATE_HZ
    rng = np.random.default_rng(3)
    amplitude = np.array([0.3, -0.2, 0.5, 0.4])
    q = np.zeros((len(t), len(JOINTS)))
    v = np.zeros_like(q)
    for k, (start, end) in enumerate(MOVES):
        phase = np.clip((t - start) / (end - start), 0, 1)
        scale = amplitude * (k + 1) / 2
        q += scale * (1 - np.cos(np.pi * phase))[:, None]
        moving = (t > start) & (t < end)
        v[moving] += scale * (np.pi / (end - start) * np.sin(np.pi * phase[moving]))[:, None]
    ticks = np.round(q / ENCODER_TICK) + rng.integers(0, 2, q.shape)  # encoder flicker by one tick
    return t, ticks * ENCODER_TICK, v


def expected_still_images() -> list[float]:
    near_move = [any(start - 0.25 < s < end + 0.25 for start, end in MOVES) for s in IMAGE_TIMES]
    in_dropout = [DROPOUT[0] - 0.02 < s < DROPOUT[1] + 0.02 for s in IMAGE_TIMES]
    return [s for s, m, d in zip(IMAGE_TIMES, near_move, in_dropout, strict=True) if not (m or d)]


def write_recording(
    path: Path, config: RobotConfig, joint_topic: str | None = None, camera_info: CameraModel | None = None
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """A ROS 2 recording as rosbag2 writes it: streams with their own stamps, 256x192 mono png images."""
    import cv2

    t, q, v = joint_trajectory()
    with path.open("wb") as handle:
        writer = Ros2Writer(handle)
        schemas = {name: writer.register_msgdef(name, text) for name, text in MSGDEFS.items()}
        events = [(s, "joints", i) for i, s in enumerate(t) if not DROPOUT[0] < s < DROPOUT[1]]
        events += [(s, "image", i) for i, s in enumerate(IMAGE_TIMES)]
        for s, kind, i in sorted(events):
            stamp = T0 + int(round(s * 1e9))
            header = {"stamp": stamp_dict(stamp), "frame_id": ""}
            if kind == "joints":
                message = {
                    "header": header,
                    "name": JOINTS,
                    "position": q[i].tolist(),
                    "velocity": v[i].tolist(),
                    "effort": [],
                }
                writer.write_message(
                    joint_topic or config.joint_states_topic,
                    schemas[JOINT_STATE],
                    message,
                    log_time=stamp + 1_000_000,
                )
                continue
            image = np.random.default_rng(i).integers(0, 256, (192, 256), np.uint8)
            data = cv2.imencode(".png", image)[1].tobytes()
            writer.write_message(
                config.camera.topic,
                schemas[COMPRESSED_IMAGE],
                {"header": header, "format": "png", "data": data},
                log_time=stamp + 5_000_000,
            )
            if camera_info is not None:
                info = camera_info_message(camera_info, (0, 0), stamp, "camera_optical_frame")
                writer.write_message(config.camera.info_topic, schemas[CAMERA_INFO], info, log_time=stamp + 5_000_000)
        writer.finish()
    return t, q, v


def test_recording_keeps_only_still_frames_paired_with_the_nearest_joint_state(tmp_path, config, camera):
    path = tmp_path / "rosbag.mcap"
    info_camera = camera.scaled(0.25, 0.25, 512, 384)  # CameraInfo at 512x384, images at 256x192
    t, q, v = write_recording(path, config, camera_info=info_camera)
    capture = read_capture(path, config)
    kept = [(s.stamp_ns - T0) / 1e9 for s in capture.samples]
    expected = expected_still_images()
    np.testing.assert_allclose(kept, expected, atol=1e-9)
    assert len(capture.skipped) == len(IMAGE_TIMES) - len(expected)
    assert sum("not still" in reason for reason in capture.skipped) == 10
    assert sum("within 20 ms" in reason for reason in capture.skipped) == 1
    differs_from_neighbour = False
    for sample in capture.samples:
        nearest = int(round((sample.stamp_ns - T0) / 1e9 * RATE_HZ))
        assert np.array_equal(sample.positions, q[nearest]) and np.array_equal(sample.velocities, v[nearest])
        differs_from_neighbour |= not np.array_equal(q[nearest], q[nearest + 1])
        assert_same_camera(sample.images[HEAD_CAMERA].camera, info_camera.scaled(0.5, 0.5, 256, 192))
    assert differs_from_neighbour  # the pairing is tested, not only the phase


def test_recording_without_camera_info_uses_the_config_intrinsics(tmp_path, config, camera):
    path = tmp_path / "rosbag.mcap"
    write_recording(path, config)
    capture = read_capture(path, config)
    assert len(capture.samples) == len(expected_still_images())
    assert_same_camera(capture.samples[0].images[HEAD_CAMERA].camera, camera.scaled(0.125, 0.125, 256, 192))


def test_missing_topic_lists_present_and_expected_topics(tmp_path, config):
    path = tmp_path / "rosbag.mcap"
    write_recording(path, config, joint_topic="/robot/joint_states")
    with pytest.raises(WolfcalError) as error:
        read_capture(path, config)
    message = str(error.value)
    assert str(path) in message and "/robot/joint_states" in message and config.joint_states_topic in message
    assert str(config.path) in message


def test_recording_without_any_intrinsics_says_what_to_pass(tmp_path, config):
    text = config.path.read_text().replace("urdf: wolfgang.urdf", f"urdf: {config.urdf}")
    no_intrinsics = tmp_path / "robot.yaml"
    no_intrinsics.write_text("\n".join(line for line in text.splitlines() if "intrinsics:" not in line))
    bare = load_robot_config(no_intrinsics)
    path = tmp_path / "rosbag.mcap"
    write_recording(path, bare)
    with pytest.raises(WolfcalError, match=r"rosbag\.mcap: no CameraInfo .* --intrinsics FILE"):
        read_capture(path, bare)


def test_pairing_split_publishers_and_sparse_states_with_velocities():
    ms = 1_000_000
    legs = [(k * 20 * ms, ["RKnee"], [0.5], [0.0]) for k in range(50)]  # 50 Hz, still
    head = [(k * 20 * ms + 7 * ms, ["HeadPan"], [0.1 * (k > 30)], []) for k in range(50)]  # moves at 0.62 s
    states = JointStates.from_messages(legs + head)
    assert states.names == ["RKnee", "HeadPan"]
    paired = pair_frame(states, 300 * ms)
    assert isinstance(paired, Paired) and paired.positions.tolist() == [0.5, 0.0] and paired.velocities is None
    assert "HeadPan moved" in pair_frame(states, 500 * ms)

    sparse = [(k * 500 * ms, ["RKnee"], [0.5], [0.0 if k < 3 else 0.2]) for k in range(6)]  # 2 Hz
    sparse_states = JointStates.from_messages(sparse)
    assert isinstance(pair_frame(sparse_states, 1000 * ms + 5 * ms), Paired)
    assert "turning" in pair_frame(sparse_states, 2000 * ms)
    no_velocity = JointStates.from_messages([(t, n, q, []) for t, n, q, _ in sparse])
    assert "too few joint states" in pair_frame(no_velocity, 1000 * ms)
