"""Checks on what a capture file or recording holds, before it becomes samples: joint readings must be finite
numbers, images must be whole. A few bad ones are left out with a note; more than `MAX_LEFT_OUT` is an error."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.io.recording import JointLog, JointStates
from wolfcal.leftout import MAX_LEFT_OUT, check_left_out, too_many


def finite_joint_states(path: Path, topic: str, log: JointLog) -> tuple[JointStates, set[int], list[str]]:
    """(the joint states of the messages whose positions are all finite, stamps of those left out, a note on them).

    WolfcalError naming the file, topic, joints and counts when more than MAX_LEFT_OUT of them are bad."""
    keep: list[np.ndarray] = []
    dropped: set[int] = set()
    joints: Counter[str] = Counter()
    for names, stamps, positions, _ in log.groups():
        finite = np.isfinite(positions)
        keep.append(finite.all(axis=1))
        dropped.update(int(s) for s in stamps[~keep[-1]])
        joints.update({names[j]: int(n) for j, n in enumerate((~finite).sum(axis=0)) if n})
    states = JointStates.from_log(log, keep)
    if not joints:
        return states, set(), []
    n_bad = log.count - sum(int(k.sum()) for k in keep)
    listed = ", ".join(f"{joint} {count}x" for joint, count in joints.most_common())
    what = f"{path}: {n_bad} of {log.count} joint state(s) on {topic} hold NaN or infinite positions ({listed})"
    if too_many(n_bad, log.count):
        raise WolfcalError(
            f"{what}: more than {MAX_LEFT_OUT:.0%} of the readings are unusable; check the servo and the joint "
            "state publisher of these joints, then capture again"
        )
    return states, dropped, [f"{what}: the sample(s) at these readings are left out"]


def drop_damaged_images(
    path: Path, camera: str, damage: dict[int, str | None], stamps: list[int]
) -> tuple[set[int], list[str]]:
    """(the stamps of the whole images, why the others are left out) among the used images of `camera`
    (`damage`: stamp -> why its bytes are damaged (bad checksum, cut short; `image_damage`) or None); each is
    named by its index among the camera's images in the file (`stamps`, sorted) and its time."""
    notes = []
    whole = {stamp for stamp, problem in damage.items() if not problem}
    for stamp, problem in damage.items():
        if problem:
            index = stamps.index(stamp)
            notes.append(
                f"'{camera}' image {index + 1} of {len(stamps)} ({(stamp - stamps[0]) / 1e9:.3f} s after the "
                f"first): {problem}"
            )
    if notes:
        where = f"{path}: {notes[0]}" + (f" (and {len(notes) - 1} more damaged)" if len(notes) > 1 else "")
        check_left_out({"images": (len(notes), len(stamps))}, where, "copy the file again or re-record it")
        if not whole:
            raise WolfcalError(f"{where}: no undamaged image left; copy the file again or re-record it")
    return whole, notes
