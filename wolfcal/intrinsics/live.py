"""Live and video view collection: keep still, new views; show coverage in the terminal.

Works headless over SSH: the view is text (rich), like ROS camera_calibration's X / Y / Size / Skew bars, plus
hints where to move the board. Stops as soon as coverage is complete; kept frames can be saved (PNG) as they
are kept, so an interrupted session keeps its views.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Callable, Iterable
from pathlib import Path

import cv2
import numpy as np
from rich.console import Console, Group, RenderableType
from rich.live import Live
from rich.table import Table
from rich.text import Text

from wolfcal.atomic import write_bytes_atomic
from wolfcal.intrinsics.coverage import PARAM_NAMES, ViewSelector
from wolfcal.intrinsics.detect import Detection, detect_board

Frame = tuple[str, np.ndarray]


def collect_views(
    frames: Iterable[Frame],
    selector: ViewSelector,
    min_views: int,
    method: str = "classic",
    save_dir: Path | None = None,
    show: Callable[[ViewSelector, int], None] | None = None,
) -> bool:
    """Feed frames to `selector` until coverage is complete (True) or the frames end (False)."""
    for count, (name, image) in enumerate(frames, start=1):
        found = detect_board(image, selector.board, name, method, fallback=False)
        detection = found if isinstance(found, Detection) else None
        if selector.offer(detection) and save_dir is not None:
            path = save_dir / f"view_{len(selector.kept):03d}.png"
            ok, png = cv2.imencode(".png", image)
            if ok:
                write_bytes_atomic(path, png.tobytes())
                selector.kept[-1] = dataclasses.replace(selector.kept[-1], name=str(path))
        if show:
            show(selector, count)
        if selector.coverage.complete(min_views):
            return True
    return False


def _bar(value: float, width: int = 30) -> Text:
    filled = int(round(value * width))
    style = "green" if value >= 1.0 else "yellow"
    return Text("█" * filled, style=style) + Text("░" * (width - filled), style="dim")


def render(selector: ViewSelector, frames: int, min_views: int) -> Group:
    """The terminal view: coverage bars, counts, the last frame's status and hints."""
    table = Table.grid(padding=(0, 1))
    for name, value in zip(PARAM_NAMES, selector.coverage.progress(), strict=True):
        table.add_row(Text(f"{name:>4}"), _bar(float(value)), Text(f"{100 * value:3.0f} %"))
    lines: list[RenderableType] = [
        table,
        Text(f"views kept {len(selector.kept)} (need {min_views}), frames seen {frames}"),
        Text(selector.status, style="bold"),
    ]
    lines += [Text(f"-> {hint}", style="cyan") for hint in selector.coverage.hints()]
    return Group(*lines)


class LiveView:
    """Context manager that redraws `render` in place (at most 8 times per second)."""

    def __init__(self, min_views: int, console: Console | None = None) -> None:
        self.min_views = min_views
        self._live = Live(console=console, refresh_per_second=8, transient=False)

    def __enter__(self) -> LiveView:
        self._live.__enter__()
        return self

    def __exit__(self, *exc) -> None:
        self._live.__exit__(*exc)
        if not self._live.console.is_terminal:  # a file or pipe gets the last view without a line end
            self._live.console.line()

    def __call__(self, selector: ViewSelector, frames: int) -> None:
        self._live.update(render(selector, frames, self.min_views))
