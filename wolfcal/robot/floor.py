"""The floor a robot stands on: the plane of its standing soles (config `floor.soles`)."""

from __future__ import annotations

import numpy as np


def floor_frames(sole_poses: np.ndarray) -> np.ndarray:
    """T_base_floor (N, 4, 4) from the poses of the soles (K, N, 4, 4) in the base frame: origin midway between
    the soles, z along their mean z axis, x along their mean x axis made orthogonal to z."""
    origin = sole_poses[:, :, :3, 3].mean(axis=0)
    z = sole_poses[:, :, :3, 2].mean(axis=0)
    z /= np.linalg.norm(z, axis=1, keepdims=True)
    x = sole_poses[:, :, :3, 0].mean(axis=0)
    x -= np.einsum("ni,ni->n", x, z)[:, None] * z
    x /= np.linalg.norm(x, axis=1, keepdims=True)
    T = np.tile(np.eye(4), (len(origin), 1, 1))
    T[:, :3, 0], T[:, :3, 1], T[:, :3, 2], T[:, :3, 3] = x, np.cross(z, x), z, origin
    return T
