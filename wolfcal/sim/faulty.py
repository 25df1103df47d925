"""Capture files with known faults, made from good ones: for the tests.

`rewrite_capture` copies an MCAP file message by message (schemas, channels, attachments kept), letting an edit
change or drop each decoded message; the helpers below are the faults a team meets: NaN or infinite joint
readings, a damaged image, a CameraInfo with a wrong focal length.
"""

from __future__ import annotations

from collections import Counter
from collections.abc import Callable, Iterable
from pathlib import Path
from typing import Any

from mcap.reader import make_reader
from mcap.writer import Writer as McapWriter
from mcap_ros2._dynamic import serialize_dynamic
from mcap_ros2.decoder import DecoderFactory

from wolfcal.errors import WolfcalError

Edit = Callable[[str, int, Any], Any]  # (topic, index of the message on its topic, decoded message) -> message | None


def rewrite_capture(src: Path, dst: Path, edit: Edit) -> None:
    """Copy `src` to `dst`, each message passed through `edit` (return it, changed or not, or None to drop it)."""
    with open(src, "rb") as handle, open(dst, "wb") as out:
        reader = make_reader(handle, decoder_factories=[DecoderFactory()])
        summary = reader.get_summary()
        if summary is None:
            raise WolfcalError(f"{src}: no MCAP summary (the file is torn: run `wolfcal recover` on it first)")
        writer = McapWriter(out)
        writer.start(profile="ros2", library="wolfcal-faulty")
        schema_ids = {k: writer.register_schema(s.name, s.encoding, s.data) for k, s in summary.schemas.items()}
        channel_ids = {
            k: writer.register_channel(c.topic, c.message_encoding, schema_ids[c.schema_id], c.metadata)
            for k, c in summary.channels.items()
        }
        encoders = {s.name: serialize_dynamic(s.name, s.data.decode())[s.name] for s in summary.schemas.values()}
        counts: Counter[str] = Counter()
        for schema, channel, message, decoded in reader.iter_decoded_messages(log_time_order=True):
            index = counts[channel.topic]
            counts[channel.topic] += 1
            changed = edit(channel.topic, index, decoded)
            if changed is not None and schema is not None:
                data = encoders[schema.name](changed)
                channel_id = channel_ids[channel.id]
                writer.add_message(channel_id, message.log_time, data, message.publish_time, message.sequence)
        for a in reader.iter_attachments():
            writer.add_attachment(a.create_time, a.log_time, a.name, a.media_type, a.data)
        writer.finish()


def with_joint_values(topic: str, samples: Iterable[int], joint: str, value: float) -> Edit:
    """An edit setting `joint` to `value` (e.g. nan, inf) in the joint states of the given sample indices."""
    chosen = set(samples)

    def edit(channel_topic: str, index: int, message: Any) -> Any:
        if channel_topic == topic and index in chosen:
            positions = list(message.position)
            positions[list(message.name).index(joint)] = value
            message.position = positions
        return message

    return edit


def with_damaged_image(topic: str, sample: int) -> Edit:
    """An edit flipping bytes in the middle of one image (its checksums then fail, as after a bad copy)."""

    def edit(channel_topic: str, index: int, message: Any) -> Any:
        if channel_topic == topic and index == sample:
            data = bytearray(message.data)
            middle = len(data) // 2
            data[middle : middle + 64] = bytes(b ^ 0xA5 for b in data[middle : middle + 64])
            message.data = bytes(data)
        return message

    return edit


def with_camera_info(topic: str, **fields: Any) -> Edit:
    """An edit setting fields of every CameraInfo (e.g. k=[0, ...], width=640)."""

    def edit(channel_topic: str, index: int, message: Any) -> Any:
        if channel_topic == topic:
            for name, value in fields.items():
                setattr(message, name, value)
        return message

    return edit
