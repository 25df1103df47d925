"""The order in which the robot takes the planned poses: short moves, starting from the rest pose.

A move's time is its largest joint travel over the profile velocity (every joint moves at that velocity at most, all
at once). Order: nearest neighbour from the rest pose, then 2-opt reversals of the open path while they shorten it.
"""

from __future__ import annotations

import numpy as np


def move_times(q: np.ndarray, velocity: float) -> np.ndarray:
    """(N, N) time of the move between every two configurations q (N, J) [rad] at `velocity` [rad/s] [s]."""
    return np.max(np.abs(q[:, None, :] - q[None, :, :]), axis=2) / velocity


def capture_order(q: np.ndarray, rest: np.ndarray, velocity: float) -> tuple[np.ndarray, float]:
    """(N,) visiting order of the poses q (N, J) from `rest` (J,), and the total time of the moves [s]."""
    points = np.vstack([rest[None], q])  # node 0: the rest pose
    T = move_times(points, velocity)
    path, left = [0], set(range(1, len(points)))
    while left:
        nxt = min(left, key=lambda k: T[path[-1], k])
        path.append(nxt)
        left.remove(nxt)
    improved = True
    while improved:
        improved = False
        for i in range(1, len(path) - 1):
            for j in range(i + 1, len(path)):
                a, b = path[i - 1], path[i]
                c, d = path[j], path[j + 1] if j + 1 < len(path) else None
                before = T[a, b] + (T[c, d] if d is not None else 0.0)
                after = T[a, c] + (T[b, d] if d is not None else 0.0)
                if after < before - 1e-12:
                    path[i : j + 1] = path[i : j + 1][::-1]
                    improved = True
    total = float(sum(T[a, b] for a, b in zip(path[:-1], path[1:])))
    return np.array(path[1:]) - 1, total
