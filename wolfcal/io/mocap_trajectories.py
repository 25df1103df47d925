"""Marker trajectories, the data every motion-capture reader returns (`mocap_files.read_mocap_file`, the C3D and
CSV readers, the ROS 2 Markers recordings), and the unit and time rules the readers share.

Times are frame times [ns] on the source's own clock (a file: time since its first frame, frame number / rate,
exact); positions are in metres, NaN where a marker was not measured; labels as the source writes them.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path

import numpy as np

from wolfcal.errors import WolfcalError

UNIT_SCALE = {"mm": 0.001, "millimeters": 0.001, "millimetres": 0.001, "cm": 0.01, "centimeters": 0.01,
              "centimetres": 0.01, "m": 1.0, "meters": 1.0, "metres": 1.0}  # fmt: skip
USE_INDEX = 1  # mocap4r2_msgs/msg/Marker id_type: USE_NAME = 0, USE_INDEX = 1, USE_BOTH = 2


@dataclass
class MarkerTrajectories:
    path: Path
    times_ns: np.ndarray  # (F,) int64 frame times on the source's clock [ns]
    labels: list[str]  # (K,) marker labels as the source names them, in its column order
    xyz: np.ndarray  # (F, K, 3) positions in the motion-capture frame [m], NaN where not measured
    file_clock: bool  # True: times are since the file's first frame (a clock offset to the joint states is needed)
    format: str = ""  # what wrote it, e.g. "Motive CSV 1.23", "C3D (Intel, float)", "Vicon Nexus CSV"
    rate_hz: float = 0.0  # frame rate the source states [Hz] (0: none, e.g. a recording)
    unit: str = "m"  # length unit as the source writes it ("Millimeters", "mm", "m")
    notes: list[str] = field(default_factory=list)  # what a person should know about the file (read nonetheless)


class NoMarkers(WolfcalError):
    """A readable file that holds no marker trajectories (analog channels, rotations or rigid bodies only)."""


def unit_scale(path: Path, units: str, where: str) -> float:
    """Metres per unit of `units` (as a file writes it: 'mm', 'Millimeters', 'm', NUL or space padded)."""
    key = units.replace("\0", "").strip().lower()
    if key not in UNIT_SCALE:
        found = f"{units.replace(chr(0), '').strip()!r}" if key else "none"
        raise WolfcalError(
            f"{path}: {where} gives no length unit this reader knows (found {found}); the file must state mm, cm or m"
        )
    return UNIT_SCALE[key]


def times_from_frames(frames: np.ndarray, rate_hz: float) -> np.ndarray:
    """(F,) int64 [ns] since the first frame: (frame - first frame) / rate, exact to the nanosecond."""
    return np.round((frames - frames[0]) / rate_hz * 1e9).astype(np.int64)
