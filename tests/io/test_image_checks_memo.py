"""The reader's memo of a file's image checks: a second read of an unchanged file takes the damaged images from the
memo instead of checking every image's checksums again, with the same samples and the same notes; a changed file, a
memo taken too soon after the file's last change, a memo of another file or `--no-cache` check the images again."""

from __future__ import annotations

import json
import shutil
from pathlib import Path

import pytest

from wolfcal.config import load_robot_config
from wolfcal.io import filememo
from wolfcal.io import reader as reader_module
from wolfcal.io.cdr import compressed_image
from wolfcal.io.reader import read_capture
from wolfcal.sim.faulty import rewrite_capture, with_damaged_image
from wolfcal.sim.simulate import SimOptions, simulate_capture
from wolfcal.vision.cache import cache_enabled

ROBOT = Path(__file__).resolve().parents[2] / "configs" / "wolfgang"
IMAGE_TOPIC = "/camera/image_proc/compressed"
N = 8


@pytest.fixture(scope="module")
def good(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("good") / "good.mcap"
    simulate_capture(ROBOT, path, SimOptions(samples=N, seed=5, binning=4), say=lambda _: None)
    return path


@pytest.fixture
def config():
    return load_robot_config(ROBOT)


@pytest.fixture
def checks(monkeypatch) -> list[int]:
    """Counts the images whose checksums the reader checks; memos trusted at once (no 2 s wait after a write);
    a cache folder of the test's own."""
    calls: list[int] = []
    real = reader_module.image_damage

    def counted(data: bytes) -> str | None:
        calls.append(1)
        return real(data)

    monkeypatch.setattr(reader_module, "image_damage", counted)
    monkeypatch.setattr(filememo, "RACY_NS", 0)
    return calls


def read(path: Path, config):
    capture = read_capture(path, config)
    return [s.stamp_ns for s in capture.samples], capture.skipped


def damaged_copy(good: Path, path: Path, sample: int) -> Path:
    rewrite_capture(good, path, with_damaged_image(IMAGE_TOPIC, sample))
    return path


def test_an_unchanged_file_is_not_checked_again_and_reads_the_same(good, tmp_path, config, checks, monkeypatch):
    monkeypatch.setenv("WOLFCAL_CACHE_DIR", str(tmp_path / "cache"))
    bad = damaged_copy(good, tmp_path / "bad.mcap", 3)
    first = read(bad, config)
    assert len(checks) == N  # every image checked
    assert len(first[0]) == N - 1 and any("'head' image 4 of 8" in n and "png checksum error" in n for n in first[1])
    checks.clear()
    assert read(bad, config) == first  # the same samples and notes, from the memo
    assert checks == []


def test_a_changed_file_is_checked_again(good, tmp_path, config, checks, monkeypatch):
    monkeypatch.setenv("WOLFCAL_CACHE_DIR", str(tmp_path / "cache"))
    path = damaged_copy(good, tmp_path / "bad.mcap", 3)
    read(path, config)
    other = damaged_copy(good, tmp_path / "other.mcap", 6)
    shutil.copyfile(other, path)  # same path and size, other content: a new status-change time
    checks.clear()
    stamps, notes = read(path, config)
    assert len(checks) == N
    assert any("'head' image 7 of 8" in n for n in notes) and not any("image 4 of 8" in n for n in notes)
    assert stamps == read(other, config)[0]


def test_a_memo_taken_right_after_a_change_is_not_trusted(good, tmp_path, config, checks, monkeypatch):
    monkeypatch.setenv("WOLFCAL_CACHE_DIR", str(tmp_path / "cache"))
    monkeypatch.setattr(filememo, "RACY_NS", 10**18)
    path = damaged_copy(good, tmp_path / "bad.mcap", 3)
    read(path, config)
    checks.clear()
    read(path, config)
    assert len(checks) == N


def test_no_cache_neither_reads_nor_writes_a_memo(good, tmp_path, config, checks, monkeypatch):
    monkeypatch.setenv("WOLFCAL_CACHE_DIR", str(tmp_path / "cache"))
    path = damaged_copy(good, tmp_path / "bad.mcap", 3)
    with cache_enabled(False):
        read(path, config)
    assert not list((tmp_path / "cache").glob("*.images.json"))
    first = read(path, config)  # writes the memo
    checks.clear()
    with cache_enabled(False):
        assert read(path, config) == first
    assert len(checks) == N


def test_a_memo_that_does_not_fit_the_file_is_not_used(good, tmp_path, config, checks, monkeypatch):
    """A memo counting other images than the file holds (not written for this file) is ignored and rewritten."""
    monkeypatch.setenv("WOLFCAL_CACHE_DIR", str(tmp_path / "cache"))
    path = damaged_copy(good, tmp_path / "bad.mcap", 3)
    first = read(path, config)
    (memo,) = (tmp_path / "cache").glob("*.images.json")
    saved = json.loads(memo.read_text())
    saved["memo"]["images"] += 1
    saved["memo"]["damaged"] = []
    memo.write_text(json.dumps(saved))
    checks.clear()
    assert read(path, config) == first
    assert len(checks) == N
    checks.clear()
    assert read(path, config) == first  # the memo was written again, right
    assert checks == []


@pytest.mark.parametrize("frame_id", ["", "c", "cam", "camera", "head_camera_optical"])
@pytest.mark.parametrize("image_format", ["", "png", "mono8; png compressed mono8", "jpeg"])
def test_compressed_image_layout_reads_as_the_ros_decoder(frame_id, image_format):
    """The reader takes a CompressedImage's stamp and image bytes from the CDR layout (no copy of the image):
    the same as the general ROS 2 decoder for every padding of the two strings before the image."""
    from types import SimpleNamespace

    from mcap_ros2._dynamic import generate_dynamic, serialize_dynamic

    from wolfcal.io.msgdefs import COMPRESSED_IMAGE, MSGDEFS

    encode = serialize_dynamic(COMPRESSED_IMAGE, MSGDEFS[COMPRESSED_IMAGE])[COMPRESSED_IMAGE]
    decode = generate_dynamic(COMPRESSED_IMAGE, MSGDEFS[COMPRESSED_IMAGE])[COMPRESSED_IMAGE]
    for payload in (b"", b"\x89PNG\r\n\x1a\n" + bytes(range(61)), bytes(5)):
        data = encode({"header": {"stamp": {"sec": 1_700_000_123, "nanosec": 456_789}, "frame_id": frame_id},
                       "format": image_format, "data": payload})  # fmt: skip
        decoded = decode(data)
        stamp, image = compressed_image(data, SimpleNamespace(name=COMPRESSED_IMAGE), 7)
        assert stamp == decoded.header.stamp.sec * 10**9 + decoded.header.stamp.nanosec
        assert bytes(image) == bytes(decoded.data) == payload
        assert compressed_image(data[:-1], SimpleNamespace(name=COMPRESSED_IMAGE), 7) is None
        assert compressed_image(data, SimpleNamespace(name="sensor_msgs/msg/Image"), 7) is None
