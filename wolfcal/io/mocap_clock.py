"""The clock offset between a motion-capture file and the ROS 2 recording of the joint states.

t_recording = t_file + offset [s], t_file: seconds since the file's first frame. Both streams see the same motion:
the markers' speed (per frame, the mean over markers of the speed of their centred 0.05 s moving median, so noise and
reflections do not count) and the joints' speed (sum of |dq/dt| over the joints) rise and fall together. Both
profiles are resampled on a `GRID_S` grid, normalised, and cross-correlated over every lag at which the two overlap
by at least `MIN_OVERLAP` of the shorter one (a session's moves repeat in rhythm: a half overlap can match a wrong
move); the peak, refined by a parabola through its neighbours, gives the offset. A peak
correlation below `MIN_CORRELATION` means the two do not show the same motion: the offset is not found.
"""

from __future__ import annotations

import numpy as np

from wolfcal.errors import WolfcalError
from wolfcal.io.mocap_samples import nanmedian
from wolfcal.io.mocap_trajectories import MarkerTrajectories
from wolfcal.io.recording import JointStates

GRID_S = 0.002  # resampling step of the speed profiles [s]
SMOOTH_S = 0.05  # moving-median width for marker positions, and smoothing of both profiles [s]
MIN_CORRELATION = 0.6
MIN_OVERLAP = 0.9


def _smooth(x: np.ndarray, n: int) -> np.ndarray:
    return np.convolve(x, np.ones(n) / n, mode="same") if n > 1 else x


def marker_speed(traj: MarkerTrajectories, columns: list[int], grid: np.ndarray) -> np.ndarray:
    """Mean marker speed [m/s] on `grid` [s since the file's first frame]."""
    t = traj.times_ns / 1e9
    xyz = traj.xyz[:, columns]
    width = 2 * int(round(SMOOTH_S / max(np.median(np.diff(t)), 1e-6) / 2)) + 1  # odd: centred, no delay
    pad = width // 2
    padded = np.concatenate([np.repeat(xyz[:1], pad, 0), xyz, np.repeat(xyz[-1:], pad, 0)])
    windows = np.lib.stride_tricks.sliding_window_view(padded, width, axis=0)[: len(xyz)]
    filtered = nanmedian(windows, axis=-1)  # (F, K, 3)
    speed = np.linalg.norm(np.gradient(filtered, t, axis=0), axis=2)
    with np.errstate(all="ignore"):
        mean = np.nanmean(np.where(np.isfinite(speed), speed, np.nan), axis=1)
    mean = np.nan_to_num(mean)
    return np.interp(grid, t, mean)


def joint_speed(states: JointStates, grid_ns: np.ndarray) -> np.ndarray:
    """Sum over joints of |dq/dt| [rad/s] on `grid_ns` [ns of the recording's clock]."""
    total = np.zeros(len(grid_ns))
    for name in states.names:
        s = states.series[name]
        if len(s.times) < 2:
            continue
        q = np.interp(grid_ns, s.times, s.positions)
        total += np.abs(np.gradient(q, grid_ns / 1e9))
    return total


def estimate_offset(traj: MarkerTrajectories, columns: list[int], states: JointStates) -> float:
    """The offset [s] (t_recording = t_file + offset); a clear error when the motions do not match."""
    n_smooth = max(1, int(round(SMOOTH_S / GRID_S)))
    file_grid = np.arange(0.0, traj.times_ns[-1] / 1e9, GRID_S)
    start = min(int(s.times[0]) for s in states.series.values())
    end = max(int(s.times[-1]) for s in states.series.values())
    rec_grid = np.arange(start, end, int(GRID_S * 1e9), dtype=np.int64)
    a = _smooth(marker_speed(traj, columns, file_grid), n_smooth)
    b = _smooth(joint_speed(states, rec_grid), n_smooth)
    if len(a) < 10 or len(b) < 10 or np.std(a) == 0 or np.std(b) == 0:
        raise _not_found(traj, "one of them shows no motion")
    c, lags = pearson_by_lag(a, b)
    k = int(np.argmax(c))
    if not np.isfinite(c[k]) or c[k] < MIN_CORRELATION:
        raise _not_found(traj, f"best correlation {c[k]:.2f} of their speed profiles, below {MIN_CORRELATION}")
    frac = 0.0
    if 0 < k < len(c) - 1 and np.all(np.isfinite(c[k - 1 : k + 2])):
        denom = c[k - 1] - 2 * c[k] + c[k + 1]
        frac = 0.5 * (c[k - 1] - c[k + 1]) / denom if denom < 0 else 0.0
    return (start + (lags[k] + frac) * GRID_S * 1e9) / 1e9


def pearson_by_lag(a: np.ndarray, b: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Pearson correlation of a[i] with b[i + k] over their overlap, for every lag k (-inf where the overlap is
    shorter than MIN_OVERLAP of the shorter series), and the lags."""
    n = len(a) + len(b)
    size = 1 << (n - 1).bit_length()
    ab = np.fft.irfft(np.conj(np.fft.rfft(a, size)) * np.fft.rfft(b, size), size)
    lags = np.arange(-len(a) + 1, len(b))
    ab = np.concatenate([ab[size - len(a) + 1 :], ab[: len(b)]])
    i0, i1 = np.maximum(0, -lags), np.minimum(len(a), len(b) - lags)  # overlap: a[i0:i1], b[i0+k:i1+k]
    ca, ca2 = np.concatenate([[0], np.cumsum(a)]), np.concatenate([[0], np.cumsum(a * a)])
    cb, cb2 = np.concatenate([[0], np.cumsum(b)]), np.concatenate([[0], np.cumsum(b * b)])
    m = (i1 - i0).astype(float)
    sa, saa = ca[i1] - ca[i0], ca2[i1] - ca2[i0]
    sb, sbb = cb[i1 + lags] - cb[i0 + lags], cb2[i1 + lags] - cb2[i0 + lags]
    with np.errstate(all="ignore"):
        c = (ab - sa * sb / m) / np.sqrt((saa - sa**2 / m) * (sbb - sb**2 / m))
    c[(m < MIN_OVERLAP * min(len(a), len(b))) | ~np.isfinite(c)] = -np.inf
    return c, lags


def _not_found(traj: MarkerTrajectories, why: str) -> WolfcalError:
    return WolfcalError(
        f"{traj.path}: cannot find the clock offset between this file and the joint-state recording ({why}); check "
        "that both are of the same session, or give it with --mocap-offset SECONDS (t_recording = t_file + offset)"
    )
