"""Choose the checkerboard corner refinement from the data: the cornerSubPix window the views fit best.

A window sized from the corner spacing ("just under half the spacing") averages blur and noise well on soft
images, but on sharp real photographs it reaches across neighbouring squares' edges and biases the corners:
on OpenCV's sample photographs (left01..14.jpg, 640x480) it gave a per-point RMS of 0.50 px and a focal
length 5 px off, where a 7 px half-window gives 0.18 px. So each view carries its corners refined with a
few windows (`wolfcal.intrinsics.detect.WINDOWS` below its spacing-sized one), each window's corners are
calibrated on a subset of the views, and the window with the smallest per-point reprojection RMS is kept
for all views. Every candidate has the same model and the same points, so the RMS compares like with like.
"""

from __future__ import annotations

import dataclasses
from dataclasses import dataclass

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.intrinsics.calibrate import fit_views
from wolfcal.intrinsics.detect import Detection
from wolfcal.vision.board import Board

SPACING = 0  # the label of the spacing-sized window in `Choice.rms`
MAX_SCORING_VIEWS = 15  # views calibrated per candidate (evenly spread), to keep the choice cheap


@dataclass(frozen=True)
class Choice:
    """The window kept and the per-point RMS [px] of every window tried (0: the spacing-sized one)."""

    window: int
    rms: dict[int, float]

    def describe(self) -> str:
        name = {SPACING: "spacing-sized"}
        tried = ", ".join(f"{name.get(w, f'{w} px')} {r:.3f}" for w, r in sorted(self.rms.items()))
        kept = name.get(self.window, f"half-window {self.window} px")
        return f"corner refinement: cornerSubPix {kept} (per-point RMS of the windows tried: {tried} px)"


def _candidates(view: Detection) -> dict[int, np.ndarray]:
    return {SPACING: view.corners, **dict(view.alternatives)}


def _rms(views: list[Detection], board: Board, model: str) -> float:
    r = fit_views(views, board, model, views[0].image_size).residual
    return float(np.sqrt(np.mean(np.sum(r**2, axis=1))))


def choose_window(views: list[Detection], board: Board, model: str) -> tuple[list[Detection], Choice | None]:
    """Views with the corners of the window that fits best, and the choice (None when there was none to make:
    ChArUco, the "sb" detector, or windows that not every view has)."""
    shared = set.intersection(*(set(_candidates(v)) for v in views)) if views else set()
    if len(shared) < 2:
        return views, None
    step = max(1, len(views) // MAX_SCORING_VIEWS)
    subset = views[::step][:MAX_SCORING_VIEWS]
    scores: dict[int, float] = {}
    for window in sorted(shared):
        trial = [dataclasses.replace(v, corners=_candidates(v)[window]) for v in subset]
        try:
            scores[window] = _rms(trial, board, model)
        except WolfcalError:  # this window's corners did not calibrate; the others may
            continue
    if not scores:
        return views, None
    best = min(scores, key=scores.__getitem__)
    return [dataclasses.replace(v, corners=_candidates(v)[best]) for v in views], Choice(best, scores)
