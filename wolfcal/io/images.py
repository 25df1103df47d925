"""Encoded images of `sensor_msgs/CompressedImage`: encode, decode to gray, recognise the format, read the size
cheaply."""

from __future__ import annotations

import struct
from collections.abc import Iterator
from zlib import crc32

import numpy as np

from wolfcal.errors import WolfcalError

PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
JPEG_SIGNATURE = b"\xff\xd8"
PNG_HEAD = 64  # bytes of a png that give its kind and size (signature, IHDR)
JPEG_QUALITY = 95
# png as wolfcal writes it: stored (zlib level 0), rows unfiltered. A standard png that any tool opens, the size of
# the raw pixels, several times faster to encode and decode than a deflated one (which is 2-3x smaller): the fit
# decodes every image, and a capture is written while the robot waits.
PNG_COMPRESSION = 0
# IDAT chunks of up to 1 MiB (OpenCV's largest; 8 KiB by default): a few chunk checksums per image for
# `image_damage` instead of hundreds
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
    import cv2  # here, not at the top: a fit from cached detections does not load OpenCV

    encoding = "mono8" if image.ndim == 2 else "bgr8"
    if image_format == "png":
        params = [cv2.IMWRITE_PNG_COMPRESSION, PNG_COMPRESSION]
        if hasattr(cv2, "IMWRITE_PNG_FILTER"):  # recent OpenCV; older ones filter the rows (slower to decode)
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
    """8-bit gray (H, W) image of an encoded png or jpeg (OpenCV's IMREAD_GRAYSCALE: a colour jpeg decodes only its
    luma); None if it cannot be decoded."""
    import cv2

    return cv2.imdecode(np.frombuffer(data, dtype=np.uint8), cv2.IMREAD_GRAYSCALE) if len(data) else None


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
