"""Encoded images of `sensor_msgs/CompressedImage`: encode, decode to gray, recognise the format, read the size
cheaply."""

from __future__ import annotations

import struct
from collections.abc import Iterator

import numpy as np

try:  # ISA-L's checksums (python-isal): zlib's values, 5x faster (75 MB: CRC-32 3.6 vs 18 ms, Adler-32 4.3 vs 21 ms)
    from isal.isal_zlib import adler32, crc32
except ImportError:  # a platform without its wheels: zlib's own
    from zlib import adler32, crc32

from wolfcal.errors import WolfcalError

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
JPEG_SIGNATURE = b"\xff\xd8"
PNG_HEAD = 64  # bytes of a png that give its kind and size (signature, IHDR)
JPEG_QUALITY = 95
# png as wolfcal writes it: stored (zlib level 0), rows unfiltered. A standard png that any tool opens, the size of
# the raw pixels (+0.1 %), decoded 5-10x faster than deflated (the fit decodes every image: inflating and unfiltering
# were a quarter to two fifths of a first run's detection) and encoded 10-25x faster (bench/bench_image_storage.py:
# 512x384 0.15-0.26 vs 1.9 ms to decode, 2048x1536 2.6-3.8 vs 25-27 ms); deflated files were 1.9-2.8x smaller on
# simulated and photo-like images. Filtering alone costs most of a stored png's decoding (0.7 ms at 512x384 with it).
PNG_COMPRESSION = 0
# IDAT chunks of up to 1 MiB (OpenCV's largest; 8 KiB by default): one chunk per 512x384 image instead of 25, so
# `image_damage` checks a few checksums per image instead of hundreds (2048x1536: 4 chunks instead of 385)
PNG_CHUNK_BYTES = 1 << 20
# JPEG start-of-frame markers (baseline, progressive, lossless, ...): they carry the image size
_JPEG_SOF = {0xC0, 0xC1, 0xC2, 0xC3, 0xC5, 0xC6, 0xC7, 0xC9, 0xCA, 0xCB, 0xCD, 0xCE, 0xCF}


def encode_image(image: np.ndarray, image_format: str) -> tuple[bytes, str]:
    """(H, W) mono8 or (H, W, 3) bgr8 uint8 image -> (encoded bytes, CompressedImage format string).

    The format string follows image_transport's compressed plugin, e.g. "bgr8; png compressed bgr8".
    """
    if image.dtype != np.uint8 or not (image.ndim == 2 or (image.ndim == 3 and image.shape[2] == 3)):
        raise WolfcalError(
            f"cannot store an image of shape {image.shape} and type {image.dtype}: "
            "give (H, W) mono8 or (H, W, 3) bgr8 uint8 images"
        )
    import cv2  # here, not at the top: a fit from cached detections never loads OpenCV (45 ms of CPU, 20 MB)

    encoding = "mono8" if image.ndim == 2 else "bgr8"
    if image_format == "png":
        params = [cv2.IMWRITE_PNG_COMPRESSION, PNG_COMPRESSION]
        if hasattr(cv2, "IMWRITE_PNG_FILTER"):  # recent OpenCV; older: libpng filters (0.7 ms at 512x384)
            params += [cv2.IMWRITE_PNG_FILTER, cv2.IMWRITE_PNG_FILTER_NONE,
                       cv2.IMWRITE_PNG_ZLIBBUFFER_SIZE, PNG_CHUNK_BYTES]  # fmt: skip
        ok, buffer = cv2.imencode(".png", image, params)
    elif image_format == "jpeg":
        ok, buffer = cv2.imencode(".jpg", image, [cv2.IMWRITE_JPEG_QUALITY, JPEG_QUALITY])
    else:
        raise WolfcalError(f"unknown image format {image_format!r}: use 'png' (lossless) or 'jpeg'")
    if not ok:
        raise WolfcalError(f"OpenCV could not encode an image of shape {image.shape} as {image_format}")
    return buffer.tobytes(), f"{encoding}; {image_format} compressed {encoding}"


def decode_gray(data: bytes | memoryview) -> np.ndarray | None:
    """8-bit gray (H, W) image of an encoded png or jpeg (as OpenCV's IMREAD_GRAYSCALE gives it); None if it cannot
    be decoded. A png as wolfcal writes mono8 images (stored, unfiltered: `PNG_COMPRESSION`) is read by
    `_stored_gray` without a decoder: its pixels lie in the file as they are, and its zlib checksum is verified
    (2048x1536: 1.6 ms of CPU against OpenCV's 2.7-4.2 ms, which also checks each chunk's CRC: the reader has
    checked those of every image it read from a capture file, `image_damage`; 512x384: 0.10 against 0.17 ms). Any
    other image goes to OpenCV."""
    gray = _stored_gray(data)
    if gray is not None:
        return gray
    import cv2

    return cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_GRAYSCALE) if len(data) else None


def _stored_gray(data: bytes | memoryview) -> np.ndarray | None:
    """The pixels (H, W) of an 8-bit gray, non-interlaced png whose zlib stream is made of stored blocks only and
    whose rows are all unfiltered, with its zlib checksum (Adler-32 of the rows) verified; None for any other
    image (or one that is damaged: then OpenCV says so)."""
    view = memoryview(data)
    if len(view) < 33 or bytes(view[: len(PNG_SIGNATURE)]) != PNG_SIGNATURE or bytes(view[12:16]) != b"IHDR":
        return None
    width, height, depth, colour, _, _, interlace = struct.unpack_from(">IIBBBBB", view, 16)
    if depth != 8 or colour != 0 or interlace != 0 or width == 0 or height == 0:
        return None
    parts = [view[pos + 8 : pos + 8 + length] for chunk, pos, length in _png_chunks(view) if chunk == b"IDAT"]
    # stored blocks (<= 64 KiB) run across the IDAT chunks: the chunks' data in one array (copied by numpy: joining
    # them as bytes took 1.7 ms at 2048x1536, copying 0.2 ms)
    stream = _concatenated(parts)
    size = (width + 1) * height  # each row: its filter byte, then the pixels
    if size > 1 << 31 or len(stream) < 2 or stream[0] & 0x0F != 8 or stream[1] & 0x20:  # deflate, no dictionary
        return None
    out = np.empty(size, np.uint8)
    pos, filled, last = 2, 0, False
    while not last:
        if pos + 5 > len(stream) or stream[pos] & 0x06:  # cut short, or a compressed block
            return None
        last = bool(stream[pos] & 1)
        count, complement = struct.unpack_from("<HH", stream, pos + 1)
        if count ^ complement != 0xFFFF or filled + count > size or pos + 5 + count > len(stream):
            return None
        out[filled : filled + count] = np.frombuffer(stream, np.uint8, count, pos + 5)
        filled, pos = filled + count, pos + 5 + count
    if filled != size or pos + 4 > len(stream) or adler32(out.data) != struct.unpack_from(">I", stream, pos)[0]:
        return None
    rows = out.reshape(height, width + 1)
    if rows[:, 0].any():  # a filtered row
        return None
    return rows[:, 1:]


def _png_chunks(view: memoryview) -> Iterator[tuple[bytes, int, int]]:
    """(type, offset of its length field, data length) of each chunk of a png whose header fits in `view`, after
    the signature, up to and including IEND (a chunk's data and checksum may run past the end of a cut-short
    file: the caller checks)."""
    pos = len(PNG_SIGNATURE)
    while pos + 12 <= len(view):
        (length,) = struct.unpack_from(">I", view, pos)
        chunk = bytes(view[pos + 4 : pos + 8])
        yield chunk, pos, length
        if chunk == b"IEND":
            return
        pos += 12 + length


def _concatenated(parts: list[memoryview]) -> memoryview:
    """The bytes of `parts` one after the other (the only part itself: no copy)."""
    if len(parts) == 1:
        return parts[0]
    joined = np.empty(sum(len(part) for part in parts), np.uint8)
    start = 0
    for part in parts:
        joined[start : start + len(part)] = np.frombuffer(part, np.uint8)
        start += len(part)
    return joined.data


def image_kind(data: bytes | memoryview) -> str | None:
    """'png' or 'jpeg' from the file signature; None for anything else (e.g. compressedDepth)."""
    head = bytes(data[: len(PNG_SIGNATURE)])
    if head.startswith(PNG_SIGNATURE):
        return "png"
    if head.startswith(JPEG_SIGNATURE):
        return "jpeg"
    return None


def image_size(data: bytes | memoryview) -> tuple[int, int] | None:
    """(width, height) of an encoded png or jpeg from its header, without decoding (`data` may be a view into a
    larger buffer); None if not found."""
    kind = image_kind(data)
    if kind == "png":
        if len(data) < 24 or data[12:16] != b"IHDR":
            return None
        width, height = struct.unpack(">II", data[16:24])
        return int(width), int(height)
    if kind == "jpeg":
        pos = 2
        while pos + 4 <= len(data):
            if data[pos] != 0xFF:
                return None
            marker = data[pos + 1]
            if marker == 0xFF:  # fill byte
                pos += 1
                continue
            if marker in (0x01, *range(0xD0, 0xD8)):  # markers without a length
                pos += 2
                continue
            (length,) = struct.unpack(">H", data[pos + 2 : pos + 4])
            if marker in _JPEG_SOF:
                if pos + 9 > len(data):
                    return None
                height, width = struct.unpack(">HH", data[pos + 5 : pos + 9])
                return int(width), int(height)
            pos += 2 + length
    return None


def image_damage(data: bytes | memoryview) -> str | None:
    """Why an encoded png or jpeg is damaged (bad chunk checksum, cut short), or None when it looks whole.
    Cheap: checks the structure and checksums, does not decode; `data` may be a view into a larger buffer (the
    image's bytes are not copied)."""
    view = memoryview(data)  # checksums over slices without copying them
    kind = image_kind(view)
    if kind == "png":
        for chunk, pos, length in _png_chunks(view):
            end = pos + 12 + length
            if end > len(view):
                return f"png cut short in its {chunk.decode('latin-1')} chunk"
            (crc,) = struct.unpack_from(">I", view, end - 4)
            if crc32(view[pos + 4 : end - 4]) & 0xFFFFFFFF != crc:
                return f"png checksum error in its {chunk.decode('latin-1')} chunk"
            if chunk == b"IEND":
                return None
        return "png cut short (no IEND chunk)"
    if kind == "jpeg":
        if image_size(view) is None:
            return "jpeg without a readable frame header"
        if b"\xff\xd9" not in bytes(view[-64:]):
            return "jpeg cut short (no end-of-image marker)"
        return None
    return "not a png or jpeg image"
