"""Random placements of a simulated external camera (the ranges of `wolfcal.placement`)."""

from __future__ import annotations

import numpy as np

from wolfcal.placement import AZIMUTH_RAD, DISTANCE_M, HEIGHT_M, ROLL_RAD, TARGET_BASE, TARGET_JITTER_M, look_at


def random_placement(rng: np.random.Generator) -> np.ndarray:
    """(4, 4) T_base_camera of a tripod drawn from the ranges of `wolfcal.placement` (its module docstring)."""
    distance, azimuth = rng.uniform(*DISTANCE_M), rng.uniform(*AZIMUTH_RAD)
    position_base = np.array([distance * np.cos(azimuth), distance * np.sin(azimuth), rng.uniform(*HEIGHT_M)])
    target_base = TARGET_BASE + rng.uniform(-TARGET_JITTER_M, TARGET_JITTER_M, 3)
    return look_at(position_base, target_base, rng.uniform(-ROLL_RAD, ROLL_RAD))
