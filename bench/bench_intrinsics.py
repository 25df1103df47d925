"""Benchmarks of `wolfcal intrinsics` on rendered boards of a known camera.

1. Corner accuracy of the checkerboard detectors against the rendered truth (RMS / max error, time per image):
   classic search + spacing-aware cornerSubPix (wolfcal's default), the same with OpenCV's sample 11x11
   window, and findChessboardCornersSB.
2. Calibration accuracy over several seeds (640x480, 16 views, blur and noise): focal error [%], principal point
   error [px], and how often the reported 1-sigma covers the true error (expect ~68 % / 95 % / 99.7 %).
3. Speed: 50 images at 1920x1080 from PNG files: load + detect (both cores) + calibrate + report, end to end.

Usage: python bench/bench_intrinsics.py [--quick]  (rendered images are cached in the system temp folder)
"""

from __future__ import annotations

import sys
import tempfile
import time
from concurrent.futures import ThreadPoolExecutor
from pathlib import Path

import cv2
import numpy as np

from wolfcal.intrinsics.calibrate import calibrate_views
from wolfcal.intrinsics.detect import Detection, detect_board
from wolfcal.intrinsics.pipeline import IntrinsicsOptions, run_intrinsics
from wolfcal.intrinsics.synthetic import example_camera, random_board_poses, render_view, true_corners
from wolfcal.vision.board import Board

BOARD = Board(9, 6, 0.025)
CACHE = Path(tempfile.gettempdir()) / "wolfcal_bench_intrinsics"


def rendered(width: int, height: int, n: int, seed: int, blur: float = 1.5):
    """(camera, poses, image paths) of `n` rendered views, cached as PNG."""
    camera = example_camera(width, height)
    poses = random_board_poses(camera, BOARD, n, np.random.default_rng(seed))
    folder = CACHE / f"{width}x{height}_n{n}_s{seed}_b{blur}"
    paths = [folder / f"view_{i:03d}.png" for i in range(n)]
    missing = [i for i, p in enumerate(paths) if not p.is_file()]
    if missing:
        folder.mkdir(parents=True, exist_ok=True)

        def make(i: int) -> None:
            image = render_view(camera, BOARD, poses[i], np.random.default_rng([seed, i]), 2.0, blur)
            cv2.imwrite(str(paths[i]), image)

        with ThreadPoolExecutor(2) as pool:
            list(pool.map(make, missing))
    return camera, poses, paths


def fixed_window(gray: np.ndarray) -> np.ndarray | None:
    """OpenCV sample practice: findChessboardCorners at full size, cornerSubPix with an 11x11 half-window."""
    found, corners = cv2.findChessboardCorners(gray, (BOARD.cols, BOARD.rows), flags=3)
    if not found:
        return None
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3)
    return cv2.cornerSubPix(gray, corners, (11, 11), (-1, -1), criteria).reshape(-1, 2)


def corner_accuracy(width: int, height: int, n: int) -> None:
    camera, poses, paths = rendered(width, height, n, seed=1)
    images = [cv2.imread(str(p), cv2.IMREAD_GRAYSCALE) for p in paths]
    methods = {
        "classic + spacing-aware cornerSubPix": lambda im: detect_board(im, BOARD, method="classic"),
        "classic + fixed 11x11 cornerSubPix": fixed_window,
        "findChessboardCornersSB (ACCURACY)": lambda im: detect_board(im, BOARD, method="sb"),
    }
    print(f"\ncorner accuracy, {n} views {width}x{height}, blur 1.5 px, noise 2 grey levels")
    for name, method in methods.items():
        errors, failed, start = [], 0, time.perf_counter()
        for T, image in zip(poses, images, strict=True):
            found = method(image)
            corners = found.corners if isinstance(found, Detection) else found
            if corners is None or not isinstance(corners, np.ndarray):
                failed += 1
                continue
            truth = true_corners(camera, BOARD, T)
            e1, e2 = (np.linalg.norm(c - truth, axis=1) for c in (corners, corners[::-1]))
            errors.append(e1 if e1.mean() < e2.mean() else e2)
        seconds = (time.perf_counter() - start) / n
        e = np.concatenate(errors)
        print(f"  {name:40s} RMS {np.sqrt(np.mean(e**2)):.3f} px  max {e.max():.3f} px  "
              f"failed {failed}/{n}  {1000 * seconds:.0f} ms/image")  # fmt: skip


def calibration_accuracy(seeds: int) -> None:
    print(f"\ncalibration accuracy, {seeds} seeds x 16 views 640x480 (plumb_bob)")
    z, focal, principal = [], [], []
    for seed in range(100, 100 + seeds):
        camera, _, paths = rendered(640, 480, 16, seed)
        found = [detect_board(cv2.imread(str(p), cv2.IMREAD_GRAYSCALE), BOARD, p.name) for p in paths]
        result = calibrate_views([d for d in found if isinstance(d, Detection)], BOARD, min_views=10)
        est = result.camera
        errors = {k: getattr(est, k) - getattr(camera, k) for k in ("fx", "fy", "cx", "cy")}
        z += [errors[k] / result.std[k] for k in errors]
        focal += [100 * errors["fx"] / camera.fx, 100 * errors["fy"] / camera.fy]
        principal += [errors["cx"], errors["cy"]]
    z = np.abs(np.array(z))
    print(f"  focal error: max |.| {np.abs(focal).max():.3f} %   principal point: max |.| "
          f"{np.abs(principal).max():.2f} px")  # fmt: skip
    print(f"  |error| / reported 1-sigma: within 1 sigma {np.mean(z < 1):.0%}, 2 sigma {np.mean(z < 2):.0%}, "
          f"3 sigma {np.mean(z < 3):.0%} (n = {len(z)})")  # fmt: skip


def speed(n: int) -> None:
    _, _, paths = rendered(1920, 1080, n, seed=2)
    out = CACHE / "bench_out" / "camera_info.yaml"
    for workers in (1, 2):
        start = time.perf_counter()
        run_intrinsics([str(paths[0].parent)], BOARD, out, IntrinsicsOptions(workers=workers), say=lambda s: None)
        print(f"  {n} images 1920x1080, {workers} worker(s): load + detect + calibrate + report "
              f"{time.perf_counter() - start:.1f} s")  # fmt: skip


def main() -> None:
    quick = "--quick" in sys.argv
    corner_accuracy(640, 480, 10 if quick else 30)
    corner_accuracy(1920, 1080, 5 if quick else 15)
    calibration_accuracy(3 if quick else 10)
    print("\nspeed")
    speed(50)


if __name__ == "__main__":
    main()
