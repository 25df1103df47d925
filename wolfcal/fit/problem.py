"""The estimation problem: pixel residuals of tag corners plus Gaussian priors, in normalised units.

Unknowns are z = values / prior_sigma, so the prior residual is z itself. Data residual per corner and axis:
r = project(K, D, T_camera_tag(q_s + offsets) @ p_corner) - u_detected [px].

Noise model: the corners of one sample share the error of that sample's joint readings (encoder quantisation moves
the whole tag), and so do all frames taken at one still pose (identical readings, e.g. several frames of a
recording). Each such group's residuals have covariance C_g = sigma_px^2 I + sigma_q^2 A_g A_g^T with
A_g = d(uv_g)/d(q_g). Residuals are whitened by a block-diagonal W (W_g = chol(C_g)^-1), built once per solver
round at the current estimate, then passed through a Huber-shaped function so a misdetected corner cannot drag the
solution while priors stay purely quadratic. Everything is vectorised over corners; the only Python loops are over
joints (inside FK and for A) and over sample groups when W is rebuilt, never inside the residual.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse

from wolfcal.observations import Observations
from wolfcal.projection import corner_points, predict_corners
from wolfcal.robot.corrections import Corrections
from wolfcal.robot.parameters import ParameterSet
from wolfcal.robot.robot import Robot

BEHIND_CAMERA_PX = 1e4  # residual given to a corner that a candidate model puts behind the camera
JOINT_STEP = 1e-6  # finite-difference step for d(uv)/d(q) [rad]


def huber_sqrt(r: np.ndarray, k: float) -> np.ndarray:
    """Residual transform whose square is the Huber loss: r for |r| <= k, sign(r) sqrt(2k|r| - k^2) beyond."""
    a = np.abs(r)
    return np.where(a <= k, r, np.sign(r) * np.sqrt(np.maximum(2.0 * k * a - k * k, 0.0)))


@dataclass
class Problem:
    robot: Robot
    obs: Observations
    params: ParameterSet
    tag_ids: list[int]  # tags whose observations are used, in column order of T_camera_tag
    sigma_px: float = 0.2  # corner noise per axis [px]
    sigma_q: float = 0.00044  # joint reading noise [rad]
    huber_k: float = 3.0  # robust threshold in whitened units (standard deviations)
    weights: scipy.sparse.csr_matrix | None = field(default=None, repr=False)

    def __post_init__(self) -> None:
        self._points = corner_points(self.robot, self.obs, self.tag_ids)
        self.q = self.obs.q_measured
        # One whitening block per group of samples with identical joint readings (fixed: derived once here).
        _, group_of_sample = np.unique(self.q, axis=0, return_inverse=True)
        group_of_corner = group_of_sample.ravel()[self.obs.sample_index]
        self._blocks = [np.flatnonzero(group_of_corner == g) for g in np.unique(group_of_corner)]
        rows = [np.stack([2 * c, 2 * c + 1], axis=1).ravel() for c in self._blocks]  # u0 v0 u1 v1 ...
        self._weight_rows = np.concatenate([np.repeat(r, len(r)) for r in rows])
        self._weight_cols = np.concatenate([np.tile(r, len(r)) for r in rows])
        # A view is one tag seen in one sample: the unit in which outliers are left out.
        views, self.view_of_corner = np.unique(
            np.stack([self.obs.sample_index, self.obs.tag_ids], axis=1), axis=0, return_inverse=True
        )
        self.view_of_corner = self.view_of_corner.ravel()
        self.view_sample, self.view_tag = views[:, 0], views[:, 1]
        self.exclude(np.zeros(len(views), dtype=bool))
        self.linearize(np.zeros(len(self.params)))

    def values(self, z: np.ndarray) -> np.ndarray:
        return np.asarray(z) * self.params.prior_sigmas

    def corrections(self, z: np.ndarray) -> Corrections:
        return self.params.corrections(self.values(z))

    def predict(self, z: np.ndarray, q: np.ndarray | None = None) -> np.ndarray:
        """Predicted pixel positions (M, 2) of the observed corners (NaN behind the camera)."""
        return predict_corners(self.robot, self.obs, self.corrections(z), self.tag_ids, q, self._points)

    def pixel_residuals(self, z: np.ndarray) -> np.ndarray:
        """(M, 2) predicted minus detected [px]; corners behind the camera get a large finite value."""
        r = self.predict(z) - self.obs.uv
        return np.where(np.isfinite(r), r, BEHIND_CAMERA_PX)

    def joint_sensitivity(self, z: np.ndarray) -> np.ndarray:
        """(M, 2, J) d(uv)/d(q) of every corner with respect to its sample's joint readings [px/rad]."""
        uv0 = self.predict(z)
        columns = []
        for j in range(self.q.shape[1]):
            q = self.q.copy()
            q[:, j] += JOINT_STEP
            columns.append((self.predict(z, q) - uv0) / JOINT_STEP)
        return np.nan_to_num(np.stack(columns, axis=-1))

    def linearize(self, z: np.ndarray) -> None:
        """Recompute d(uv)/d(q) at z and rebuild the whitening for the current noise levels."""
        self._A = self.joint_sensitivity(z)
        self.set_noise(self.sigma_px)

    def set_noise(self, sigma_px: float) -> None:
        """Rebuild the whitening matrix for this corner noise [px] (encoder noise fixed). One block per group of
        samples with identical joint readings: frames of one still pose share its quantisation error."""
        self.sigma_px = sigma_px
        A = self._A
        vals = []
        for corners in self._blocks:
            A_g = A[corners].reshape(-1, A.shape[-1])  # (2c, J), rows ordered u0 v0 u1 v1 ...
            C = self.sigma_px**2 * np.eye(len(A_g)) + self.sigma_q**2 * (A_g @ A_g.T)
            vals.append(np.linalg.inv(np.linalg.cholesky(C)).ravel())
        n = 2 * len(self.obs.uv)
        self.weights = scipy.sparse.csr_matrix(
            (np.concatenate(vals), (self._weight_rows, self._weight_cols)), shape=(n, n)
        )

    def exclude(self, views: np.ndarray) -> None:
        """Give the residuals of these views (bool mask (V,) over (sample, tag) pairs) zero weight."""
        self.excluded = np.asarray(views, dtype=bool).copy()
        self.inlier_corners = ~self.excluded[self.view_of_corner]
        self._row_weight = np.repeat(self.inlier_corners, 2).astype(float)

    def whiten(self, residuals_px: np.ndarray) -> np.ndarray:
        """Whitened residuals (2M,) of pixel residuals (M, 2) under the current noise model, every view included."""
        return self.weights @ residuals_px.ravel()

    def residuals(self, z: np.ndarray) -> np.ndarray:
        """Robust whitened data residuals (zero for excluded views) followed by the prior residuals z
        (unit-variance Gaussian priors)."""
        whitened = self.whiten(self.pixel_residuals(z)) * self._row_weight
        return np.concatenate([huber_sqrt(whitened, self.huber_k), np.asarray(z, dtype=float)])
