"""SE(3)/SO(3) helpers, batched over leading axes.

Conventions: `T_a_b` maps points in frame b to frame a (`p_a = T_a_b @ p_b`), arrays of poses are (..., 4, 4),
rotations (..., 3, 3), angles in radians, lengths in metres. URDF `rpy` is fixed-axis roll-pitch-yaw:
R = Rz(yaw) @ Ry(pitch) @ Rx(roll).
"""

from __future__ import annotations

import numpy as np


def skew(v: np.ndarray) -> np.ndarray:
    """(..., 3) vectors -> (..., 3, 3) cross-product matrices."""
    v = np.asarray(v, dtype=float)
    out = np.zeros(v.shape[:-1] + (3, 3))
    out[..., 0, 1], out[..., 0, 2] = -v[..., 2], v[..., 1]
    out[..., 1, 0], out[..., 1, 2] = v[..., 2], -v[..., 0]
    out[..., 2, 0], out[..., 2, 1] = -v[..., 1], v[..., 0]
    return out


def exp_so3(rotvec: np.ndarray) -> np.ndarray:
    """Rotation vectors (..., 3) [rad] -> rotation matrices (..., 3, 3) (Rodrigues, exact near zero)."""
    rotvec = np.asarray(rotvec, dtype=float)
    theta = np.linalg.norm(rotvec, axis=-1)[..., None, None]
    K = skew(rotvec)
    small = theta < 1e-8
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 1.0 - theta**2 / 6.0, np.sin(safe) / safe)
    b = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(safe)) / safe**2)
    return np.eye(3) + a * K + b * (K @ K)


def log_so3(R: np.ndarray) -> np.ndarray:
    """Rotation matrices (..., 3, 3) -> rotation vectors (..., 3) [rad]."""
    R = np.asarray(R, dtype=float)
    cos = np.clip((np.trace(R, axis1=-2, axis2=-1) - 1.0) / 2.0, -1.0, 1.0)
    theta = np.arccos(cos)
    w = np.stack([R[..., 2, 1] - R[..., 1, 2], R[..., 0, 2] - R[..., 2, 0], R[..., 1, 0] - R[..., 0, 1]], axis=-1)
    sin = np.sin(theta)
    small = sin < 1e-6
    factor = np.where(small, 0.5, theta / (2.0 * np.where(small, 1.0, sin)))
    out = factor[..., None] * w
    near_pi = small & (theta > 1.0)
    if np.any(near_pi):
        # theta ~ pi: axis from the largest diagonal of (R + I) / 2.
        B = (R[near_pi] + np.eye(3)) / 2.0
        idx = np.argmax(np.diagonal(B, axis1=-2, axis2=-1), axis=-1)
        axis = B[np.arange(len(idx)), :, idx]
        axis /= np.linalg.norm(axis, axis=-1, keepdims=True)
        out[near_pi] = axis * theta[near_pi][..., None]
    return out


def rotation_angle(R: np.ndarray) -> np.ndarray:
    """Angle [rad] of rotation matrices (..., 3, 3)."""
    return np.linalg.norm(log_so3(R), axis=-1)


def rpy_to_matrix(rpy: np.ndarray) -> np.ndarray:
    """URDF roll-pitch-yaw (..., 3) [rad] -> (..., 3, 3), R = Rz(yaw) Ry(pitch) Rx(roll)."""
    rpy = np.asarray(rpy, dtype=float)
    r, p, y = rpy[..., 0], rpy[..., 1], rpy[..., 2]
    cr, sr, cp, sp, cy, sy = np.cos(r), np.sin(r), np.cos(p), np.sin(p), np.cos(y), np.sin(y)
    R = np.empty(rpy.shape[:-1] + (3, 3))
    R[..., 0, 0] = cy * cp
    R[..., 0, 1] = cy * sp * sr - sy * cr
    R[..., 0, 2] = cy * sp * cr + sy * sr
    R[..., 1, 0] = sy * cp
    R[..., 1, 1] = sy * sp * sr + cy * cr
    R[..., 1, 2] = sy * sp * cr - cy * sr
    R[..., 2, 0] = -sp
    R[..., 2, 1] = cp * sr
    R[..., 2, 2] = cp * cr
    return R


def matrix_to_rpy(R: np.ndarray) -> np.ndarray:
    """(..., 3, 3) -> URDF roll-pitch-yaw (..., 3) [rad]; inverse of `rpy_to_matrix` (pitch in [-pi/2, pi/2])."""
    R = np.asarray(R, dtype=float)
    pitch = np.arcsin(np.clip(-R[..., 2, 0], -1.0, 1.0))
    gimbal = np.abs(R[..., 2, 0]) > 1.0 - 1e-9
    roll = np.where(gimbal, 0.0, np.arctan2(R[..., 2, 1], R[..., 2, 2]))
    yaw = np.where(
        gimbal,
        np.arctan2(-R[..., 0, 1], R[..., 1, 1]),
        np.arctan2(R[..., 1, 0], R[..., 0, 0]),
    )
    return np.stack([roll, pitch, yaw], axis=-1)


def make_transform(R: np.ndarray, t: np.ndarray) -> np.ndarray:
    """Rotation (..., 3, 3) and translation (..., 3) [m] -> homogeneous (..., 4, 4)."""
    R = np.asarray(R, dtype=float)
    t = np.asarray(t, dtype=float)
    shape = np.broadcast_shapes(R.shape[:-2], t.shape[:-1])
    T = np.zeros(shape + (4, 4))
    T[..., :3, :3] = R
    T[..., :3, 3] = t
    T[..., 3, 3] = 1.0
    return T


def transform_from_xyz_rpy(xyz, rpy) -> np.ndarray:
    """URDF origin (xyz [m], rpy [rad]) -> T_parent_child (..., 4, 4)."""
    return make_transform(rpy_to_matrix(np.asarray(rpy, dtype=float)), np.asarray(xyz, dtype=float))


def transform_from_twist_params(xyz_rxyz: np.ndarray) -> np.ndarray:
    """Frame correction Delta = Trans(x, y, z) @ Exp(rx, ry, rz) from (..., 6) [m, rad]."""
    p = np.asarray(xyz_rxyz, dtype=float)
    return make_transform(exp_so3(p[..., 3:]), p[..., :3])


def invert_transform(T: np.ndarray) -> np.ndarray:
    """Inverse of rigid transforms (..., 4, 4)."""
    R = np.swapaxes(T[..., :3, :3], -1, -2)
    t = -(R @ T[..., :3, 3, None])[..., 0]
    return make_transform(R, t)


def axis_angle_matrix(axis: np.ndarray, angle: np.ndarray) -> np.ndarray:
    """Rotation about a unit axis (3,) by angles (N,) [rad] -> (N, 3, 3)."""
    return exp_so3(np.asarray(angle, dtype=float)[..., None] * np.asarray(axis, dtype=float))


def transform_points(T: np.ndarray, points: np.ndarray) -> np.ndarray:
    """Apply transforms (..., 4, 4) to points (..., P, 3) -> (..., P, 3)."""
    return points @ np.swapaxes(T[..., :3, :3], -1, -2) + T[..., None, :3, 3]


def right_jacobian_so3(rotvec: np.ndarray) -> np.ndarray:
    """J_r (..., 3, 3) of rotation vectors (..., 3): Exp(r + dr) = Exp(r) @ Exp(J_r(r) @ dr) to first order."""
    r = np.asarray(rotvec, dtype=float)
    theta = np.linalg.norm(r, axis=-1)[..., None, None]
    K = skew(r)
    small = theta < 1e-6
    safe = np.where(small, 1.0, theta)
    a = np.where(small, 0.5 - theta**2 / 24.0, (1.0 - np.cos(safe)) / safe**2)
    b = np.where(small, 1.0 / 6.0 - theta**2 / 120.0, (safe - np.sin(safe)) / safe**3)
    return np.eye(3) - a * K + b * (K @ K)


def rigid_registration(p_b: np.ndarray, p_a: np.ndarray) -> np.ndarray:
    """T_a_b (4, 4), the rotation and translation (no scale) that best maps points p_b (N, 3) onto p_a (N, 3) in the
    least-squares sense (Kabsch / Umeyama, N >= 3 points not on one line)."""
    c_a, c_b = p_a.mean(axis=0), p_b.mean(axis=0)
    U, _, Vt = np.linalg.svd((p_a - c_a).T @ (p_b - c_b))
    D = np.diag([1.0, 1.0, np.sign(np.linalg.det(U @ Vt))])
    T = np.eye(4)
    T[:3, :3] = U @ D @ Vt
    T[:3, 3] = c_a - T[:3, :3] @ c_b
    return T


def tag_corners(size: float) -> np.ndarray:
    """(4, 3) corners of a tag with black-square edge `size` [m] in the tag frame, aruco order (here, not in
    `wolfcal.vision.tags`, so the fit's geometry does not load OpenCV)."""
    h = size / 2.0
    return np.array([[-h, h, 0.0], [h, h, 0.0], [h, -h, 0.0], [-h, -h, 0.0]])
