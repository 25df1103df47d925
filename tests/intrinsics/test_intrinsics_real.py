"""Intrinsics on real photographs of a printed board (OpenCV's sample photos from two cameras) against a plain
OpenCV script on the same photos. The photos ship in tests/data/opencv_samples (see its README for source and
licence)."""

from __future__ import annotations

from pathlib import Path

import cv2
import numpy as np
import pytest

from wolfcal.intrinsics.pipeline import IntrinsicsOptions, run_intrinsics
from wolfcal.vision.board import Board

PHOTOS = Path(__file__).resolve().parents[1] / "data" / "opencv_samples"
BOARD = Board(9, 6, 0.025)


def photos(camera: str) -> list[Path]:
    found = sorted(PHOTOS.glob(f"{camera}*.jpg"))
    if len(found) < 10:
        pytest.skip(f"the sample photographs are not in {PHOTOS}")
    return found


def plain_opencv(files: list[Path], win: int) -> tuple[float, np.ndarray]:
    """The tutorial recipe: findChessboardCorners, cornerSubPix (half-window `win`), calibrateCamera."""
    obj = np.zeros((54, 3), np.float32)
    obj[:, :2] = np.mgrid[0:9, 0:6].T.reshape(-1, 2) * BOARD.square
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_MAX_ITER, 30, 0.001)
    points = []
    for path in files:
        gray = cv2.imread(str(path), cv2.IMREAD_GRAYSCALE)
        found, corners = cv2.findChessboardCorners(gray, (9, 6), None)
        assert found, path
        points.append(cv2.cornerSubPix(gray, corners, (win, win), (-1, -1), criteria))
    rms, K, _, _, _ = cv2.calibrateCamera([obj] * len(points), points, (640, 480), None, None)
    return rms, K


@pytest.mark.parametrize("camera", ["left", "right"])
def test_real_photos_fit_as_well_as_plain_opencv(camera, tmp_path):
    """Per-point RMS no worse than the better of OpenCV's 5x5 and 11x11 recipes, focal length within 3 of
    wolfcal's own standard deviations of the 5x5 recipe's (the spacing-sized window alone gave 0.50 / 0.98 px
    and a focal length 4-27 sigma off)."""
    files = photos(camera)
    out = tmp_path / "cam.yaml"
    result = run_intrinsics([str(f) for f in files], BOARD, out, IntrinsicsOptions(), say=lambda s: None)
    plain = {win: plain_opencv(files, win) for win in (5, 11)}
    best_rms = min(rms for rms, _ in plain.values())
    assert len(result.views) == len(files) and not result.rejected
    assert result.rms_per_point <= 1.05 * best_rms, (result.rms_per_point, best_rms)
    K5 = plain[5][1]
    for name, value, ref in (("fx", result.camera.fx, K5[0, 0]), ("fy", result.camera.fy, K5[1, 1])):
        assert abs(value - ref) < 3 * result.std[name], (name, value, ref, result.std[name])
    assert "cornerSubPix half-window" in (tmp_path / "cam_report" / "summary.md").read_text()
