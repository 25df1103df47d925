"""A plain OpenCV calibration script (the tutorial's recipe), the reference `wolfcal intrinsics` is measured
against: for each image, imread (gray), findChessboardCorners, cornerSubPix with a fixed half-window, then
calibrateCamera (plumb_bob). Serial, no report, no outlier rejection.

Usage: python bench/opencv_intrinsics.py FOLDER_OR_FILES... [--board 9x6] [--square 0.025] [--win 11]
Prints: images, views with the board, per-point RMS [px] (calibrateCamera's return value), fx fy cx cy [px],
and the wall time [s].
"""

from __future__ import annotations

import argparse
import time
from pathlib import Path

import cv2
import numpy as np

SUFFIXES = {".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff"}


def image_files(inputs: list[str]) -> list[Path]:
    files: list[Path] = []
    for item in map(Path, inputs):
        files += sorted(p for p in item.iterdir() if p.suffix.lower() in SUFFIXES) if item.is_dir() else [item]
    return files


def calibrate(files: list[Path], cols: int, rows: int, square: float, win: int) -> dict:
    """The plain recipe on `files` -> figures (see the module docstring)."""
    start = time.perf_counter()
    obj = np.zeros((cols * rows, 3), np.float32)
    obj[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * square
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)
    object_points, image_points, size = [], [], None
    for path in files:
        gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        size = gray.shape[::-1]
        found, corners = cv2.findChessboardCorners(gray, (cols, rows), None)
        if found:
            object_points.append(obj)
            image_points.append(cv2.cornerSubPix(gray, corners, (win, win), (-1, -1), criteria))
    rms, K, D, _, _ = cv2.calibrateCamera(object_points, image_points, size, None, None)
    return {
        "images": len(files),
        "views": len(image_points),
        "rms_per_point": float(rms),
        "fx": float(K[0, 0]),
        "fy": float(K[1, 1]),
        "cx": float(K[0, 2]),
        "cy": float(K[1, 2]),
        "seconds": time.perf_counter() - start,
    }


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("inputs", nargs="+")
    parser.add_argument("--board", default="9x6")
    parser.add_argument("--square", type=float, default=0.025)
    parser.add_argument("--win", type=int, default=11)
    args = parser.parse_args()
    cols, rows = map(int, args.board.lower().split("x"))
    r = calibrate(image_files(args.inputs), cols, rows, args.square, args.win)
    print(f"{r['views']}/{r['images']} views  RMS per point {r['rms_per_point']:.3f} px  fx {r['fx']:.2f} "
          f"fy {r['fy']:.2f} cx {r['cx']:.2f} cy {r['cy']:.2f}  {r['seconds']:.2f} s")  # fmt: skip


if __name__ == "__main__":
    main()
