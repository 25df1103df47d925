"""Checks on what a capture file or recording holds, before it becomes samples: joint readings must be finite
numbers, images must be whole. A few bad ones are left out with a note; more than `MAX_LEFT_OUT` is an error."""

from __future__ import annotations

from collections import Counter
from collections.abc import Sequence
from pathlib import Path

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.io.images import image_damage
from wolfcal.io.samples import SampleImage
from wolfcal.leftout import MAX_LEFT_OUT, check_left_out, too_many

JointMessage = tuple[int, Sequence[str], Sequence[float], Sequence[float]]  # stamp [ns], names, positions, velocities


def finite_joint_states(
    path: Path, topic: str, messages: list[JointMessage]
) -> tuple[list[JointMessage], set[int], list[str]]:
    """(the messages whose positions are all finite, stamps of those left out, a note on them).

    WolfcalError naming the file, topic, joints and counts when more than MAX_LEFT_OUT of them are bad."""
    kept: list[JointMessage] = []
    dropped: set[int] = set()
    joints: Counter[str] = Counter()
    for message in messages:
        stamp, names, positions, _ = message
        bad = np.flatnonzero(~np.isfinite(np.asarray(positions, dtype=float)))
        if bad.size == 0:
            kept.append(message)
            continue
        dropped.add(stamp)
        joints.update(str(names[k]) if k < len(names) else f"position[{k}]" for k in bad.tolist())
    if not joints:
        return messages, set(), []
    n_bad = len(messages) - len(kept)
    listed = ", ".join(f"{joint} {count}x" for joint, count in joints.most_common())
    what = f"{path}: {n_bad} of {len(messages)} joint state(s) on {topic} hold NaN or infinite positions ({listed})"
    if too_many(n_bad, len(messages)):
        raise WolfcalError(
            f"{what}: more than {MAX_LEFT_OUT:.0%} of the readings are unusable; check the servo and the joint "
            "state publisher of these joints, then capture again"
        )
    return kept, dropped, [f"{what}: the sample(s) at these readings are left out"]


def drop_damaged_images(path: Path, camera: str, kept: dict[int, SampleImage], stamps: list[int]) -> list[str]:
    """Remove the images of `camera` that are damaged (bad checksum, cut short) from `kept` (stamp -> image with
    its bytes); returns why, naming each by its index among the camera's images in the file (`stamps`, sorted)
    and its time."""
    notes = []
    for stamp, image in list(kept.items()):
        problem = image_damage(image.data)
        if problem:
            index = stamps.index(stamp)
            notes.append(
                f"'{camera}' image {index + 1} of {len(stamps)} ({(stamp - stamps[0]) / 1e9:.3f} s after the "
                f"first): {problem}"
            )
            del kept[stamp]
    if notes:
        where = f"{path}: {notes[0]}" + (f" (and {len(notes) - 1} more damaged)" if len(notes) > 1 else "")
        check_left_out({"images": (len(notes), len(stamps))}, where, "copy the file again or re-record it")
        if not kept:
            raise WolfcalError(f"{where}: no undamaged image left; copy the file again or re-record it")
    return notes
