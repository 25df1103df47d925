"""Atomic file output: write to a temporary file in the target folder, fsync, rename over the target.

Scratch files (`atomic_output(path, scratch=True)`: cache entries, which only save time) are renamed without
fsync and at once, never staged in an output set: an fsync of the file and its folder waits for the disk, often
longer than the rest of a cached fit, and a crash may then leave a scratch file empty or torn, which its reader
must detect and ignore (`wolfcal.vision.cache` checks every entry whole and keyed).

`output_set()` makes the outputs of one command a set: inside it, every atomic write (and `replace_file`,
`remove_output`) is staged as a temporary file beside its target, and nothing replaces or removes a target
until the block ends without an exception; then all staged files are renamed into place together. A command
that fails halfway (bad URDF, Ctrl-C, a full disk) leaves the outputs of an earlier run as they were and no new
ones: never a lone result.yaml without its calibrated.urdf. Folders the set made (`make_folder`, the parents of
its files) are removed again when it fails, so that a failed run leaves nothing behind to block the next one.
"""

from __future__ import annotations

import contextvars
import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path
from typing import BinaryIO

# (staged temporary file or None for a removal, target) of the output set being written, if any
_STAGED: contextvars.ContextVar[list[tuple[Path | None, Path]] | None] = contextvars.ContextVar(
    "wolfcal_output_set", default=None
)
# folders made by the output set being written, outermost first
_MADE: contextvars.ContextVar[list[Path] | None] = contextvars.ContextVar("wolfcal_output_folders", default=None)


def _umask() -> int:
    mask = os.umask(0)
    os.umask(mask)
    return mask


def _fsync_directory(folder: Path) -> None:
    """Make a rename durable (POSIX); a no-op where directories cannot be opened."""
    try:
        fd = os.open(folder, os.O_RDONLY)
    except OSError:
        return
    try:
        os.fsync(fd)
    finally:
        os.close(fd)


@contextmanager
def output_set() -> Iterator[None]:
    """Stage every atomic write inside the block; rename all into place only when the block succeeds."""
    outer = _STAGED.get()
    if outer is not None:  # nested: part of the enclosing set
        yield
        return
    staged: list[tuple[Path | None, Path]] = []
    made: list[Path] = []
    token, made_token = _STAGED.set(staged), _MADE.set(made)
    try:
        yield
    except BaseException:
        for tmp, _ in staged:
            if tmp is not None:
                tmp.unlink(missing_ok=True)
        for folder in reversed(made):
            try:
                folder.rmdir()  # only when empty: a file the set did not stage stays, and so does its folder
            except OSError:
                pass
        raise
    finally:
        _STAGED.reset(token)
        _MADE.reset(made_token)
    for tmp, target in staged:
        if tmp is None:
            target.unlink(missing_ok=True)
        else:
            os.replace(tmp, target)
    for folder in {target.parent for _, target in staged}:
        _fsync_directory(folder)


def make_folder(folder: str | Path) -> Path:
    """Make `folder` and its missing parents; inside an output set, those made are removed again if it fails."""
    folder = Path(folder)
    missing = [f for f in [folder, *folder.parents] if not f.exists()][::-1]  # outermost first
    folder.mkdir(parents=True, exist_ok=True)
    made = _MADE.get()
    if made is not None:
        made.extend(missing)
    return folder


def replace_file(src: Path, target: Path) -> None:
    """Rename the finished file `src` to `target` now, or when the enclosing output set succeeds (and remove
    `src` if it fails)."""
    staged = _STAGED.get()
    if staged is None:
        os.replace(src, target)
        _fsync_directory(target.parent)
    else:
        staged.append((Path(src), Path(target)))


def remove_output(path: Path) -> bool:
    """Remove an output of an earlier run (now, or when the enclosing output set succeeds); whether it existed."""
    if not path.exists():
        return False
    staged = _STAGED.get()
    if staged is None:
        path.unlink()
    else:
        staged.append((None, Path(path)))
    return True


@contextmanager
def atomic_output(path: str | Path, scratch: bool = False) -> Iterator[BinaryIO]:
    """A binary file that replaces `path` only when the block ends without an exception (and, inside
    `output_set()`, only when the whole set succeeds), so readers see either the old file or the whole new one;
    alone, it is a set of one (the folders it made go too if it fails). Mode 0666 & ~umask, like a plain open().
    `scratch`: a cache file, not fsynced and renamed at once, never part of a set (module docstring)."""
    if scratch:
        with _atomic_file(Path(path), scratch=True) as handle:
            yield handle
    else:
        with output_set(), _atomic_file(Path(path), scratch=False) as handle:
            yield handle


@contextmanager
def _atomic_file(path: Path, scratch: bool) -> Iterator[BinaryIO]:
    if scratch:
        path.parent.mkdir(parents=True, exist_ok=True)  # a cache folder: kept whatever happens
    else:
        make_folder(path.parent)
    fd, name = tempfile.mkstemp(dir=path.parent, prefix=f".{path.name}.", suffix=".tmp")
    tmp = Path(name)
    try:
        with os.fdopen(fd, "wb") as handle:
            yield handle
            if not scratch:
                handle.flush()
                os.fsync(handle.fileno())
        os.chmod(tmp, 0o666 & ~_umask())
        if scratch:
            os.replace(tmp, path)
        else:
            replace_file(tmp, path)
    except BaseException:
        tmp.unlink(missing_ok=True)
        raise


def write_bytes_atomic(path: str | Path, data: bytes) -> None:
    """Write `data` to `path` atomically."""
    with atomic_output(path) as handle:
        handle.write(data)


def write_text_atomic(path: str | Path, text: str) -> None:
    """Text variant of `write_bytes_atomic` (UTF-8)."""
    write_bytes_atomic(path, text.encode("utf-8"))
