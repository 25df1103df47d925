"""Marker trajectories from motion-capture sources: ROS 2 recordings with mocap4r2_msgs/msg/Markers, C3D files and
OptiTrack Motive / Vicon Nexus CSV exports.

Every reader returns `MarkerTrajectories`: frame times [ns] on the source's own clock (a recording: header stamps;
a file: time since its first frame, frame / rate) and positions in metres (NaN where a marker was not measured:
absent, NaN, or a C3D point whose residual is negative). Units come from the file (C3D `POINT:UNITS`, the CSV
header), never assumed: a file without them is refused.

C3D is read with the pure-python `c3d` package (numpy only, installs on any platform the robot's computer may
have; its Reader decodes Intel, DEC and SGI/MIPS processor formats and integer or float points).
"""

from __future__ import annotations

import csv
import struct
import warnings
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from wolfcal.errors import WolfcalError

UNIT_SCALE = {"mm": 0.001, "millimeters": 0.001, "millimetres": 0.001, "cm": 0.01, "m": 1.0, "meters": 1.0,
              "metres": 1.0}  # fmt: skip
USE_INDEX = 1  # mocap4r2_msgs/msg/Marker id_type: USE_NAME = 0, USE_INDEX = 1, USE_BOTH = 2


@dataclass
class MarkerTrajectories:
    path: Path
    times_ns: np.ndarray  # (F,) int64 frame times on the source's clock [ns]
    labels: list[str]  # (K,) marker labels as the source names them
    xyz: np.ndarray  # (F, K, 3) positions in the motion-capture frame [m], NaN where not measured
    file_clock: bool  # True: times are since the file's first frame (a clock offset to the joint states is needed)


def _scale(path: Path, units: str, where: str) -> float:
    key = units.strip().lower()
    if key not in UNIT_SCALE:
        found = f"{units.strip()!r}" if units.strip() else "none"
        raise WolfcalError(f"{path}: {where} gives no length unit this reader knows (found {found}); the file must "
                           f"state mm, cm or m")
    return UNIT_SCALE[key]


def read_c3d(path: Path) -> MarkerTrajectories:
    """Points of a C3D file; invalid points (negative residual) are NaN."""
    import c3d

    try:
        with path.open("rb") as handle, warnings.catch_warnings():
            warnings.simplefilter("ignore")
            reader = c3d.Reader(handle)
            units = reader.get("POINT:UNITS")
            scale = _scale(path, units.string_value if units is not None else "", "POINT:UNITS")
            labels = [str(label).strip() for label in reader.point_labels]
            frames = [points for _, points, _ in reader.read_frames()]
            rate = float(reader.point_rate)
    except (OSError, ValueError, AssertionError, struct.error) as exc:
        raise WolfcalError(f"{path}: not a readable C3D file ({exc})") from None
    if not frames:
        raise WolfcalError(f"{path}: the C3D file holds no frames")
    data = np.stack(frames)  # (F, K, 5): x, y, z, residual, camera mask
    xyz = data[:, :, :3] * scale
    xyz[data[:, :, 3] < 0] = np.nan
    times = np.round(np.arange(len(data)) / rate * 1e9).astype(np.int64)  # t_file: since the file's first frame
    return MarkerTrajectories(path, times, labels, xyz, file_clock=True)


def _csv_rows(path: Path) -> list[list[str]]:
    try:
        with path.open(newline="", encoding="utf-8-sig") as handle:
            return [row for row in csv.reader(handle)]
    except (OSError, UnicodeDecodeError) as exc:
        raise WolfcalError(f"{path}: cannot read the CSV file ({exc})") from None


def _numbers(path: Path, rows: list[list[str]], first: int, columns: list[int]) -> np.ndarray:
    """(F, len(columns)) floats of the data rows, NaN for empty cells."""
    out = np.full((len(rows) - first, len(columns)), np.nan)
    for i, row in enumerate(rows[first:]):
        for j, c in enumerate(columns):
            if c < len(row) and row[c].strip():
                try:
                    out[i, j] = float(row[c])
                except ValueError:
                    raise WolfcalError(f"{path}: row {first + i + 1}, column {c + 1}: {row[c]!r} is not a number"
                                       ) from None
    return out


def read_motive_csv(path: Path, rows: list[list[str]]) -> MarkerTrajectories:
    """OptiTrack Motive CSV export: a metadata line ('Format Version', ..., 'Length Units', 'Millimeters', ...),
    a blank line, then the rows Type / Name / ID / (Parent) / 'Rotation|Position' / 'Frame, Time (Seconds), X, Y, Z',
    then one line per frame. Columns of Type 'Marker' (labelled) are read; rigid bodies and unlabelled markers are
    not."""
    meta = rows[0]
    pairs = {meta[i].strip(): meta[i + 1].strip() for i in range(0, len(meta) - 1, 2)}
    scale = _scale(path, pairs.get("Length Units", ""), "the header's 'Length Units'")
    kinds = {r[0].strip(): i for i, r in enumerate(rows[:12]) if r and r[0].strip()}
    if "Type" not in kinds or "Name" not in kinds or "Frame" not in kinds:
        raise WolfcalError(f"{path}: not a Motive CSV export (no Type, Name and Frame rows)")
    types, names, axes = rows[kinds["Type"]], rows[kinds["Name"]], rows[kinds["Frame"]]
    labels, columns = [], []
    for c in range(2, len(types) - 2):
        if types[c].strip() == "Marker" and axes[c].strip() == "X":
            labels.append(names[c].split(":")[-1].strip())
            columns += [c, c + 1, c + 2]
    data = _numbers(path, rows, kinds["Frame"] + 1, [1] + columns)
    times = np.round((data[:, 0] - data[0, 0]) * 1e9).astype(np.int64)
    return MarkerTrajectories(path, times, labels, data[:, 1:].reshape(len(data), -1, 3) * scale, file_clock=True)


def read_vicon_csv(path: Path, rows: list[list[str]]) -> MarkerTrajectories:
    """Vicon Nexus CSV export of trajectories: 'Trajectories', the rate, the marker names ('Subject:Marker' above
    each X column), 'Frame, Sub Frame, X, Y, Z, ...', the units row (mm under each X, Y, Z), then one line per
    frame. Only the Trajectories section is read."""
    start = next((i for i, r in enumerate(rows) if r and r[0].strip() == "Trajectories"), None)
    if start is None or start + 4 >= len(rows):
        raise WolfcalError(f"{path}: not a Vicon Nexus CSV export (no 'Trajectories' section)")
    rate = float(rows[start + 1][0])
    names, axes, units = rows[start + 2], rows[start + 3], rows[start + 4]
    labels, columns = [], []
    for c in range(2, len(axes)):
        if axes[c].strip() == "X":
            labels.append(names[c].split(":")[-1].strip())
            columns += [c, c + 1, c + 2]
    if not labels:
        raise WolfcalError(f"{path}: the Trajectories section names no markers")
    scale = _scale(path, units[columns[0]] if columns[0] < len(units) else "", "the units row under X")
    end = next((i for i in range(start + 5, len(rows)) if not rows[i] or not rows[i][0].strip()), len(rows))
    data = _numbers(path, rows[:end], start + 5, [0] + columns)
    times = np.round((data[:, 0] - data[0, 0]) / rate * 1e9).astype(np.int64)
    return MarkerTrajectories(path, times, labels, data[:, 1:].reshape(len(data), -1, 3) * scale, file_clock=True)


def read_mocap_file(path: Path) -> MarkerTrajectories:
    """A C3D file or a Motive / Vicon CSV export, by its extension and header."""
    path = Path(path)
    if not path.is_file():
        raise WolfcalError(f"{path}: motion-capture file not found; check the path")
    if path.suffix.lower() == ".c3d":
        return read_c3d(path)
    if path.suffix.lower() == ".csv":
        rows = _csv_rows(path)
        if rows and rows[0] and rows[0][0].strip() == "Format Version":
            return read_motive_csv(path, rows)
        return read_vicon_csv(path, rows)
    raise WolfcalError(f"{path}: unknown motion-capture file type; give a .c3d file or a Motive / Vicon .csv export")
