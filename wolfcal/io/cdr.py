"""ROS 2 messages read from their little-endian CDR layout, without the general decoder: the kinds a capture or
recording holds many of (sensor_msgs/CompressedImage, sensor_msgs/JointState; of sensor_msgs/CameraInfo, which
repeats one content, the stamp and a key of that content). Each reader returns None for a message it does not read
so (another type, big-endian, cut short): the caller then uses the general decoder
(`wolfcal.io.mcapfile.channel_decoder`), which gives the same values (tests); `image_of` does both for an image."""

from __future__ import annotations

import struct
from collections.abc import Callable
from pathlib import Path

from mcap.records import Channel, Message

from wolfcal.io.images import PNG_HEAD
from wolfcal.io.mcapfile import channel_decoder
from wolfcal.io.msgdefs import CAMERA_INFO, COMPRESSED_IMAGE, JOINT_STATE, header_stamp_ns, stamp_ns


def compressed_image(data: bytes, schema, log_time: int, complete: bool = True) -> tuple[int, memoryview] | None:
    """(header stamp [ns], `log_time` when unset (`msgdefs.stamp_ns`); the encoded image, a view into `data`) of a
    little-endian CDR sensor_msgs/CompressedImage message, read from its layout without copying the image; None for
    anything else (the caller decodes it with the general decoder). `complete` False: `data` is the message's first
    bytes only; the view holds the image's bytes among them (at least a png's header, else None)."""
    span = compressed_image_span(data, schema, log_time)
    if span is None:
        return None
    stamp, start, length = span
    if start + (length if complete else min(length, PNG_HEAD)) > len(data):
        return None
    return stamp, memoryview(data)[start : start + length]


def compressed_image_span(data: bytes, schema, log_time: int) -> tuple[int, int, int] | None:
    """(header stamp [ns] as `compressed_image` gives it, where the encoded image begins in the message's data
    [bytes], its length [bytes]) of a little-endian CDR sensor_msgs/CompressedImage message whose first bytes are
    `data` (up to the image's length field at least); None for anything else."""
    if schema is None or schema.name != COMPRESSED_IMAGE or data[:2] != b"\x00\x01":
        return None
    try:
        sec, nanosec, length = struct.unpack_from("<iII", data, 4)
        pos = 4 + 12 + length  # after header.frame_id (CDR offsets count from the end of the 4-byte encapsulation)
        pos += -(pos - 4) % 4
        (length,) = struct.unpack_from("<I", data, pos)
        pos += 4 + length  # after format
        pos += -(pos - 4) % 4
        (length,) = struct.unpack_from("<I", data, pos)
    except struct.error:
        return None
    return stamp_ns(sec, nanosec, log_time), pos + 4, length


def image_of(
    path: Path, decoders: dict[int, Callable], schema, channel: Channel, message: Message, complete: bool = True
) -> tuple[int, memoryview]:
    """(header stamp [ns], the encoded image, a view) of a CompressedImage message of the file `path`: from its layout
    (`compressed_image`), else by the channel's general decoder (`channel_decoder`, kept in `decoders`; a whole
    message: `complete` False only where `compressed_image` has read the head)."""
    image = compressed_image(message.data, schema, message.log_time, complete)
    if image is None:
        decoded = channel_decoder(path, decoders, channel, schema)(message.data)
        image = (header_stamp_ns(decoded.header, message.log_time), memoryview(decoded.data))
    return image


def camera_info_key(data: bytes, schema, log_time: int) -> tuple[int, bytes] | None:
    """(header stamp [ns] (`msgdefs.stamp_ns`), the message's bytes without its stamp) of a little-endian CDR
    sensor_msgs/CameraInfo message: messages with the same key hold the same frame and intrinsics, so a reader decodes
    one of them (the general decoder is slow per message); None for anything else."""
    if schema is None or schema.name != CAMERA_INFO or data[:2] != b"\x00\x01" or len(data) < 12:
        return None
    sec, nanosec = struct.unpack_from("<iI", data, 4)
    return stamp_ns(sec, nanosec, log_time), bytes(data[:4]) + bytes(data[12:])


def joint_state(
    data: bytes, schema, log_time: int, names_seen: dict[bytes, list[str]]
) -> tuple[int, list[str], tuple[float, ...], tuple[float, ...]] | None:
    """(header stamp [ns] (`msgdefs.stamp_ns`), names, positions [rad], velocities [rad/s]) of a little-endian CDR
    sensor_msgs/JointState message, read from its layout (a recording holds many, and the general decoder is slow
    per message); None for anything else (the caller decodes it with the general decoder).
    `names_seen`: the name lists read so far by their bytes (a recording repeats one or two lists)."""
    if schema is None or schema.name != JOINT_STATE or data[:2] != b"\x00\x01":
        return None
    try:
        sec, nanosec, length = struct.unpack_from("<iII", data, 4)
        pos = 16 + length  # after header.frame_id (CDR offsets count from the end of the 4-byte encapsulation)
        pos += -(pos - 4) % 4
        start = pos
        (count,) = struct.unpack_from("<I", data, pos)
        pos += 4
        for _ in range(count):
            pos += -(pos - 4) % 4
            (length,) = struct.unpack_from("<I", data, pos)
            pos += 4 + length
        key = bytes(data[start:pos])
        names = names_seen.get(key)
        if names is None:
            names = names_seen[key] = _strings(key, count)
        arrays = []
        for _ in range(2):  # position, velocity (effort is not read)
            pos += -(pos - 4) % 4
            (count,) = struct.unpack_from("<I", data, pos)
            pos += 4
            if count:
                pos += -(pos - 4) % 8
            arrays.append(struct.unpack_from(f"<{count}d", data, pos))
            pos += 8 * count
    except (struct.error, UnicodeDecodeError):
        return None
    return stamp_ns(sec, nanosec, log_time), names, arrays[0], arrays[1]


def _strings(data: bytes, count: int) -> list[str]:
    """The `count` strings of a CDR string sequence (`data` from its count, aligned as at a 4-byte boundary)."""
    strings = []
    pos = 4
    for _ in range(count):
        pos += -pos % 4
        (length,) = struct.unpack_from("<I", data, pos)
        strings.append(data[pos + 4 : pos + 3 + length].decode("utf-8"))
        pos += 4 + length
    return strings
