"""The fast decoders of JointState, CompressedImage and CameraInfo give what mcap_ros2's decoder gives, field by
field, on real files: a capture written by `CaptureWriter` (the shipped demo) and a ROS 2 recording written with
mcap_ros2's writer; messages they do not read (big-endian, cut short, another layout) go to mcap_ros2's decoder."""

from __future__ import annotations

from pathlib import Path

import pytest
from mcap.reader import make_reader
from mcap.records import Schema
from mcap_ros2.decoder import DecoderFactory

from wolfcal.io.cdr import FastDecoderFactory
from wolfcal.io.msgdefs import CAMERA_INFO, COMPRESSED_IMAGE, JOINT_STATE, MSGDEFS
from wolfcal.sim.recording import RecordingOptions, simulate_recording

DEMO = Path(__file__).resolve().parents[1] / "captures" / "demo.mcap"
KNOWN = {JOINT_STATE, COMPRESSED_IMAGE, CAMERA_INFO}


def fields_of(message) -> object:
    """A decoded message as plain nested dicts and lists (mcap_ros2's objects and ours alike)."""
    names = getattr(message, "__slots__", None) or list(getattr(message, "__dict__", {}))
    if names and not isinstance(message, (str, bytes)):
        return {name: fields_of(getattr(message, name)) for name in names}
    if isinstance(message, list):
        return [fields_of(x) for x in message]
    return (type(message).__name__, message)


def outcome(decoder, data: bytes) -> tuple:
    """("fields", the decoded fields) or ("error", the exception's type and text)."""
    try:
        return "fields", fields_of(decoder(data))
    except Exception as exc:  # noqa: BLE001 (any error: both decoders must raise the same)
        return "error", type(exc), str(exc)


def messages(path: Path) -> list:
    with path.open("rb") as handle:
        return list(make_reader(handle).iter_messages())


@pytest.fixture(scope="module")
def recording(robot, tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("cdr") / "recording.mcap"
    simulate_recording(robot, path, 2, options=RecordingOptions(seed=3))
    return path


@pytest.mark.parametrize("which", ["capture", "recording"])
def test_fast_decoders_give_mcap_ros2s_fields(which, recording):
    path = DEMO if which == "capture" else recording
    fast, general = FastDecoderFactory(), DecoderFactory()
    seen: dict[str, int] = {}
    for schema, channel, message in messages(path):
        ours = fast.decoder_for(channel.message_encoding, schema)
        theirs = general.decoder_for(channel.message_encoding, schema)
        assert ours is not None and theirs is not None
        plain = DecoderFactory.decoder_for(fast, channel.message_encoding, schema)  # mcap_ros2's, unwrapped
        assert (ours is not plain) == (schema.name in KNOWN)  # the fast path is taken for the three
        assert fields_of(ours(message.data)) == fields_of(theirs(message.data)), schema.name
        seen[schema.name] = seen.get(schema.name, 0) + 1
    assert KNOWN <= set(seen) and min(seen[name] for name in KNOWN) >= 2


def test_messages_the_fast_path_cannot_read_go_to_mcap_ros2():
    fast, general = FastDecoderFactory(), DecoderFactory()
    schemas = {schema.name: schema for schema, _, _ in messages(DEMO)}
    joint = next(m for s, _, m in messages(DEMO) if s.name == JOINT_STATE)
    ours = fast.decoder_for("cdr", schemas[JOINT_STATE])
    theirs = general.decoder_for("cdr", schemas[JOINT_STATE])
    assert ours is not None and theirs is not None
    big_endian = b"\x00\x00" + joint.data[2:]  # read as mcap_ros2 reads it, whatever that gives
    cut = joint.data[: len(joint.data) // 2]
    for data in (big_endian, cut):
        assert outcome(ours, data) == outcome(theirs, data)
    assert outcome(ours, cut)[0] == "error"
    # another layout under a known name (a field more): mcap_ros2's decoder, not the fast one
    other = Schema(id=99, name=JOINT_STATE, encoding="ros2msg",
                   data=MSGDEFS[JOINT_STATE].replace("float64[] effort\n", "float64[] effort\nuint32 extra\n").encode())
    assert fast.decoder_for("cdr", other) is DecoderFactory.decoder_for(fast, "cdr", other)
