"""Fast decoding of the three ROS 2 messages a capture holds by the thousand: JointState, CompressedImage, CameraInfo.

mcap_ros2's decoder reads any message from its schema text, a Python call per field and per number (a JointState of
20 joints: about 50 us). These read the fixed layouts of `wolfcal.io.msgdefs` (little-endian CDR, XCDR1, as
rosbag2 and mcap_ros2 write them) with a few struct and numpy calls, into objects with the same attribute names and
values as mcap_ros2's. `FastDecoderFactory` uses one for a channel when its schema is one of the three, its encoding
`cdr` and its schema text the definition (`MSGDEFS`, or a recording's: the same fields in the same order); anything
else (another type, a big-endian message, a definition with other fields) goes to mcap_ros2's decoder, and so does a
message these cannot read (cut short: mcap_ros2 then names the error).
"""

from __future__ import annotations

import re
import struct
from collections.abc import Callable
from types import SimpleNamespace
from typing import Any

from mcap.records import Schema
from mcap_ros2.decoder import DecoderFactory

from wolfcal.io.msgdefs import CAMERA_INFO, COMPRESSED_IMAGE, JOINT_STATE, MSGDEFS

_LITTLE_ENDIAN_CDR = b"\x00\x01"  # encapsulation kind CDR_LE (the 2 option bytes after it are ignored)
_U32 = struct.Struct("<I")
_STAMP = struct.Struct("<iI")
_TWO_U32 = struct.Struct("<II")
_ROI = struct.Struct("<IIIIB")


class _Reader:
    """Little-endian CDR fields from a message's bytes; alignment relative to the payload (after the 4-byte
    encapsulation header)."""

    __slots__ = ("data", "at")

    def __init__(self, data: bytes) -> None:
        self.data, self.at = data, 4

    def align(self, size: int) -> None:
        self.at += -(self.at - 4) % size

    def u32(self) -> int:
        self.align(4)
        (value,) = _U32.unpack_from(self.data, self.at)
        self.at += 4
        return value

    def string(self) -> str:
        length = self.u32()  # with the terminating NUL (some writers give 0 for an empty string)
        start, self.at = self.at, self.at + length
        if self.at > len(self.data):
            raise ValueError("string past the end")
        return self.data[start : self.at - 1].decode("utf-8") if length > 1 else ""

    def strings(self) -> list[str]:
        data, out = self.data, []
        at = self.at + (-(self.at - 4) % 4)
        (count,) = _U32.unpack_from(data, at)
        at += 4
        for _ in range(count):
            at += -(at - 4) % 4
            (length,) = _U32.unpack_from(data, at)
            at += 4 + length
            out.append(data[at - length : at - 1].decode("utf-8") if length > 1 else "")
        if at > len(data):
            raise ValueError("string past the end")
        self.at = at
        return out

    def float64s(self, count: int | None = None) -> list[float]:
        count = self.u32() if count is None else count
        if not count:
            return []
        self.align(8)
        values = struct.unpack_from(f"<{count}d", self.data, self.at)
        self.at += 8 * count
        return list(values)

    def octets(self) -> bytes:
        count = self.u32()
        start, self.at = self.at, self.at + count
        if self.at > len(self.data):
            raise ValueError("byte sequence past the end")
        return self.data[start : self.at]

    def header(self) -> SimpleNamespace:
        sec, nanosec = _STAMP.unpack_from(self.data, self.at)
        self.at += 8
        return SimpleNamespace(stamp=SimpleNamespace(sec=sec, nanosec=nanosec), frame_id=self.string())


def _joint_state(data: bytes) -> SimpleNamespace:
    read = _Reader(data)
    header = read.header()
    return SimpleNamespace(header=header, name=read.strings(), position=read.float64s(), velocity=read.float64s(),
                           effort=read.float64s())  # fmt: skip


def _compressed_image(data: bytes) -> SimpleNamespace:
    read = _Reader(data)
    return SimpleNamespace(header=read.header(), format=read.string(), data=read.octets())


def _camera_info(data: bytes) -> SimpleNamespace:
    read = _Reader(data)
    header = read.header()
    read.align(4)
    height, width = _TWO_U32.unpack_from(data, read.at)
    read.at += 8
    model, d = read.string(), read.float64s()
    k, r, p = read.float64s(9), read.float64s(9), read.float64s(12)
    read.align(4)
    binning_x, binning_y = _TWO_U32.unpack_from(data, read.at)
    x_offset, y_offset, roi_height, roi_width, rectify = _ROI.unpack_from(data, read.at + 8)
    roi = SimpleNamespace(x_offset=x_offset, y_offset=y_offset, height=roi_height, width=roi_width,
                          do_rectify=rectify != 0)  # fmt: skip
    return SimpleNamespace(header=header, height=height, width=width, distortion_model=model, d=d, k=k, r=r, p=p,
                           binning_x=binning_x, binning_y=binning_y, roi=roi)  # fmt: skip


_FAST: dict[str, Callable[[bytes], SimpleNamespace]] = {
    JOINT_STATE: _joint_state,
    COMPRESSED_IMAGE: _compressed_image,
    CAMERA_INFO: _camera_info,
}


def _fields(definition: str) -> list[str]:
    """The field lines of a `ros2msg` definition and of the types it uses (comments, constants and blank lines left
    out, spaces normalised; a package's `/msg/` infix dropped), in order: what fixes the layout."""
    lines = []
    for line in definition.splitlines():
        line = re.sub(r"\s+", " ", line.split("#", 1)[0]).strip()
        if line and not line.startswith("=") and "=" not in line.partition(" ")[2]:
            lines.append(line.replace("/msg/", "/"))
    return lines


_LAYOUTS = {name: _fields(MSGDEFS[name]) for name in _FAST}


class FastDecoderFactory(DecoderFactory):
    """mcap_ros2's `DecoderFactory` (same decoders, same errors) whose decoders of the three messages this module
    knows take the fast path for little-endian messages of the known layout."""

    def __init__(self) -> None:
        super().__init__()
        self._wrapped: dict[int, Callable[[bytes], Any]] = {}

    def decoder_for(self, message_encoding: str, schema: Schema | None) -> Callable[[bytes], Any] | None:
        general = super().decoder_for(message_encoding, schema)
        if general is None or schema is None or schema.name not in _FAST:
            return general
        if schema.id not in self._wrapped:
            known = _fields(schema.data.decode("utf-8", errors="replace")) == _LAYOUTS[schema.name]
            self._wrapped[schema.id] = _with_fast_path(_FAST[schema.name], general) if known else general
        return self._wrapped[schema.id]


def _with_fast_path(fast: Callable[[bytes], SimpleNamespace], general: Callable[[bytes], Any]):
    def decode(data: bytes) -> Any:
        if data[:2] == _LITTLE_ENDIAN_CDR:
            try:
                return fast(data)
            except (ValueError, struct.error, UnicodeDecodeError):
                pass  # cut short or malformed: mcap_ros2's decoder raises its own error for it
        return general(data)

    return decode
