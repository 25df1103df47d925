"""Checks on what a capture file or recording holds, before it becomes samples: joint readings must be finite
numbers, images must be whole. A few bad ones are left out with a note; more than `MAX_LEFT_OUT` is an error."""

from __future__ import annotations

from collections import Counter
from pathlib import Path

from wolfcal.errors import WolfcalError
from wolfcal.leftout import MAX_LEFT_OUT, check_left_out, too_many


def finite_joint_note(path: Path, topic: str, messages: int, bad: int, joints: Counter[str]) -> list[str]:
    """The note on the `bad` of `messages` joint states left out for NaN or infinite positions (`joints`: joint ->
    how many of its positions), [] when none. The sample(s) at those readings are left out by the reader.

    WolfcalError naming the file, topic, joints and counts when more than MAX_LEFT_OUT of them are bad."""
    if not bad:
        return []
    listed = ", ".join(f"{joint} {count}x" for joint, count in joints.most_common())
    what = f"{path}: {bad} of {messages} joint state(s) on {topic} hold NaN or infinite positions ({listed})"
    if too_many(bad, messages):
        raise WolfcalError(
            f"{what}: more than {MAX_LEFT_OUT:.0%} of the readings are unusable; check the servo and the joint "
            "state publisher of these joints, then capture again"
        )
    return [f"{what}: the sample(s) at these readings are left out"]


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
