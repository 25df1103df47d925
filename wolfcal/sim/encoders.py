"""What a real robot's encoders report: true angle minus true offset, quantised to the servo's ticks."""

from __future__ import annotations

import numpy as np

TICKS_PER_TURN = 4096
RAD_PER_TICK = 2.0 * np.pi / TICKS_PER_TURN


def encoder_readings(q_true: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """(N, J) readings [rad] from true angles (N, J) and true offsets (J,), quantised to 4096 ticks per turn."""
    return np.round((q_true - offsets) / RAD_PER_TICK) * RAD_PER_TICK
