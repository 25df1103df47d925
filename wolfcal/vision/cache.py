"""Detection cache: the tag corners of a capture file's images, so a second fit or evaluation skips detection.

Where: `$WOLFCAL_CACHE_DIR`, else `$XDG_CACHE_HOME/wolfcal/detections`, else `~/.cache/wolfcal/detections`.
Not beside the capture: capture folders are often read-only (a USB stick, a shared data set, the repository's
demo captures) and travel with the data; an entry keyed by content stays valid wherever the file is copied.
Entries are small (corners only: ~0.3 kB per image); delete the folder at any time.

Key: one entry per (capture file, camera), named by the SHA-256 of the file's whole content (size and mtime
are not enough: an edited or re-recorded file can keep both), the camera name, and the detector settings
(families and ids, refinement, wolfcal's detector version, OpenCV's version). An entry stores its full key
and the image stamps it was made for; it is used only if both match, so a stale or foreign entry (another
file, other settings, another reader that kept other frames) is detected again and overwritten. Entries are
written atomically (temporary file, rename) without fsync (a scratch file, `wolfcal.atomic`: the two fsyncs of each
of a first run's two writes waited 0.1-0.4 s for a shared disk); one that a crash left empty or torn fails
`_load`'s checks and is detected again. Hashing costs about 0.07-0.15 s per 100 MB (bench/bench_detection.py),
so a file's digest is remembered beside the entries (`file_digest`) with the file's identity: device, inode, size,
modification and status-change times [ns]. Any write to the file changes its status-change time (the kernel sets
it; no tool can set it back), so the file is hashed again; and, as git does for its index, a digest taken less than
2 s after the file's last change is not trusted (a write within the same clock tick could keep every time).
"""

from __future__ import annotations

import hashlib
import json
import os
import time
import zipfile
from collections.abc import Callable, Iterable, Mapping
from contextlib import contextmanager
from contextvars import ContextVar
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wolfcal.atomic import atomic_output
from wolfcal.vision.batch import Detections, detect_encoded

# bump when detection or refinement changes its corners (4: refined in crops, ~1e-5 px; 5: window and profile
# length from the cell across each edge, profiles clear of the other edge at acute corners)
DETECTOR_VERSION = 5
FORMAT = 1  # entry layout
RACY_NS = 2_000_000_000  # a digest taken this soon after the file's last change is not remembered [ns]
_enabled: ContextVar[bool] = ContextVar("wolfcal_detection_cache", default=True)


@dataclass(frozen=True)
class DetectorSettings:
    """What the detections depend on besides the image: {family: ids (None: all)} and the refinement."""

    families: tuple[tuple[str, tuple[int, ...] | None], ...]
    refine: str = "edges"

    @classmethod
    def of(cls, families: Mapping[str, set[int] | None], refine: str = "edges") -> DetectorSettings:
        items = sorted((f, None if ids is None else tuple(sorted(ids))) for f, ids in families.items())
        return cls(tuple(items), refine)

    def family_map(self) -> dict[str, set[int] | None]:
        return {f: None if ids is None else set(ids) for f, ids in self.families}

    def describe(self) -> dict:
        import cv2

        return {
            "families": [[f, None if ids is None else list(ids)] for f, ids in self.families],
            "refine": self.refine,
            "detector_version": DETECTOR_VERSION,
            "opencv": cv2.__version__,
        }


def cache_dir() -> Path:
    """The cache folder (see the module docstring)."""
    if os.environ.get("WOLFCAL_CACHE_DIR"):
        return Path(os.environ["WOLFCAL_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "wolfcal" / "detections"


@contextmanager
def cache_enabled(enabled: bool):
    """Within the block, `cached_detect` reads and writes the cache only if `enabled` (CLI `--no-cache`)."""
    token = _enabled.set(enabled)
    try:
        yield
    finally:
        _enabled.reset(token)


def content_digest(path: Path, chunk: int = 1 << 20) -> str:
    """SHA-256 hex digest of a file's whole content."""
    digest = hashlib.sha256()
    with open(path, "rb") as handle:
        while block := handle.read(chunk):
            digest.update(block)
    return digest.hexdigest()


def file_digest(path: Path) -> str:
    """`content_digest` of a file, remembered in the cache folder by the file's identity (module docstring)."""
    before = os.stat(path)
    identity = [before.st_dev, before.st_ino, before.st_size, before.st_mtime_ns, before.st_ctime_ns]
    memo = cache_dir() / f"{hashlib.sha256(str(Path(path).resolve()).encode()).hexdigest()[:40]}.digest.json"
    try:
        saved = json.loads(memo.read_text())
        if saved["identity"] == identity and saved["hashed_ns"] - before.st_ctime_ns >= RACY_NS:
            return str(saved["sha256"])
    except (OSError, ValueError, KeyError, TypeError):  # none yet, torn or foreign
        pass
    hashed_ns = time.time_ns()
    digest = content_digest(path)
    if hashed_ns - before.st_ctime_ns >= RACY_NS:
        try:
            with atomic_output(memo, scratch=True) as handle:
                handle.write(json.dumps({"identity": identity, "hashed_ns": hashed_ns, "sha256": digest}).encode())
        except OSError:
            pass
    return digest


def _entry_key(digest: str, camera_name: str, settings: DetectorSettings) -> str:
    return json.dumps({"format": FORMAT, "content_sha256": digest, "camera": camera_name, **settings.describe()})


def _entry_path(key: str) -> Path:
    return cache_dir() / f"{hashlib.sha256(key.encode()).hexdigest()[:40]}.npz"


def _load(path: Path, key: str, stamps: np.ndarray) -> list[Detections] | None:
    """The entry's detections if it exists, is whole, and was made for this key and these stamps."""
    try:
        with np.load(path, allow_pickle=False) as entry:
            if str(entry["key"]) != key or not np.array_equal(entry["stamps"], stamps):
                return None
            counts, ids, corners = entry["counts"], entry["ids"], entry["corners"]
    except (OSError, ValueError, KeyError, EOFError, zipfile.BadZipFile):  # missing, torn or foreign
        return None
    if len(counts) != len(stamps) or counts.sum() != len(ids) or corners.shape != (len(ids), 4, 2):
        return None
    starts = np.concatenate([[0], np.cumsum(counts)])
    return [
        {int(i): c for i, c in zip(ids[a:b], corners[a:b])} for a, b in zip(starts[:-1], starts[1:], strict=True)
    ]


def _save(path: Path, key: str, stamps: np.ndarray, detections: list[Detections]) -> None:
    """Write the entry atomically; a cache that cannot be written is skipped (it only saves time)."""
    ids = [tag for found in detections for tag in sorted(found)]
    corners = [found[tag] for found in detections for tag in sorted(found)]
    try:
        with atomic_output(path, scratch=True) as handle:
            np.savez(
                handle,
                key=np.array(key),
                stamps=stamps,
                counts=np.array([len(found) for found in detections], dtype=np.int64),
                ids=np.array(ids, dtype=np.int64),
                corners=np.array(corners, dtype=np.float64).reshape(-1, 4, 2),
            )
    except OSError:
        pass


def cached_detect(
    path: Path,
    camera_name: str,
    stamps: list[int],
    images: Iterable[bytes],
    settings: DetectorSettings,
    progress: Callable[[int, int | None], None] | None = None,
    labels: Callable[[int], str] | None = None,
    workers: int | None = None,
) -> list[Detections]:
    """Detections of the images of one camera in one capture file, from the cache when it holds them.

    `stamps` [ns]: one per image, in order; `images`: their encoded bytes, read only when the cache misses.
    Returns per image {tag id: (4, 2) corners [px]} as `wolfcal.vision.batch.detect_encoded` gives them
    (`workers` processes, default one per core; `labels(i)` names image i in errors).
    """
    stamps_array = np.asarray(stamps, dtype=np.int64)
    use = _enabled.get() and bool(str(path)) and Path(path).is_file()  # samples made in memory have no file
    if use:
        try:
            key = _entry_key(file_digest(Path(path)), camera_name, settings)
        except OSError:
            use = False
    if use:
        entry = _entry_path(key)
        found = _load(entry, key, stamps_array)
        if found is not None:
            if progress:
                progress(len(found), len(found))
            return found
    found = detect_encoded(images, settings.family_map(), settings.refine, workers, progress, len(stamps), labels)
    if len(found) != len(stamps):
        raise ValueError(f"{len(found)} images but {len(stamps)} stamps")
    if use:
        _save(entry, key, stamps_array, found)
    return found


def detect_by_source(
    sources: list[str],
    stamps: list[int],
    images: Callable[[list[int]], Iterable[bytes]],
    camera_name: str | list[str],
    settings: DetectorSettings,
    progress: Callable[[int, int], None] | None = None,
    labels: Callable[[int], str] | None = None,
    workers: int | None = None,
) -> list[Detections]:
    """`cached_detect` for images from several capture files and cameras: image i came from `sources[i]` (a
    path) with stamp `stamps[i]` [ns], seen by `camera_name` (one name for all, or one per image);
    `images(indices)` gives the encoded bytes of those images in that order, lazily (a generator: read only when
    the cache misses, as the detection goes). One cache entry per (file, camera). Results in input order."""
    names = [camera_name] * len(sources) if isinstance(camera_name, str) else list(camera_name)
    groups: dict[tuple[str, str], list[int]] = {}
    for index, key in enumerate(zip(sources, names, strict=True)):
        groups.setdefault(key, []).append(index)
    found: list[Detections | None] = [None] * len(sources)
    done = 0
    for (source, name), indices in groups.items():
        step = (lambda n, _t, base=done: progress(base + n, len(sources))) if progress else None
        named = (lambda k, ix=indices: labels(ix[k])) if labels else None
        times = [stamps[i] for i in indices]
        results = cached_detect(Path(source), name, times, images(indices), settings, step, named, workers)
        for i, result in zip(indices, results, strict=True):
            found[i] = result
        done += len(indices)
    return found  # type: ignore[return-value]
