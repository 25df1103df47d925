"""Pairing frames with joint states while a recording is read (`wolfcal.io.pairing`) gives what pairing on the whole
log gives: simulated ROS 2 recordings rewritten with messages out of order (images logged after their stamps, joint
states jittered, a late batch), a second camera, joints published in two groups; a file beyond the bound is paired on
the whole log; the window of joint states stays bounded. Frames that repeat the image before them are named."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest
from mcap.reader import make_reader
from mcap.writer import Writer as McapWriter
from mcap_ros2._dynamic import serialize_dynamic
from mcap_ros2.decoder import DecoderFactory

import wolfcal.io.reader as reader_module
from wolfcal.config import load_robot_config
from wolfcal.fit.pipeline import repeat_warnings
from wolfcal.io.cdr import camera_info_key, joint_state
from wolfcal.io.msgdefs import header_stamp_ns
from wolfcal.io.pairing import BATCH_NS, DISORDER_NS, FramePairer
from wolfcal.io.reader import read_capture
from wolfcal.io.recording import STILL_WINDOW_NS, JointStates, Paired, pair_exact, pair_frame
from wolfcal.io.samples import Capture
from wolfcal.robot.robot import load_robot
from wolfcal.sim.faulty import rewrite_capture
from wolfcal.sim.recording import RecordingOptions, simulate_recording
from wolfcal.vision.observe import detect_observations

WOLFGANG = Path(__file__).resolve().parents[2] / "configs" / "wolfgang"
MS = 1_000_000


@pytest.fixture(scope="module")
def simulated(tmp_path_factory) -> Path:
    """A simulated plain recording: 6 still poses, joint states at 100 Hz, head images at 10 Hz (log time = stamp)."""
    path = tmp_path_factory.mktemp("rec") / "sim.mcap"
    options = RecordingOptions(hold_s=1.5, move_s=0.8, flicker=0.3, seed=3)
    simulate_recording(load_robot(WOLFGANG), path, 6, offsets="legs", binning=8, options=options)
    return path


def rewrite(src: Path, dst: Path, late_ns: int = 0, tripod: bool = False, split_head_from_s: float | None = None):
    """Copy a recording with its messages logged out of their stamps' order: images 120 ms after their stamp, joint
    states 0-30 ms after (random), the joint states stamped 5.0-5.5 s after the start `late_ns` after; with
    `tripod`, a second camera's images 8 ms after each head image (60 ms after every 4th), logged 300 ms late;
    with `split_head_from_s`, the head joints on messages of their own, first published that long after the start."""
    rng = np.random.default_rng(0)
    config = load_robot_config(WOLFGANG)
    with open(src, "rb") as handle, open(dst, "wb") as out:
        reader = make_reader(handle, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        assert summary is not None
        writer = McapWriter(out)
        writer.start(profile="ros2", library="test")
        schemas = {s.name: (k, s) for k, s in summary.schemas.items()}
        schema_ids = {k: writer.register_schema(s.name, s.encoding, s.data) for k, s in summary.schemas.items()}
        channels = {c.topic: writer.register_channel(c.topic, c.message_encoding, schema_ids[c.schema_id], {})
                    for c in summary.channels.values()}  # fmt: skip
        image_schema = schemas["sensor_msgs/msg/CompressedImage"][0]
        channels["tripod"] = writer.register_channel(config.camera_topics("tripod")[0], "cdr", schema_ids[image_schema],
                                                     {})  # fmt: skip
        encoders = {s.name: serialize_dynamic(s.name, s.data.decode())[s.name] for s in summary.schemas.values()}
        messages = []
        start = None
        for schema, channel, message, decoded in reader.iter_decoded_messages():
            stamp = header_stamp_ns(decoded.header, message.log_time)
            start = stamp if start is None else start
            t = (stamp - start) / 1e9
            encode = encoders[schema.name]
            if channel.topic == config.joint_states_topic:
                delay = int(rng.uniform(0, 30 * MS)) + (late_ns if 5.0 <= t < 5.5 else 0)
                if split_head_from_s is None:
                    messages.append((stamp + delay, channels[channel.topic], encode(decoded)))
                    continue
                names, positions = list(decoded.name), list(decoded.position)
                head = [i for i, n in enumerate(names) if n.startswith("Head")]
                rest = [i for i in range(len(names)) if i not in head]
                for part in (rest, head) if t >= split_head_from_s else (rest,):
                    decoded.name, decoded.position = [names[i] for i in part], [positions[i] for i in part]
                    messages.append((stamp + delay, channels[channel.topic], encode(decoded)))
            elif channel.topic == config.camera.topic:
                messages.append((stamp + 120 * MS, channels[channel.topic], encode(decoded)))
                if tripod:
                    index = round((stamp - start) / 1e8)
                    shift = (60 if index % 4 == 3 else 8) * MS
                    image = cv2.imdecode(np.frombuffer(bytes(decoded.data), np.uint8), cv2.IMREAD_UNCHANGED)
                    decoded.data = cv2.imencode(".png", cv2.resize(image, (240, 135)))[1].tobytes()
                    decoded.header.stamp.nanosec = (decoded.header.stamp.nanosec + shift) % 1_000_000_000
                    decoded.header.stamp.sec += (decoded.header.stamp.nanosec < shift) * 1
                    messages.append((stamp + shift + 300 * MS, channels["tripod"], encode(decoded)))
            else:
                messages.append((message.log_time, channels[channel.topic], encode(decoded)))
        for log_time, channel_id, data in sorted(messages, key=lambda m: m[0]):
            writer.add_message(channel_id, log_time, data, log_time)
        writer.finish()


def read_both(path: Path, monkeypatch) -> tuple[Capture, Capture, list[int | None]]:
    """(read as a stream, read on the whole log, the disorder bound of each pass of the streamed read)."""
    config = load_robot_config(WOLFGANG)
    passes: list[int | None] = []
    pass_one = reader_module._pass_one

    def spy(*args, **kwargs):
        passes.append(args[-1])
        return pass_one(*args, **kwargs)

    monkeypatch.setattr(reader_module, "_pass_one", spy)
    streamed = read_capture(path, config)
    monkeypatch.setattr(reader_module, "DISORDER_NS", None)
    whole = read_capture(path, config)
    return streamed, whole, passes[:-1]


def assert_same(a: Capture, b: Capture) -> None:
    assert a.skipped == b.skipped and a.cameras == b.cameras
    assert len(a.samples) == len(b.samples)
    for x, y in zip(a.samples, b.samples):
        assert (x.stamp_ns, x.joint_names, x.source) == (y.stamp_ns, y.joint_names, y.source)
        assert np.array_equal(x.positions, y.positions)
        assert (x.velocities is None and y.velocities is None) or np.array_equal(x.velocities, y.velocities)
        assert image_keys(x) == image_keys(y)


def image_keys(sample) -> dict:
    images = sample.images.items()
    return {k: (i.stamp_ns, i.location, i.format, i.camera.width, i.camera.K.tolist()) for k, i in images}


def whole_log_pairing(path: Path, topic: str) -> dict[int, Paired | str]:
    """Each image of `topic` paired by `pair_frame` on every joint state of the file (no reader involved)."""
    config = load_robot_config(WOLFGANG)
    joints, stamps = [], []
    with open(path, "rb") as handle:
        reader = make_reader(handle, decoder_factories=[DecoderFactory()])
        for _, channel, message, decoded in reader.iter_decoded_messages(topics=[config.joint_states_topic, topic]):
            stamp = header_stamp_ns(decoded.header, message.log_time)
            if channel.topic == topic:
                stamps.append(stamp)
            else:
                joints.append((stamp, list(decoded.name), list(decoded.position), list(decoded.velocity)))
    states = JointStates.from_messages(joints)
    return {s: pair_frame(states, s) for s in stamps}


@pytest.mark.parametrize(
    "late_ms, tripod, split, falls_back",
    [(0, False, None, False), (1500, True, None, False), (4000, True, None, True), (0, False, 4.0, True),
     (0, True, 0.0, False)],
)  # fmt: skip
def test_streamed_pairing_equals_the_whole_log(simulated, tmp_path, monkeypatch, late_ms, tripod, split, falls_back):
    path = tmp_path / "rec.mcap"
    rewrite(simulated, path, late_ms * MS, tripod, split)
    streamed, whole, passes = read_both(path, monkeypatch)
    assert passes == ([DISORDER_NS, None] if falls_back else [DISORDER_NS])
    assert_same(streamed, whole)
    config = load_robot_config(WOLFGANG)
    for camera in ["head", "tripod"] if tripod else ["head"]:
        reference = whole_log_pairing(path, config.camera_topics(camera)[0])
        kept = {s.images[camera].stamp_ns: s for s in streamed.samples if camera in s.images}
        still = {stamp: p for stamp, p in reference.items() if isinstance(p, Paired)}
        assert 20 <= len(still) < len(reference) and set(kept) <= set(still)
        first = {s.stamp_ns for s in streamed.samples}
        for stamp, sample in kept.items():  # a sample's readings are those of its first frame
            if stamp in first:
                assert np.array_equal(sample.positions, still[stamp].positions)
        assert len(set(still) - set(kept)) == 0 or camera == "tripod"  # tripod frames grouped with a head frame
    if tripod:
        assert sum(set(s.images) == {"head", "tripod"} for s in streamed.samples) >= 10


@pytest.mark.parametrize("image_delay_ns", [3 * MS, 0])
def test_the_window_of_joint_states_stays_bounded(image_delay_ns):
    """A minute of 20 joints at 100 Hz and images at 10 Hz (3 ms after a joint state, or with its very stamp, as in a
    simulator's clock): the pairer never holds more than the window's states, and pairs every image as the whole log
    does."""
    names = [f"j{k}" for k in range(20)]
    t_ns = np.arange(6000) * 10 * MS
    q = np.where((t_ns // (3000 * MS)) % 2 == 0, 0.1, 0.1 + 1e-3 * (t_ns % (3000 * MS)) / MS)  # still 3 s, moving 3 s
    streamed, whole = FramePairer(), FramePairer(None)
    largest = 0
    for k, stamp in enumerate(t_ns.tolist()):
        for pairer in (streamed, whole):
            pairer.add_joints(stamp, names, [q[k]] * 20, [])
            if k % 10 == 5:
                pairer.add_frame("head", stamp + image_delay_ns, k)
        largest = max(largest, sum(len(g[1]) for g in streamed._log.groups()))
    a, b = streamed.finish(), whole.finish()
    assert largest <= (DISORDER_NS + 2 * STILL_WINDOW_NS + BATCH_NS) // (10 * MS) + 2
    assert [(f.stamp, f.item) for f in a.frames] == [(f.stamp, f.item) for f in b.frames]
    kept = 0
    for x, y in zip(a.frames, b.frames):
        if isinstance(x.result, Paired):
            kept += 1
            assert isinstance(y.result, Paired) and np.array_equal(x.result.positions, y.result.positions)
        else:
            assert x.result == y.result
    assert 200 <= kept <= 300 and not a.exact


def test_frames_repeating_one_image_are_counted_and_warned_about(simulated, tmp_path):
    """Each still frame's own image noise makes its corners differ from the frame before; a stream that repeats the
    image before (every second frame a copy of the one before, as a driver repeating its last frame) is named."""
    config = load_robot_config(WOLFGANG)
    robot = load_robot(WOLFGANG)
    previous: dict[str, bytes] = {}

    def repeat_every_second(topic: str, index: int, message):
        if topic == config.camera.topic:
            if index % 2 == 1:
                message.data = previous["data"]
            previous["data"] = bytes(message.data)
        return message

    repeated = tmp_path / "repeated.mcap"
    rewrite_capture(simulated, repeated, repeat_every_second)
    counts = {}
    for path in (simulated, repeated):
        samples = read_capture(path, config).samples
        observations, _ = detect_observations(samples, robot)
        counts[path] = (observations["head"].repeated_samples(), observations["head"].n_samples)
    assert counts[simulated][0] == 0 and counts[simulated][1] >= 20
    assert counts[repeated][1] == counts[simulated][1] and counts[repeated][0] >= counts[repeated][1] // 3
    warning = repeat_warnings({"head": observations["head"]}, 0.05)
    assert len(warning) == 1 and f"head camera: {counts[repeated][0]} of {counts[repeated][1]} sample(s)" in warning[0]
    assert "stays at its floor (0.05 px)" in warning[0]


def _exact_one_by_one(states: JointStates, stamp: int) -> Paired | str:
    """The exact rule of a capture file for one frame, written out: each joint, in name order, needs a state stamped
    like the frame (the first of equal stamps); velocities only where every joint reported one."""
    positions, velocities = [], []
    for name in states.names:
        series = states.series[name]
        same = np.flatnonzero(series.times == stamp)
        if not len(same):
            return f"no joint state of {name} with the image's stamp"
        positions.append(series.positions[same[0]])
        velocities.append(series.velocities[same[0]])
    v = np.asarray(velocities)
    return Paired(np.asarray(positions), v if np.all(np.isfinite(v)) else None)


def test_capture_frames_paired_at_once_as_one_by_one():
    """`pair_exact` (a capture file's frames, all at once) gives what the exact rule gives frame by frame:
    the readings stamped like the frame, velocities only where every joint reported one, and for a frame without a
    state of its stamp the first joint (in name order) that lacks one; joints published in two groups, one group
    without velocities in one message, one missing a stamp."""
    rng = np.random.default_rng(5)
    stamps = np.arange(1, 9) * 1_000 * MS
    messages = []
    for k, stamp in enumerate(stamps):
        legs = rng.normal(size=3)
        messages.append((int(stamp), ["a", "b", "c"], legs.tolist(), [] if k == 2 else (legs / 10).tolist()))
        if k != 5:  # the head group lacks the sixth stamp
            messages.append((int(stamp), ["d", "e"], rng.normal(size=2).tolist(), [0.0, 0.0]))
    states = JointStates.from_messages(messages)
    frames = np.array([*stamps, stamps[3] + 1, 0], dtype=np.int64)  # and two stamps no joint state has
    expected = [_exact_one_by_one(states, int(stamp)) for stamp in frames]
    got = pair_exact(states, frames)
    assert [isinstance(r, str) for r in expected] == [False] * 5 + [True] + [False] * 2 + [True, True]
    for want, have in zip(expected, got, strict=True):
        if isinstance(want, str):
            assert have == want
        else:
            assert isinstance(have, Paired)
            np.testing.assert_array_equal(have.positions, want.positions)
            assert (have.velocities is None) == (want.velocities is None)
            if want.velocities is not None:
                np.testing.assert_array_equal(have.velocities, want.velocities)
    assert got[2].velocities is None and got[5] == "no joint state of d with the image's stamp"  # type: ignore[union-attr]


def test_joint_states_read_from_their_layout_as_the_decoder_reads_them():
    """`wolfcal.io.cdr.joint_state` (the reader's layout reading) gives the stamp, names, positions and velocities the
    general ROS 2 decoder gives, for frame ids and names of every length modulo 4 (the CDR padding), empty velocity
    and effort lists, no joints, a zero stamp (the log time) and a non-ASCII name; a message cut short is left to the
    decoder (None)."""
    from mcap_ros2._dynamic import generate_dynamic

    from wolfcal.io.msgdefs import JOINT_STATE, MSGDEFS

    encode = serialize_dynamic(JOINT_STATE, MSGDEFS[JOINT_STATE])[JOINT_STATE]
    decode = generate_dynamic(JOINT_STATE, MSGDEFS[JOINT_STATE])[JOINT_STATE]

    class Schema:
        name = JOINT_STATE

    cases = [
        ("", ["a"], [0.5], [0.1], [1.0], (3, 7)),
        ("b", ["ab", "abc", "abcd", "abcde"], [1.0, -2.0, 3.5, 1e-9], [], [], (12, 999_999_999)),
        ("base", [], [], [], [], (1, 0)),
        ("fr_3", ["knee_ä", "x"], [np.pi, -np.pi], [0.0, float("nan")], [2.0, 3.0], (0, 0)),
    ]
    names_seen: dict[bytes, list[str]] = {}
    for frame_id, names, positions, velocities, effort, (sec, nanosec) in cases:
        data = encode({"header": {"stamp": {"sec": sec, "nanosec": nanosec}, "frame_id": frame_id}, "name": names,
                       "position": positions, "velocity": velocities, "effort": effort})  # fmt: skip
        want = decode(data)
        got = joint_state(data, Schema, 42, names_seen)
        assert got is not None
        assert got[0] == header_stamp_ns(want.header, 42) == (sec * 10**9 + nanosec or 42)
        assert got[1] == list(want.name) == names
        np.testing.assert_array_equal(got[2], want.position)
        np.testing.assert_array_equal(got[3], want.velocity)
        assert joint_state(data[:12], Schema, 42, {}) is None  # within the header
        if len(positions) == 4:  # the last 12 bytes of the positions and the empty lists' counts missing
            assert joint_state(data[:-20], Schema, 42, {}) is None


def test_camera_info_messages_are_keyed_by_all_but_their_stamp():
    """`wolfcal.io.cdr.camera_info_key` gives the stamp the general decoder gives (the log time for a zero stamp) and
    one key for messages that differ only in their stamp; another frame id or other intrinsics give another key, and a
    message of another type is left to the decoder (None)."""
    from mcap_ros2._dynamic import generate_dynamic

    from wolfcal.io.msgdefs import CAMERA_INFO, MSGDEFS

    encode = serialize_dynamic(CAMERA_INFO, MSGDEFS[CAMERA_INFO])[CAMERA_INFO]
    decode = generate_dynamic(CAMERA_INFO, MSGDEFS[CAMERA_INFO])[CAMERA_INFO]

    class Schema:
        name = CAMERA_INFO

    def message(stamp: tuple[int, int], frame_id: str = "cam", fx: float = 500.0) -> bytes:
        return encode({"header": {"stamp": {"sec": stamp[0], "nanosec": stamp[1]}, "frame_id": frame_id},
                       "height": 384, "width": 512, "distortion_model": "plumb_bob", "d": [0.1, 0.0, 0.0, 0.0, 0.0],
                       "k": [fx, 0, 256, 0, fx, 192, 0, 0, 1], "r": [1, 0, 0, 0, 1, 0, 0, 0, 1],
                       "p": [fx, 0, 256, 0, 0, fx, 192, 0, 0, 0, 1, 0]})  # fmt: skip

    keys = {}
    for stamp in [(3, 7), (12, 999_999_999), (0, 0)]:
        data = message(stamp)
        got = camera_info_key(data, Schema, 42)
        assert got is not None
        assert got[0] == header_stamp_ns(decode(data).header, 42) == (stamp[0] * 10**9 + stamp[1] or 42)
        keys[stamp] = got[1]
    assert len(set(keys.values())) == 1
    assert camera_info_key(message((3, 7), "cam2"), Schema, 42)[1] != keys[3, 7]  # type: ignore[index]
    assert camera_info_key(message((3, 7), fx=501.0), Schema, 42)[1] != keys[3, 7]  # type: ignore[index]

    class Other:
        name = "sensor_msgs/msg/Image"

    assert camera_info_key(message((3, 7)), Other, 42) is None
