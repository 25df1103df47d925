"""What wolfcal remembers about a capture file between runs, beside the detection cache, and the switch for both.

Where: `$WOLFCAL_CACHE_DIR`, else `$XDG_CACHE_HOME/wolfcal/detections`, else `~/.cache/wolfcal/detections`.
A memo is tied to a file by its path and identity (device, inode, size, modification and status-change times
[ns]): any write to the file changes its status-change time (the kernel sets it; no tool can set it back), so a
memo of a changed file is not used. As git does for its index, a memo taken less than RACY_NS after the file's last
change is not trusted (a write within the same clock tick could keep every time). `--no-cache`
(`cache_enabled(False)`) turns off the detection cache and these memos.
"""

from __future__ import annotations

import json
import os
from collections.abc import Generator
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path

import xxhash

from wolfcal.atomic import atomic_output

RACY_NS = 2_000_000_000  # a memo taken this soon after the file's last change is not trusted [ns]
_enabled: ContextVar[bool] = ContextVar("wolfcal_detection_cache", default=True)


def cache_dir() -> Path:
    """The cache folder (see the module docstring)."""
    if os.environ.get("WOLFCAL_CACHE_DIR"):
        return Path(os.environ["WOLFCAL_CACHE_DIR"])
    base = os.environ.get("XDG_CACHE_HOME") or str(Path.home() / ".cache")
    return Path(base) / "wolfcal" / "detections"


@contextmanager
def cache_enabled(enabled: bool) -> Generator[None, None, None]:
    """Within the block, the detection cache and the file memos are read and written only if `enabled` (CLI
    `--no-cache`)."""
    token = _enabled.set(enabled)
    try:
        yield
    finally:
        _enabled.reset(token)


def caching() -> bool:
    """Whether the cache and memos are on (`cache_enabled`)."""
    return _enabled.get()


def identity_and_memo(path: Path, kind: str) -> tuple[list[int], Path]:
    """The file's identity (device, inode, size, modification and status-change times [ns]) and the path of its
    memo of `kind` (e.g. 'digest') in the cache folder (named by the hash of its resolved path)."""
    info = os.stat(path)
    identity = [info.st_dev, info.st_ino, info.st_size, info.st_mtime_ns, info.st_ctime_ns]
    return identity, cache_dir() / f"{name_digest(str(Path(path).resolve()))}.{kind}.json"


def name_digest(text: str) -> str:
    """The name of a cache file for `text` (a key or a path): its XXH3-128 hex digest (`wolfcal.vision.cache`)."""
    return xxhash.xxh3_128(text.encode()).hexdigest()


def read_memo(path: Path, kind: str) -> dict | None:
    """The memo of `kind` of the file, if one was taken of the file as it is now, RACY_NS or more after its last
    change; None otherwise (none, torn, foreign, the file changed or cannot be looked at, or taken too soon)."""
    try:
        return recall(path, kind)[0]
    except OSError:
        return None


def recall(path: Path, kind: str) -> tuple[dict | None, bool]:
    """(`read_memo`, whether a memo of `kind` was taken of this path at all, trusted or not: none or torn is
    False, one of another file there or too recent is True). OSError when the file cannot be looked at."""
    identity, memo = identity_and_memo(path, kind)
    try:
        saved = json.loads(memo.read_text())
    except (OSError, ValueError):  # none yet, or torn
        return None, False
    try:
        if saved["identity"] == identity and saved["taken_ns"] - identity[4] >= RACY_NS:
            return (saved["memo"] if isinstance(saved["memo"], dict) else None), True
    except (KeyError, TypeError):  # foreign
        pass
    return None, True


def write_memo(path: Path, kind: str, identity: list[int], taken_ns: int, memo: dict) -> None:
    """Remember `memo` of the file whose identity was `identity` when the memo was begun at `taken_ns` (time.time_ns);
    atomic, without fsync (a scratch file); skipped when the cache folder cannot be written (a memo only saves time)."""
    try:
        _, where = identity_and_memo(path, kind)
        with atomic_output(where, scratch=True) as handle:
            handle.write(json.dumps({"identity": identity, "taken_ns": taken_ns, "memo": memo}).encode())
    except OSError:
        pass
