"""Board corner detection in one image, and in many images on both cores.

Pixels follow OpenCV (centre of the top-left pixel is (0, 0)). Checkerboards: by default ("classic") the
`findChessboardCorners` search (`findChessboardCornersSB` where it fails) on a copy halved (pyrDown) to at
most 1000 px, then `cornerSubPix` at full size with a window sized from the corner spacing: on rendered boards
with blur and noise more accurate than the corners of `findChessboardCornersSB` (method "sb") and much faster
(docs/accuracy.md). Sharp real photographs want smaller windows, so every
view also carries its corners refined with the half-windows of `WINDOWS` (capped at the spacing-sized one),
and `wolfcal.intrinsics.refine_choice` keeps the window the data fit best. ChArUco boards:
`cv2.aruco.CharucoDetector`, then `cornerSubPix` with a half-window of 0.1 corner spacing (more accurate than
the detector's own corners; wider windows reach into the markers and bias them).
"""

from __future__ import annotations

from collections.abc import Callable, Iterable, Iterator
from concurrent.futures import ThreadPoolExecutor
from dataclasses import dataclass

import cv2
import numpy as np

from wolfcal.vision.board import Board

METHODS = ("classic", "sb")
_CLASSIC_MAX_SIDE = 1000  # the classic detector searches a copy halved to this size (speed), refines at full size
_MIN_CHARUCO_CORNERS = 6
_CHARUCO_WINDOW = 0.1  # ChArUco cornerSubPix half-window / corner spacing: larger windows reach the markers
WINDOWS = (3, 5, 7, 11)  # checkerboard cornerSubPix half-windows [px] tried besides the spacing-sized one
_SUBPIX_CRITERIA = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3)


@dataclass(frozen=True)
class Detection:
    """Corners of one view: `corners` (N, 2) [px], `ids` (N,) indices into `Board.object_points()`."""

    name: str
    corners: np.ndarray
    ids: np.ndarray
    image_size: tuple[int, int]  # (width, height)
    alternatives: tuple[tuple[int, np.ndarray], ...] = ()  # (cornerSubPix half-window [px], corners (N, 2))


@dataclass(frozen=True)
class Failure:
    """A view that gave no corners, and why."""

    name: str
    reason: str


def to_gray(image: np.ndarray) -> np.ndarray:
    """uint8 gray copy of a gray, BGR or BGRA image."""
    if image.ndim == 3:
        code = cv2.COLOR_BGRA2GRAY if image.shape[2] == 4 else cv2.COLOR_BGR2GRAY
        image = cv2.cvtColor(image, code)
    if image.dtype != np.uint8:
        image = cv2.normalize(image, None, 0, 255, cv2.NORM_MINMAX)  # type: ignore[call-overload]  # dst=None is valid; the stubs lack it.astype(np.uint8)
    return image


def subpix_window(corners: np.ndarray, cols: int, rows: int) -> int:
    """cornerSubPix half-window [px]: under half the smallest spacing of neighbouring corners, 2..15."""
    grid = corners.reshape(rows, cols, 2)
    spacing = min(
        np.linalg.norm(np.diff(grid, axis=1), axis=2).min(initial=np.inf),
        np.linalg.norm(np.diff(grid, axis=0), axis=2).min(initial=np.inf),
    )
    return int(np.clip(np.floor(spacing / 2) - 1, 2, 15))


def _find_coarse(small: np.ndarray, size: tuple[int, int], fallback: bool) -> np.ndarray | None:
    """Pixel-level corners: the classic search (two threshold settings), else the sector-based one.

    FAST_CHECK only for live frames (`fallback` False), where most frames may show no board: on images with a
    board it made the search slower (OpenCV 5) and missed some boards.
    """
    base = cv2.CALIB_CB_ADAPTIVE_THRESH | (0 if fallback else cv2.CALIB_CB_FAST_CHECK)
    for flags in (base | cv2.CALIB_CB_NORMALIZE_IMAGE, base):
        found, corners = cv2.findChessboardCorners(small, size, flags=flags)
        if found:
            return corners.reshape(-1, 2)
    if not fallback:
        return None
    found, corners = cv2.findChessboardCornersSB(small, size, flags=cv2.CALIB_CB_NORMALIZE_IMAGE)
    return corners.reshape(-1, 2) if found else None


def _subpix(gray: np.ndarray, corners: np.ndarray, win: int) -> np.ndarray:
    start = corners.astype(np.float32).reshape(-1, 1, 2)
    return cv2.cornerSubPix(gray, start, (win, win), (-1, -1), _SUBPIX_CRITERIA).reshape(-1, 2).astype(float)


def _checkerboard_classic(
    gray: np.ndarray, board: Board, fallback: bool
) -> tuple[np.ndarray, tuple[tuple[int, np.ndarray], ...]] | None:
    """Corners refined with the spacing-sized window, and with each of `WINDOWS` capped at it (files only)."""
    small, factor = gray, 1
    while max(small.shape) > _CLASSIC_MAX_SIDE:  # Gaussian pyramid: faster than an INTER_AREA resize
        small, factor = cv2.pyrDown(small), factor * 2
    corners = _find_coarse(small, (board.cols, board.rows), fallback)
    if corners is None:
        return None
    corners = corners * factor  # pyrDown's pixel i is centred on pixel factor * i of the full image
    win = subpix_window(corners, board.cols, board.rows)
    spaced = _subpix(gray, corners, win)
    others = WINDOWS if fallback else ()
    return spaced, tuple((w, spaced if w >= win else _subpix(gray, corners, w)) for w in others)


def _checkerboard_sb(gray: np.ndarray, board: Board) -> np.ndarray | None:
    flags = cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_ACCURACY
    found, corners = cv2.findChessboardCornersSB(gray, (board.cols, board.rows), flags=flags)
    return corners.reshape(-1, 2) if found else None


def _charuco(gray: np.ndarray, board: Board) -> tuple[np.ndarray, np.ndarray] | None:
    detector = cv2.aruco.CharucoDetector(board.charuco())
    corners, ids, _, _ = detector.detectBoard(gray)
    if ids is None or len(ids) < _MIN_CHARUCO_CORNERS:
        return None
    corners = corners.reshape(-1, 2)
    distance = np.linalg.norm(corners[:, None] - corners[None], axis=2)
    np.fill_diagonal(distance, np.inf)
    win = int(max(2, round(_CHARUCO_WINDOW * distance.min())))
    criteria = (cv2.TERM_CRITERIA_EPS | cv2.TERM_CRITERIA_MAX_ITER, 50, 1e-3)
    refined = cv2.cornerSubPix(gray, corners.astype(np.float32).reshape(-1, 1, 2), (win, win), (-1, -1), criteria)
    return refined.reshape(-1, 2), ids.ravel().astype(int)


def detect_board(
    image: np.ndarray, board: Board, name: str = "image", method: str = "classic", fallback: bool = True
) -> Detection | Failure:
    """Find the board's corners in one image (gray or colour).

    `fallback`: let the classic checkerboard search fall back to the slower sector-based one (off for live
    frames, where a frame without a board must cost little).
    """
    gray = to_gray(image)
    size = (gray.shape[1], gray.shape[0])
    if board.is_charuco:
        charuco = _charuco(gray, board)
        if charuco is None:
            return Failure(name, f"fewer than {_MIN_CHARUCO_CORNERS} ChArUco corners found ({board.describe()})")
        return Detection(name, charuco[0].astype(float), charuco[1], size)
    alternatives: tuple[tuple[int, np.ndarray], ...] = ()
    if method == "sb":
        corners = _checkerboard_sb(gray, board)
    else:
        found = _checkerboard_classic(gray, board, fallback)
        corners, alternatives = found if found is not None else (None, ())
    if corners is None:
        return Failure(name, f"no {board.cols}x{board.rows} checkerboard found")
    return Detection(name, corners.astype(float), np.arange(board.n_corners), size, alternatives)


def probe_board_size(image: np.ndarray) -> tuple[int, int] | None:
    """Inner-corner size (cols, rows) of the largest checkerboard in the image, if any."""
    gray = to_gray(image)
    flags = cv2.CALIB_CB_NORMALIZE_IMAGE | cv2.CALIB_CB_EXHAUSTIVE | cv2.CALIB_CB_LARGER
    found, corners, meta = cv2.findChessboardCornersSBWithMeta(gray, (3, 3), flags)
    if not found or meta is None:
        return None
    return int(meta.shape[1]), int(meta.shape[0])


Job = tuple[str, Callable[[], np.ndarray]]  # a view's name and how to load it (raises OSError/ValueError)


def _run(job: Job, board: Board, method: str) -> Detection | Failure:
    name, load = job
    try:
        image = load()
    except (OSError, ValueError) as exc:
        return Failure(name, str(exc))
    return detect_board(image, board, name, method)


def detect_many(
    jobs: Iterable[Job],
    board: Board,
    method: str = "classic",
    workers: int = 2,
    progress: Callable[[Detection | Failure], None] | None = None,
) -> Iterator[Detection | Failure]:
    """Load and detect views on `workers` threads (OpenCV releases the GIL); results in input order."""
    with ThreadPoolExecutor(max_workers=max(1, workers)) as pool:
        for result in pool.map(lambda job: _run(job, board, method), jobs):
            if progress:
                progress(result)
            yield result
