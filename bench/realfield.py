"""The field-line detector on real head-camera images of a RoboCup field: https://github.com/GuiFornes/field_detector
(a humanoid robot's head camera, 800x448 PNG, artificial turf in a hall under warm light; `data/logK/NNN-rgb.png`
and, for 42 of them, a hand-made mask of the field region in `mask-field/logK/NNN-rgb.png`). The repository has no
licence: its images are read where they lie (a clone's working tree or a bare mirror, `--field-images`) and never
copied; only the figures are kept.

Measured, with `detect_line_points(image)` (no camera model for these images, so no expected line width):
- the field region (`field_region` of `turf_mask`) against the 42 masks: intersection over union per image, and the
  share of detected line points that lie outside the mask (points beyond the field: stands, people, walls);
- line points against the lines labelled by hand in `realfield_lines.yaml` (centre polylines in pixels): a point
  within `NEAR_PX` of a labelled line is true, any other point false; a labelled line's coverage is the share of its
  length (sampled every pixel) with a detected point within `NEAR_PX`.
For comparison, the same detector on rendered views with their truth (`rendered`): a cluttered 512x384 view from a
standing robot (goals, robots, ball, shadows, people, 2 px motion blur) over `RENDER_SEEDS`, in neutral light and
under `WARM_LIGHT`, with the expected line width: share of points on a truth line pixel, share of the lines'
crossings found, median distance of the points on a line to its centre, and share of points more than 2 px from
every true line centre. With `--before PATH` the detector of that tree (its `wolfcal/field/detect.py`) is measured
on the same images too.
"""

from __future__ import annotations

import importlib.util
import subprocess
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path
from types import ModuleType

import numpy as np
import yaml

SOURCE_URL = "https://github.com/GuiFornes/field_detector"
LABELS = Path(__file__).resolve().with_name("realfield_lines.yaml")
NEAR_PX = 6.0  # a point this close to a labelled centre line is on it [px]
RENDER_SEEDS = (4, 5, 6)


def _reader(folder: Path) -> tuple[Callable[[str], np.ndarray], list[str]] | None:
    """Image reader (repository path -> BGR image) and the masks' repository paths of a working tree or a bare
    git mirror of the repository; None when `folder` holds neither."""
    import cv2

    def decode(data: bytes) -> np.ndarray:
        return cv2.imdecode(np.frombuffer(data, np.uint8), cv2.IMREAD_COLOR)

    if (folder / "mask-field").is_dir():
        masks = sorted(str(p.relative_to(folder)) for p in (folder / "mask-field").glob("log*/*.png"))
        return (lambda path: decode((folder / path).read_bytes())), masks
    git = ["git", "--git-dir", str(folder)]
    listing = subprocess.run([*git, "ls-tree", "-r", "--name-only", "HEAD", "mask-field"], capture_output=True)
    if listing.returncode != 0:
        return None
    masks = sorted(p for p in listing.stdout.decode().split() if p.endswith(".png"))
    return (lambda path: decode(subprocess.run([*git, "show", f"HEAD:{path}"], capture_output=True).stdout)), masks


def _detector(tree: Path) -> ModuleType:
    """The `wolfcal.field.detect` module of a source tree, loaded under its own name."""
    spec = importlib.util.spec_from_file_location(f"detect_{abs(hash(tree))}", tree / "wolfcal" / "field" / "detect.py")
    assert spec is not None and spec.loader is not None
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    return module


def _distance_to_polyline(points: np.ndarray, polyline: np.ndarray) -> np.ndarray:
    """(N,) distance [px] of points (N, 2) to a polyline (M, 2)."""
    a, b = polyline[:-1], polyline[1:]
    ab = b - a
    t = np.clip(((points[:, None] - a[None]) * ab[None]).sum(-1) / np.maximum((ab * ab).sum(-1), 1e-12), 0.0, 1.0)
    nearest = a[None] + t[..., None] * ab[None]
    return np.linalg.norm(points[:, None] - nearest, axis=-1).min(axis=1)


def _resampled(polyline: np.ndarray) -> np.ndarray:
    """Points every pixel along a polyline (M, 2)."""
    length = np.r_[0.0, np.cumsum(np.linalg.norm(np.diff(polyline, axis=0), axis=1))]
    s = np.linspace(0.0, length[-1], max(2, int(np.ceil(length[-1])) + 1))
    return np.column_stack([np.interp(s, length, polyline[:, 0]), np.interp(s, length, polyline[:, 1])])


def measure(detect: ModuleType, read: Callable[[str], np.ndarray], masks: list[str], labels: dict) -> dict:
    """The figures of one detector module on the repository's images (see the module docstring)."""
    import cv2

    iou, outside, points = [], 0, 0
    for mask_path in masks:
        image = read(mask_path.replace("mask-field/", "data/", 1))
        truth = cv2.cvtColor(read(mask_path), cv2.COLOR_BGR2GRAY) > 127
        region = detect.field_region(detect.turf_mask(image))
        iou.append((region & truth).sum() / max((region | truth).sum(), 1))
        uv = np.round(detect.detect_line_points(image).uv).astype(int)
        points += len(uv)
        outside += int((~truth[uv[:, 1], uv[:, 0]]).sum())
    true_points, false_points, coverage = 0, 0, []
    for name, lines in labels.items():
        uv = detect.detect_line_points(read(f"data/{name}-rgb.png")).uv
        polylines = [np.asarray(line, float) for line in lines]
        near = np.min([_distance_to_polyline(uv, p) for p in polylines], axis=0) if len(uv) else np.zeros(0)
        true_points += int((near <= NEAR_PX).sum())
        false_points += int((near > NEAR_PX).sum())
        for p in polylines:
            samples = _resampled(p)
            nearest = np.linalg.norm(samples[:, None] - uv[None], axis=-1).min(axis=1) if len(uv) else np.inf
            covered = np.zeros(len(samples), bool) | (nearest <= NEAR_PX)
            coverage.append(float(covered.mean()))
    return {
        "region_iou": {"median": float(np.median(iou)), "mean": float(np.mean(iou)), "min": float(np.min(iou))},
        "points_per_image": points / len(masks),
        "outside_share": outside / max(points, 1),
        "true_points": true_points,
        "false_points": false_points,
        "line_coverage": {"median": float(np.median(coverage)), "mean": float(np.mean(coverage))},
        "lines_half_covered": int(np.sum(np.asarray(coverage) >= 0.5)),
    }


def rendered(detect: ModuleType) -> dict:
    """Detection figures of one detector module on rendered views, per light (see the module docstring)."""
    from wolfcal.camera.camera_info import load_camera_info
    from wolfcal.field.ground import expected_line_width, ground_points, ground_step
    from wolfcal.field.model import KIDSIZE, distance_to_lines, field_lines
    from wolfcal.field.quality import detection_quality
    from wolfcal.field.render import render_field_view
    from wolfcal.field.scene import WARM_LIGHT, cluttered_scene

    camera = load_camera_info(Path(__file__).resolve().parents[1] / "configs/wolfgang/basler_acA2040.yaml").binned(4)
    pitch, lines = 0.35, field_lines(KIDSIZE)
    forward = np.array([np.cos(pitch), 0.0, -np.sin(pitch)])
    right = np.array([0.0, -1.0, 0.0])
    T = np.eye(4)
    T[:3, :3] = np.column_stack([right, np.cross(forward, right), forward])
    T[:3, 3] = [-3.0, 0.0, 0.6]  # a standing robot's head at the penalty mark, looking down the field
    width = expected_line_width(camera, T, KIDSIZE.line_width)
    figures = {}
    for light, cast in (("neutral", (1.0, 1.0, 1.0)), ("warm", WARM_LIGHT)):
        on = found = crossings = points = off = 0
        centre: list[np.ndarray] = []
        for seed in RENDER_SEEDS:
            rng = np.random.default_rng(seed)
            scene = replace(cluttered_scene(KIDSIZE, rng), colour_cast=cast)
            view = render_field_view(camera, T, KIDSIZE, scene, rng, noise_sigma=3.0, blur_px=2.0)
            found_points = detect.detect_line_points(view.image, width)
            q = detection_quality(found_points, view.line_mask, camera, T, lines, step=4, max_run_px=12)
            on, found, crossings, points = on + q.on_line, found + q.found, crossings + q.crossings, points + q.points
            centre.append(q.centre_error_px)
            uv = found_points.uv
            px = distance_to_lines(lines, ground_points(camera, T, uv)) / np.nanmin(ground_step(camera, T, uv), axis=1)
            off += int(np.sum(~(px <= 2.0)))
        figures[light] = {
            "points": points,
            "precision": on / max(points, 1),
            "recall": found / max(crossings, 1),
            "centre_px_median": float(np.median(np.concatenate(centre))) if points else None,
            "off_2px_share": off / max(points, 1),
        }
    return figures


def realfield(source: Path | None, trees: dict[str, Path], say) -> dict | None:
    """Measure the detector of each tree (name -> folder holding `wolfcal`); None (and a message) when the
    repository's images are not at `source`."""
    found = _reader(source) if source is not None else None
    if found is None:
        say(f"realfield: skipped: pass --field-images PATH, a clone of {SOURCE_URL} (working tree or bare mirror)")
        return None
    read, masks = found
    labels = yaml.safe_load(LABELS.read_text())["images"]
    result: dict = {"masks": len(masks), "labelled_images": len(labels), "labelled_lines": 0, "near_px": NEAR_PX}
    result["labelled_lines"] = sum(len(lines) for lines in labels.values())
    for name, tree in trees.items():
        detector = _detector(tree)
        figures = measure(detector, read, masks, labels)
        figures["rendered"] = rendered(detector)
        result[name] = figures
        say(
            f"realfield {name}: region IoU median {figures['region_iou']['median']:.3f}, points outside the field "
            f"{100 * figures['outside_share']:.1f} %, true / false points {figures['true_points']} / "
            f"{figures['false_points']}, line coverage median {figures['line_coverage']['median']:.2f}"
        )
    return result


def _rendered_cell(f: dict) -> str:
    if not f["points"]:
        return "no points"
    centre = "n/a" if f["centre_px_median"] is None else f"{f['centre_px_median']:.2f} px"
    return f"{100 * f['precision']:.0f} % / {100 * f['recall']:.0f} % / {centre} / {100 * f['off_2px_share']:.0f} %"


def realfield_section(results: dict) -> list[str]:
    """The docs/accuracy.md section of the part (nothing when it was not run)."""
    if "realfield" not in results:
        return []
    r = results["realfield"]
    trees = [name for name in ("before", "after") if name in r]
    rows = [
        ["field region: IoU with the masks, median / min"]
        + [f"{r[t]['region_iou']['median']:.3f} / {r[t]['region_iou']['min']:.3f}" for t in trees],
        ["line points per image (masked images)"] + [f"{r[t]['points_per_image']:.0f}" for t in trees],
        ["points outside the field's mask"] + [f"{100 * r[t]['outside_share']:.1f} %" for t in trees],
        ["points on a labelled line / elsewhere"] + [f"{r[t]['true_points']} / {r[t]['false_points']}" for t in trees],
        ["share of points on a labelled line"]
        + [f"{100 * r[t]['true_points'] / max(r[t]['true_points'] + r[t]['false_points'], 1):.0f} %" for t in trees],
        ["labelled line length covered, median / mean"]
        + [f"{r[t]['line_coverage']['median']:.2f} / {r[t]['line_coverage']['mean']:.2f}" for t in trees],
        [f"labelled lines at least half covered (of {r['labelled_lines']})"]
        + [str(r[t]["lines_half_covered"]) for t in trees],
    ]
    for light in ("neutral", "warm"):
        rows.append(
            [f"rendered, {light} light: on a line / crossings found / centre error / off lines by > 2 px"]
            + [_rendered_cell(r[t]["rendered"][light]) for t in trees]
        )
    head = ["figure", *trees]
    return [
        "## Field lines on real robot-camera images",
        "",
        f"Head-camera images of a RoboCup humanoid robot (800x448, artificial turf in a hall under warm light, "
        f"people and stands beyond the field, motion blur) from {SOURCE_URL}, measured locally (the images are "
        f"not part of wolfcal): the field region against the repository's {r['masks']} hand-made masks, and line "
        f"points against the field lines labelled by hand on {r['labelled_images']} of these images "
        f"(`bench/realfield_lines.yaml`): a point within {r['near_px']:.0f} px of a labelled line is on it; a "
        "line's coverage is the share of its length with a point that near. No camera model is known for these "
        "images, so the detector runs without the expected line width. The last rows: the same detector on "
        f"rendered cluttered views ({len(RENDER_SEEDS)} seeds, 512x384, with the expected line width) in neutral "
        "light and under a warm light seen without white balance, against their truth: share of points on a "
        "line pixel, of the lines' crossings found, median distance from the line centre, share of points more "
        "than 2 px from every line. `before`: the detector of the tree given by `--before`. "
        f"Taken {r['taken']}, {r['seconds']:.0f} s.",
        "",
        "| " + " | ".join(head) + " |",
        "|" + "---|" * len(head),
        *("| " + " | ".join(row) + " |" for row in rows),
        "",
    ]
