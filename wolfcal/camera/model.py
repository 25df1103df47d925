"""Pinhole camera with ROS/OpenCV distortion models, vectorised over any number of points.

Frames: points are given in the camera's optical frame (z forward, x right, y down), metres. Pixels follow OpenCV:
the centre of the top-left pixel is (0, 0).
Models (coefficient order as in ROS CameraInfo / OpenCV):
- plumb_bob: k1 k2 p1 p2 k3
- rational_polynomial: k1 k2 p1 p2 k3 k4 k5 k6
- equidistant (OpenCV fisheye): k1 k2 k3 k4
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

from wolfcal.errors import WolfcalError

MODELS = {"plumb_bob": 5, "rational_polynomial": 8, "equidistant": 4}


@dataclass(frozen=True)
class CameraModel:
    """Intrinsics of one camera at the resolution of its images."""

    width: int
    height: int
    K: np.ndarray  # (3, 3) camera matrix [px]
    D: np.ndarray  # distortion coefficients, length per MODELS
    distortion_model: str = "plumb_bob"
    name: str = "camera"
    extra: dict = field(default_factory=dict, compare=False)

    def __post_init__(self) -> None:
        if self.distortion_model not in MODELS:
            raise ValueError(f"unknown distortion model {self.distortion_model!r}; use one of {', '.join(MODELS)}")
        D = np.zeros(MODELS[self.distortion_model])
        given = np.asarray(self.D, dtype=float).ravel()
        D[: min(len(given), len(D))] = given[: len(D)]
        object.__setattr__(self, "D", D)
        object.__setattr__(self, "K", np.asarray(self.K, dtype=float).reshape(3, 3))

    @property
    def fx(self) -> float:
        """Focal length along x [px]."""
        return float(self.K[0, 0])

    @property
    def fy(self) -> float:
        """Focal length along y [px]."""
        return float(self.K[1, 1])

    @property
    def cx(self) -> float:
        """Principal point x [px] (OpenCV: centre of the top-left pixel at 0)."""
        return float(self.K[0, 2])

    @property
    def cy(self) -> float:
        """Principal point y [px] (OpenCV: centre of the top-left pixel at 0)."""
        return float(self.K[1, 2])

    def scaled(self, sx: float, sy: float, width: int, height: int) -> CameraModel:
        """The same lens at another resolution (e.g. binned images): pixel = scale * pixel (OpenCV centres)."""
        K = self.K.copy()
        K[0, 0] *= sx
        K[0, 1] *= sx
        K[1, 1] *= sy
        K[0, 2] = (K[0, 2] + 0.5) * sx - 0.5
        K[1, 2] = (K[1, 2] + 0.5) * sy - 0.5
        return CameraModel(width, height, K, self.D.copy(), self.distortion_model, self.name)

    def binned(self, b: int, name: str | None = None) -> CameraModel:
        """The same lens in images binned b x b (b = 1: this model). A WolfcalError naming `--binning` and the camera
        (`name`, else the model's) when b does not divide the size."""
        if b < 1 or self.width % b or self.height % b:
            raise WolfcalError(
                f"--binning {b}: must divide the size {self.width}x{self.height} of camera '{name or self.name}'"
            )
        return self if b == 1 else self.scaled(1 / b, 1 / b, self.width // b, self.height // b)

    # --- distortion on normalised coordinates -------------------------------------------------------------
    def distort_normalized(self, xy: np.ndarray) -> np.ndarray:
        """Ideal normalised coordinates (..., 2) = (X/Z, Y/Z) -> distorted normalised coordinates (..., 2)."""
        x, y = xy[..., 0], xy[..., 1]
        D = self.D
        r2 = x * x + y * y
        if self.distortion_model == "equidistant":
            r = np.sqrt(r2)
            theta = np.arctan(r)
            t2 = theta * theta
            theta_d = theta * (1 + t2 * (D[0] + t2 * (D[1] + t2 * (D[2] + t2 * D[3]))))
            scale = np.where(r > 1e-12, theta_d / np.where(r > 1e-12, r, 1.0), 1.0)
            return xy * scale[..., None]
        k1, k2, p1, p2, k3 = D[0], D[1], D[2], D[3], D[4]
        radial = 1 + r2 * (k1 + r2 * (k2 + r2 * k3))
        if self.distortion_model == "rational_polynomial":
            k4, k5, k6 = D[5], D[6], D[7]
            radial = radial / (1 + r2 * (k4 + r2 * (k5 + r2 * k6)))
        xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
        yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
        return np.stack([xd, yd], axis=-1)

    def undistort_normalized(self, xy_d: np.ndarray, iterations: int = 30) -> np.ndarray:
        """Inverse of `distort_normalized` by Newton's method (numerical 2x2 Jacobian), accurate to ~1e-12."""
        xy_d = np.asarray(xy_d, dtype=float)
        xy = xy_d.copy()
        h = 1e-7
        for _ in range(iterations):
            f = self.distort_normalized(xy) - xy_d
            if np.max(np.abs(f), initial=0.0) < 1e-13:
                break
            fx = (self.distort_normalized(xy + [h, 0.0]) - xy_d - f) / h
            fy = (self.distort_normalized(xy + [0.0, h]) - xy_d - f) / h
            a, c = fx[..., 0], fx[..., 1]
            b, d = fy[..., 0], fy[..., 1]
            det = a * d - b * c
            det = np.where(np.abs(det) < 1e-12, 1e-12, det)
            dx = (d * f[..., 0] - b * f[..., 1]) / det
            dy = (-c * f[..., 0] + a * f[..., 1]) / det
            step = np.stack([dx, dy], axis=-1)
            xy = xy - np.clip(step, -0.5, 0.5)
        return xy

    # --- pixels -------------------------------------------------------------------------------------------
    def normalized_to_pixels(self, xy_d: np.ndarray) -> np.ndarray:
        """Distorted normalized image coordinates (..., 2) -> pixels (..., 2) [px] through K (with its skew)."""
        K = self.K
        u = K[0, 0] * xy_d[..., 0] + K[0, 1] * xy_d[..., 1] + K[0, 2]
        v = K[1, 1] * xy_d[..., 1] + K[1, 2]
        return np.stack([u, v], axis=-1)

    def pixels_to_normalized(self, uv: np.ndarray) -> np.ndarray:
        """Pixels (..., 2) [px] -> distorted normalized image coordinates (..., 2): the inverse of
        `normalized_to_pixels`."""
        K = self.K
        y = (uv[..., 1] - K[1, 2]) / K[1, 1]
        x = (uv[..., 0] - K[0, 2] - K[0, 1] * y) / K[0, 0]
        return np.stack([x, y], axis=-1)

    def project(self, p_camera: np.ndarray) -> np.ndarray:
        """Points in the optical frame (..., 3) [m] -> pixels (..., 2). Points behind the camera give NaN."""
        p = np.asarray(p_camera, dtype=float)
        z = p[..., 2]
        safe_z = np.where(z > 1e-9, z, np.nan)
        xy = p[..., :2] / safe_z[..., None]
        return self.normalized_to_pixels(self.distort_normalized(xy))

    def unproject(self, uv: np.ndarray) -> np.ndarray:
        """Pixels (..., 2) -> unit-free rays (..., 3) with z = 1 in the optical frame."""
        xy = self.undistort_normalized(self.pixels_to_normalized(np.asarray(uv, dtype=float)))
        return np.concatenate([xy, np.ones(xy.shape[:-1] + (1,))], axis=-1)

    def in_image(self, uv: np.ndarray, margin: float = 0.0) -> np.ndarray:
        """Whether pixels (..., 2) lie inside the image, `margin` pixels from its border (NaN is outside)."""
        u, v = uv[..., 0], uv[..., 1]
        with np.errstate(invalid="ignore"):
            return (
                (u >= margin - 0.5)
                & (u <= self.width - 0.5 - margin)
                & (v >= margin - 0.5)
                & (v <= self.height - 0.5 - margin)
            )
