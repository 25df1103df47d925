"""Calibrate intrinsics from board views: OpenCV's solver, rejection of outlier views, uncertainty.

Residual r = project(K, D, R_v p + t_v) - u_detected [px] for every corner p of every view v. Reported RMS:
- per point (OpenCV's `calibrateCamera` return value): sqrt(mean over corners of |r|^2);
- per axis (mrcal's): sqrt(mean over the 2N components of r) = per point / sqrt(2).
Standard deviations come from the Jacobian of all residuals with respect to the intrinsics and every view's
pose: cov = s^2 (J^T J)^-1 with s^2 = sum(r^2) / (2N - P) (the per-axis residual variance), marginalised over
the poses.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import cv2
import numpy as np

from wolfcal.camera.model import CameraModel
from wolfcal.errors import WolfcalError
from wolfcal.geometry import exp_so3
from wolfcal.intrinsics.detect import Detection
from wolfcal.outliers import INTRINSICS_VIEW_PX
from wolfcal.vision.board import Board

DISTORTION_NAMES = {
    "plumb_bob": ["k1", "k2", "p1", "p2", "k3"],
    "rational_polynomial": ["k1", "k2", "p1", "p2", "k3", "k4", "k5", "k6"],
    "equidistant": ["k1", "k2", "k3", "k4"],
}
MAX_REJECTED_SHARE = 1 / 3


@dataclass
class Calibration:
    """The estimated camera, its uncertainty and the per-view fit."""

    camera: CameraModel
    std: dict[str, float]  # 1-sigma of fx fy cx cy [px] and each distortion coefficient
    views: list[Detection]  # views used
    rvecs: np.ndarray  # (V, 3) board -> camera rotation vectors
    tvecs: np.ndarray  # (V, 3) [m]
    residuals: list[np.ndarray]  # (N_v, 2) reprojection residuals per view [px]
    rejected: list[tuple[Detection, float]] = field(default_factory=list)  # outlier views, their per-point RMS

    @property
    def view_rms(self) -> np.ndarray:
        """Per-point RMS of each used view [px]."""
        return np.array([np.sqrt(np.mean(np.sum(r**2, axis=1))) for r in self.residuals])

    @property
    def rms_per_point(self) -> float:
        """RMS reprojection error over all used points, Euclidean per point [px]."""
        r = np.concatenate(self.residuals)
        return float(np.sqrt(np.mean(np.sum(r**2, axis=1))))

    @property
    def rms_per_axis(self) -> float:
        """RMS reprojection error per image axis [px] (OpenCV's figure): `rms_per_point` / sqrt(2)."""
        return float(self.rms_per_point / np.sqrt(2.0))

    @property
    def n_points(self) -> int:
        """Board corners used, over all views."""
        return int(sum(len(r) for r in self.residuals))


def _project_all(
    camera: CameraModel, rvecs: np.ndarray, tvecs: np.ndarray, obj: np.ndarray, view: np.ndarray
) -> np.ndarray:
    """Pixels (N, 2) of stacked object points `obj` (N, 3), each seen in view `view[i]`."""
    R = exp_so3(rvecs)
    p = np.einsum("nij,nj->ni", R[view], obj) + tvecs[view]
    return camera.project(p)


def _camera(template: CameraModel, intrinsics: np.ndarray) -> CameraModel:
    K = np.array([[intrinsics[0], 0, intrinsics[2]], [0, intrinsics[1], intrinsics[3]], [0, 0, 1]])
    return CameraModel(template.width, template.height, K, intrinsics[4:], template.distortion_model, template.name)


def _intrinsics_std(
    camera: CameraModel,
    rvecs: np.ndarray,
    tvecs: np.ndarray,
    obj: np.ndarray,
    img: np.ndarray,
    view: np.ndarray,
) -> np.ndarray:
    """1-sigma of [fx, fy, cx, cy, D...] from the numerical Jacobian of all residuals (poses marginalised)."""
    x0 = np.concatenate([[camera.fx, camera.fy, camera.cx, camera.cy], camera.D])
    n_in, n_views = len(x0), len(rvecs)
    rows = 2 * len(obj)
    J = np.zeros((rows, n_in + 6 * n_views))
    for k in range(n_in):  # intrinsics: central differences
        h = 1e-6 * max(1.0, abs(x0[k]))
        plus, minus = x0.copy(), x0.copy()
        plus[k] += h
        minus[k] -= h
        J[:, k] = (
            _project_all(_camera(camera, plus), rvecs, tvecs, obj, view)
            - _project_all(_camera(camera, minus), rvecs, tvecs, obj, view)
        ).ravel() / (2 * h)
    pose = np.hstack([rvecs, tvecs])
    row_view = np.repeat(view, 2)
    for k in range(6):  # each view's rows depend on its own pose only: perturb all views at once
        h = 1e-7 if k < 3 else 1e-7 * max(1.0, float(np.abs(tvecs).max()))
        plus, minus = pose.copy(), pose.copy()
        plus[:, k] += h
        minus[:, k] -= h
        d = (
            _project_all(camera, plus[:, :3], plus[:, 3:], obj, view)
            - _project_all(camera, minus[:, :3], minus[:, 3:], obj, view)
        ).ravel() / (2 * h)
        J[np.arange(rows), n_in + 6 * row_view + k] = d
    r = (_project_all(camera, rvecs, tvecs, obj, view) - img).ravel()
    dof = max(rows - J.shape[1], 1)
    sigma2 = float(r @ r) / dof
    scale = np.linalg.norm(J, axis=0)
    scale[scale == 0] = 1.0
    Js = J / scale
    H = Js.T @ Js
    # Marginalise the poses by the Schur complement: each view's 6x6 pose block is independent of the others,
    # so the intrinsics block of H^-1 is (A - sum_v B_v C_v^-1 B_v^T)^-1 (no SVD of the whole of H).
    A, B = H[:n_in, :n_in], H[:n_in, n_in:].reshape(n_in, n_views, 6)
    C = H[n_in:, n_in:].reshape(n_views, 6, n_views, 6)[np.arange(n_views), :, np.arange(n_views), :]
    S = A - np.einsum("ivk,vkl,jvl->ij", B, np.linalg.pinv(C), B)
    cov = sigma2 * np.linalg.pinv(S) / np.outer(scale[:n_in], scale[:n_in])
    return np.sqrt(np.clip(np.diag(cov), 0, None))


def _solve(
    views: list[Detection], board: Board, model: str, size: tuple[int, int]
) -> tuple[CameraModel, np.ndarray, np.ndarray]:
    """OpenCV's calibration of the given views -> (camera, rvecs (V, 3), tvecs (V, 3))."""
    all_obj = board.object_points()
    obj = [all_obj[v.ids].astype(np.float32) for v in views]
    img = [v.corners.astype(np.float32) for v in views]
    criteria = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-12)
    try:
        if model == "equidistant":
            flags = cv2.CALIB_RECOMPUTE_EXTRINSIC | cv2.CALIB_FIX_SKEW
            _, K, D, rvecs, tvecs = cv2.fisheye.calibrate(  # type: ignore[call-overload]  # None K/D: stubs lack it
                [o.reshape(1, -1, 3).astype(np.float64) for o in obj],  # OpenCV 5 takes (1, N, 3) here
                [i.reshape(1, -1, 2).astype(np.float64) for i in img],
                size,
                None,
                None,
                flags=flags,
                criteria=criteria,
            )
        else:
            flags = cv2.CALIB_RATIONAL_MODEL if model == "rational_polynomial" else 0
            _, K, D, rvecs, tvecs = cv2.calibrateCamera(obj, img, size, None, None, flags=flags, criteria=criteria)
    except cv2.error as exc:
        raise WolfcalError(
            f"the {model} calibration did not converge ({exc.err}); take more views with the board "
            "tilted and covering the whole image, or try another --model"
        ) from None
    camera = CameraModel(size[0], size[1], K, np.asarray(D).ravel(), model)
    return camera, np.asarray(rvecs, float).reshape(-1, 3), np.asarray(tvecs, float).reshape(-1, 3)


@dataclass
class ViewFit:
    """OpenCV's calibration of some views, with every corner's board point, detection and residual (views in
    order)."""

    camera: CameraModel
    rvecs: np.ndarray  # (V, 3) board -> camera rotation vectors
    tvecs: np.ndarray  # (V, 3) [m]
    obj: np.ndarray  # (N, 3) board points of the corners [m]
    img: np.ndarray  # (N, 2) detected corners [px]
    view: np.ndarray  # (N,) view index of each corner
    residual: np.ndarray  # (N, 2) projected minus detected [px]


def fit_views(views: list[Detection], board: Board, model: str, size: tuple[int, int]) -> ViewFit:
    """Calibrate the views (`_solve`) and project every corner through the result."""
    camera, rvecs, tvecs = _solve(views, board, model, size)
    all_obj = board.object_points()
    obj = np.concatenate([all_obj[v.ids] for v in views])
    img = np.concatenate([v.corners for v in views])
    view = np.concatenate([np.full(len(v.ids), i) for i, v in enumerate(views)])
    return ViewFit(camera, rvecs, tvecs, obj, img, view, _project_all(camera, rvecs, tvecs, obj, view) - img)


def calibrate_views(
    views: list[Detection],
    board: Board,
    model: str = "plumb_bob",
    min_views: int = 10,
    reject_outliers: bool = True,
) -> Calibration:
    """Calibrate; while the worst view's RMS is an outlier (`INTRINSICS_VIEW_PX`), drop it and calibrate again."""
    if model not in DISTORTION_NAMES:
        raise WolfcalError(f"unknown --model {model!r}; use one of {', '.join(DISTORTION_NAMES)}")
    if len(views) < min_views:
        raise WolfcalError(
            f"only {len(views)} views with the board, at least {min_views} needed: add views (tilted, "
            "near and far, covering the image corners) or lower --min-views"
        )
    sizes = {v.image_size for v in views}
    if len(sizes) > 1:
        raise WolfcalError(f"the views have different image sizes {sorted(sizes)}; calibrate one resolution at a time")
    size = views[0].image_size
    used = list(views)
    rejected: list[tuple[Detection, float]] = []
    max_rejected = int(len(views) * MAX_REJECTED_SHARE)
    while True:
        fit = fit_views(used, board, model, size)
        residuals = [fit.residual[fit.view == i] for i in range(len(used))]
        rms = np.array([np.sqrt(np.mean(np.sum(e**2, axis=1))) for e in residuals])
        worst = int(np.argmax(rms))
        can_drop = len(rejected) < max_rejected and len(used) > min_views
        if not (reject_outliers and can_drop and INTRINSICS_VIEW_PX.flags(rms)[worst]):
            break
        rejected.append((used.pop(worst), float(rms[worst])))
    std = _intrinsics_std(fit.camera, fit.rvecs, fit.tvecs, fit.obj, fit.img, fit.view)
    names = ["fx", "fy", "cx", "cy", *DISTORTION_NAMES[model]]
    return Calibration(fit.camera, dict(zip(names, map(float, std), strict=True)), used, fit.rvecs, fit.tvecs,
                       residuals, rejected)  # fmt: skip
