"""The live terminal view of a capture (rich): samples taken, tags in view, sharpness, stillness, joint
coverage.

On a terminal the view redraws in place; otherwise (logs, tests) only events are printed, one line each.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from rich.console import Console, Group
from rich.live import Live
from rich.table import Table
from rich.text import Text

COVERAGE_BINS = 10


@dataclass
class Coverage:
    """Which tenths of each joint's URDF range the samples have visited."""

    limits: dict[str, tuple[float, float]]
    hits: dict[str, set[int]] = field(default_factory=dict)
    span: dict[str, tuple[float, float]] = field(default_factory=dict)

    def add(self, joints: list[str], positions: np.ndarray) -> None:
        for joint, q in zip(joints, positions, strict=True):
            if joint not in self.limits:
                continue
            lo, hi = self.limits[joint]
            b = int(np.clip((q - lo) / (hi - lo) * COVERAGE_BINS, 0, COVERAGE_BINS - 1))
            self.hits.setdefault(joint, set()).add(b)
            a, z = self.span.get(joint, (q, q))
            self.span[joint] = (min(a, q), max(z, q))

    def fraction(self, joint: str) -> float:
        return len(self.hits.get(joint, ())) / COVERAGE_BINS


@dataclass
class Status:
    mode: str
    target: int | None
    taken: int = 0
    tags: list[int] = field(default_factory=list)
    line_points: int | None = None  # field views: the field-line points of the last frame checked (None: tags)
    sharpness: float | None = None
    still: str = "-"
    waiting: str = ""
    pose: str = ""


class LiveView:
    """Draws `Status` and `Coverage`; `event` prints a line above the view."""

    def __init__(self, status: Status, coverage: Coverage, console: Console | None = None):
        self.status, self.coverage = status, coverage
        self.console = console or Console(stderr=True)
        self.live = (
            Live(self._render(), console=self.console, auto_refresh=False, transient=False)
            if self.console.is_terminal
            else None
        )

    def __enter__(self) -> LiveView:
        if self.live is not None:
            self.live.start()
        return self

    def __exit__(self, *exc) -> None:
        if self.live is not None:
            self.refresh()
            self.live.stop()

    def event(self, message: str) -> None:
        self.console.print(message, highlight=False)

    def refresh(self) -> None:
        if self.live is not None:
            self.live.update(self._render(), refresh=True)

    def _render(self) -> Group:
        s = self.status
        target = f"/{s.target}" if s.target else ""
        head = Table.grid(padding=(0, 2))
        head.add_row(
            Text(f"{s.mode} capture", style="bold"),
            f"samples {s.taken}{target}",
            f"tags in view: {', '.join(map(str, s.tags)) or 'none'}"
            if s.line_points is None
            else f"field-line points: {s.line_points}",
            f"sharpness: {s.sharpness:.0f}" if s.sharpness is not None else "sharpness: -",
            f"stillness: {s.still}",
        )
        if s.pose:
            head.add_row("pose", s.pose, "", "", "")
        cov = Table(title="joint range coverage (URDF range in tenths)", title_justify="left", box=None)
        cov.add_column("joint")
        cov.add_column("sampled [deg]", justify="right")
        cov.add_column("coverage")
        for joint in self.coverage.limits:
            span = self.coverage.span.get(joint)
            text = f"{np.degrees(span[0]):.0f} .. {np.degrees(span[1]):.0f}" if span else "-"
            hits = self.coverage.hits.get(joint, set())
            bar = "".join("#" if b in hits else "." for b in range(COVERAGE_BINS))
            cov.add_row(joint, text, f"{bar} {self.coverage.fraction(joint):.0%}")
        waiting = Text(f"waiting: {s.waiting}" if s.waiting else "", style="yellow")
        return Group(head, waiting, cov)
