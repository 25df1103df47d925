"""Simulated motion capture: where the markers really are, and what a motion-capture system reports of them.

True marker positions use true joint angles, the true model (frame corrections) and the true marker mounts (each
marker's offset from its configured place in its link [m]). Measurements add per-axis noise, drop occluded markers
and move some to a reflection a few millimetres away (the study's failure: a reflection detected as the LED).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from wolfcal.robot.corrections import Corrections
from wolfcal.robot.robot import Robot


@dataclass(frozen=True)
class MocapNoise:
    """What the simulated motion-capture system does to marker positions (SI units)."""

    sigma: float = 0.0003  # per axis [m]
    occluded: float = 0.03  # share of marker samples missing
    reflections: float = 0.01  # share of marker samples replaced by a reflection
    reflection_range: tuple[float, float] = (0.002, 0.02)  # distance of a reflection from the marker [m]
    mount_sigma: float = 0.001  # true mount offsets per axis [m]


def true_marker_positions(robot: Robot, q_true: np.ndarray, truth: Corrections, mounts: np.ndarray,
                          T_mocap_base: np.ndarray) -> np.ndarray:  # fmt: skip
    """(N, K, 3) markers of the robot config (in its order) in the mocap frame [m] at true angles q_true (N, J);
    `mounts` (K, 3) [m] are the true offsets from the configured places (link frames)."""
    markers = robot.config.marker_config().entries
    links = list(dict.fromkeys(m.link for m in markers))
    true_frames = Corrections(frames=truth.frames, tags=truth.tags)
    poses = robot.model.link_poses(np.atleast_2d(q_true), links, true_frames, base=robot.config.base_link)
    out = np.empty((len(np.atleast_2d(q_true)), len(markers), 3))
    for k, m in enumerate(markers):
        T = T_mocap_base @ poses[m.link]
        out[:, k] = np.einsum("nij,j->ni", T[:, :3, :3], np.asarray(m.xyz) + mounts[k]) + T[:, :3, 3]
    return out


def measure(p_true: np.ndarray, noise: MocapNoise, rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """Measured positions (N, K, 3) [m], NaN where occluded, and (N, K) bool marking reflections."""
    p = p_true + rng.normal(0.0, noise.sigma, p_true.shape)
    u = rng.uniform(size=p_true.shape[:2])
    occluded = u < noise.occluded
    reflection = (u >= noise.occluded) & (u < noise.occluded + noise.reflections)
    direction = rng.normal(size=p_true.shape)
    direction /= np.linalg.norm(direction, axis=-1, keepdims=True)
    distance = rng.uniform(*noise.reflection_range, size=p_true.shape[:2])
    p = np.where(reflection[..., None], p_true + direction * distance[..., None], p)
    p[occluded] = np.nan
    return p, reflection
