"""What a camera sees when it shows none of the robot's tags: the words a stopped session gives the operator."""

from __future__ import annotations

import cv2
import numpy as np

from wolfcal.capture.gating import sharpness
from wolfcal.vision.tags import detect_tags

FAMILIES = ("tag36h11", "tag25h9", "tag16h5", "tag36h10")  # looked for beyond the robot's own
DARK, BRIGHT = 20.0, 235.0  # mean grey levels of an image too dark / too bright to show a tag
FLAT_STD = 4.0  # grey-level standard deviation below which an image shows nothing (a cap, a wall)


def what_the_camera_sees(frames: list[np.ndarray], tag_ids: set[int]) -> str:
    """One message: the camera showed none of `tag_ids` in these frames (one per pose), and what it shows
    instead: other tags, or a dark, bright, flat or blurred image."""
    grays = [f if f.ndim == 2 else cv2.cvtColor(f, cv2.COLOR_BGR2GRAY) for f in frames]
    mean = float(np.mean([g.mean() for g in grays]))
    std = float(np.mean([g.std() for g in grays]))
    sharp = float(np.mean([sharpness(g, {}) for g in grays]))
    others = {}
    for family in FAMILIES:
        found = set().union(*(detect_tags(g, family) for g in grays))
        if found:
            others[family] = sorted(found)
    wanted = ", ".join(map(str, sorted(tag_ids)))
    head = (f"the camera showed none of the robot's tags ({wanted}) in the first {len(frames)} poses, so the "
            "session stopped")  # fmt: skip
    if others:
        listed = "; ".join(f"{family} {', '.join(map(str, ids))}" for family, ids in others.items())
        return (
            f"{head}: it sees other tags ({listed}); check the tag ids and families in the robot config, or "
            "put the robot's own tags on"
        )
    if mean < DARK:
        look = f"a dark image (mean grey {mean:.0f} of 255): lens cap on, or exposure far too short?"
    elif mean > BRIGHT:
        look = f"a bright image (mean grey {mean:.0f} of 255): overexposed, or facing a light?"
    elif std < FLAT_STD:
        look = f"a flat image (grey {mean:.0f} +- {std:.1f}): nothing in view, or the lens covered?"
    else:
        look = (
            f"an image without AprilTags (mean grey {mean:.0f}, contrast {std:.0f}, sharpness {sharp:.0f}): "
            "the wrong camera (--camera), tags not on the feet, or the camera pointing elsewhere?"
        )
    return f"{head}: it sees {look}"
