"""Joint encoders of the Dynamixel servos: resolution, and what a robot's encoders report.

Joint angle [rad] = (present position - 2048) * RAD_PER_TICK; the sign of a joint comes from the URDF axis only.
"""

from __future__ import annotations

import numpy as np

TICKS_PER_TURN = 4096
RAD_PER_TICK = 2.0 * np.pi / TICKS_PER_TURN
QUANTISATION_NOISE = RAD_PER_TICK / np.sqrt(12.0)  # standard deviation of rounding to a tick [rad]


def encoder_readings(q_true: np.ndarray, offsets: np.ndarray) -> np.ndarray:
    """(N, J) readings [rad] from true angles (N, J) and true offsets (J,): true angle minus offset, quantised to
    4096 ticks per turn (the encoder model q_model = q_measured + offset)."""
    return np.round((q_true - offsets) / RAD_PER_TICK) * RAD_PER_TICK
