"""Detection on all cores (wolfcal.vision.batch) and the detection cache (wolfcal.vision.cache)."""

from __future__ import annotations

import os
from pathlib import Path

import cv2
import numpy as np
import pytest
import yaml
from test_tag_detection import CAMERA, random_view, tag_target
from typer.testing import CliRunner

from wolfcal.cli import app
from wolfcal.errors import WolfcalError
from wolfcal.io import filememo
from wolfcal.vision import cache
from wolfcal.vision.batch import detect_encoded, iter_detect_encoded, task_size
from wolfcal.vision.cache import DetectorSettings, cache_enabled, cached_detect
from wolfcal.vision.edges import TAGS_PER_PASS
from wolfcal.vision.render import render_targets
from wolfcal.vision.tags import detect_tags

ROOT = Path(__file__).resolve().parents[2]
BINNED = CAMERA.scaled(0.25, 0.25, 512, 384)
FAMILIES = {"tag36h11": {3, 4}}


@pytest.fixture(scope="module")
def images() -> list[bytes]:
    """8 encoded 512x384 views of tags 3 and 4 (png and jpeg), and 2 without any tag."""
    rng = np.random.default_rng(3)
    out = []
    for k in range(8):
        tags = [tag_target("tag36h11", 3 + k % 2, random_view(BINNED, rng))]
        image = render_targets(BINNED, tags, noise_sigma=2.0, rng=rng)
        out.append(cv2.imencode(".png" if k % 3 else ".jpg", image)[1].tobytes())
    blank = render_targets(BINNED, [], noise_sigma=2.0, rng=rng)
    return out + [cv2.imencode(".png", blank)[1].tobytes()] * 2


def fresh(images: list[bytes], families=FAMILIES) -> list[dict]:
    """What detect_tags gives for each decoded image (the reference)."""
    out = []
    for data in images:
        image = cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_UNCHANGED)
        found = {}
        for family, ids in families.items():
            found.update(detect_tags(image, family, ids))
        out.append(found)
    return out


def assert_same(a: list[dict], b: list[dict]) -> None:
    """The same tags, the same corners (to 1e-9 px: tags of several images refined together differ by ~1e-13)."""
    assert len(a) == len(b)
    for x, y in zip(a, b, strict=True):
        assert x.keys() == y.keys()
        for k in x:
            np.testing.assert_allclose(x[k], y[k], rtol=0, atol=1e-9)


def never(n: int):
    """An image source that must not be read (the cache must answer)."""
    raise AssertionError("the images were read although the cache holds the detections")
    yield  # pragma: no cover


def test_workers_give_exactly_the_detections_of_detect_tags(images):
    reference = fresh(images)
    assert sum(len(d) for d in reference) == 8
    assert_same(detect_encoded(images, FAMILIES, workers=2), reference)
    assert_same(detect_encoded(images, FAMILIES, workers=2, processes=True), reference)
    assert_same(detect_encoded(images, FAMILIES, workers=1), reference)
    assert_same(detect_encoded(images[:2], FAMILIES, workers=2), reference[:2])  # in this thread


def test_consecutive_images_tags_are_refined_together_in_passes_of_bounded_size(images, monkeypatch):
    """The tags of consecutive images are refined in one pass, up to TAGS_PER_PASS tags (here 3), and give the
    corners of detect_tags on each image alone."""
    from wolfcal.vision import edges, tags

    passes = []

    def counted(found):
        passes.append(sum(f.count() for f in found))
        return refine_found(found)

    reference = fresh(images)
    refine_found = tags.refine_found
    monkeypatch.setattr(edges, "TAGS_PER_PASS", 3)
    monkeypatch.setattr(tags, "refine_found", counted)
    assert_same(detect_encoded(images, FAMILIES, workers=2), reference)
    assert passes == [3, 3, 2]  # 8 images of one tag each, then 2 blank ones (in the last pass)


def test_colour_images_give_the_corners_of_their_gray_version(images):
    """Colour jpeg and png (decoded straight to gray) give the tags and, within 0.03 px, the corners of
    detect_tags on the colour image (the gray levels differ by at most 1: up to 0.011 px seen here)."""
    gray = [cv2.imdecode(np.frombuffer(d, np.uint8), cv2.IMREAD_GRAYSCALE) for d in images[:4]]
    colour = [cv2.merge([g, np.clip(g.astype(int) + 12, 0, 255).astype(np.uint8), g]) for g in gray]
    for ext in (".jpg", ".png"):
        encoded = [cv2.imencode(ext, c)[1].tobytes() for c in colour]
        decoded = [cv2.imdecode(np.frombuffer(d, np.uint8), cv2.IMREAD_UNCHANGED) for d in encoded]
        reference = [{k: v for f, ids in FAMILIES.items() for k, v in detect_tags(c, f, ids).items()} for c in decoded]
        found = detect_encoded(encoded, FAMILIES, workers=1)
        assert [f.keys() for f in found] == [r.keys() for r in reference] and sum(map(len, found)) >= 3
        for f, r in zip(found, reference, strict=True):
            for k in f:
                np.testing.assert_allclose(f[k], r[k], atol=0.03)


@pytest.mark.parametrize("processes", [False, True], ids=["threads", "processes"])
def test_read_ahead_is_bounded(images, processes):
    """A long lazy input is read at most 2 tasks per worker ahead of the results, and the images whose tags wait
    for one refinement pass (at most TAGS_PER_PASS; only their tags' crops are kept)."""
    pulled = []

    def source():
        for k in range(60):
            pulled.append(k)
            yield images[k % len(images)]

    results = iter_detect_encoded(source(), FAMILIES, workers=2, processes=processes)
    next(results)
    assert len(pulled) <= 2 * 2 * task_size(images[0], processes) + TAGS_PER_PASS
    assert sum(1 for _ in results) == 59


def test_undecodable_image_is_named(images):
    with pytest.raises(WolfcalError, match="sample 5: the image cannot be decoded"):
        detect_encoded([*images[:5], b"\x89PNG broken", *images[:3]], FAMILIES, labels=lambda i: f"sample {i}")


@pytest.fixture
def capture(tmp_path, images) -> tuple[Path, list[int]]:
    """A file standing in for a capture (the cache keys on its bytes) and one stamp per image."""
    path = tmp_path / "capture.mcap"
    path.write_bytes(b"".join(images))
    return path, [1_000_000 * (k + 1) for k in range(len(images))]


def entries(folder: Path) -> list[Path]:
    return sorted(folder.glob("*.npz"))


def test_second_run_reads_the_cache_and_equals_a_fresh_detection(capture, images, tmp_path, monkeypatch):
    monkeypatch.setenv("WOLFCAL_CACHE_DIR", str(tmp_path / "cache"))
    path, stamps = capture
    settings = DetectorSettings.of(FAMILIES)
    first = cached_detect(path, "head", stamps, iter(images), settings)
    assert len(entries(tmp_path / "cache")) == 1
    second = cached_detect(path, "head", stamps, never(0), settings)
    assert_same(second, fresh(images))
    assert_same(first, second)
    other_camera = cached_detect(path, "tripod", stamps, iter(images[::-1]), settings)  # its own entry
    assert_same(other_camera, fresh(images[::-1]))
    assert len(entries(tmp_path / "cache")) == 2


def test_stale_entry_after_the_capture_changes_is_not_used(capture, images, tmp_path, monkeypatch):
    """Same size, same mtime, one byte changed: detected again (content hash, not size + mtime)."""
    monkeypatch.setenv("WOLFCAL_CACHE_DIR", str(tmp_path / "cache"))
    path, stamps = capture
    settings = DetectorSettings.of(FAMILIES)
    cached_detect(path, "head", stamps, iter(images), settings)
    info = path.stat()
    data = bytearray(path.read_bytes())
    data[-1] ^= 0xFF
    path.write_bytes(bytes(data))
    os.utime(path, ns=(info.st_atime_ns, info.st_mtime_ns))
    changed = images[::-1]  # what the "new" capture holds: a wrong answer would show
    assert_same(cached_detect(path, "head", stamps, iter(changed), settings), fresh(changed))


def test_a_remembered_digest_holds_only_while_the_file_is_the_same(capture, tmp_path, monkeypatch):
    """The file's digest is remembered by its identity; a file changed less than RACY_NS before hashing is not
    remembered, and a replaced file (new inode, same size and mtime) is hashed again."""
    folder = tmp_path / "cache"
    monkeypatch.setenv("WOLFCAL_CACHE_DIR", str(folder))
    path, _ = capture
    true_digest = cache.content_digest(path)
    assert cache.hash_file(path) == true_digest
    assert cache.remembered_digest(path) == (None, True)  # just written: too recent to trust, but hashed before
    monkeypatch.setattr(filememo, "RACY_NS", 0)
    assert cache.remembered_digest(path) == (true_digest, True)
    (memo,) = folder.glob("*.digest.json")
    memo.write_text(memo.read_text().replace(true_digest, "f" * 64))
    assert cache.remembered_digest(path) == ("f" * 64, True)  # remembered: not hashed again
    info = path.stat()
    data = bytearray(path.read_bytes())
    data[-1] ^= 0xFF
    replacement = tmp_path / "new.mcap"
    replacement.write_bytes(bytes(data))
    os.utime(replacement, ns=(info.st_atime_ns, info.st_mtime_ns))
    replacement.replace(path)  # re-recorded: same name, size and mtime
    assert cache.remembered_digest(path) == (None, True)  # a new inode: hashed again
    assert cache.hash_file(path) == cache.content_digest(path) != true_digest


def test_a_first_run_saves_its_entry_and_a_copied_capture_finds_it(capture, images, tmp_path, monkeypatch):
    """A path never hashed is hashed and its detections saved; a copy of a cached capture (a new path, the same
    content) is answered by the entry, whatever its images would have given (reversed
    here, so a fresh detection would show)."""
    folder = tmp_path / "cache"
    monkeypatch.setenv("WOLFCAL_CACHE_DIR", str(folder))
    path, stamps = capture
    settings = DetectorSettings.of(FAMILIES)
    assert cache.remembered_digest(path) == (None, False)
    assert_same(cached_detect(path, "head", stamps, iter(images), settings), fresh(images))
    assert cache.remembered_digest(path)[1] and len(entries(folder)) == 1
    assert_same(cached_detect(path, "head", stamps, never(0), settings), fresh(images))
    copy = tmp_path / "moved" / "capture.mcap"
    copy.parent.mkdir()
    copy.write_bytes(path.read_bytes())
    assert_same(cached_detect(copy, "head", stamps, iter(images[::-1]), settings), fresh(images))
    assert len(entries(folder)) == 1


def test_entry_for_other_settings_or_stamps_is_not_used(capture, images, tmp_path, monkeypatch):
    monkeypatch.setenv("WOLFCAL_CACHE_DIR", str(tmp_path / "cache"))
    path, stamps = capture
    cached_detect(path, "head", stamps, iter(images), DetectorSettings.of(FAMILIES))
    only_3 = {"tag36h11": {3}}
    assert_same(cached_detect(path, "head", stamps, iter(images), DetectorSettings.of(only_3)), fresh(images, only_3))
    subpix = cached_detect(path, "head", stamps, iter(images), DetectorSettings.of(FAMILIES, "subpix"))
    assert_same(subpix, [{k: detect_tags(cv2.imdecode(np.frombuffer(d, np.uint8), -1), "tag36h11", {3, 4}, "subpix")[k]
                          for k in f} for d, f in zip(images, fresh(images), strict=True)])  # fmt: skip
    shifted = [s + 1 for s in stamps]  # another reader kept other frames
    reversed_images = images[::-1]
    got = cached_detect(path, "head", shifted, iter(reversed_images), DetectorSettings.of(FAMILIES))
    assert_same(got, fresh(reversed_images))


def test_foreign_or_damaged_entries_are_not_used(capture, images, tmp_path, monkeypatch):
    folder = tmp_path / "cache"
    monkeypatch.setenv("WOLFCAL_CACHE_DIR", str(folder))
    path, stamps = capture
    settings = DetectorSettings.of(FAMILIES)
    cached_detect(path, "head", stamps, iter(images), settings)
    (entry,) = entries(folder)
    other = tmp_path / "other.mcap"
    other.write_bytes(path.read_bytes() + b"x")
    cached_detect(other, "head", stamps, iter(images), settings)
    (foreign,) = [e for e in entries(folder) if e != entry]
    foreign.write_bytes(entry.read_bytes())  # the first file's entry under the second file's name
    assert_same(cached_detect(other, "head", stamps, iter(images[::-1]), settings), fresh(images[::-1]))
    entry.write_bytes(entry.read_bytes()[:100])  # torn
    assert_same(cached_detect(path, "head", stamps, iter(images[::-1]), settings), fresh(images[::-1]))
    assert_same(cached_detect(path, "head", stamps, never(0), settings), fresh(images[::-1]))  # rewritten whole
    # what a crash can leave of a file written without fsync: empty, or its blocks zeroed
    whole = entry.read_bytes()
    for left in (b"", whole[:-600] + bytes(600), whole[:200] + bytes(len(whole) - 400) + whole[-200:]):
        entry.write_bytes(left)
        assert_same(cached_detect(path, "head", stamps, iter(images), settings), fresh(images))
        entry.write_bytes(whole)


def test_no_cache_neither_reads_nor_writes(capture, images, tmp_path, monkeypatch):
    folder = tmp_path / "cache"
    monkeypatch.setenv("WOLFCAL_CACHE_DIR", str(folder))
    path, stamps = capture
    settings = DetectorSettings.of(FAMILIES)
    with cache_enabled(False):
        cached_detect(path, "head", stamps, iter(images), settings)
    assert entries(folder) == []
    cached_detect(path, "head", stamps, iter(images), settings)
    with cache_enabled(False):
        assert_same(cached_detect(path, "head", stamps, iter(images[::-1]), settings), fresh(images[::-1]))


def test_unwritable_cache_still_detects(capture, images, tmp_path, monkeypatch):
    blocker = tmp_path / "file"
    blocker.write_text("not a folder")
    monkeypatch.setenv("WOLFCAL_CACHE_DIR", str(blocker / "cache"))
    path, stamps = capture
    assert_same(cached_detect(path, "head", stamps, iter(images), DetectorSettings.of(FAMILIES)), fresh(images))


def test_detect_by_source_keeps_input_order_across_files_and_cameras(capture, images, tmp_path, monkeypatch):
    monkeypatch.setenv("WOLFCAL_CACHE_DIR", str(tmp_path / "cache"))
    path, stamps = capture
    other = tmp_path / "other.mcap"
    other.write_bytes(b"another capture")
    sources = [str(path), str(other), "", str(path)] * 3  # "" : samples made in memory, never cached
    names = ["head", "head", "head", "tripod"] * 3
    picks = [k % len(images) for k in range(len(sources))]
    found = cache.detect_by_source(sources, list(range(len(sources))), lambda ix: (images[picks[k]] for k in ix), names,
                                   DetectorSettings.of(FAMILIES))  # fmt: skip
    assert_same(found, fresh([images[k] for k in picks]))
    assert len(entries(tmp_path / "cache")) == 3  # (capture, head), (other, head), (capture, tripod)


def test_default_location_follows_xdg(monkeypatch, tmp_path):
    monkeypatch.delenv("WOLFCAL_CACHE_DIR")
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    assert cache.cache_dir() == tmp_path / "wolfcal" / "detections"


def test_fit_twice_uses_the_cache_and_no_cache_skips_it(tmp_path, monkeypatch):
    """The demo capture: the second fit gives the same result from the cache; --no-cache writes no entry."""
    folder = tmp_path / "cache"
    monkeypatch.setenv("WOLFCAL_CACHE_DIR", str(folder))
    capture = ROOT / "captures" / "demo.mcap"
    robot = ROOT / "configs" / "wolfgang"
    runner = CliRunner()
    plain = runner.invoke(app, ["fit", str(capture), "--robot", str(robot), "--out", str(tmp_path / "a"), "--no-cache"])
    assert plain.exit_code == 0, plain.output
    assert entries(folder) == []
    for out in ("b", "c"):
        result = runner.invoke(app, ["fit", str(capture), "--robot", str(robot), "--out", str(tmp_path / out)])
        assert result.exit_code == 0, result.output
        assert len(entries(folder)) == 1
    values = [yaml.safe_load((tmp_path / out / "result.yaml").read_text())["corrections"] for out in "abc"]
    assert values[0] == values[1] == values[2]
