"""decode_gray: wolfcal's own stored pngs read without a decoder give OpenCV's pixels; anything else goes to OpenCV."""

from __future__ import annotations

import struct
import zlib

import cv2
import numpy as np
import pytest

from wolfcal.io.images import _stored_gray, decode_gray, encode_image


def _noise(height: int, width: int, seed: int = 0) -> np.ndarray:
    return np.random.default_rng(seed).integers(0, 256, (height, width), dtype=np.uint8)


def _opencv(data: bytes) -> np.ndarray | None:
    return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_GRAYSCALE)


def _chunk(kind: bytes, payload: bytes) -> bytes:
    return struct.pack(">I", len(payload)) + kind + payload + struct.pack(">I", zlib.crc32(kind + payload))


def _png(rows: bytes, width: int, height: int, level: int) -> bytes:
    """A gray 8-bit png of the given raw rows (each: filter byte, pixels), written by the png spec with zlib."""
    header = struct.pack(">IIBBBBB", width, height, 8, 0, 0, 0, 0)
    return (b"\x89PNG\r\n\x1a\n" + _chunk(b"IHDR", header) + _chunk(b"IDAT", zlib.compress(rows, level))
            + _chunk(b"IEND", b""))  # fmt: skip


@pytest.mark.parametrize(("height", "width"), [(1, 1), (77, 301), (1000, 1200)])
def test_wolfcals_own_png_is_read_as_opencv_reads_it(height, width):
    """1000x1200: stored blocks of 64 KiB that run across IDAT chunks of 1 MiB."""
    image = _noise(height, width)
    data, _ = encode_image(image, "png")
    fast = _stored_gray(data)
    assert fast is not None  # read without a decoder
    assert np.array_equal(fast, image) and np.array_equal(decode_gray(data), _opencv(data))


def test_a_stored_png_written_by_zlib_is_read_without_a_decoder():
    image = _noise(40, 70, seed=1)
    data = _png(b"".join(b"\x00" + row.tobytes() for row in image), 70, 40, level=0)
    assert np.array_equal(_stored_gray(data), image)


def test_a_filtered_row_goes_to_opencv():
    image = _noise(40, 70, seed=2)
    rows = [b"\x00" + row.tobytes() for row in image]
    sub = np.diff(image[5].astype(np.int16), prepend=0).astype(np.uint8)  # filter 1: each byte minus its left one
    rows[5] = b"\x01" + sub.tobytes()
    data = _png(b"".join(rows), 70, 40, level=0)
    assert _stored_gray(data) is None
    assert np.array_equal(decode_gray(data), image)


@pytest.mark.parametrize("kind", ["deflated png", "colour png", "jpeg"])
def test_other_images_give_opencvs_gray(kind):
    gray = _noise(60, 90, seed=3)
    if kind == "deflated png":
        data = cv2.imencode(".png", gray)[1].tobytes()
    elif kind == "colour png":
        data, _ = encode_image(np.dstack([gray, gray[::-1], gray[:, ::-1]]), "png")
    else:
        data, _ = encode_image(gray, "jpeg")
    assert _stored_gray(data) is None
    assert np.array_equal(decode_gray(data), _opencv(data))


def test_a_damaged_or_cut_png_cannot_be_decoded():
    image = _noise(50, 80, seed=4)
    data, _ = encode_image(image, "png")
    damaged = bytearray(data)
    damaged[len(data) // 2] ^= 0x10  # a pixel byte: neither its chunk's CRC nor the zlib checksum hold
    for bad in (bytes(damaged), data[: len(data) // 2], b""):
        assert _stored_gray(bad) is None
        assert decode_gray(bad) is None


def test_the_image_checksums_are_zlibs():
    """CRC-32 and Adler-32 as the images' checks compute them (ISA-L's where installed) give zlib's values."""
    from wolfcal.io import images

    data = np.random.default_rng(7).integers(0, 256, 1 << 20, np.uint8).tobytes()
    for part in (data, data[:1], data[3 : 70_001], b""):
        assert images.crc32(part) == zlib.crc32(part)
        assert images.adler32(part) == zlib.adler32(part)
