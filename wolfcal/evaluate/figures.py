"""Report pictures as PNG bytes, drawn with OpenCV and numpy (no plotting library).

Colours are fixed across all pictures: before (input URDF) red, after (calibrated) blue, detected green.
Pixel inputs follow OpenCV (centre of the top-left pixel at (0, 0)).
"""

from __future__ import annotations

import cv2
import numpy as np

BEFORE = (60, 60, 220)  # BGR red
AFTER = (200, 110, 30)  # BGR blue
DETECTED = (40, 170, 40)  # BGR green
INK = (40, 40, 40)
GRID = (225, 225, 225)
FONT = cv2.FONT_HERSHEY_SIMPLEX


def png(image: np.ndarray) -> bytes:
    ok, data = cv2.imencode(".png", image)
    if not ok:
        raise RuntimeError("PNG encoding failed")
    return data.tobytes()


def _text(img: np.ndarray, text: str, org: tuple[int, int], scale: float = 0.45, color=INK, anchor: str = "left"):
    (w, h), _ = cv2.getTextSize(text, FONT, scale, 1)
    x, y = org
    if anchor == "center":
        x -= w // 2
    elif anchor == "right":
        x -= w
    cv2.putText(img, text, (int(x), int(y + h // 2)), FONT, scale, color, 1, cv2.LINE_AA)


def _legend(
    img: np.ndarray, items: list[tuple[str, tuple[int, int, int]]], right: int, top: int, gap: int, text_y: int
) -> None:
    """Colour boxes (12 px, top edge at `top`) with their labels (centred at `text_y`), in one row ending at `right`
    [px]."""
    x = right
    for label, color in reversed(items):
        (w, _), _ = cv2.getTextSize(label, FONT, 0.45, 1)
        x -= w + gap
        cv2.rectangle(img, (x, top), (x + 12, top + 12), color, -1)
        _text(img, label, (x + 16, text_y))


class LogAxes:
    """A white canvas with a title, a framed plot area and a legend above it; charts map their data into it."""

    def __init__(
        self,
        width: int,
        height: int,
        title: str,
        left: int = 70,
        right: int = 20,
        top: int = 64,
        bottom: int = 55,
    ):
        self.img = np.full((height, width, 3), 255, np.uint8)
        self.x0, self.x1, self.y0, self.y1 = left, width - right, top, height - bottom
        _text(self.img, title, (width // 2, 16), 0.55, anchor="center")

    def legend(self, items: list[tuple[str, tuple[int, int, int]]]) -> None:
        _legend(self.img, items, self.x1 - 10, self.y0 - 26, 22, self.y0 - 20)

    def frame(self) -> None:
        cv2.rectangle(self.img, (self.x0, self.y0), (self.x1, self.y1), INK, 1)


def _decades(lo: float, hi: float) -> np.ndarray:
    return 10.0 ** np.arange(np.floor(np.log10(lo)), np.ceil(np.log10(hi)) + 1)


def _log_range(values: np.ndarray) -> tuple[float, float]:
    v = values[np.isfinite(values) & (values > 0)]
    if v.size == 0:
        return 0.01, 1.0
    return 10 ** np.floor(np.log10(v.min())), 10 ** np.ceil(np.log10(v.max()))


def _tick_label(v: float) -> str:
    return f"{v:g}"


def _count_ticks(top: int) -> list[int]:
    """About four round tick values (1, 2 or 5 times a power of ten apart) from 0 to `top`."""
    raw = top / 4
    power = 10 ** np.floor(np.log10(max(raw, 1)))
    step = int(next(m * power for m in (1, 2, 5, 10) if m * power >= raw))
    return list(range(0, top + 1, max(step, 1)))


def histogram_png(before: np.ndarray, after: np.ndarray, xlabel: str, title: str) -> bytes:
    """Histograms of two error samples (e.g. corner distances [px]) on a log-spaced x axis."""
    return histograms_png([("before (input URDF)", before, BEFORE), ("after (calibrated)", after, AFTER)], xlabel,
                          title)  # fmt: skip


def histograms_png(series: list[tuple[str, np.ndarray, tuple[int, int, int]]], xlabel: str, title: str) -> bytes:
    """Overlaid histograms of several error samples (label, values, BGR colour) on a log-spaced x axis."""
    ax = LogAxes(760, 364, title)
    lo, hi = _log_range(np.concatenate([np.asarray(v, dtype=float) for _, v, _ in series]))
    edges = np.logspace(np.log10(lo), np.log10(hi), 41)
    counts = [np.histogram(np.clip(v, lo, hi), edges)[0] for _, v, _ in series]
    top = max(1, max(int(c.max()) for c in counts))

    def x_of(v: float) -> int:
        return int(ax.x0 + (np.log10(v) - np.log10(lo)) / (np.log10(hi) - np.log10(lo)) * (ax.x1 - ax.x0))

    def y_of(c: float) -> int:
        return int(ax.y1 - c / top * (ax.y1 - ax.y0 - 30))

    for d in _decades(lo, hi):
        cv2.line(ax.img, (x_of(d), ax.y0), (x_of(d), ax.y1), GRID, 1)
        _text(ax.img, _tick_label(d), (x_of(d), ax.y1 + 14), anchor="center")
    for c in _count_ticks(top):
        cv2.line(ax.img, (ax.x0, y_of(c)), (ax.x1, y_of(c)), GRID, 1)
        _text(ax.img, str(c), (ax.x0 - 6, y_of(c)), anchor="right")
    overlay = ax.img.copy()
    for bin_counts, (_, _, color) in zip(counts, series):
        for i, n in enumerate(bin_counts):
            if n:
                cv2.rectangle(overlay, (x_of(edges[i]) + 1, y_of(n)), (x_of(edges[i + 1]) - 1, ax.y1), color, -1)
    ax.img[:] = cv2.addWeighted(overlay, 0.65, ax.img, 0.35, 0)
    ax.frame()
    ax.legend([(label, color) for label, _, color in series])
    _text(ax.img, xlabel, ((ax.x0 + ax.x1) // 2, ax.y1 + 36), anchor="center")
    _text(ax.img, "count", (8, ax.y0 - 12))
    return png(ax.img)


def per_sample_png(before: np.ndarray, after: np.ndarray, outliers: np.ndarray, ylabel: str, title: str) -> bytes:
    """Paired bars per sample (log y axis); outlier samples get a grey background and an 'x' under their bars."""
    n = len(before)
    ax = LogAxes(max(760, 60 + 22 * n), 364, title)
    lo, hi = _log_range(np.concatenate([before, after]))

    def y_of(v: float) -> int:
        v = min(max(v, lo), hi)
        return int(ax.y1 - (np.log10(v) - np.log10(lo)) / (np.log10(hi) - np.log10(lo)) * (ax.y1 - ax.y0 - 30))

    for d in _decades(lo, hi):
        cv2.line(ax.img, (ax.x0, y_of(d)), (ax.x1, y_of(d)), GRID, 1)
        _text(ax.img, _tick_label(d), (ax.x0 - 6, y_of(d)), anchor="right")
    width = (ax.x1 - ax.x0) / max(n, 1)
    for i in range(n):
        x = ax.x0 + i * width
        if outliers[i]:
            cv2.rectangle(ax.img, (int(x), ax.y0 + 1), (int(x + width), ax.y1 - 1), (215, 215, 215), -1)
            _text(ax.img, "x", (int(x + width / 2), ax.y1 + 30), color=BEFORE, anchor="center")
        for j, (v, color) in enumerate(((before[i], BEFORE), (after[i], AFTER))):
            if np.isfinite(v) and v > 0:
                a = int(x + width * (0.15 + 0.35 * j))
                cv2.rectangle(ax.img, (a, y_of(v)), (int(a + width * 0.33), ax.y1), color, -1)
        if n <= 40 or i % 5 == 0:
            _text(ax.img, str(i), (int(x + width / 2), ax.y1 + 14), 0.38, anchor="center")
    ax.frame()
    ax.legend(
        [("before", BEFORE), ("after", AFTER)] + ([("outlier sample", (215, 215, 215))] if outliers.any() else [])
    )
    _text(ax.img, "sample", ((ax.x0 + ax.x1) // 2, ax.y1 + 44), anchor="center")
    _text(ax.img, ylabel, (8, ax.y0 - 12))
    return png(ax.img)


def _polyline(img: np.ndarray, uv: np.ndarray, color, thickness: int) -> None:
    finite = np.isfinite(uv).all(axis=1)
    for a, b in zip(uv[:-1][finite[:-1] & finite[1:]], uv[1:][finite[:-1] & finite[1:]]):
        cv2.line(
            img,
            tuple(np.round(a * 16).astype(int)),
            tuple(np.round(b * 16).astype(int)),
            color,
            thickness,
            cv2.LINE_AA,
            shift=4,
        )


def overlay_png(
    image: np.ndarray,
    detected: np.ndarray,
    predicted: dict[str, np.ndarray],
    skeletons: dict[str, list[np.ndarray]],
    caption: str,
    width: int = 900,
) -> bytes:
    """The camera image with detected corners (green rings), predicted corners and quadrilaterals per model, and the
    kinematic skeleton per model as polylines (each (K, 2) [px] at the image's resolution; NaN breaks a line).

    Models are keyed 'before' / 'after' (colours as the other pictures).
    """
    img = image if image.ndim == 3 else cv2.cvtColor(image, cv2.COLOR_GRAY2BGR)
    scale = width / img.shape[1]
    img = cv2.resize(
        img,
        (width, int(round(img.shape[0] * scale))),
        interpolation=cv2.INTER_AREA if scale < 1 else cv2.INTER_LINEAR,
    )
    img = (0.6 * img + 0.4 * 255).astype(np.uint8)  # lighten so the drawing stands out

    def to_view(uv: np.ndarray) -> np.ndarray:
        return (uv + 0.5) * scale - 0.5

    colors = {"before": BEFORE, "after": AFTER}
    for name, lines in skeletons.items():
        for line in lines:
            _polyline(img, to_view(line), colors[name], 2)
    for name, uv in predicted.items():
        quads = to_view(uv).reshape(-1, 4, 2)
        for quad in quads:
            _polyline(img, np.vstack([quad, quad[:1]]), colors[name], 1)
            for p in quad[np.isfinite(quad).all(axis=1)]:
                cv2.drawMarker(img, tuple(np.round(p).astype(int)), colors[name], cv2.MARKER_CROSS, 10, 2)
    for p in to_view(detected):
        cv2.circle(img, tuple(np.round(p * 16).astype(int)), 6 * 16, DETECTED, 2, cv2.LINE_AA, shift=4)
    banner = np.full((28, img.shape[1], 3), 255, np.uint8)
    _text(banner, caption, (8, 13))
    _legend(banner, [("detected", DETECTED), ("before", BEFORE), ("after", AFTER)], img.shape[1] - 10, 8, 24, 13)
    return png(np.vstack([banner, img]))


def correlation_png(names: list[str], correlation: np.ndarray, title: str) -> bytes:
    """Heat map of a parameter correlation matrix (blue -1, white 0, red +1), values written in the cells."""
    n = len(names)
    labels = [f"{name}  {i}" for i, name in enumerate(names)]
    cell = max(30, min(48, 640 // max(n, 1)))
    label_w = 12 + max((cv2.getTextSize(s, FONT, 0.42, 1)[0][0] for s in labels), default=0)
    img = np.full((40 + n * cell + 30, label_w + n * cell + 20, 3), 255, np.uint8)
    _text(img, title, (img.shape[1] // 2, 16), 0.55, anchor="center")
    white = np.array([255.0, 255.0, 255.0])
    for i in range(n):
        _text(img, labels[i], (label_w - 8, 40 + i * cell + cell // 2), 0.42, anchor="right")
        _text(img, str(i), (label_w + i * cell + cell // 2, 40 + n * cell + 12), 0.38, anchor="center")
        for j in range(n):
            c = float(np.clip(correlation[i, j], -1, 1))
            tone = np.array(BEFORE if c > 0 else AFTER, dtype=float)
            color = tuple(int(v) for v in white + abs(c) * (tone - white))
            x, y = label_w + j * cell, 40 + i * cell
            cv2.rectangle(img, (x, y), (x + cell - 1, y + cell - 1), color, -1)
            _text(
                img,
                f"{round(c, 1) + 0.0:+.1f}" if cell < 40 else f"{round(c, 2) + 0.0:+.2f}",
                (x + cell // 2, y + cell // 2),
                0.32,
                INK if abs(c) < 0.6 else (255, 255, 255),
                anchor="center",
            )
    return png(img)
