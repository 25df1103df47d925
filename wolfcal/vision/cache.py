"""Detection cache: the tag corners of a capture file's images, so a second fit or evaluation skips detection.

Where: `$WOLFCAL_CACHE_DIR`, else `$XDG_CACHE_HOME/wolfcal/detections`, else `~/.cache/wolfcal/detections`.
Not beside the capture: capture folders are often read-only (a USB stick, a shared data set, the repository's
demo captures) and travel with the data; an entry keyed by content stays valid wherever the file is copied.
Entries are small (corners only); delete the folder at any time.

Key: one entry per (capture file, camera), named by the XXH3-128 hash of the file's whole content (size and mtime
are not enough: an edited or re-recorded file can keep both), the camera name, and the detector settings
(families and ids, refinement, wolfcal's detector version, OpenCV's version). An entry stores its full key
and the image stamps it was made for; it is used only if both match, so a stale or foreign entry (another
file, other settings, another reader that kept other frames) is detected again and overwritten. Entries are
written atomically (temporary file, rename) without fsync (a scratch file, `wolfcal.atomic`); one that a crash
left empty or torn fails `_load`'s checks and is detected again. A file's digest is remembered beside the entries
(`hash_file`, `remembered_digest`) as a memo tied to the file's identity (`wolfcal.io.filememo`: a file changed
since is hashed again, a digest taken less than RACY_NS after the file's last change is not trusted), so a cache
hit reads neither the file's content nor its images.

Why XXH3-128 and not hashlib's SHA-256: the digest names content and guards against no adversary (whoever could
forge a collision could as well edit the cache folder); at 128 bits two different captures share a digest with a
chance of about 1e-38; and it reads a multi-GB recording at the speed of the disk, where SHA-256 would add
seconds to a first run. The same hash names the cache's files.
"""

from __future__ import annotations

import json
import time
import zipfile
from collections.abc import Callable, Generator, Iterable, Mapping
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import xxhash

from wolfcal.atomic import atomic_output
from wolfcal.io.filememo import cache_dir, caching, identity_and_memo, name_digest, recall, write_memo
from wolfcal.io.filememo import cache_enabled as cache_enabled  # `--no-cache`: this cache and the reader's memos
from wolfcal.vision.batch import Detections, iter_detect_checked
from wolfcal.vision.found_tags import FoundTags

# bump when detection or refinement changes its corners (4: refined in crops, ~1e-5 px; 5: window and profile
# length from the cell across each edge, profiles clear of the other edge at acute corners; 6: profiles of large
# cells averaged in bins, a settled tag not iterated again; 7: window sums and bins summed on their own, not by a
# cumulative sum or matmul, ~1e-5 px)
# 8: each tag refined in a crop of its own (smaller float32 sample coordinates, ~1e-5 px)
DETECTOR_VERSION = 9  # 9: consecutive images' tags refined together, up to TAGS_PER_PASS a pass (~1e-13 px)
FORMAT = 1  # entry layout
DIGEST = "xxh3_128"  # the content digest's name in memos and entry keys (entries keyed by "sha256" before)


@dataclass(frozen=True)
class DetectorSettings:
    """What the detections depend on besides the image: {family: ids (None: all)} and the refinement."""

    families: tuple[tuple[str, tuple[int, ...] | None], ...]
    refine: str = "edges"

    @classmethod
    def of(cls, families: Mapping[str, set[int] | None], refine: str = "edges") -> DetectorSettings:
        """The settings of {family: ids (None: all)} and `refine`, in a canonical order (families and ids sorted)."""
        items = sorted((f, None if ids is None else tuple(sorted(ids))) for f, ids in families.items())
        return cls(tuple(items), refine)

    def family_map(self) -> dict[str, set[int] | None]:
        """{family: ids (None: all)}, as `of` takes it."""
        return {f: None if ids is None else set(ids) for f, ids in self.families}

    def describe(self) -> dict:
        """The settings as the entry key states them, with wolfcal's detector version and OpenCV's version."""
        import cv2

        return {
            "families": [[f, None if ids is None else list(ids)] for f, ids in self.families],
            "refine": self.refine,
            "detector_version": DETECTOR_VERSION,
            "opencv": cv2.__version__,
        }


def content_digest(path: Path, chunk: int = 1 << 20) -> str:
    """XXH3-128 hex digest of a file's whole content (see the module docstring for why this hash)."""
    digest = xxhash.xxh3_128()
    with open(path, "rb") as handle:
        while block := handle.read(chunk):
            digest.update(block)
    return digest.hexdigest()


def remembered_digest(path: Path) -> tuple[str | None, bool]:
    """(the file's digest as remembered for its present identity, or None: never hashed, changed since, or hashed
    too soon after a change; whether this path was hashed before at all); reads no more than the memo
    (`filememo.recall`)."""
    memo, seen = recall(path, "digest")
    digest = memo.get(DIGEST) if memo is not None else None
    return (str(digest) if digest is not None else None), seen


def hash_file(path: Path) -> str:
    """`content_digest` of the file, remembered beside the cache entries for `remembered_digest` (`filememo`:
    trusted only if the file changed RACY_NS or more before it was hashed; remembered also when too recent to
    trust, so that `remembered_digest` tells the path was hashed before)."""
    identity, _ = identity_and_memo(path, "digest")
    hashed_ns = time.time_ns()
    digest = content_digest(path)
    write_memo(path, "digest", identity, hashed_ns, {DIGEST: digest})
    return digest


def _entry_key(digest: str, camera_name: str, settings: DetectorSettings) -> str:
    """The key of a cache entry (JSON): the format, the file's content hash, the camera and the detector settings."""
    return json.dumps({"format": FORMAT, f"content_{DIGEST}": digest, "camera": camera_name, **settings.describe()})


def _entry_path(key: str) -> Path:
    """The entry's file in the cache folder, named by the hash of its key."""
    return cache_dir() / f"{name_digest(key)}.npz"


def _load(path: Path, key: str, stamps: np.ndarray) -> FoundTags | None:
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
    return FoundTags.from_arrays(counts, ids, corners)


def _save(path: Path, key: str, stamps: np.ndarray, detections: FoundTags) -> None:
    """Write the entry atomically; a cache that cannot be written is skipped (it only saves time)."""
    counts, ids, corners = detections.arrays()
    try:
        with atomic_output(path, scratch=True) as handle:
            np.savez(handle, key=np.array(key), stamps=stamps, counts=counts, ids=ids, corners=corners)
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
) -> FoundTags:
    """Detections of the images of one camera in one capture file, from the cache when it holds them.

    `stamps` [ns]: one per image, in order; `images`: their encoded bytes, read only when the cache misses.
    Returns per image {tag id: (4, 2) corners [px]} as `wolfcal.vision.batch.detect_encoded` gives them, kept
    compactly as they come (`FoundTags`; `workers` processes, default one per core; `labels(i)` names image i in
    errors).
    """
    stamps_array = np.asarray(stamps, dtype=np.int64)

    def detect() -> Generator[Detections, None, None]:
        return iter_detect_checked(images, settings.family_map(), settings.refine, workers, progress, len(stamps),
                                   labels)  # fmt: skip

    if not (caching() and bool(str(path)) and Path(path).is_file()):  # samples made in memory have no file
        return _all(detect(), stamps)
    try:
        digest = remembered_digest(Path(path))[0] or hash_file(Path(path))
    except OSError:
        return _all(detect(), stamps)
    key = _entry_key(digest, camera_name, settings)
    found = _load(_entry_path(key), key, stamps_array)
    if found is not None:
        if progress:
            progress(len(found), len(found))
        return found
    found = _all(detect(), stamps)
    _save(_entry_path(key), key, stamps_array, found)
    return found


def _all(detections: Iterable[Detections], stamps: list[int] | np.ndarray) -> FoundTags:
    """The detections kept as they come (`FoundTags`), one image per stamp."""
    return _one_per_stamp(FoundTags.of(detections), stamps)


def _one_per_stamp(found: FoundTags, stamps: list[int] | np.ndarray) -> FoundTags:
    """`found`, checked to hold one image per stamp."""
    if len(found) != len(stamps):
        raise ValueError(f"{len(found)} images but {len(stamps)} stamps")
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
) -> FoundTags:
    """`cached_detect` for images from several capture files and cameras: image i came from `sources[i]` (a
    path) with stamp `stamps[i]` [ns], seen by `camera_name` (one name for all, or one per image);
    `images(indices)` gives the encoded bytes of those images in that order, lazily (a generator: read only when
    the cache misses, as the detection goes). One cache entry per (file, camera). Results in input order."""
    names = [camera_name] * len(sources) if isinstance(camera_name, str) else list(camera_name)
    groups: dict[tuple[str, str], list[int]] = {}
    for index, key in enumerate(zip(sources, names, strict=True)):
        groups.setdefault(key, []).append(index)
    parts, order = [], []
    done = 0
    for (source, name), indices in groups.items():
        step = (lambda n, _t, base=done: progress(base + n, len(sources))) if progress else None
        named = (lambda k, ix=indices: labels(ix[k])) if labels else None
        times = [stamps[i] for i in indices]
        parts.append(cached_detect(Path(source), name, times, images(indices), settings, step, named, workers))
        order += indices
        done += len(indices)
    if len(parts) == 1:  # one file and camera: already in input order
        return parts[0]
    return FoundTags.concat(parts).take(np.argsort(order))
