"""Checks on a command's output paths, made before any work starts.

No command replaces an existing output without `--force`, and none ever writes over one of its inputs (a
capture, a config, a URDF, an image), with or without it. An output below a file, or in a folder that cannot
be written, is refused up front instead of failing after minutes of work.
"""

from __future__ import annotations

import os
from collections.abc import Iterable
from pathlib import Path

from wolfcal.errors import WolfcalError


def _nearest_existing(path: Path) -> Path:
    for folder in [path, *path.parents]:
        if folder.exists():
            return folder
    return Path(".")


def check_folder(folder: Path, option: str = "--out") -> None:
    """`folder` can hold outputs: it is a folder or can be made one, and may be written."""
    folder = Path(folder)
    existing = _nearest_existing(folder)
    if not existing.is_dir():
        raise WolfcalError(f"{option} {folder}: {existing} is a file, not a folder; choose an output path in a folder")
    if not os.access(existing, os.W_OK | os.X_OK):
        raise WolfcalError(f"{option} {folder}: cannot write in {existing} (permission denied); choose another place")


def check_outputs(paths: Iterable[Path], force: bool, inputs: Iterable[Path] = (), option: str = "--out") -> None:
    """Refuse outputs that are inputs, exist without `force`, are folders, or cannot be written."""
    paths = [Path(p) for p in paths]
    inputs_resolved = {Path(p).resolve() for p in inputs}
    existing = []
    for path in paths:
        if path.resolve() in inputs_resolved:
            raise WolfcalError(
                f"{option} {path}: this is an input of the command; it is never overwritten, choose another output"
            )
        check_folder(path.parent, option)
        if path.is_dir():
            raise WolfcalError(f"{option} {path}: is a folder; give a file name")
        if path.exists():
            if not os.access(path, os.W_OK) and not force:
                raise WolfcalError(f"{option} {path}: exists and is read-only; choose another output")
            existing.append(path)
    if existing and not force:
        listed = ", ".join(map(str, existing[:3])) + (f" and {len(existing) - 3} more" if len(existing) > 3 else "")
        raise WolfcalError(
            f"{listed} exist{'s' if len(existing) == 1 else ''}; pass --force to replace "
            f"{'it' if len(existing) == 1 else 'them'}, or choose another {option}"
        )


def check_output_folder(
    folder: Path, names: Iterable[str], force: bool, inputs: Iterable[Path] = (), option: str = "--out"
) -> None:
    """An output folder: not a file, writable, none of `names` in it without `force`, no input inside it
    among the files the command writes."""
    folder = Path(folder)
    if folder.exists() and not folder.is_dir():
        raise WolfcalError(f"{option} {folder}: is a file, not a folder; choose an output folder")
    check_folder(folder, option)
    check_outputs([folder / name for name in names], force, inputs, option)
