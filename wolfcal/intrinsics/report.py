"""The calibration report folder: figures (OpenCV drawing), per-view table, detections and a markdown summary.

Files: summary.md, intrinsics.yaml (values and 1-sigma), per_view.csv, detections.yaml (written before
calibrating, so detections survive a failed calibration), residual_histogram.png, per_view_errors.png,
corner_map.png, distortion_field.png.
"""

from __future__ import annotations

import json
from pathlib import Path

import cv2
import numpy as np

from wolfcal.atomic import write_bytes_atomic, write_text_atomic
from wolfcal.camera.model import CameraModel
from wolfcal.intrinsics.calibrate import Calibration
from wolfcal.intrinsics.coverage import GRID, REGION_NAMES, region_counts
from wolfcal.intrinsics.detect import Detection, Failure
from wolfcal.yamlfile import dump_yaml

_FONT = cv2.FONT_HERSHEY_SIMPLEX
_W, _H, _M = 800, 420, 50  # chart size and margin [px]


def _save_png(path: Path, image: np.ndarray) -> None:
    ok, data = cv2.imencode(".png", image)
    assert ok
    write_bytes_atomic(path, data.tobytes())


def _text(img: np.ndarray, text: str, org: tuple[int, int], scale: float = 0.45, color=(0, 0, 0)) -> None:
    cv2.putText(img, text, org, _FONT, scale, color, 1, cv2.LINE_AA)


def _bar_chart(values: np.ndarray, colors: list[tuple[int, int, int]], title: str, xlabel: str, ticks: list[str]):
    """White BGR chart of bars `values` (>= 0) with a y axis in the values' unit."""
    img = np.full((_H, _W, 3), 255, np.uint8)
    top = float(values.max()) * 1.1 if len(values) and values.max() > 0 else 1.0
    plot_w, plot_h = _W - 2 * _M, _H - 2 * _M
    n = max(len(values), 1)
    for i, (v, c) in enumerate(zip(values, colors, strict=True)):
        x0 = _M + int(i * plot_w / n)
        x1 = _M + int((i + 1) * plot_w / n) - 1
        cv2.rectangle(img, (x0, _H - _M - int(v / top * plot_h)), (max(x0, x1 - 1), _H - _M), c, -1)
    cv2.line(img, (_M, _H - _M), (_W - _M, _H - _M), (0, 0, 0))
    cv2.line(img, (_M, _M), (_M, _H - _M), (0, 0, 0))
    for k in range(5):
        y = _H - _M - int(k / 4 * plot_h)
        _text(img, f"{k / 4 * top:.3g}", (4, y + 4), 0.4)
    for i, label in ticks_at(ticks, n):
        _text(img, label, (_M + int((i + 0.5) * plot_w / n) - 8, _H - _M + 16), 0.35)
    _text(img, title, (_M, 30), 0.55)
    _text(img, xlabel, (_W // 2 - 80, _H - 10), 0.45)
    return img


def ticks_at(labels: list[str], n: int, most: int = 12) -> list[tuple[int, str]]:
    """At most `most` evenly spaced (index, label) pairs of `labels`."""
    step = max(1, int(np.ceil(n / most)))
    return [(i, labels[i]) for i in range(0, min(n, len(labels)), step)]


def residual_histogram(calibration: Calibration) -> np.ndarray:
    """Histogram of per-corner residual lengths |r| [px] of the used views."""
    lengths = np.linalg.norm(np.concatenate(calibration.residuals), axis=1)
    edges = np.linspace(0, max(float(np.percentile(lengths, 99.5)), 1e-6), 31)
    counts, _ = np.histogram(np.clip(lengths, 0, edges[-1]), edges)
    labels = [f"{e:.2f}" for e in edges[:-1]]
    return _bar_chart(
        counts.astype(float),
        [(180, 120, 40)] * len(counts),
        f"corner residuals |r|: RMS per point {calibration.rms_per_point:.3f} px, "
        f"per axis {calibration.rms_per_axis:.3f} px",
        "|r| [px] (count per bin)",
        labels,
    )


def per_view_chart(calibration: Calibration) -> np.ndarray:
    """Per-point RMS of every view: used (blue) and rejected as outliers (red)."""
    values = list(calibration.view_rms) + [rms for _, rms in calibration.rejected]
    colors = [(180, 120, 40)] * len(calibration.views) + [(40, 40, 220)] * len(calibration.rejected)
    labels = [str(i) for i in range(len(values))]
    return _bar_chart(
        np.array(values),
        colors,
        "per-view RMS per point [px] (red: rejected outliers)",
        "view (see per_view.csv)",
        labels,
    )


def corner_map(views: list[Detection], image_size: tuple[int, int]) -> np.ndarray:
    """Where the corners fell in the image; regions without corners shaded red, corner counts per region."""
    width, height = image_size
    scale = min(1.0, 960 / width)
    w, h = int(round(width * scale)), int(round(height * scale))
    img = np.full((h, w, 3), 255, np.uint8)
    counts = region_counts(views, image_size)
    for r in range(GRID):
        for c in range(GRID):
            p0 = (int(c * w / GRID), int(r * h / GRID))
            p1 = (int((c + 1) * w / GRID) - 1, int((r + 1) * h / GRID) - 1)
            if counts[r, c] == 0:
                cv2.rectangle(img, p0, p1, (200, 200, 255), -1)
            cv2.rectangle(img, p0, p1, (160, 160, 160), 1)
            _text(img, f"{REGION_NAMES[r][c]}: {counts[r, c]}", (p0[0] + 6, p0[1] + 18), 0.45, (90, 90, 90))
    rng = np.random.default_rng(0)
    for view in views:
        color = tuple(int(x) for x in rng.integers(30, 200, 3))
        for u, v in view.corners * scale:
            cv2.circle(img, (int(round(u)), int(round(v))), 2, color, -1, cv2.LINE_AA)
    _text(img, f"{sum(len(v.corners) for v in views)} corners in {len(views)} views", (6, h - 8), 0.5)
    return img


def distortion_field(camera: CameraModel) -> np.ndarray:
    """Arrows from where an ideal pinhole puts a point to where the lens puts it, on a grid.

    Arrows are drawn at their true length, or shortened by a stated factor so the longest spans ~1.5 grid steps;
    the shift in pixels is written at every fourth grid point.
    """
    width, height = camera.width, camera.height
    scale = min(1.0, 960 / width)
    img = np.full((int(round(height * scale)), int(round(width * scale)), 3), 255, np.uint8)
    step = max(width, height) / 24
    v, u = np.mgrid[step / 2 : height : step, step / 2 : width : step]
    distorted = np.stack([u, v], axis=-1)
    ideal = camera.normalized_to_pixels(camera.undistort_normalized(camera.pixels_to_normalized(distorted)))
    shift = np.linalg.norm(distorted - ideal, axis=-1)
    longest = float(np.nanmax(shift, initial=0.0))
    factor = min(1.0, 1.5 * step / longest) if longest > 0 else 1.0
    for (r, c), end in np.ndenumerate(shift):
        p1 = distorted[r, c] * scale
        p0 = p1 - (distorted[r, c] - ideal[r, c]) * factor * scale
        if np.all(np.isfinite(p0)):
            tip = (int(round(p1[0])), int(round(p1[1])))
            cv2.arrowedLine(img, (int(round(p0[0])), int(round(p0[1]))), tip, (180, 80, 0), 1, cv2.LINE_AA,
                            tipLength=0.25)  # fmt: skip
            if r % 4 == 1 and c % 4 == 1:
                _text(img, f"{end:.1f}", (tip[0] + 3, tip[1] - 3), 0.35, (60, 60, 60))
    cv2.drawMarker(img, (int(camera.cx * scale), int(camera.cy * scale)), (0, 0, 220), cv2.MARKER_CROSS, 14, 2)
    length = "true length" if factor == 1.0 else f"arrows x{factor:.2g}"
    title = f"distortion ({camera.distortion_model}): pinhole -> lens [px], {length}; max {longest:.1f} px; "
    _text(img, title + "red cross: principal point", (6, 18), 0.45)
    return img


def detections_yaml(detections: list[Detection], failures: list[Failure]) -> str:
    """detections.yaml text: corners [px] rounded to 1e-4, one flow-style line per list. Written directly (the
    structure is fixed): much faster than a YAML emitter, and loads to the same data."""
    lines = ["views:" if detections else "views: []"]
    for d in detections:
        corners = ", ".join(f"[{x!r}, {y!r}]" for x, y in np.round(d.corners, 4).tolist())
        lines += [
            f"- name: {json.dumps(d.name)}",
            f"  image_size: [{d.image_size[0]}, {d.image_size[1]}]",
            f"  ids: [{', '.join(str(int(i)) for i in d.ids)}]",
            f"  corners: [{corners}]",
        ]
    lines.append("failures:" if failures else "failures: []")
    for f in failures:
        lines += [f"- name: {json.dumps(f.name)}", f"  reason: {json.dumps(f.reason)}"]
    return "\n".join(lines) + "\n"


REPORT_FILES = (
    "detections.yaml", "residual_histogram.png", "per_view_errors.png", "corner_map.png", "distortion_field.png",
    "per_view.csv", "intrinsics.yaml", "summary.md",
)  # fmt: skip


def write_detections(folder: Path, detections: list[Detection], failures: list[Failure]) -> None:
    """Corners of every view and the reason of every failure, as YAML."""
    write_text_atomic(folder / "detections.yaml", detections_yaml(detections, failures))


def write_report(
    folder: Path, calibration: Calibration, failures: list[Failure], warnings: list[str], method: str
) -> None:
    """All figures, tables and summary.md into `folder`."""
    cam = calibration.camera
    _save_png(folder / "residual_histogram.png", residual_histogram(calibration))
    _save_png(folder / "per_view_errors.png", per_view_chart(calibration))
    _save_png(folder / "corner_map.png", corner_map(calibration.views, (cam.width, cam.height)))
    _save_png(folder / "distortion_field.png", distortion_field(cam))
    rows = ["view,name,rms_per_point_px,status"]
    rows += [
        f"{i},{v.name},{rms:.4f},used"
        for i, (v, rms) in enumerate(zip(calibration.views, calibration.view_rms, strict=True))
    ]
    n = len(calibration.views)
    rows += [f"{n + i},{v.name},{rms:.4f},rejected" for i, (v, rms) in enumerate(calibration.rejected)]
    write_text_atomic(folder / "per_view.csv", "\n".join(rows) + "\n")
    values = {"fx": cam.fx, "fy": cam.fy, "cx": cam.cx, "cy": cam.cy}
    values.update(zip(list(calibration.std)[4:], map(float, cam.D), strict=True))
    write_text_atomic(
        folder / "intrinsics.yaml",
        dump_yaml(
            {
                "distortion_model": cam.distortion_model,
                "image_size": [cam.width, cam.height],
                "parameters": {k: {"value": float(values[k]), "std": calibration.std[k]} for k in calibration.std},
                "rms_per_point_px": calibration.rms_per_point,
                "rms_per_axis_px": calibration.rms_per_axis,
                "views_used": len(calibration.views),
                "views_rejected": len(calibration.rejected),
                "views_failed": len(failures),
            },
            sort_keys=False,
        ),
    )
    write_text_atomic(folder / "summary.md", summary_markdown(calibration, failures, warnings, method))


def summary_markdown(calibration: Calibration, failures: list[Failure], warnings: list[str], method: str) -> str:
    """The human summary of a calibration."""
    cam = calibration.camera
    values = [cam.fx, cam.fy, cam.cx, cam.cy, *cam.D]
    lines = [
        f"# Intrinsics: {cam.width}x{cam.height}, {cam.distortion_model}",
        "",
        f"- views used {len(calibration.views)}, rejected as outliers {len(calibration.rejected)}, "
        f"without a board or unreadable {len(failures)}; {calibration.n_points} corners; detector {method}",
        f"- reprojection RMS **per point {calibration.rms_per_point:.3f} px** (OpenCV's convention, sqrt "
        f"of the mean squared residual length); per axis {calibration.rms_per_axis:.3f} px (mrcal's; "
        "= per point / sqrt 2)",
        "",
        "| parameter | value | 1-sigma |",
        "|---|---|---|",
    ]
    lines += [f"| {k} | {v:.6g} | {s:.2g} |" for (k, s), v in zip(calibration.std.items(), values, strict=True)]
    lines += [
        "",
        "1-sigma from the Jacobian of all residuals, scaled by the residual variance, poses marginalised.",
    ]
    if warnings:
        lines += ["", "## Warnings", ""] + [f"- {w}" for w in warnings]
    if calibration.rejected:
        lines += ["", "## Rejected views", ""] + [f"- {v.name}: {rms:.3f} px" for v, rms in calibration.rejected]
    if failures:
        lines += ["", "## Views without corners", ""] + [f"- {f.name}: {f.reason}" for f in failures]
    lines += [
        "",
        "## Figures",
        "",
        "![residuals](residual_histogram.png)",
        "![per view](per_view_errors.png)",
        "![corners](corner_map.png)",
        "![distortion](distortion_field.png)",
        "",
    ]
    return "\n".join(lines)
